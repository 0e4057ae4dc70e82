"""A calibration file for the ROS ``imu_calib`` package (dpkoch/imu_calib, ``apply_calib`` node).

imu_calib reads a YAML file with ``SM`` (9 numbers, a 3x3 matrix row by row) and ``bias`` (3)
and corrects each sensor_msgs/Imu linear_acceleration as ``corrected = SM raw - bias`` (bias in
the output unit).  The raw message carries REP-103 units (m/s^2) when the calibration's raw unit
is physical, else the raw counts; so SM = M / u_a (u_a: m/s^2 per raw unit, 1 for counts) and
bias = M b_a, with M, b_a station's compensation.  imu_calib corrects only the accelerometers
(it re-estimates the gyro bias at start-up); the same convention for the gyros, into rad/s, is
added as ``gyro_SM`` and ``gyro_bias`` (ignored by imu_calib, read by anything that wants it).
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from station.io.exporters.source import ExportSource, safe_comment, write_text, yaml_float as fmt

TITLE = "ROS imu_calib YAML (SM, bias; gyro_SM, gyro_bias)"
SUFFIX = ".yaml"
CONVENTION = ("imu_calib: corrected = SM raw - bias, SM row-major 3x3; raw in REP-103 units "
              "(m/s^2, rad/s) when the calibration's raw unit is physical, else counts; output "
              "m/s^2 and rad/s in station's frame p (accelerometer-defined)")


def matrices(source: ExportSource):
    """(SM, bias, gyro_SM or None, gyro_bias or None) in imu_calib's convention."""
    u_a = source.accel_input_to_si() or 1.0
    sm = source.accel_matrix / u_a
    bias = source.accel_matrix @ source.accel_bias
    if not source.has_gyro:
        return sm, bias, None, None
    dps = source.gyro_input_to_dps()
    u_g = math.radians(dps) if dps else 1.0          # rad/s per raw gyro unit (1 for counts)
    out_rad = math.radians(1.0)                        # rad/s per deg/s of station's output
    gsm = out_rad * source.gyro_matrix / u_g
    gbias = out_rad * source.gyro_matrix @ source.gyro_bias
    return sm, bias, gsm, gbias


def write(source: ExportSource, path) -> list[Path]:
    sm, bias, gsm, gbias = matrices(source)
    row = lambda a: "[" + ", ".join(fmt(v) for v in np.ravel(a)) + "]"  # noqa: E731
    lines = [f"# {safe_comment(line)}" for line in [*source.header_lines(), "convention: " + CONVENTION]]
    lines += [f"SM: {row(sm)}", f"bias: {row(bias)}"]
    if gsm is not None:
        lines += [f"gyro_SM: {row(gsm)}", f"gyro_bias: {row(gbias)}"]
    return [write_text(path, "\n".join(lines) + "\n")]
