"""imu_tk's calibrated-triad text files (``imu_tk::CalibratedTriad_::load``), one per triad.

imu_tk (A. Pretto, Tedaldi et al. ICRA 2014) corrects a raw triad reading X as
  X' = T K (X - B)
with T a misalignment matrix with unit diagonal, K diagonal scale factors and B the bias, and
reads a file as 21 whitespace-separated numbers: T (3x3, row by row), K (3x3), B (3).  station's
compensation matrix M = T K with K = diag(M) and T = M diag(M)^-1; B is the raw-unit bias.  The
loader stops after the 21 numbers, so the convention follows them as ``#`` lines.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from station.io.exporters.source import ExportSource, fmt, safe_comment, write_text

TITLE = "imu_tk text, T K B per triad (PREFIX_acc.calib, PREFIX_gyro.calib)"
SUFFIX = ".calib"
CONVENTION = ("imu_tk: X' = T K (X - B); T misalignment (unit diagonal), K diagonal scale, "
              "B bias in raw units; output m/s^2 (accelerometers) and deg/s (gyros) in station's "
              "frame p (accelerometer-defined)")


def split(matrix: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(T with unit diagonal, K diagonal) with T K = matrix."""
    scale = np.diag(matrix).copy()
    return matrix / scale[None, :], np.diag(scale)


def triad_text(matrix, bias, lines) -> str:
    T, K = split(np.asarray(matrix, float))
    rows = [" ".join(fmt(v) for v in row) for row in T] + [""]
    rows += [" ".join(fmt(v) for v in row) for row in K] + [""]
    rows += [fmt(v) for v in bias] + [""]
    return "\n".join(rows + [f"# {safe_comment(line)}" for line in lines]) + "\n"


def paths(path) -> tuple[Path, Path]:
    """PREFIX_acc.calib and PREFIX_gyro.calib from the path given (its .calib ending dropped)."""
    path = Path(path)
    stem = path.name[:-len(SUFFIX)] if path.name.endswith(SUFFIX) else path.name
    return path.with_name(f"{stem}_acc{SUFFIX}"), path.with_name(f"{stem}_gyro{SUFFIX}")


def write(source: ExportSource, path) -> list[Path]:
    acc_path, gyro_path = paths(path)
    notes = [*source.header_lines(), "convention: " + CONVENTION]
    written = [write_text(acc_path, triad_text(source.accel_matrix, source.accel_bias,
                                               [f"accelerometers: raw {source.accel_unit} -> m/s^2", *notes]))]
    if source.has_gyro:
        written.append(write_text(gyro_path, triad_text(source.gyro_matrix, source.gyro_bias,
                                                        [f"gyros: raw {source.gyro_unit} -> deg/s", *notes])))
    return written
