"""Noise figures on file: the ``noise`` block of a calibration file, and ``station-noise/1``
files for recordings that have no calibration (a ``noise`` scheme run).  docs/calibration-file.md
describes the block."""
from __future__ import annotations

import math
from pathlib import Path

import yaml

from station.core.errors import UserError
from station.core import yaml_text
from station.io.calfile import write_new_file

FORMAT = "station-noise/1"
CALIBRATION_FORMAT = "station-calibration/1"
# Kalibr's four numbers and the rate (the block ``kalibr``): a density and the rate are > 0, a
# random walk >= 0 (0: none seen); each a finite number, else another tool is handed nonsense
KALIBR_POSITIVE = ("accelerometer_noise_density", "gyroscope_noise_density", "update_rate")
KALIBR_NON_NEGATIVE = ("accelerometer_random_walk", "gyroscope_random_walk")


def check_kalibr(kal: dict, where) -> None:
    """UserError naming ``where`` and the field when a number of the ``kalibr`` block that is
    present is not a finite number in its range (a density or rate <= 0, a random walk < 0)."""
    for key in KALIBR_POSITIVE + KALIBR_NON_NEGATIVE:
        if key not in kal:
            continue
        v = kal[key]
        positive = key in KALIBR_POSITIVE
        if not (isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
                and (v > 0 if positive else v >= 0)):
            raise UserError(f"{where}: field 'noise.kalibr.{key}': {str(v)[:40]!r} is not a finite number "
                            f"{'> 0' if positive else '>= 0'}")


def _load(path: Path) -> dict:
    from station.core.user_files import read_user_text

    text = read_user_text(path, "noise file")                 # (a FIFO is refused, not read: it hung)
    try:
        doc = yaml_text.safe_load(text)
    except (yaml.YAMLError, ValueError) as e:
        raise UserError(f"{path}: not valid YAML: {yaml_text.error_line(e)}") from None
    if not isinstance(doc, dict):
        raise UserError(f"{path}: not a mapping")
    return doc


def _dump(path: Path, doc: dict) -> Path:
    write_new_file(path, yaml.safe_dump(doc, sort_keys=False, width=100).encode("utf-8"), what="noise file")
    return path


def write_into_calibration(path, block: dict) -> Path:
    """Add (or replace) the ``noise`` block of a calibration file; everything else is kept."""
    from station.io.calfile import read_calfile

    path = Path(path)
    read_calfile(path)                      # a valid calibration file, or one clear line
    doc = _load(path)
    doc["noise"] = block
    return _dump(path, doc)


def write_noise_file(path, block: dict, imu_model=None, imu_serial=None) -> Path:
    return _dump(Path(path), {"format": FORMAT, "imu": {"model": imu_model, "serial": imu_serial},
                              "noise": block})


def noise_serial(path) -> str | None:
    """The IMU serial a noise or calibration file names, if any."""
    doc = _load(Path(path))
    serial = (doc.get("imu") or {}).get("serial") if isinstance(doc.get("imu"), dict) else None
    if serial is None and isinstance(doc.get("provenance"), dict):
        serial = doc["provenance"].get("imu_serial")
    return serial if isinstance(serial, str) else None


def read_noise_block(path) -> dict:
    """The noise block of a station-noise/1 file or of a calibration file."""
    path = Path(path)
    doc = _load(path)
    if doc.get("format") not in (FORMAT, CALIBRATION_FORMAT):
        raise UserError(f"{path}: field 'format': expected {FORMAT} or {CALIBRATION_FORMAT}")
    block = doc.get("noise")
    if not isinstance(block, dict):
        raise UserError(f"{path}: field 'noise': missing (run `station noise` first)")
    kal = block.get("kalibr")
    if not isinstance(kal, dict):
        raise UserError(f"{path}: field 'noise.kalibr': missing or not a mapping")
    check_kalibr(kal, path)
    return block
