"""The noise a design is for: datasheet numbers, a ``station noise`` result (a station-noise/1
file or a calibration file's noise block), or the noise a capture's own data show (the white
noise per sample the estimator weights it with, station/estimate/summaries.py)."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from station.core.errors import UserError
from station.design.information import Noise

G0 = 9.80665


def _white(block: dict, sensor: str, key: str, path) -> float:
    part = block.get(sensor)
    if not isinstance(part, dict):
        raise UserError(f"{path}: field 'noise.{sensor}': missing or not a mapping")
    values = []
    for axis in "xyz":
        entry = part.get(axis)
        v = entry.get(key) if isinstance(entry, dict) else None
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
            raise UserError(f"{path}: field 'noise.{sensor}.{axis}.{key}': must be a positive number, got {v!r}")
        values.append(float(v))
    return max(values)          # the noisiest axis: a design for every axis


def from_noise_file(path, table_angle_arcsec: float) -> Noise:
    """White noise densities (the noisiest axis of each sensor) from ``station noise``'s result;
    the white acceleration disturbance is in the measured density already (0 here)."""
    from station.io.noise_file import read_noise_block

    block = read_noise_block(path)
    return Noise(accel_noise_ug=_white(block, "accel", "white_noise_ug_rthz", path),
                 gyro_noise_dph=_white(block, "gyro", "white_noise_dph_rthz", path),
                 table_angle_arcsec=table_angle_arcsec, accel_disturbance_ug=0.0,
                 source=f"white noise of {Path(path).name} (station noise)")


def from_capture(path, summaries=None) -> Noise:
    """The white noise the capture's statics show (per sample, to densities by the sample rate)
    and the table angle error its manifest states (``summaries``: the capture's, when read
    already)."""
    from station.estimate.summaries import summarise
    from station.io.capture import read_capture

    s = summaries if summaries is not None else summarise(read_capture(Path(path), load_data=False))
    fs = float(s.sample_rate_hz)
    a = float(np.max(s.accel_sigma)) / G0 * 1e6 / math.sqrt(fs)
    g = float(np.max(s.gyro_sigma)) * 3600.0 / math.sqrt(fs)
    if not (math.isfinite(a) and a > 0 and math.isfinite(g) and g > 0):
        raise UserError(f"{path}: its statics show no noise to design for (give --accel-noise-ug and --gyro-noise-dph)")
    angle = float(s.table_angle_sigma_deg) * 3600.0
    return Noise(accel_noise_ug=a, gyro_noise_dph=g, table_angle_arcsec=angle, accel_disturbance_ug=0.0,
                 source=f"white noise of the capture {Path(path).name}")
