"""Exporters: a station calibration file written in other tools' formats.

Each module converts the calibration's *compensation* (docs/calibration-file.md) into the
convention of one tool and states that convention in the file it writes (or next to it, when the
format has no room for a comment).  ``FORMATS`` maps the name ``station export --to`` takes to
the module; every module has ``TITLE``, ``CONVENTION`` (one paragraph, printed and written),
``SUFFIX`` (the default file name ending) and ``write(source, path) -> list[Path]``.
"""
from __future__ import annotations

from station.io.exporters import c_header, imu_tk, imucal_json, json_plain, kalibr, ros_imu_calib
from station.io.exporters.source import ExportSource, source_from_document

FORMATS = {
    "imucal": imucal_json,
    "imu_tk": imu_tk,
    "kalibr": kalibr,
    "ros": ros_imu_calib,
    "c": c_header,
    "json": json_plain,
}

__all__ = ["FORMATS", "ExportSource", "source_from_document"]
