"""Kalibr's IMU configuration ``imu.yaml`` (ethz-asl/kalibr, kalibr_calibrate_imu_camera --imu).

Kalibr reads four noise figures in continuous time and the sample rate:
  accelerometer_noise_density  m/s^2/sqrt(Hz)   white noise (= VRW)
  accelerometer_random_walk    m/s^3/sqrt(Hz)   bias random walk
  gyroscope_noise_density      rad/s/sqrt(Hz)   white noise (= ARW)
  gyroscope_random_walk        rad/s^2/sqrt(Hz) bias random walk
  rostopic, update_rate (Hz)
They come from the calibration's ``noise`` block (``station noise``): per triad the largest of
the three axes.  Kalibr's imu.yaml holds no scale factors or misalignments: publish the
compensated stream (``station apply`` or one of the other exports) on the topic Kalibr reads.
"""
from __future__ import annotations

from pathlib import Path

from station.core.errors import UserError
from station.io.exporters.source import ExportSource, safe_comment, write_text, yaml_float as fmt

TITLE = "Kalibr imu.yaml (noise densities, random walks, rate)"
SUFFIX = ".yaml"
KEYS = ("accelerometer_noise_density", "accelerometer_random_walk",
        "gyroscope_noise_density", "gyroscope_random_walk")
CONVENTION = ("Kalibr: continuous-time white-noise densities (accelerometer m/s^2/sqrt(Hz), gyroscope "
              "rad/s/sqrt(Hz)) and bias random walks (m/s^3/sqrt(Hz), rad/s^2/sqrt(Hz)) from the "
              "overlapping Allan deviation, the largest of the three axes per triad; an upper bound "
              "where the Allan curve did not reach its +1/2 slope; for the compensated stream")
ROSTOPIC = "/imu0"


def write(source: ExportSource, path) -> list[Path]:
    from station.io.noise_file import check_kalibr

    kal = (source.noise or {}).get("kalibr")
    missing = not isinstance(kal, dict) or any(k not in kal for k in (*KEYS, "update_rate"))
    if missing:
        raise UserError(f"{source.noise_origin or source.origin}: no noise figures: Kalibr's imu.yaml needs the noise "
                        "densities and random walks; run `station noise CAPTURE --cal CAL.yaml` first")
    check_kalibr(kal, source.noise_origin or source.origin)
    lines = [f"# {safe_comment(line)}" for line in [*source.header_lines(), "convention: " + CONVENTION]]
    for key in KEYS:
        note = " (upper bound)" if key.endswith("random_walk") and kal.get(f"{key}_is_upper_bound") else ""
        lines.append(f"{key}: {fmt(kal[key])}{'   #' + note if note else ''}")
    lines += [f"rostopic: {ROSTOPIC}", f"update_rate: {fmt(kal['update_rate'])}"]
    return [write_text(path, "\n".join(lines) + "\n")]
