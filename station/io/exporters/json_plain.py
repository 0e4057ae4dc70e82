"""Plain JSON: the compensation, every parameter with its unit and 1 sigma, the noise figures,
the convention in words.  For programs that want station's own convention without a YAML parser.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from station.io.exporters.source import ExportSource, write_text

TITLE = "plain JSON (station's compensation, parameters, noise)"
SUFFIX = ".json"
FORMAT = "station-calibration-json/1"
CONVENTION = ("station: f_p = accel_matrix (accel_raw - accel_bias) in m/s^2, w_p = gyro_matrix "
              "(gyro_raw - gyro_bias) in deg/s; biases in the raw units; frame p defined by the "
              "accelerometers (x along x's sensing axis, y in the x-y sensing plane); matrices row by row")


def document(source: ExportSource) -> dict:
    comp = {"accel_matrix": np.asarray(source.accel_matrix).tolist(),
            "accel_bias": np.asarray(source.accel_bias).tolist(),
            "raw_units": {"accel": source.accel_unit, "gyro": source.gyro_unit},
            "output_units": {"accel": "m/s^2", "gyro": "deg/s"}}
    if source.has_gyro:
        comp["gyro_matrix"] = np.asarray(source.gyro_matrix).tolist()
        comp["gyro_bias"] = np.asarray(source.gyro_bias).tolist()
    return {"format": FORMAT, "convention": CONVENTION, "notes": source.header_lines(),
            "imu": {"model": source.imu_model, "serial": source.imu_serial},
            "date_utc": source.date_utc, "effects": source.effects,
            "compensation": comp, "parameters": source.parameters,
            **({"noise": source.noise} if source.noise else {})}


def write(source: ExportSource, path) -> list[Path]:
    return [write_text(path, json.dumps(document(source), indent=1) + "\n")]
