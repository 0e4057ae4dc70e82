"""imucal's calibration JSON, format version 2.0.0 (``imucal.management.load_calibration_info``).

imucal (mad-lab-fau/imucal, ``FerrarisCalibrationInfo``) calibrates
  acc_out = R_a^-1 K_a^-1 (acc - b_a)
  gyr_out = R_g^-1 K_g^-1 (gyr - K_ga acc_out - b_g)
with K diagonal gains, R the sensing axes as unit rows and K_ga the g-sensitivity.  station's
compensation matrix M is the inverse of K R, so K = the row norms of M^-1 and R = its rows
divided by their norms; b stays in raw units; K_ga = 0 (station's base model has no
g-sensitivity; with the g_sensitivity effect added it is dropped with a note).
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from station.io.exporters.source import ExportSource, write_text

TITLE = "imucal calibration JSON v2 (Turntable/Ferraris calibration info)"
SUFFIX = ".json"
FORMAT_VERSION = "2.0.0"
CONVENTION = ("imucal 2.x: acc_out = inv(R_a) inv(K_a) (acc - b_a), gyr_out = inv(R_g) inv(K_g) "
              "(gyr - K_ga acc_out - b_g); K diagonal gains (raw per output unit), R rows the unit "
              "sensing axes in station's frame p (accelerometer-defined), b in raw units, K_ga = 0; "
              "output m/s^2 and deg/s")


def gains_and_axes(matrix: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(K diagonal, R unit rows) with inv(R) inv(K) = matrix."""
    forward = np.linalg.inv(matrix)
    gains = np.linalg.norm(forward, axis=1)
    return np.diag(gains), forward / gains[:, None]


def document(source: ExportSource) -> dict:
    K_a, R_a = gains_and_axes(source.accel_matrix)
    if source.has_gyro:
        K_g, R_g = gains_and_axes(source.gyro_matrix)
        b_g, gyr_unit = source.gyro_bias, "deg/s"
    else:   # imucal needs both triads: the identity passes the gyro through in its raw unit
        K_g, R_g, b_g, gyr_unit = np.eye(3), np.eye(3), np.zeros(3), source.gyro_unit
    comment = " | ".join([*source.header_lines(), "convention: " + CONVENTION])
    return {
        "acc_unit": "m/s^2",
        "gyr_unit": gyr_unit,
        "from_acc_unit": source.accel_unit,
        "from_gyr_unit": source.gyro_unit,
        "comment": comment,
        "K_a": K_a.tolist(), "R_a": R_a.tolist(), "b_a": np.asarray(source.accel_bias).tolist(),
        "K_g": K_g.tolist(), "R_g": R_g.tolist(), "K_ga": np.zeros((3, 3)).tolist(),
        "b_g": np.asarray(b_g).tolist(),
        "cal_type": "Turntable",
        "_format_version": FORMAT_VERSION,
    }


def write(source: ExportSource, path) -> list[Path]:
    return [write_text(path, json.dumps(document(source), indent=4) + "\n")]
