"""Several IMUs in one run: the layout of the run's folder and each IMU's own configuration.

A run of the IMUs of station.yaml ``imus:`` writes one folder::

    RUN/run.yaml          station-run/1 with ``imus:`` (index, folder, port of each IMU) and the
                          whole configuration (for --resume)
    RUN/scheme.yaml       the scheme as run
    RUN/<folder>/         one capture bundle per IMU (manifest.yaml, segment CSVs, its own
                          run.yaml and scheme.yaml: a one-IMU run of its own, so that
                          ``station run --resume RUN/<folder>`` continues that IMU alone), and
                          its calibration.yaml

``<folder>`` is the serial number the IMU reports (its driver's identity), else the entry's
``name``, else ``imu<k>`` (k from 1); a name used twice gets ``-<k>`` appended.
"""
from __future__ import annotations

import re
from dataclasses import replace

_SAFE = re.compile(r"[^A-Za-z0-9._-]+")


def imu_config(config, k: int):
    """The one-IMU configuration of IMU ``k`` of ``config.imus``: its connection as ``imu``, its
    mounting and offset as the table's (what its own bundle records and a resume of it alone
    compiles for)."""
    imu = config.imu_list[k]
    table = replace(config.table, mounting=tuple(imu.mounting or config.table.mounting),
                    imu_offset_m=imu.offset_m if imu.offset_m is not None else config.table.imu_offset_m)
    return replace(config, imu=replace(imu, name=None, mounting=None, offset_m=None), imus=(), table=table)


def folder_names(serials: list, names: list) -> list:
    """The folder of each IMU: its serial number, else its name, else imu<k>; unique."""
    out, used = [], set()
    for k, (serial, name) in enumerate(zip(serials, names), 1):
        base = _SAFE.sub("_", str(serial or name or f"imu{k}")).strip("._") or f"imu{k}"
        folder = base if base not in used else f"{base}-{k}"
        used.add(folder)
        out.append(folder)
    return out


def done_segments(done_sets: list) -> set:
    """The segments every IMU has complete: the steps of the others are run again (each IMU
    records only the segments it lacks)."""
    sets = [set(d) for d in done_sets]
    return set.intersection(*sets) if sets else set()
