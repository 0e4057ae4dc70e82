"""The true (hidden) sensor error model of the simulated IMU, and its YAML file.

Physical model (case frame b; see docs/simulation.md for the exact equations):

    accel_raw = K_a S_a f_b             + b_a(T) + n_a      (raw units: m/s^2)
    gyro_raw  = K_g S_g w_ib_b [deg/s]  + b_g(T) + n_g      (raw units: deg/s)

S_a rows are the unit sensing directions u_ai of the three accelerometers in
case axes, each given by two small tilt angles from case axis i towards the
other two case axes; K_a = diag(scale).  Likewise for the gyros.  Optional
higher-order effects (all zero by default): accelerometer second-order
nonlinearity K2_i a_i^2 and cross-coupling sum_j C_ij a_i a_j (a in g, result
in ug, added like the bias), gyro g-sensitivity G f (deg/h per g, f in case
axes), scale-factor asymmetry (k_i (1 +- A_i) for +- input, gyros and
accelerometers), a temperature-dependent scale factor k_i (1 + s_i dT), a bias
step at a given bench time, the gyro rate-squared term k_i q_i r_i^2 and the
anisoelastic gyro term sum N_i,jk F_j F_k (deg/h per g^2).  Then quantisation
to an LSB (0 = none).

:meth:`Truth.paper_parameters` re-expresses this physical truth in the
parameterisation of Zhang et al. (2010), eqs. (1)-(6).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from scipy.spatial.transform import Rotation

from station.core.errors import UserError
from station.core import yaml_text

from .world import ARCSEC, DEG_PER_HOUR, G_STANDARD, MICRO_G, cross3

SCHEMA_VERSION = 1

#: default white-noise densities (Zhang 2010, table 4 settings)
DEFAULT_ACCEL_NOISE_UG_RTHZ = 100.0
DEFAULT_GYRO_NOISE_DPH_RTHZ = 0.03
DEFAULT_SAMPLE_RATE_HZ = 100.0

MAX_TILT_ARCSEC = 36000.0   # 10 degrees: beyond that it is not a "misalignment"
# Plausibility bounds of the higher-order effects (far beyond any real IMU; they catch unit
# mistakes, e.g. a ppm value entered as ug/g^2 * 1e6).
MAX_SECOND_ORDER_UG_PER_G2 = 1e5      # 10 % of full scale per g^2
MAX_G_SENSITIVITY_DPH_PER_G = 1e6     # ~280 deg/s per g
MAX_SCALE_ASYMMETRY_PPM = 1e5         # 10 %
MAX_TIME_OFFSET_S = 1.0
MAX_WOBBLE_ARCSEC = 3600.0            # 1 degree
MAX_SCALE_TEMPCO_PPM_PER_C = 1e4      # 1 % per degC
MAX_RATE_SQUARED_PPM_PER_DPS = 1e4    # 1 % per deg/s
MAX_ANISOELASTIC_DPH_PER_G2 = 1e6
MAX_VIBRATION_MG = 1e4                # 10 g
MAX_VIBRATION_REF_RATE_DPS = 1e4      # deg/s
MAX_IMBALANCE_G_MM = 1e7              # 10 kg m
MAX_BASE_MASS_KG = 1e6
MAX_REMOUNT_ARCSEC = 36000.0          # 10 degrees
MAX_ENCODER_SCALE_PPM = 1e4            # 1 %
MAX_JITTER_FRACTION = 0.1             # stamp jitter 1 sigma <= 10 % of the sample period

# The two "other" axes of each case axis, in x<y<z order: the columns of
# axis_tilt_arcsec.
OTHER_AXES = ((1, 2), (0, 2), (0, 1))
AXIS_NAMES = "xyz"
# Columns of gyroscope.anisoelastic_dph_per_g2: the products F_j F_k of case-axis specific force.
ANISOELASTIC_PRODUCTS = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))


# --------------------------------------------------------------------------
# Validation helpers
# --------------------------------------------------------------------------

class _Checker:
    """Validates fields of a loaded YAML mapping and names file + field on error."""

    def __init__(self, source: str):
        self.source = source

    def fail(self, field_name: str, msg: str):
        raise UserError(f"{self.source}: field '{field_name}': {msg}")

    def mapping(self, value, field_name: str, allowed: set[str]) -> dict:
        if value is None:
            return {}
        if not isinstance(value, dict):
            self.fail(field_name, f"expected a mapping, got {type(value).__name__}")
        for k in value:
            if not isinstance(k, str) or k not in allowed:
                full = f"{field_name}.{k}" if field_name else str(k)
                self.fail(full, f"unknown field (allowed: {', '.join(sorted(allowed))})")
        return value

    def number(self, value, field_name: str, *, lo=None, hi=None, lo_open=False,
               hi_open=False) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            self.fail(field_name, f"expected a number, got {value!r}")
        x = float(value)
        if not math.isfinite(x):
            self.fail(field_name, f"must be finite, got {value!r}")
        if lo is not None and (x < lo or (lo_open and x == lo)):
            self.fail(field_name, f"must be {'>' if lo_open else '>='} {lo}, got {x!r}")
        if hi is not None and (x > hi or (hi_open and x == hi)):
            self.fail(field_name, f"must be {'<' if hi_open else '<='} {hi}, got {x!r}")
        return x

    def vector(self, value, field_name: str, n: int = 3, **bounds) -> np.ndarray:
        if not isinstance(value, (list, tuple)) or len(value) != n:
            self.fail(field_name, f"expected a list of {n} numbers, got {value!r}")
        return np.array([self.number(v, f"{field_name}[{i}]", **bounds)
                         for i, v in enumerate(value)])

    def matrix(self, value, field_name: str, rows: int, cols: int, **bounds) -> np.ndarray:
        if not isinstance(value, (list, tuple)) or len(value) != rows:
            self.fail(field_name, f"expected {rows} rows of {cols} numbers, got {value!r}")
        return np.array([self.vector(r, f"{field_name}[{i}]", cols, **bounds)
                         for i, r in enumerate(value)])


# --------------------------------------------------------------------------
# Model pieces
# --------------------------------------------------------------------------

def sensing_axes(tilt_arcsec) -> np.ndarray:
    """Unit sensing directions (rows) in case axes from the 3x2 tilt angles.

    Row i: u_i = unit(e_i + tan(t_i0) e_j + tan(t_i1) e_k), where (j, k) are
    the other two case axes in x<y<z order.  For small angles u_i . e_j ~ t_i0.
    """
    tilt = np.asarray(tilt_arcsec, dtype=float).reshape(3, 2) * ARCSEC
    S = np.eye(3)
    for i, (j, k) in enumerate(OTHER_AXES):
        S[i, j] = math.tan(tilt[i, 0])
        S[i, k] = math.tan(tilt[i, 1])
    return S / np.linalg.norm(S, axis=1, keepdims=True)


def triad_frame(S: np.ndarray) -> np.ndarray:
    """Orthonormal frame defined by sensing axes (rows of S), Zhang 2010 sec. 2.

    x' = u_x; y' in the (u_x, u_y) plane (Gram-Schmidt); z' = x' x y'.
    Returns C (3x3), rows x', y', z' in case coordinates: C maps case
    coordinates to the triad frame (v' = C v_b).
    """
    x = S[0] / np.linalg.norm(S[0])
    y = S[1] - np.dot(S[1], x) * x
    y /= np.linalg.norm(y)
    z = cross3(x, y)
    return np.vstack([x, y, z])


def misalignment_angles(T: np.ndarray) -> np.ndarray:
    """(a_yz, a_zy, a_zx) = (asin T10, -asin T20, asin T21), Zhang 2010 eq. (3)."""
    return np.array([math.asin(T[1, 0]), -math.asin(T[2, 0]), math.asin(T[2, 1])])


@dataclass
class TriadTruth:
    """One sensor triad.

    ``bias`` and ``bias_tempco`` are in the triad's physical units
    (accelerometer: ug and ug/degC; gyro: deg/h and deg/h/degC),
    ``noise_density`` in ug/sqrt(Hz) or deg/h/sqrt(Hz), ``lsb`` in raw units.
    """

    scale: np.ndarray = field(default_factory=lambda: np.ones(3))
    axis_tilt_arcsec: np.ndarray = field(default_factory=lambda: np.zeros((3, 2)))
    bias: np.ndarray = field(default_factory=lambda: np.zeros(3))
    bias_tempco: np.ndarray = field(default_factory=lambda: np.zeros(3))
    noise_density: float = 0.0
    lsb: float = 0.0
    # accelerometers only: where each sensing element sits (row i: element i), m, case axes,
    # relative to the IMU reference point (the 2017 paper's size effect)
    position_m: np.ndarray = field(default_factory=lambda: np.zeros((3, 3)))
    # accelerometers only: second-order nonlinearity K2_i (ug/g^2), accel i adds K2_i a_i^2
    nonlinearity_ug_per_g2: np.ndarray = field(default_factory=lambda: np.zeros(3))
    # accelerometers only: cross-coupling C_ij (ug/g^2, zero diagonal), accel i adds
    # sum_{j != i} C_ij a_i f_j  (a_i along its sensing axis, f_j along case axis j, in g)
    cross_coupling_ug_per_g2: np.ndarray = field(default_factory=lambda: np.zeros((3, 3)))
    # gyros only: g-sensitivity G_ij (deg/h per g), gyro i adds sum_j G_ij f_j (f: case axes, g)
    g_sensitivity_dph_per_g: np.ndarray = field(default_factory=lambda: np.zeros((3, 3)))
    # scale-factor asymmetry A_i (ppm): scale k_i (1 + A_i 1e-6) for a positive input along the
    # sensing axis, k_i (1 - A_i 1e-6) for a negative one (gyros and accelerometers)
    scale_asymmetry_ppm: np.ndarray = field(default_factory=lambda: np.zeros(3))
    # temperature-dependent scale factor s_i (ppm/degC): scale k_i (1 + s_i 1e-6 (T - T_ref))
    scale_tempco_ppm_per_c: np.ndarray = field(default_factory=lambda: np.zeros(3))
    # a bias step (the triad's bias units: ug or deg/h) added from bench time bias_step_time_s on
    bias_step: np.ndarray = field(default_factory=lambda: np.zeros(3))
    bias_step_time_s: float = 0.0
    # gyros only: rate-squared scale term q_i (ppm per deg/s): gyro i adds k_i q_i 1e-6 r_i^2
    rate_squared_ppm_per_dps: np.ndarray = field(default_factory=lambda: np.zeros(3))
    # gyros only: anisoelastic term N (deg/h per g^2), row i: gyro i, columns the products
    # F_x^2, F_y^2, F_z^2, F_x F_y, F_x F_z, F_y F_z (F: case axes, g; ANISOELASTIC_PRODUCTS)
    anisoelastic_dph_per_g2: np.ndarray = field(default_factory=lambda: np.zeros((3, 6)))
    # accelerometers only: third-order nonlinearity K3_i (ug/g^3), accel i adds K3_i a_i^3
    cubic_ug_per_g3: np.ndarray = field(default_factory=lambda: np.zeros(3))
    # second-order bias temperature coefficient c2_i (bias units per degC^2): b += c2 dT^2
    bias_tempco2: np.ndarray = field(default_factory=lambda: np.zeros(3))
    # bias drifting linearly in bench time (bias units per hour): b += d t / 3600
    bias_drift_per_h: np.ndarray = field(default_factory=lambda: np.zeros(3))
    # gyros only: odd rate-squared scale term q'_i (ppm per deg/s): gyro i adds k_i q'_i 1e-6 r_i |r_i|
    rate_odd_squared_ppm_per_dps: np.ndarray = field(default_factory=lambda: np.zeros(3))
    # full-scale range (raw units; 0: none): the converter's output cannot go beyond +-full_scale,
    # an input beyond it reads the rail (the last code), as a real ADC saturates
    full_scale: float = 0.0
    # stuck samples: from each bench time in stuck_at_s on, for stuck_duration_s, the output
    # register of the axes in stuck_axes (0..2) stops updating and repeats the sample taken at
    # (or first after) that time, as a sensor whose data-ready is missed or a driver that resends
    # its last frame
    stuck_at_s: list = field(default_factory=list)
    stuck_duration_s: float = 0.0
    stuck_axes: list = field(default_factory=lambda: [0, 1, 2])
    # --- effects the station's library has no model for (issue 25: the term search and the
    # emitted plugin are measured on them, benchmarks/emit_cases.py)
    # second-order temperature coefficient of the scale factor s2_i (ppm/degC^2):
    # scale k_i (1 + s_i 1e-6 dT + s2_i 1e-6 dT^2)
    scale_tempco2_ppm_per_c2: np.ndarray = field(default_factory=lambda: np.zeros(3))
    # the sensing axes tilt with temperature (thermal stress on the mounting): the tilt angles
    # are axis_tilt_arcsec + axis_tilt_tempco_arcsec_per_c dT (arcsec/degC, the same 3x2 layout)
    axis_tilt_tempco_arcsec_per_c: np.ndarray = field(default_factory=lambda: np.zeros((3, 2)))
    # bias proportional to the rate of change of the temperature (a thermal gradient across the
    # element): b += r_i dT/dt, r_i in bias units per (degC/min)
    bias_temprate_per_c_per_min: np.ndarray = field(default_factory=lambda: np.zeros(3))
    # accelerometers only: a general second-order response in the case-axis specific force
    # (ug per g^2), row i: accel i, columns F_x^2, F_y^2, F_z^2, F_x F_y, F_x F_z, F_y F_z
    # (ANISOELASTIC_PRODUCTS; F at the element, case axes, g): the products of the OTHER axes'
    # forces that a pendulous element with a flexure off its axis feels
    force_products_ug_per_g2: np.ndarray = field(default_factory=lambda: np.zeros((3, 6)))
    # gyros only: cubic rate nonlinearity c_i (ppm per (deg/s)^2): gyro i adds k_i c_i 1e-6 r_i^3
    rate_cubic_ppm_per_dps2: np.ndarray = field(default_factory=lambda: np.zeros(3))
    # gyros only: the scale factor changes with the specific force (ppm per g), row i: gyro i,
    # column j: the force along case axis j: gyro i adds k_i r_i 1e-6 sum_j S_ij F_j
    scale_g_ppm_per_g: np.ndarray = field(default_factory=lambda: np.zeros((3, 3)))

    def __post_init__(self):
        self.scale = np.asarray(self.scale, dtype=float).reshape(3)
        self.axis_tilt_arcsec = np.asarray(self.axis_tilt_arcsec, dtype=float).reshape(3, 2)
        self.bias = np.asarray(self.bias, dtype=float).reshape(3)
        self.bias_tempco = np.asarray(self.bias_tempco, dtype=float).reshape(3)
        self.noise_density = float(self.noise_density)
        self.lsb = float(self.lsb)
        self.position_m = np.asarray(self.position_m, dtype=float).reshape(3, 3)
        self.nonlinearity_ug_per_g2 = np.asarray(self.nonlinearity_ug_per_g2, dtype=float).reshape(3)
        self.cross_coupling_ug_per_g2 = np.asarray(self.cross_coupling_ug_per_g2,
                                                   dtype=float).reshape(3, 3)
        self.g_sensitivity_dph_per_g = np.asarray(self.g_sensitivity_dph_per_g,
                                                  dtype=float).reshape(3, 3)
        self.scale_asymmetry_ppm = np.asarray(self.scale_asymmetry_ppm, dtype=float).reshape(3)
        self.scale_tempco_ppm_per_c = np.asarray(self.scale_tempco_ppm_per_c, dtype=float).reshape(3)
        self.bias_step = np.asarray(self.bias_step, dtype=float).reshape(3)
        self.bias_step_time_s = float(self.bias_step_time_s)
        self.rate_squared_ppm_per_dps = np.asarray(self.rate_squared_ppm_per_dps,
                                                   dtype=float).reshape(3)
        self.anisoelastic_dph_per_g2 = np.asarray(self.anisoelastic_dph_per_g2,
                                                  dtype=float).reshape(3, 6)
        self.cubic_ug_per_g3 = np.asarray(self.cubic_ug_per_g3, dtype=float).reshape(3)
        self.bias_tempco2 = np.asarray(self.bias_tempco2, dtype=float).reshape(3)
        self.bias_drift_per_h = np.asarray(self.bias_drift_per_h, dtype=float).reshape(3)
        self.rate_odd_squared_ppm_per_dps = np.asarray(self.rate_odd_squared_ppm_per_dps,
                                                       dtype=float).reshape(3)
        self.scale_tempco2_ppm_per_c2 = np.asarray(self.scale_tempco2_ppm_per_c2, dtype=float).reshape(3)
        self.axis_tilt_tempco_arcsec_per_c = np.asarray(self.axis_tilt_tempco_arcsec_per_c,
                                                        dtype=float).reshape(3, 2)
        self.bias_temprate_per_c_per_min = np.asarray(self.bias_temprate_per_c_per_min,
                                                      dtype=float).reshape(3)
        self.force_products_ug_per_g2 = np.asarray(self.force_products_ug_per_g2, dtype=float).reshape(3, 6)
        self.rate_cubic_ppm_per_dps2 = np.asarray(self.rate_cubic_ppm_per_dps2, dtype=float).reshape(3)
        self.scale_g_ppm_per_g = np.asarray(self.scale_g_ppm_per_g, dtype=float).reshape(3, 3)
        self.full_scale = float(self.full_scale)
        self.stuck_at_s = [float(x) for x in np.asarray(self.stuck_at_s, dtype=float).reshape(-1)]
        self.stuck_duration_s = float(self.stuck_duration_s)
        self.stuck_axes = [int(k) for k in self.stuck_axes]
        if any(k not in (0, 1, 2) for k in self.stuck_axes):
            raise ValueError("stuck_axes must name axes 0, 1 or 2")
        if np.any(np.diag(self.cross_coupling_ug_per_g2) != 0.0):
            raise ValueError("cross_coupling_ug_per_g2 must have a zero diagonal "
                             "(the a_i^2 term is nonlinearity_ug_per_g2)")

    def outside_library(self) -> bool:
        """Whether any effect the station's library has no model for is set."""
        return bool(np.any(self.scale_tempco2_ppm_per_c2) or np.any(self.axis_tilt_tempco_arcsec_per_c)
                    or np.any(self.bias_temprate_per_c_per_min) or np.any(self.force_products_ug_per_g2)
                    or np.any(self.rate_cubic_ppm_per_dps2) or np.any(self.scale_g_ppm_per_g))

    @property
    def axes(self) -> np.ndarray:
        """S: rows are the unit sensing directions in case axes."""
        return sensing_axes(self.axis_tilt_arcsec)

    @property
    def matrix(self) -> np.ndarray:
        """K S: the case-axes input -> raw output matrix."""
        return self.scale[:, None] * self.axes


@dataclass
class TemperatureTruth:
    """T(t) = start + drift_c_per_h t/3600 + warmup_delta (1 - exp(-t/tau)), t = bench time.

    In a temperature chamber (``air``: sim_devices/chamber.py ChamberAir, its air starting at
    ``start_c``, the room) the constant ``start`` is replaced by the IMU's case following the
    chamber's air as a first-order lag of ``chamber_time_constant_s``; the self-heating warm-up
    and the drift add to it as before.

    Biases in the truth file are those at ``reference_c``.
    """

    start_c: float = 25.0
    reference_c: float = 25.0
    drift_c_per_h: float = 0.0
    warmup_delta_c: float = 2.0
    warmup_time_constant_s: float = 900.0
    chamber_time_constant_s: float = 600.0    # the IMU's case behind the chamber's air (thermal mass)

    def at(self, t, air=None) -> np.ndarray:
        t = np.asarray(t, dtype=float)
        base = self.start_c if air is None or not air.commanded else air.lagged(t, self.chamber_time_constant_s)
        return (base + self.drift_c_per_h * t / 3600.0
                + self.warmup_delta_c * -np.expm1(-t / self.warmup_time_constant_s))

    def rate(self, t, air=None) -> np.ndarray:
        """dT/dt (degC/s) at bench time t: the derivative of :meth:`at`."""
        t = np.asarray(t, dtype=float)
        base = 0.0 if air is None or not air.commanded else air.lagged_rate(t, self.chamber_time_constant_s)
        return (base + self.drift_c_per_h / 3600.0
                + self.warmup_delta_c / self.warmup_time_constant_s * np.exp(-t / self.warmup_time_constant_s))


@dataclass
class BenchSettings:
    """The physical bench the IMU sits on."""

    latitude_deg: float = 45.0
    height_m: float = 0.0
    lever_arm_m: np.ndarray = field(default_factory=lambda: np.array([0.03, 0.0, 0.04]))
    # a table whose axes do not intersect: the table axis that turns the IMU about case axis k
    # (the case axis nearest the rotation's axis) runs along a line that is axis_offsets_m[k]
    # (case axes, m) further from the IMU than lever_arm_m says: that rotation's lever arm is
    # lever_arm_m + axis_offsets_m[k].  Zero: the axes meet at one point.
    axis_offsets_m: np.ndarray = field(default_factory=lambda: np.zeros((3, 3)))
    table_angle_error_arcsec: float = 2.0
    rate_ripple_fraction: float = 0.0
    rate_drift_fraction: float = 0.0      # rate change over a rotation without encoder (screwdriver)
    rate_ripple_hz: float = 1.0
    accel_disturbance_ug: float = 0.0
    move_s: float = 10.0
    settle_s: float = 5.0
    # the IMU's time stamps lag the table's clock: the sample stamped t was taken at table
    # time t + time_offset_s
    time_offset_s: float = 0.0
    # the platter's axis is tilted by wobble_arcsec from the nominal table axis, the tilt turning
    # once per revolution relative to the platter (world.wobbling_table, harmonic 1)
    wobble_arcsec: float = 0.0
    wobble_phase_deg: float = 0.0
    # a once-per-revolution vibration during rotations, driven by the platter's angle (issue 28,
    # twenty-first session; world.table_vibration_enu): the base moves along D = A_axis a + A_ref r
    # + A_perp a x r (a the table axis, r the reference direction, a x r) by -cos(theta + phase)
    # D / w_ref^2, so it accelerates by (theta_dot^2 cos(theta + phase) + theta_ddot sin(theta +
    # phase)) D / w_ref^2: zero at rest, A cos(theta + phase) at the steady rate
    # vibration_ref_rate_dps (vibration_mg: the amplitudes in mg AT THAT RATE), (w / w_ref)^2 of it
    # at a steady w, with a part from the angular acceleration over a ramp.  A truth file that
    # gives a non-zero vibration_mg must give vibration_ref_rate_dps (files written before the
    # twenty-first session meant the amplitude at every rate, which no imbalance makes)
    vibration_mg: np.ndarray = field(default_factory=lambda: np.zeros(3))
    vibration_phase_deg: float = 0.0
    vibration_ref_rate_dps: float = 100.0
    # an imbalance of the platter (world.imbalance_acceleration_enu): m rho in g mm (as balancing
    # grades state it) at the platter angle imbalance_phase_deg from r at a rotation's start, on a
    # base of effective mass base_mass_kg that moves as a free mass (its mount's resonance below the
    # rotation frequency): the base accelerates by (m rho / M) (theta_dot^2 e - theta_ddot a x e),
    # e the imbalance's direction turning with the platter.  0: none
    imbalance_g_mm: float = 0.0
    imbalance_phase_deg: float = 0.0
    base_mass_kg: float = 100.0
    # placement error: every static segment's attitude gets an extra random rotation, 1 sigma
    # per axis (arcsec), as when the IMU is taken off and put back for each attitude
    remount_error_arcsec: float = 0.0
    remount_rotations: bool = False     # True: every rotation segment is remounted too
    remount_axes: bool = False          # True: the IMU remounted once for each rotation axis (the
                                        #   rotations about one axis, both directions, share it)
    # the IMU's time stamps jitter: stamp = nominal sample time + N(0, sigma) (ms); the samples
    # themselves are taken on the regular grid
    time_stamp_jitter_ms: float = 0.0
    # the table turns (1 + e 1e-6) times the angle its encoder reads (a scale error of the
    # encoder or of its gearing): the encoder reports the swept angle / (1 + e 1e-6)
    encoder_scale_error_ppm: float = 0.0
    # a table of several axes, each with its own encoder: table_axes 3 turns the IMU about case
    # axis k (the nearest to axis_body, as axis_offsets_m) with table axis k + 1, records that axis
    # with each rotation (``table_axis``, as a bench run does), and its encoder reads with
    # encoder_scale_error_ppm + encoder_scale_error_per_axis_ppm[k]; 1: one axis (no table_axis)
    table_axes: int = 1
    encoder_scale_error_per_axis_ppm: np.ndarray = field(default_factory=lambda: np.zeros(3))

    def __post_init__(self):
        self.lever_arm_m = np.asarray(self.lever_arm_m, dtype=float).reshape(3)
        self.axis_offsets_m = np.asarray(self.axis_offsets_m, dtype=float).reshape(3, 3)
        self.vibration_mg = np.asarray(self.vibration_mg, dtype=float).reshape(3)
        self.encoder_scale_error_per_axis_ppm = np.asarray(self.encoder_scale_error_per_axis_ppm,
                                                           dtype=float).reshape(3)
        self.table_axes = int(self.table_axes)


def _cross_coupling(c: "_Checker", value, field_name: str) -> np.ndarray:
    """Cross-coupling coefficients as 3x3 (zero diagonal) or 3x2 (row i: the two other case
    axes in x<y<z order, like axis_tilt_arcsec) -> 3x3 with a zero diagonal."""
    bounds = dict(lo=-MAX_SECOND_ORDER_UG_PER_G2, hi=MAX_SECOND_ORDER_UG_PER_G2)
    cols = 3
    if isinstance(value, (list, tuple)) and value and isinstance(value[0], (list, tuple)) \
            and len(value[0]) == 2:
        cols = 2
    m = c.matrix(value, field_name, 3, cols, **bounds)
    if cols == 2:
        full = np.zeros((3, 3))
        for i, (j, k) in enumerate(OTHER_AXES):
            full[i, j], full[i, k] = m[i]
        return full
    for i in range(3):
        if m[i, i] != 0.0:
            c.fail(f"{field_name}[{i}][{i}]",
                   f"the diagonal must be 0 (a_i^2 is nonlinearity_ug_per_g2), got {m[i, i]!r}")
    return m


def _step(t, step_time_s: float) -> np.ndarray:
    """(N,1): 1.0 where the bench time t >= step_time_s, else 0.0."""
    if t is None:
        raise ValueError("a bias step needs the sample times: pass t= to Truth.measure")
    return (np.asarray(t, dtype=float).reshape(-1, 1) >= step_time_s).astype(float)


def _hours(t) -> np.ndarray:
    """(N,1): the bench time t in hours (a bias drift is linear in it from t = 0)."""
    if t is None:
        raise ValueError("a bias drift needs the sample times: pass t= to Truth.measure")
    return np.asarray(t, dtype=float).reshape(-1, 1) / 3600.0


def _outside_library(triad: "TriadTruth", inputs, dT, temperature, t, bias_unit: float,
                     f_case=None, air=None) -> np.ndarray:
    """What the effects outside the station's library add to a triad's raw output (N,3).

    ``inputs``: per element i the input vector it senses (N,3), case axes (accelerometer: the
    specific force at the element, m/s^2; gyro: the rate, deg/s); ``dT`` (N,1) T - T_ref;
    ``bias_unit``: raw units per bias unit (ug or deg/h); ``f_case`` (gyros): the specific force
    in case axes, g.  Per element i, with u_i its sensing direction, x_i = u_i . input_i:

        k_i s2_i 1e-6 dT^2 x_i                              (scale, second order in temperature)
        k_i (u_i(T) - u_i) . input_i                       (the axis tilted by tc_i dT)
        [r_i dT/dt (degC/min)] bias units                   (a thermal gradient)
        [sum_c P_i,c F_j F_k] ug, F = input / g0            (accelerometers: second-order products)
        k_i c_i 1e-6 x_i^3                                  (gyros: cubic rate)
        k_i x_i 1e-6 sum_j S_ij f_j                         (gyros: scale with the specific force)
    """
    n = max(len(x) for x in inputs)
    out = np.zeros((n, 3))
    S, k = triad.axes, triad.scale
    dT = np.broadcast_to(dT, (n, 1))
    x = np.column_stack([inputs[i] @ S[i] for i in range(3)])            # along each sensing axis
    if np.any(triad.scale_tempco2_ppm_per_c2):
        out += x * (k * triad.scale_tempco2_ppm_per_c2 * 1e-6) * dT * dT
    tc = triad.axis_tilt_tempco_arcsec_per_c
    if np.any(tc):
        tilt = (triad.axis_tilt_arcsec[None, :, :] + tc[None, :, :] * dT[:, :, None]) * ARCSEC   # (N,3,2)
        for i, (j, m) in enumerate(OTHER_AXES):
            u = np.zeros((n, 3))
            u[:, i] = 1.0
            u[:, j] = np.tan(tilt[:, i, 0])
            u[:, m] = np.tan(tilt[:, i, 1])
            u /= np.linalg.norm(u, axis=1, keepdims=True)
            out[:, i] += k[i] * np.einsum("nj,nj->n", u - S[i], inputs[i])
    if np.any(triad.bias_temprate_per_c_per_min):
        if t is None:
            raise ValueError("a bias that follows dT/dt needs the sample times: pass t= to Truth.measure")
        rate_c_per_min = 60.0 * temperature.rate(np.asarray(t, dtype=float), air).reshape(-1, 1)
        out += rate_c_per_min * triad.bias_temprate_per_c_per_min * bias_unit
    P = triad.force_products_ug_per_g2
    if np.any(P):
        for i in range(3):
            F = inputs[i] / G_STANDARD
            prods = np.column_stack([F[:, j] * F[:, m] for j, m in ANISOELASTIC_PRODUCTS])
            out[:, i] += prods @ P[i] * bias_unit
    if np.any(triad.rate_cubic_ppm_per_dps2):
        out += x ** 3 * (k * triad.rate_cubic_ppm_per_dps2 * 1e-6)
    if np.any(triad.scale_g_ppm_per_g):
        out += x * k * 1e-6 * (f_case @ triad.scale_g_ppm_per_g.T)
    return out


def _quantise(x: np.ndarray, lsb: float) -> np.ndarray:
    if lsb <= 0.0:
        return x
    return np.round(x / lsb) * lsb


def _converted(x: np.ndarray, triad: "TriadTruth", t) -> np.ndarray:
    """The analogue value ``x`` (N,3) through the converter: clipped at +-full_scale (an input
    beyond the range reads the rail), quantised to the LSB, then held where the output is stuck
    (the axes' register repeats the sample taken at the start of each stuck window, or at the
    first sample of this block inside it)."""
    if triad.full_scale > 0.0:
        x = np.clip(x, -triad.full_scale, triad.full_scale)
    x = _quantise(x, triad.lsb)
    starts = np.asarray(triad.stuck_at_s, dtype=float).reshape(-1)
    if len(starts) and triad.stuck_duration_s > 0.0:
        if t is None:
            raise ValueError("stuck samples need the sample times: pass t= to Truth.measure")
        t = np.asarray(t, dtype=float).reshape(-1)
        axes = np.asarray(triad.stuck_axes, dtype=int).reshape(-1)
        for start in starts:
            inside = np.flatnonzero((t >= start) & (t < start + triad.stuck_duration_s))
            if len(inside):
                x[inside[:, None], axes] = x[inside[0], axes]
    return x


_OUTSIDE_KEYS = {  # truth-file key: (attribute, shape, bound); written only when set
    "scale_tempco2_ppm_per_c2": ("scale_tempco2_ppm_per_c2", (3,), MAX_SCALE_TEMPCO_PPM_PER_C),
    "axis_tilt_tempco_arcsec_per_c": ("axis_tilt_tempco_arcsec_per_c", (3, 2), MAX_TILT_ARCSEC),
}
_OUTSIDE_ACC = {**_OUTSIDE_KEYS,
                "bias_temprate_ug_per_c_per_min": ("bias_temprate_per_c_per_min", (3,), None),
                "force_products_ug_per_g2": ("force_products_ug_per_g2", (3, 6), MAX_SECOND_ORDER_UG_PER_G2)}
_OUTSIDE_GYR = {**_OUTSIDE_KEYS,
                "bias_temprate_dph_per_c_per_min": ("bias_temprate_per_c_per_min", (3,), None),
                "rate_cubic_ppm_per_dps2": ("rate_cubic_ppm_per_dps2", (3,), MAX_RATE_SQUARED_PPM_PER_DPS),
                "scale_g_ppm_per_g": ("scale_g_ppm_per_g", (3, 3), MAX_SCALE_ASYMMETRY_PPM)}


def _outside_keys(triad: "TriadTruth", keys: dict) -> dict:
    """The effects outside the station's library in the truth file, only when set."""
    out = {}
    for key, (attr, shape, _) in keys.items():
        v = np.asarray(getattr(triad, attr), dtype=float)
        if np.any(v):
            out[key] = [float(x) for x in v] if len(shape) == 1 else [[float(x) for x in r] for r in v]
    return out


def _read_outside(c: "_Checker", d: dict, sec: str, t: "TriadTruth", keys: dict) -> None:
    for key, (attr, shape, bound) in keys.items():
        if key not in d:
            continue
        b = {} if bound is None else {"lo": -bound, "hi": bound}
        v = (c.vector(d[key], f"{sec}.{key}", **b) if len(shape) == 1
             else c.matrix(d[key], f"{sec}.{key}", shape[0], shape[1], **b))
        setattr(t, attr, v)


def _converter_keys(triad: "TriadTruth", fs_key: str) -> dict:
    """The converter's faults in the truth file, only when set (older files stay as they were)."""
    out = {}
    if triad.full_scale > 0.0:
        out[fs_key] = float(triad.full_scale)
    if len(triad.stuck_at_s) and triad.stuck_duration_s > 0.0:
        out.update(stuck_at_s=[float(x) for x in triad.stuck_at_s],
                   stuck_duration_s=float(triad.stuck_duration_s), stuck_axes=list(triad.stuck_axes))
    return out


# --------------------------------------------------------------------------
# Truth
# --------------------------------------------------------------------------

_TOP_KEYS = {"version", "sample_rate_hz", "accelerometer", "gyroscope", "temperature", "bench"}
_ACC_KEYS = {"scale", "axis_tilt_arcsec", "bias_ug", "bias_tempco_ug_per_c",
             "noise_density_ug_rthz", "lsb_mps2", "position_m", "nonlinearity_ug_per_g2",
             "cross_coupling_ug_per_g2", "scale_asymmetry_ppm", "scale_tempco_ppm_per_c",
             "bias_step_ug", "bias_step_time_s", "cubic_ug_per_g3", "bias_tempco2_ug_per_c2",
             "bias_drift_ug_per_h", "full_scale_mps2", "stuck_at_s", "stuck_duration_s",
             "stuck_axes", *_OUTSIDE_ACC}
_GYR_KEYS = {"scale", "axis_tilt_arcsec", "bias_dph", "bias_tempco_dph_per_c",
             "noise_density_dph_rthz", "lsb_dps", "g_sensitivity_dph_per_g", "scale_asymmetry_ppm",
             "scale_tempco_ppm_per_c", "bias_step_dph", "bias_step_time_s",
             "rate_squared_ppm_per_dps", "anisoelastic_dph_per_g2", "bias_tempco2_dph_per_c2",
             "bias_drift_dph_per_h", "rate_odd_squared_ppm_per_dps", "full_scale_dps", "stuck_at_s",
             "stuck_duration_s", "stuck_axes", *_OUTSIDE_GYR}
_TEMP_KEYS = {"start_c", "reference_c", "drift_c_per_h", "warmup_delta_c",
              "warmup_time_constant_s", "chamber_time_constant_s"}
_BENCH_KEYS = {"latitude_deg", "height_m", "lever_arm_m", "axis_offsets_m", "table_angle_error_arcsec",
               "rate_ripple_fraction", "rate_ripple_hz", "rate_drift_fraction", "accel_disturbance_ug",
               "move_s", "settle_s", "time_offset_s", "wobble_arcsec", "wobble_phase_deg",
               "vibration_mg", "vibration_phase_deg", "vibration_ref_rate_dps", "imbalance_g_mm",
               "imbalance_phase_deg", "base_mass_kg", "remount_error_arcsec", "remount_rotations", "remount_axes",
               "time_stamp_jitter_ms", "encoder_scale_error_ppm", "table_axes",
               "encoder_scale_error_per_axis_ppm"}


@dataclass
class Truth:
    accel: TriadTruth = field(default_factory=lambda: TriadTruth(
        noise_density=DEFAULT_ACCEL_NOISE_UG_RTHZ))
    gyro: TriadTruth = field(default_factory=lambda: TriadTruth(
        noise_density=DEFAULT_GYRO_NOISE_DPH_RTHZ))
    sample_rate_hz: float = DEFAULT_SAMPLE_RATE_HZ
    temperature: TemperatureTruth = field(default_factory=TemperatureTruth)
    bench: BenchSettings = field(default_factory=BenchSettings)

    # ---------------------------------------------------------- noise levels
    @property
    def accel_noise_sigma(self) -> float:
        """Per-sample accelerometer white-noise sigma, raw units (m/s^2)."""
        return self.accel.noise_density * MICRO_G * math.sqrt(self.sample_rate_hz)

    @property
    def gyro_noise_sigma(self) -> float:
        """Per-sample gyro white-noise sigma, raw units (deg/s)."""
        return self.gyro.noise_density * DEG_PER_HOUR * math.sqrt(self.sample_rate_hz)

    # ------------------------------------------------------------- measuring
    def measure(self, f_b, w_b_dps, temp, rng, w_eb_b=None, wdot_eb_b=None, t=None, air=None):
        """Body quantities -> raw outputs.

        f_b (N,3) m/s^2 (at the IMU reference point) and w_b_dps (N,3) deg/s in case axes,
        temp (N,) or scalar deg C, rng a numpy Generator (None: no noise).  ``w_eb_b`` and
        ``wdot_eb_b`` (rad/s, rad/s^2, body axes) are the rate of the body relative to the
        Earth and its derivative: each accelerometer then senses the specific force at its own
        position p_i, f_i = f_b + wdot x p_i + w x (w x p_i) (rigid body).  ``t`` (N,) is the
        bench time at which each sample was taken, s (needed only for a bias step: without it
        a non-zero step raises ValueError).
        Returns (accel_raw, gyro_raw), each (N,3).

        Per accelerometer i, with a_i = u_i . f_i / g0 and F = f_i / g0 (g0 = 9.80665 m/s^2),
        k_i(T) = k_i (1 + s_i 1e-6 dT), H = 1 if t >= the step time else 0:
            accel_i = k_i(T) u_i . f_i + k_i A_i 1e-6 |u_i . f_i|
                      + [b_i + c_i dT + c2_i dT^2 + d_i t_h + H step_i + K2_i a_i^2 + K3_i a_i^3
                         + sum_{j != i} C_ij a_i F_j] ug
        per gyro i, with r_i = u_gi . w_b (deg/s) and F = f_b / g0 (case axes):
            gyro_i = k_i(T) r_i + k_i A_i 1e-6 |r_i| + k_i q_i 1e-6 r_i^2 + k_i q'_i 1e-6 r_i |r_i|
                     + [b_i + c_i dT + c2_i dT^2 + d_i t_h + H step_i + sum_j G_ij F_j
                        + sum_jk N_i,jk F_j F_k] deg/h
        (t_h: the bench time in hours, dT = T - reference_c)
        then noise and quantisation.
        """
        f_b = np.atleast_2d(np.asarray(f_b, dtype=float))
        w_b = np.atleast_2d(np.asarray(w_b_dps, dtype=float))
        dT = (np.asarray(temp, dtype=float) - self.temperature.reference_c).reshape(-1, 1)
        ba = (self.accel.bias + self.accel.bias_tempco * dT + self.accel.bias_tempco2 * dT * dT) * MICRO_G
        bg = (self.gyro.bias + self.gyro.bias_tempco * dT + self.gyro.bias_tempco2 * dT * dT) * DEG_PER_HOUR
        if np.any(self.accel.bias_drift_per_h):
            ba = ba + _hours(t) * self.accel.bias_drift_per_h * MICRO_G
        if np.any(self.gyro.bias_drift_per_h):
            bg = bg + _hours(t) * self.gyro.bias_drift_per_h * DEG_PER_HOUR
        if np.any(self.accel.bias_step):
            ba = ba + _step(t, self.accel.bias_step_time_s) * self.accel.bias_step * MICRO_G
        if np.any(self.gyro.bias_step):
            bg = bg + _step(t, self.gyro.bias_step_time_s) * self.gyro.bias_step * DEG_PER_HOUR
        accel = f_b @ self.accel.matrix.T + ba
        extras = None
        if w_eb_b is not None and np.any(self.accel.position_m):
            w = np.atleast_2d(np.asarray(w_eb_b, dtype=float))
            wd = np.atleast_2d(np.asarray(wdot_eb_b if wdot_eb_b is not None else 0.0, dtype=float))
            extras = []
            for i, p in enumerate(self.accel.position_m):
                extra = cross3(wd, p) + cross3(w, cross3(w, p))
                extras.append(extra)
                accel[:, i] += extra @ self.accel.matrix[i]
        K2 = self.accel.nonlinearity_ug_per_g2
        C = self.accel.cross_coupling_ug_per_g2
        K3 = self.accel.cubic_ug_per_g3
        if np.any(K2) or np.any(C) or np.any(K3):
            S = self.accel.axes
            for i in range(3):
                F = (f_b if extras is None else f_b + extras[i]) / G_STANDARD   # g, case axes
                a = F @ S[i]                                                    # g, sensing axis
                accel[:, i] += (K2[i] * a + F @ C[i] + K3[i] * a * a) * a * MICRO_G
        sa, Aa = self.accel.scale_tempco_ppm_per_c, self.accel.scale_asymmetry_ppm
        if np.any(sa) or np.any(Aa):
            S = self.accel.axes
            a_in = f_b @ S.T                     # m/s^2 along each sensing axis (at its element)
            if extras is not None:
                for i in range(3):
                    a_in[:, i] += extras[i] @ S[i]
            accel += a_in * (self.accel.scale * sa * 1e-6) * dT
            accel += np.abs(a_in) * (self.accel.scale * Aa * 1e-6)
        gyro = w_b @ self.gyro.matrix.T + bg
        A = self.gyro.scale_asymmetry_ppm
        if np.any(A):
            gyro += np.abs(w_b @ self.gyro.axes.T) * (self.gyro.scale * A * 1e-6)
        sg, q = self.gyro.scale_tempco_ppm_per_c, self.gyro.rate_squared_ppm_per_dps
        if np.any(sg) or np.any(q):
            r = w_b @ self.gyro.axes.T           # deg/s along each sensing axis
            gyro += r * (self.gyro.scale * sg * 1e-6) * dT
            gyro += r * r * (self.gyro.scale * q * 1e-6)
        q_odd = self.gyro.rate_odd_squared_ppm_per_dps
        if np.any(q_odd):
            r = w_b @ self.gyro.axes.T           # deg/s along each sensing axis
            gyro += r * np.abs(r) * (self.gyro.scale * q_odd * 1e-6)
        G = self.gyro.g_sensitivity_dph_per_g
        if np.any(G):
            gyro += (f_b / G_STANDARD) @ G.T * DEG_PER_HOUR
        N = self.gyro.anisoelastic_dph_per_g2
        if np.any(N):
            F = f_b / G_STANDARD
            products = np.column_stack([F[:, j] * F[:, k] for j, k in ANISOELASTIC_PRODUCTS])
            gyro += products @ N.T * DEG_PER_HOUR
        if self.accel.outside_library() or self.gyro.outside_library():
            F_el = [f_b if extras is None else f_b + extras[i] for i in range(3)]   # m/s^2, at each element
            accel += _outside_library(self.accel, F_el, dT, self.temperature, t, MICRO_G, air=air)
            gyro += _outside_library(self.gyro, [w_b] * 3, dT, self.temperature, t, DEG_PER_HOUR,
                                     f_case=f_b / G_STANDARD, air=air)
        if rng is not None:
            if self.accel.noise_density > 0.0:
                accel += self.accel_noise_sigma * rng.standard_normal(accel.shape)
            if self.gyro.noise_density > 0.0:
                gyro += self.gyro_noise_sigma * rng.standard_normal(gyro.shape)
        return _converted(accel, self.accel, t), _converted(gyro, self.gyro, t)

    # ------------------------------------------------------ paper parameters
    def paper_parameters(self) -> dict[str, Any]:
        """The truth in Zhang et al. (2010)'s parameterisation.

        accel_raw = diag(accel_scale) accel_T f_p + accel_bias
        gyro_raw  = diag(gyro_scale) gyro_T R_po w_p + gyro_bias
        with f_p = C_pb f_b, w_p = C_pb w_b (deg/s); biases at reference_c,
        in raw units (m/s^2, deg/s).

        The higher-order effects in the same frames (exact): accelerometer i's own input is
        a_i = (accel_T f_p)_i / g0, gyro i's input r_i = (gyro_T R_po w_p)_i, so
        ``accel_nonlinearity_ug_per_g2`` (K2) and ``gyro_scale_asymmetry_ppm`` (A) carry over
        unchanged; the g-sensitivity against f_p is ``gyro_g_sensitivity_dph_per_g``
        = G C_pb^T.  The scale asymmetries, scale temperature coefficients and the gyro
        rate-squared term act on the same sensing-axis inputs and carry over unchanged too.
        (The cross-coupling and the anisoelastic term use case-axis components and have no
        such form here.)
        """
        Sa, Sg = self.accel.axes, self.gyro.axes
        C_pb = triad_frame(Sa)
        C_ob = triad_frame(Sg)
        T_a = Sa @ C_pb.T
        T_g = Sg @ C_ob.T
        # exact zeros above the diagonal (they are ~1e-17 by construction)
        T_a[0, 1:] = 0.0
        T_a[1, 2] = 0.0
        T_g[0, 1:] = 0.0
        T_g[1, 2] = 0.0
        R_po = C_ob @ C_pb.T
        alpha = misalignment_angles(T_a)
        gamma = misalignment_angles(T_g)
        theta = Rotation.from_matrix(R_po).as_rotvec()
        return {
            "accel_scale": self.accel.scale.copy(),
            "accel_T": T_a,
            "accel_misalignment_rad": alpha,
            "accel_bias": self.accel.bias * MICRO_G,
            "gyro_scale": self.gyro.scale.copy(),
            "gyro_T": T_g,
            "gyro_misalignment_rad": gamma,
            "gyro_bias": self.gyro.bias * DEG_PER_HOUR,
            "R_po": R_po,
            "inter_triad_rad": theta,
            # conveniences
            "C_pb": C_pb,
            "C_ob": C_ob,
            "accel_bias_ug": self.accel.bias.copy(),
            "gyro_bias_dph": self.gyro.bias.copy(),
            "accel_misalignment_arcsec": alpha / ARCSEC,
            "gyro_misalignment_arcsec": gamma / ARCSEC,
            "inter_triad_arcsec": theta / ARCSEC,
            # higher-order effects against f_p, w_p (see the docstring)
            "accel_nonlinearity_ug_per_g2": self.accel.nonlinearity_ug_per_g2.copy(),
            "gyro_scale_asymmetry_ppm": self.gyro.scale_asymmetry_ppm.copy(),
            "gyro_g_sensitivity_dph_per_g": self.gyro.g_sensitivity_dph_per_g @ C_pb.T,
            "accel_scale_asymmetry_ppm": self.accel.scale_asymmetry_ppm.copy(),
            "accel_scale_tempco_ppm_per_c": self.accel.scale_tempco_ppm_per_c.copy(),
            "gyro_scale_tempco_ppm_per_c": self.gyro.scale_tempco_ppm_per_c.copy(),
            "gyro_rate_squared_ppm_per_dps": self.gyro.rate_squared_ppm_per_dps.copy(),
        }

    # ------------------------------------------------------------------ YAML
    def to_yaml_dict(self) -> dict[str, Any]:
        def fl(a):
            return [float(x) for x in np.asarray(a).reshape(-1)]

        return {
            "version": SCHEMA_VERSION,
            "sample_rate_hz": float(self.sample_rate_hz),
            "accelerometer": {
                "scale": fl(self.accel.scale),
                "axis_tilt_arcsec": [fl(r) for r in self.accel.axis_tilt_arcsec],
                "bias_ug": fl(self.accel.bias),
                "bias_tempco_ug_per_c": fl(self.accel.bias_tempco),
                "noise_density_ug_rthz": float(self.accel.noise_density),
                "lsb_mps2": float(self.accel.lsb),
                "position_m": [fl(r) for r in self.accel.position_m],
                "nonlinearity_ug_per_g2": fl(self.accel.nonlinearity_ug_per_g2),
                "cross_coupling_ug_per_g2": [fl(r) for r in self.accel.cross_coupling_ug_per_g2],
                "scale_asymmetry_ppm": fl(self.accel.scale_asymmetry_ppm),
                "scale_tempco_ppm_per_c": fl(self.accel.scale_tempco_ppm_per_c),
                "bias_step_ug": fl(self.accel.bias_step),
                "bias_step_time_s": float(self.accel.bias_step_time_s),
                "cubic_ug_per_g3": fl(self.accel.cubic_ug_per_g3),
                "bias_tempco2_ug_per_c2": fl(self.accel.bias_tempco2),
                "bias_drift_ug_per_h": fl(self.accel.bias_drift_per_h),
                **_converter_keys(self.accel, "full_scale_mps2"),
                **_outside_keys(self.accel, _OUTSIDE_ACC),
            },
            "gyroscope": {
                "scale": fl(self.gyro.scale),
                "axis_tilt_arcsec": [fl(r) for r in self.gyro.axis_tilt_arcsec],
                "bias_dph": fl(self.gyro.bias),
                "bias_tempco_dph_per_c": fl(self.gyro.bias_tempco),
                "noise_density_dph_rthz": float(self.gyro.noise_density),
                "lsb_dps": float(self.gyro.lsb),
                "g_sensitivity_dph_per_g": [fl(r) for r in self.gyro.g_sensitivity_dph_per_g],
                "scale_asymmetry_ppm": fl(self.gyro.scale_asymmetry_ppm),
                "scale_tempco_ppm_per_c": fl(self.gyro.scale_tempco_ppm_per_c),
                "bias_step_dph": fl(self.gyro.bias_step),
                "bias_step_time_s": float(self.gyro.bias_step_time_s),
                "rate_squared_ppm_per_dps": fl(self.gyro.rate_squared_ppm_per_dps),
                "anisoelastic_dph_per_g2": [fl(r) for r in self.gyro.anisoelastic_dph_per_g2],
                "bias_tempco2_dph_per_c2": fl(self.gyro.bias_tempco2),
                "bias_drift_dph_per_h": fl(self.gyro.bias_drift_per_h),
                "rate_odd_squared_ppm_per_dps": fl(self.gyro.rate_odd_squared_ppm_per_dps),
                **_converter_keys(self.gyro, "full_scale_dps"),
                **_outside_keys(self.gyro, _OUTSIDE_GYR),
            },
            "temperature": {
                "start_c": float(self.temperature.start_c),
                "reference_c": float(self.temperature.reference_c),
                "drift_c_per_h": float(self.temperature.drift_c_per_h),
                "warmup_delta_c": float(self.temperature.warmup_delta_c),
                "warmup_time_constant_s": float(self.temperature.warmup_time_constant_s),
                # (written when not the default: files as they were before the chamber)
                **({"chamber_time_constant_s": float(self.temperature.chamber_time_constant_s)}
                   if self.temperature.chamber_time_constant_s != TemperatureTruth.chamber_time_constant_s else {}),
            },
            "bench": {
                "latitude_deg": float(self.bench.latitude_deg),
                "height_m": float(self.bench.height_m),
                "lever_arm_m": fl(self.bench.lever_arm_m),
                "axis_offsets_m": [fl(r) for r in self.bench.axis_offsets_m],
                "table_angle_error_arcsec": float(self.bench.table_angle_error_arcsec),
                "rate_ripple_fraction": float(self.bench.rate_ripple_fraction),
                "rate_drift_fraction": float(self.bench.rate_drift_fraction),
                "rate_ripple_hz": float(self.bench.rate_ripple_hz),
                "accel_disturbance_ug": float(self.bench.accel_disturbance_ug),
                "move_s": float(self.bench.move_s),
                "settle_s": float(self.bench.settle_s),
                "time_offset_s": float(self.bench.time_offset_s),
                "wobble_arcsec": float(self.bench.wobble_arcsec),
                "wobble_phase_deg": float(self.bench.wobble_phase_deg),
                "vibration_mg": fl(self.bench.vibration_mg),
                "vibration_phase_deg": float(self.bench.vibration_phase_deg),
                "vibration_ref_rate_dps": float(self.bench.vibration_ref_rate_dps),
                "imbalance_g_mm": float(self.bench.imbalance_g_mm),
                "imbalance_phase_deg": float(self.bench.imbalance_phase_deg),
                "base_mass_kg": float(self.bench.base_mass_kg),
                "remount_error_arcsec": float(self.bench.remount_error_arcsec),
                "remount_rotations": bool(self.bench.remount_rotations),
                "remount_axes": bool(self.bench.remount_axes),
                "time_stamp_jitter_ms": float(self.bench.time_stamp_jitter_ms),
                "encoder_scale_error_ppm": float(self.bench.encoder_scale_error_ppm),
                "table_axes": int(self.bench.table_axes),
                "encoder_scale_error_per_axis_ppm": fl(self.bench.encoder_scale_error_per_axis_ppm),
            },
        }

    def to_yaml(self, path) -> None:
        Path(path).write_text(yaml.safe_dump(self.to_yaml_dict(), sort_keys=False))

    @classmethod
    def from_yaml(cls, path) -> "Truth":
        path = Path(path)
        from station.core.user_files import read_user_text

        text = read_user_text(path, "truth file")             # (a FIFO is refused, not read: it hung)
        data = yaml_text.load_text(text, path)
        return cls.from_dict(data, source=str(path))

    @classmethod
    def from_dict(cls, data, source: str = "<truth>") -> "Truth":
        c = _Checker(source)
        if data is None:
            data = {}
        if not isinstance(data, dict):
            c.fail("(top level)", f"expected a mapping, got {type(data).__name__}")
        top = c.mapping(data, "", _TOP_KEYS)
        if "version" in top and top["version"] != SCHEMA_VERSION:
            c.fail("version", f"unsupported version {top['version']!r} (expected {SCHEMA_VERSION})")
        rate = c.number(top.get("sample_rate_hz", DEFAULT_SAMPLE_RATE_HZ), "sample_rate_hz",
                        lo=0.0, lo_open=True, hi=1e6)

        def triad(sec: str, keys: set[str], bias_key, tc_key, noise_key, lsb_key,
                  noise_default, step_key, tc2_key, drift_key, fs_key) -> TriadTruth:
            d = c.mapping(top.get(sec), sec, keys)
            t = TriadTruth(noise_density=noise_default)
            if fs_key in d:
                t.full_scale = c.number(d[fs_key], f"{sec}.{fs_key}", lo=0.0)
            if "stuck_at_s" in d:
                at = d["stuck_at_s"]
                at = at if isinstance(at, list) else [at]
                t.stuck_at_s = [c.number(v, f"{sec}.stuck_at_s[{i}]", lo=0.0) for i, v in enumerate(at)]
            if "stuck_duration_s" in d:
                t.stuck_duration_s = c.number(d["stuck_duration_s"], f"{sec}.stuck_duration_s", lo=0.0)
            if "stuck_axes" in d:
                axes = d["stuck_axes"]
                if (not isinstance(axes, list) or not axes
                        or any(isinstance(k, bool) or k not in (0, 1, 2) for k in axes)):
                    c.fail(f"{sec}.stuck_axes", f"expected a list of axes 0, 1, 2, got {axes!r}")
                t.stuck_axes = [int(k) for k in axes]
            if "scale" in d:
                t.scale = c.vector(d["scale"], f"{sec}.scale", lo=0.0, lo_open=True)
            if "axis_tilt_arcsec" in d:
                t.axis_tilt_arcsec = c.matrix(d["axis_tilt_arcsec"], f"{sec}.axis_tilt_arcsec",
                                              3, 2, lo=-MAX_TILT_ARCSEC, hi=MAX_TILT_ARCSEC)
            if bias_key in d:
                t.bias = c.vector(d[bias_key], f"{sec}.{bias_key}")
            if tc_key in d:
                t.bias_tempco = c.vector(d[tc_key], f"{sec}.{tc_key}")
            if noise_key in d:
                t.noise_density = c.number(d[noise_key], f"{sec}.{noise_key}", lo=0.0)
            if lsb_key in d:
                t.lsb = c.number(d[lsb_key], f"{sec}.{lsb_key}", lo=0.0)
            if "position_m" in d:
                t.position_m = c.matrix(d["position_m"], f"{sec}.position_m", 3, 3, lo=-1.0, hi=1.0)
            if "nonlinearity_ug_per_g2" in d:
                t.nonlinearity_ug_per_g2 = c.vector(
                    d["nonlinearity_ug_per_g2"], f"{sec}.nonlinearity_ug_per_g2",
                    lo=-MAX_SECOND_ORDER_UG_PER_G2, hi=MAX_SECOND_ORDER_UG_PER_G2)
            if "cross_coupling_ug_per_g2" in d:
                t.cross_coupling_ug_per_g2 = _cross_coupling(c, d["cross_coupling_ug_per_g2"],
                                                             f"{sec}.cross_coupling_ug_per_g2")
            if "g_sensitivity_dph_per_g" in d:
                t.g_sensitivity_dph_per_g = c.matrix(
                    d["g_sensitivity_dph_per_g"], f"{sec}.g_sensitivity_dph_per_g", 3, 3,
                    lo=-MAX_G_SENSITIVITY_DPH_PER_G, hi=MAX_G_SENSITIVITY_DPH_PER_G)
            if "scale_asymmetry_ppm" in d:
                t.scale_asymmetry_ppm = c.vector(
                    d["scale_asymmetry_ppm"], f"{sec}.scale_asymmetry_ppm",
                    lo=-MAX_SCALE_ASYMMETRY_PPM, hi=MAX_SCALE_ASYMMETRY_PPM)
            if "scale_tempco_ppm_per_c" in d:
                t.scale_tempco_ppm_per_c = c.vector(
                    d["scale_tempco_ppm_per_c"], f"{sec}.scale_tempco_ppm_per_c",
                    lo=-MAX_SCALE_TEMPCO_PPM_PER_C, hi=MAX_SCALE_TEMPCO_PPM_PER_C)
            if step_key in d:
                t.bias_step = c.vector(d[step_key], f"{sec}.{step_key}")
            if "bias_step_time_s" in d:
                t.bias_step_time_s = c.number(d["bias_step_time_s"], f"{sec}.bias_step_time_s",
                                              lo=0.0)
            if "rate_squared_ppm_per_dps" in d:
                t.rate_squared_ppm_per_dps = c.vector(
                    d["rate_squared_ppm_per_dps"], f"{sec}.rate_squared_ppm_per_dps",
                    lo=-MAX_RATE_SQUARED_PPM_PER_DPS, hi=MAX_RATE_SQUARED_PPM_PER_DPS)
            if "anisoelastic_dph_per_g2" in d:
                t.anisoelastic_dph_per_g2 = c.matrix(
                    d["anisoelastic_dph_per_g2"], f"{sec}.anisoelastic_dph_per_g2", 3, 6,
                    lo=-MAX_ANISOELASTIC_DPH_PER_G2, hi=MAX_ANISOELASTIC_DPH_PER_G2)
            if "cubic_ug_per_g3" in d:
                t.cubic_ug_per_g3 = c.vector(d["cubic_ug_per_g3"], f"{sec}.cubic_ug_per_g3",
                                             lo=-MAX_SECOND_ORDER_UG_PER_G2, hi=MAX_SECOND_ORDER_UG_PER_G2)
            if tc2_key in d:
                t.bias_tempco2 = c.vector(d[tc2_key], f"{sec}.{tc2_key}")
            if drift_key in d:
                t.bias_drift_per_h = c.vector(d[drift_key], f"{sec}.{drift_key}")
            if "rate_odd_squared_ppm_per_dps" in d:
                t.rate_odd_squared_ppm_per_dps = c.vector(
                    d["rate_odd_squared_ppm_per_dps"], f"{sec}.rate_odd_squared_ppm_per_dps",
                    lo=-MAX_RATE_SQUARED_PPM_PER_DPS, hi=MAX_RATE_SQUARED_PPM_PER_DPS)
            _read_outside(c, d, sec, t, _OUTSIDE_ACC if sec == "accelerometer" else _OUTSIDE_GYR)
            return t

        accel = triad("accelerometer", _ACC_KEYS, "bias_ug", "bias_tempco_ug_per_c",
                      "noise_density_ug_rthz", "lsb_mps2", DEFAULT_ACCEL_NOISE_UG_RTHZ,
                      "bias_step_ug", "bias_tempco2_ug_per_c2", "bias_drift_ug_per_h", "full_scale_mps2")
        gyro = triad("gyroscope", _GYR_KEYS, "bias_dph", "bias_tempco_dph_per_c",
                     "noise_density_dph_rthz", "lsb_dps", DEFAULT_GYRO_NOISE_DPH_RTHZ,
                     "bias_step_dph", "bias_tempco2_dph_per_c2", "bias_drift_dph_per_h", "full_scale_dps")

        d = c.mapping(top.get("temperature"), "temperature", _TEMP_KEYS)
        temp = TemperatureTruth()
        for k in ("start_c", "reference_c", "warmup_delta_c"):
            if k in d:
                setattr(temp, k, c.number(d[k], f"temperature.{k}", lo=-100.0, hi=200.0))
        if "drift_c_per_h" in d:
            temp.drift_c_per_h = c.number(d["drift_c_per_h"], "temperature.drift_c_per_h",
                                          lo=-100.0, hi=100.0)
        for k in ("warmup_time_constant_s", "chamber_time_constant_s"):
            if k in d:
                setattr(temp, k, c.number(d[k], f"temperature.{k}", lo=0.0, lo_open=True))

        d = c.mapping(top.get("bench"), "bench", _BENCH_KEYS)
        bench = BenchSettings()
        if "latitude_deg" in d:
            bench.latitude_deg = c.number(d["latitude_deg"], "bench.latitude_deg", lo=-90.0, hi=90.0)
        if "height_m" in d:
            bench.height_m = c.number(d["height_m"], "bench.height_m", lo=-1000.0, hi=20000.0)
        if "lever_arm_m" in d:
            bench.lever_arm_m = c.vector(d["lever_arm_m"], "bench.lever_arm_m", lo=-2.0, hi=2.0)
        if "axis_offsets_m" in d:
            bench.axis_offsets_m = c.matrix(d["axis_offsets_m"], "bench.axis_offsets_m", 3, 3, lo=-2.0, hi=2.0)
        if "table_angle_error_arcsec" in d:
            bench.table_angle_error_arcsec = c.number(
                d["table_angle_error_arcsec"], "bench.table_angle_error_arcsec", lo=0.0, hi=36000.0)
        if "rate_ripple_fraction" in d:
            bench.rate_ripple_fraction = c.number(
                d["rate_ripple_fraction"], "bench.rate_ripple_fraction", lo=0.0, hi=1.0, hi_open=True)
        if "rate_drift_fraction" in d:
            bench.rate_drift_fraction = c.number(
                d["rate_drift_fraction"], "bench.rate_drift_fraction", lo=-0.9, hi=0.9)
        if "rate_ripple_hz" in d:
            bench.rate_ripple_hz = c.number(d["rate_ripple_hz"], "bench.rate_ripple_hz",
                                            lo=0.0, lo_open=True)
        if "accel_disturbance_ug" in d:
            bench.accel_disturbance_ug = c.number(
                d["accel_disturbance_ug"], "bench.accel_disturbance_ug", lo=0.0)
        for k in ("move_s", "settle_s"):
            if k in d:
                setattr(bench, k, c.number(d[k], f"bench.{k}", lo=0.0))
        if "time_offset_s" in d:
            bench.time_offset_s = c.number(d["time_offset_s"], "bench.time_offset_s",
                                           lo=-MAX_TIME_OFFSET_S, hi=MAX_TIME_OFFSET_S)
        if "wobble_arcsec" in d:
            bench.wobble_arcsec = c.number(d["wobble_arcsec"], "bench.wobble_arcsec",
                                           lo=0.0, hi=MAX_WOBBLE_ARCSEC)
        if "wobble_phase_deg" in d:
            bench.wobble_phase_deg = c.number(d["wobble_phase_deg"], "bench.wobble_phase_deg",
                                              lo=-360.0, hi=360.0)
        if "vibration_mg" in d:
            bench.vibration_mg = c.vector(d["vibration_mg"], "bench.vibration_mg",
                                          lo=-MAX_VIBRATION_MG, hi=MAX_VIBRATION_MG)
        if "vibration_phase_deg" in d:
            bench.vibration_phase_deg = c.number(d["vibration_phase_deg"],
                                                 "bench.vibration_phase_deg", lo=-360.0, hi=360.0)
        if "vibration_ref_rate_dps" in d:
            bench.vibration_ref_rate_dps = c.number(d["vibration_ref_rate_dps"], "bench.vibration_ref_rate_dps",
                                                    lo=0.0, lo_open=True, hi=MAX_VIBRATION_REF_RATE_DPS)
        elif np.any(bench.vibration_mg):
            c.fail("bench.vibration_mg", "is the vibration's amplitude in mg at the steady rate "
                   "bench.vibration_ref_rate_dps (since the twenty-first session the vibration grows as the "
                   "rate squared and is zero at rest): give vibration_ref_rate_dps (deg/s), e.g. the rate at "
                   "which the amplitude was measured")
        if "imbalance_g_mm" in d:
            bench.imbalance_g_mm = c.number(d["imbalance_g_mm"], "bench.imbalance_g_mm", lo=0.0,
                                            hi=MAX_IMBALANCE_G_MM)
        if "imbalance_phase_deg" in d:
            bench.imbalance_phase_deg = c.number(d["imbalance_phase_deg"], "bench.imbalance_phase_deg",
                                                 lo=-360.0, hi=360.0)
        if "base_mass_kg" in d:
            bench.base_mass_kg = c.number(d["base_mass_kg"], "bench.base_mass_kg", lo=0.0, lo_open=True,
                                          hi=MAX_BASE_MASS_KG)
        if "remount_error_arcsec" in d:
            bench.remount_error_arcsec = c.number(d["remount_error_arcsec"],
                                                  "bench.remount_error_arcsec",
                                                  lo=0.0, hi=MAX_REMOUNT_ARCSEC)
        if "remount_rotations" in d:
            if not isinstance(d["remount_rotations"], bool):
                c.fail("bench.remount_rotations", f"expected true or false, got {d['remount_rotations']!r}")
            bench.remount_rotations = d["remount_rotations"]
        if "remount_axes" in d:
            if not isinstance(d["remount_axes"], bool):
                c.fail("bench.remount_axes", f"expected true or false, got {d['remount_axes']!r}")
            bench.remount_axes = d["remount_axes"]
        if "time_stamp_jitter_ms" in d:
            jitter = c.number(d["time_stamp_jitter_ms"], "bench.time_stamp_jitter_ms", lo=0.0)
            bound = MAX_JITTER_FRACTION * 1000.0 / rate
            if jitter > bound:
                c.fail("bench.time_stamp_jitter_ms",
                       f"must be <= {bound:g} ms (10 % of the sample period at {rate:g} Hz, so that "
                       f"the stamps keep increasing), got {jitter!r}")
            bench.time_stamp_jitter_ms = jitter
        if "encoder_scale_error_ppm" in d:
            bench.encoder_scale_error_ppm = c.number(d["encoder_scale_error_ppm"], "bench.encoder_scale_error_ppm",
                                                     lo=-MAX_ENCODER_SCALE_PPM, hi=MAX_ENCODER_SCALE_PPM)
        if "encoder_scale_error_per_axis_ppm" in d:
            bench.encoder_scale_error_per_axis_ppm = c.vector(
                d["encoder_scale_error_per_axis_ppm"], "bench.encoder_scale_error_per_axis_ppm",
                lo=-MAX_ENCODER_SCALE_PPM, hi=MAX_ENCODER_SCALE_PPM)
        if "table_axes" in d:
            axes = c.number(d["table_axes"], "bench.table_axes", lo=1.0, hi=3.0)
            if axes not in (1.0, 3.0):
                c.fail("bench.table_axes", f"must be 1 or 3, got {d['table_axes']!r}")
            bench.table_axes = int(axes)
        return cls(accel=accel, gyro=gyro, sample_rate_hz=rate, temperature=temp, bench=bench)


# --------------------------------------------------------------------------
# A random tactical-grade IMU
# --------------------------------------------------------------------------

def _signed_uniform(rng, lo: float, hi: float, shape) -> np.ndarray:
    mag = rng.uniform(lo, hi, size=shape)
    sign = np.where(rng.random(size=shape) < 0.5, -1.0, 1.0)
    return sign * mag


def default_truth(seed: int) -> Truth:
    """Random (seeded) errors of a tactical-grade IMU; see docs/simulation.md.

    scale errors   +-[100, 1000] ppm (accel and gyro, each axis)
    axis tilts     +-[10, 300] arcsec (each of the 6 accel and 6 gyro angles)
    accel biases   +-[100, 2000] ug
    gyro biases    +-[0.05, 1] deg/h
    lever arm      5 cm in a random direction
    noise          100 ug/sqrt(Hz), 0.03 deg/h/sqrt(Hz) at 100 Hz; no LSB;
    bench          latitude 45 deg, height 0, table angle error 2 arcsec,
                   no ripple, no disturbance, no temperature coefficients.
    """
    rng = np.random.default_rng(seed)
    accel = TriadTruth(
        scale=1.0 + 1e-6 * _signed_uniform(rng, 100.0, 1000.0, 3),
        axis_tilt_arcsec=_signed_uniform(rng, 10.0, 300.0, (3, 2)),
        bias=_signed_uniform(rng, 100.0, 2000.0, 3),
        noise_density=DEFAULT_ACCEL_NOISE_UG_RTHZ,
    )
    gyro = TriadTruth(
        scale=1.0 + 1e-6 * _signed_uniform(rng, 100.0, 1000.0, 3),
        axis_tilt_arcsec=_signed_uniform(rng, 10.0, 300.0, (3, 2)),
        bias=_signed_uniform(rng, 0.05, 1.0, 3),
        noise_density=DEFAULT_GYRO_NOISE_DPH_RTHZ,
    )
    d = rng.standard_normal(3)
    bench = BenchSettings(lever_arm_m=0.05 * d / np.linalg.norm(d))
    return Truth(accel=accel, gyro=gyro, sample_rate_hz=DEFAULT_SAMPLE_RATE_HZ,
                 temperature=TemperatureTruth(), bench=bench)


def mems_truth(seed: int) -> Truth:
    """Random (seeded) errors of a consumer/tactical MEMS IMU; see docs/simulation.md.

    scale errors   +-[0.1, 1] %  (accel and gyro, each axis)
    axis tilts     +-[0.1, 1] deg (each of the 6 accel and 6 gyro angles)
    accel biases   +-[1, 20] mg
    gyro biases    +-[0.1, 1] deg/s
    noise          accel [100, 200] ug/sqrt(Hz), gyro [5, 20] deg/h/sqrt(Hz) (0.08-0.33 deg/sqrt(h))
    lever arm      5 cm in a random direction
    everything else as default_truth: 100 Hz, no LSB, no temperature coefficients and no
    higher-order effect (set them in a truth file to hide them).
    """
    rng = np.random.default_rng(seed)
    accel = TriadTruth(
        scale=1.0 + 1e-6 * _signed_uniform(rng, 1000.0, 10000.0, 3),
        axis_tilt_arcsec=_signed_uniform(rng, 360.0, 3600.0, (3, 2)),
        bias=_signed_uniform(rng, 1000.0, 20000.0, 3),
        noise_density=float(rng.uniform(100.0, 200.0)),
    )
    gyro = TriadTruth(
        scale=1.0 + 1e-6 * _signed_uniform(rng, 1000.0, 10000.0, 3),
        axis_tilt_arcsec=_signed_uniform(rng, 360.0, 3600.0, (3, 2)),
        bias=_signed_uniform(rng, 360.0, 3600.0, 3),
        noise_density=float(rng.uniform(5.0, 20.0)),
    )
    d = rng.standard_normal(3)
    bench = BenchSettings(lever_arm_m=0.05 * d / np.linalg.norm(d))
    return Truth(accel=accel, gyro=gyro, sample_rate_hz=DEFAULT_SAMPLE_RATE_HZ,
                 temperature=TemperatureTruth(), bench=bench)
