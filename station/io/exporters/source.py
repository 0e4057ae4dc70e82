"""What every exporter starts from: the compensation of a calibration file, its units, which
effects an exporter cannot carry, the IMU's identity and (when characterised) its noise."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from station.core import units
from station.core.errors import UserError
from station.io.calfile import write_new_file

# Effects a plain "matrix and bias per triad" format carries; everything else is dropped with a note.
LINEAR_EFFECTS = ("base_triads", "inter_triad")


@dataclass
class ExportSource:
    """The compensation of one calibration (docs/calibration-file.md):
    f_p = accel_matrix (accel_raw - accel_bias) in m/s^2, w_p = gyro_matrix (gyro_raw - gyro_bias)
    in deg/s, frame p; biases in the raw units.  ``gyro_matrix`` is None when the calibration
    has no gyro block (an accelerometer-only calibration)."""

    accel_matrix: np.ndarray
    accel_bias: np.ndarray
    gyro_matrix: np.ndarray | None
    gyro_bias: np.ndarray | None
    accel_unit: str                 # raw unit of the accelerometer input
    gyro_unit: str                  # raw unit of the gyro input
    origin: str                     # the calibration file exported
    imu_model: str | None = None
    imu_serial: str | None = None
    date_utc: str | None = None
    effects: list = field(default_factory=list)
    parameters: dict = field(default_factory=dict)
    noise: dict | None = None       # the calibration file's noise block (station noise)
    noise_origin: str | None = None  # the noise file the block came from (export --noise), else the calibration
    # the added effects' parameters the capture did not determine (not written; compensated at
    # their nominal 0 by station apply)
    not_determined: list = field(default_factory=list)

    @property
    def dropped_effects(self) -> list[str]:
        """Estimated effects that a matrix-and-bias format cannot carry."""
        return [e for e in self.effects if e not in LINEAR_EFFECTS]

    @property
    def has_gyro(self) -> bool:
        return self.gyro_matrix is not None

    def accel_input_to_si(self) -> float | None:
        """m/s^2 per raw accelerometer unit; None for raw counts."""
        return units.accel_to_mps2_factor(self.accel_unit)

    def gyro_input_to_dps(self) -> float | None:
        """deg/s per raw gyro unit; None for raw counts."""
        return units.gyro_to_dps_factor(self.gyro_unit)

    def header_lines(self) -> list[str]:
        """Who, what and from where, for the comment block of a written file."""
        lines = [f"exported by station from {self.origin}"]
        if self.imu_model or self.imu_serial:
            lines.append(f"IMU: {self.imu_model or 'unknown model'}, serial {self.imu_serial or 'unknown'}")
        if self.date_utc:
            lines.append(f"calibrated: {self.date_utc}")
        if not self.has_gyro:
            lines.append("accelerometer-only calibration: the gyro block is absent, gyro passed "
                         "through uncalibrated")
        if self.dropped_effects:
            lines.append("estimated but not representable in this format (not compensated): "
                         + ", ".join(self.dropped_effects))
        if self.not_determined:
            lines.append("not determined by the capture (not written): " + ", ".join(self.not_determined))
        return lines


def _array(comp: dict, key: str, shape, origin: str, *, optional: bool = False):
    if comp.get(key) is None:
        if optional:
            return None
        raise UserError(f"{origin}: field 'compensation.{key}': missing")
    try:
        a = np.array(comp[key], dtype=float)
    except (TypeError, ValueError):
        raise UserError(f"{origin}: field 'compensation.{key}': must be numbers") from None
    if a.shape != shape or not np.all(np.isfinite(a)):
        raise UserError(f"{origin}: field 'compensation.{key}': must be {'x'.join(map(str, shape))} "
                        "finite numbers")
    return a


def source_from_document(doc: dict, origin) -> ExportSource:
    """An ExportSource from a calibration document as ``read_calfile`` returns it."""
    origin = str(origin)
    comp = doc.get("compensation") or {}
    accel_matrix = _array(comp, "accel_matrix", (3, 3), origin)
    accel_bias = _array(comp, "accel_bias", (3,), origin)
    gyro_matrix = _array(comp, "gyro_matrix", (3, 3), origin, optional=True)
    gyro_bias = _array(comp, "gyro_bias", (3,), origin, optional=True)
    if doc.get("gyro_pass_through"):     # an accelerometer-only calibration: read_calfile's unit
        gyro_matrix = gyro_bias = None   #   factor is no gyro calibration to write (raw: none at all)
    for key, m in (("accel_matrix", accel_matrix), ("gyro_matrix", gyro_matrix)):
        if m is not None and not (np.all(np.diag(m) != 0.0) and np.linalg.cond(m) < 1e12):
            raise UserError(f"{origin}: field 'compensation.{key}': singular or with a zero diagonal "
                            "element: not a calibration any format can carry")
    if (gyro_matrix is None) != (gyro_bias is None):
        raise UserError(f"{origin}: field 'compensation': gyro_matrix and gyro_bias go together")
    raw = comp.get("raw_units") or {}
    imu = doc.get("imu") or {}
    accel_unit = raw.get("accel", imu.get("accel_unit", "m/s^2"))
    gyro_unit = raw.get("gyro", imu.get("gyro_unit", "deg/s"))
    if accel_unit not in units.ACCEL_UNITS or gyro_unit not in units.GYRO_UNITS:
        raise UserError(f"{origin}: field 'compensation.raw_units': unknown unit "
                        f"({accel_unit!r}, {gyro_unit!r})")
    prov = doc.get("provenance") or {}
    text = lambda v: v if isinstance(v, str) else None  # noqa: E731 - untrusted: strings only
    effects = [e for e in doc.get("effects") or [] if isinstance(e, str)]
    noise = doc.get("noise") if isinstance(doc.get("noise"), dict) else None
    if noise is not None and isinstance(noise.get("kalibr"), dict):
        from station.io.noise_file import check_kalibr

        check_kalibr(noise["kalibr"], origin)
    held = [n for entry in comp.get("effects") or [] if isinstance(entry, dict)
            for n in entry.get("not_determined") or [] if isinstance(n, str)]
    return ExportSource(accel_matrix, accel_bias, gyro_matrix, gyro_bias, accel_unit, gyro_unit,
                        origin, text(prov.get("imu_model")), text(prov.get("imu_serial")),
                        text(prov.get("date_utc")), effects, doc.get("parameters") or {}, noise,
                        not_determined=held)


def safe_comment(text: str) -> str:
    """One line of text safe inside any comment syntax used here (C, YAML, plain text)."""
    return "".join(c if c.isprintable() else " " for c in text).replace("*/", "* /")


def write_text(path: Path, text: str) -> Path:
    """Write a whole file (replace it atomically, crash-safe); UserError naming the path on failure."""
    path = Path(path)
    write_new_file(path, text.encode("utf-8"), what="export")
    return path


def fmt(x: float) -> str:
    """A float written so that reading it back gives the same double."""
    x = float(x)
    if not math.isfinite(x):
        raise ValueError(f"not finite: {x}")
    return repr(x)


def yaml_float(x: float) -> str:
    """A float that YAML 1.1 (PyYAML) and 1.2 (yaml-cpp) both read as the same double: repr's
    shortest round-trip form, with a '.' in the mantissa (``1e-12`` is a string to YAML 1.1)."""
    text = fmt(x)
    mantissa, e, exponent = text.partition("e")
    if "." not in mantissa:
        mantissa += ".0"
    return mantissa + (e + exponent if e else "")
