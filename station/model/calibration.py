"""The calibration of an IMU in the Zhang et al. (2010) parameterisation.

Frames
  p  platform frame defined by the accelerometers: x_p along the x accelerometer's sensing
     axis, y_p in the plane of the x and y sensing axes, z_p completing a right-handed frame.
  o  the same construction on the gyro sensing axes.

Forward model (what the sensors do), eqs. (1)-(6) of the paper:
  accel_raw = K_a T_a f_p + b_a          gyro_raw = K_g T_g R_po w_p + b_g
with K diagonal scale factors, T lower triangular with unit rows (the sensing directions in p or
o), R_po the inter-triad rotation (p to o coordinates, R_po ~ I + [theta x]).  f_p and w_p are
expressed in the IMU's declared unit (m/s^2 or standard g; deg/s or rad/s); for a "raw" unit
they are in m/s^2 and deg/s and K carries the unit (raw per m/s^2, raw per deg/s).

Compensation (what ``station apply`` does), always into m/s^2 and deg/s in frame p:
  f_p = accel_matrix (accel_raw - accel_bias)      w_p = gyro_matrix (gyro_raw - gyro_bias)
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from station.core import units

# Names, in order, of the parameters of the base model; the MC and the tests use them.
AXES = "xyz"
MISALIGNMENT_NAMES = ("yz", "zy", "zx")


def misalignment_angles(T: np.ndarray) -> np.ndarray:
    """(yz, zy, zx) angles in rad of a lower-triangular unit-row sensing matrix (paper eq. 3)."""
    return np.array([np.arcsin(T[1, 0]), -np.arcsin(T[2, 0]), np.arcsin(T[2, 1])])


@dataclass
class Calibration:
    accel_unit: str
    gyro_unit: str
    accel_scale: np.ndarray         # (3,) declared unit per declared unit (raw per m/s^2 if raw)
    accel_T: np.ndarray             # (3,3) unit sensing directions in p, lower triangular
    accel_bias: np.ndarray          # (3,) raw units
    gyro_scale: np.ndarray          # (3,) declared unit per declared unit (raw per deg/s if raw)
    gyro_T: np.ndarray              # (3,3) unit sensing directions in o, lower triangular
    gyro_bias: np.ndarray           # (3,) raw units
    R_po: np.ndarray                # (3,3) p coordinates -> o coordinates
    effects: list = field(default_factory=lambda: ["base_triads", "inter_triad"])
    fit: dict = field(default_factory=dict)
    provenance: dict = field(default_factory=dict)
    sigma: dict = field(default_factory=dict)          # name -> 1-sigma, in the reported unit
    correlation: tuple | None = None                   # (names, matrix)
    extra_parameters: list = field(default_factory=list)   # (name, value, unit) of added effects
    compensation_extra: dict = field(default_factory=dict)  # e.g. accel_lever_arm_m (3x3, m)
    effect_compensation: list = field(default_factory=list)  # per added effect: id, source, state,
                                                             #   parameters (reported units)
    # (name, value, unit, 1-sigma) of the effect parameters the capture does not reveal, held by
    # their priors in the fit: its posterior, in memory only (not written; fit.not_determined)
    held: list = field(default_factory=list)

    # --- unit factors: SI (m/s^2, deg/s) per raw unit; 1 for "raw" -------------------------
    @property
    def accel_factor(self) -> float:
        return units.accel_to_mps2_factor(self.accel_unit) or 1.0

    @property
    def gyro_factor(self) -> float:
        return units.gyro_to_dps_factor(self.gyro_unit) or 1.0

    # --- derived quantities ---------------------------------------------------------------
    @property
    def accel_misalignment_rad(self) -> np.ndarray:
        return misalignment_angles(self.accel_T)

    @property
    def gyro_misalignment_rad(self) -> np.ndarray:
        return misalignment_angles(self.gyro_T)

    @property
    def inter_triad_rad(self) -> np.ndarray:
        from station.model.rotation import rotvec_from_matrix     # (scipy's Rotation: 0.2 s to import)

        return rotvec_from_matrix(self.R_po)

    @property
    def accel_matrix(self) -> np.ndarray:
        return self.accel_factor * np.linalg.inv(np.diag(self.accel_scale) @ self.accel_T)

    @property
    def gyro_matrix(self) -> np.ndarray:
        return self.gyro_factor * self.R_po.T @ np.linalg.inv(np.diag(self.gyro_scale) @ self.gyro_T)

    def compensate(self, accel_raw: np.ndarray, gyro_raw: np.ndarray):
        """Raw samples (N,3) -> specific force (m/s^2) and rate (deg/s) in frame p."""
        f = (np.asarray(accel_raw) - self.accel_bias) @ self.accel_matrix.T
        w = (np.asarray(gyro_raw) - self.gyro_bias) @ self.gyro_matrix.T
        return f, w

    def parameters(self) -> list[tuple[str, float, str]]:
        """(name, value, unit) of every estimated parameter, in engineering units."""
        out: list[tuple[str, float, str]] = []
        a_unit = "1" if self.accel_unit != "raw" else "raw/(m/s^2)"
        g_unit = "1" if self.gyro_unit != "raw" else "raw/(deg/s)"
        for sensor, scale, mis, unit in (("accel", self.accel_scale, self.accel_misalignment_rad, a_unit),
                                         ("gyro", self.gyro_scale, self.gyro_misalignment_rad, g_unit)):
            out += [(f"{sensor}_scale_{a}", float(scale[i]), unit) for i, a in enumerate(AXES)]
            out += [(f"{sensor}_misalignment_{n}", float(mis[i] / units.ARCSEC_RAD), "arcsec")
                    for i, n in enumerate(MISALIGNMENT_NAMES)]
        if self.accel_unit == "raw":
            out += [(f"accel_bias_{a}", float(self.accel_bias[i]), "raw") for i, a in enumerate(AXES)]
        else:
            ug = self.accel_bias * self.accel_factor / units.UG_MPS2
            out += [(f"accel_bias_{a}", float(ug[i]), "ug") for i, a in enumerate(AXES)]
        if self.gyro_unit == "raw":
            out += [(f"gyro_bias_{a}", float(self.gyro_bias[i]), "raw") for i, a in enumerate(AXES)]
        else:
            dph = self.gyro_bias * self.gyro_factor * 3600.0
            out += [(f"gyro_bias_{a}", float(dph[i]), "deg/h") for i, a in enumerate(AXES)]
        theta = self.inter_triad_rad / units.ARCSEC_RAD
        out += [(f"inter_triad_{a}", float(theta[i]), "arcsec") for i, a in enumerate(AXES)]
        return out + list(self.extra_parameters)


def parameter_errors(estimate: Calibration, truth: Calibration) -> list[tuple[str, float, float, float, str]]:
    """(name, estimate, truth, error, error unit) per parameter; scale errors are relative, in ppm."""
    out = []
    for (name, value, unit), (_, true, _) in zip(estimate.parameters()[:21], truth.parameters()):
        if "_scale_" in name:
            out.append((name, value, true, (value / true - 1.0) * 1e6, "ppm"))
        else:
            out.append((name, value, true, value - true, unit))
    return out
