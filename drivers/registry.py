"""Drivers by protocol name, and opening a device from a port URL and a protocol name."""
from __future__ import annotations

import importlib

from station.core.errors import UserError

#: protocol name -> "module:Class" (imported on first use)
TABLE_DRIVERS = {
    "acutrol": "drivers.acutrol:AcutrolTable",
    "aerosmith": "drivers.aerosmith:AerosmithTable",
}
IMU_DRIVERS = {
    "vectornav": "drivers.vectornav:VectorNavImu",
    "csv": "drivers.csvimu:CsvImu",
    "xsens": "drivers.xsens:XsensImu",
}
DEFAULT_TABLE_PROTOCOL = "acutrol"
DEFAULT_IMU_PROTOCOL = "vectornav"


def register_table(name: str, target: str) -> None:
    """Add a rate-table driver: ``register_table("mytable", "mypkg.mod:MyTable")``."""
    TABLE_DRIVERS[name] = target


def register_imu(name: str, target: str) -> None:
    IMU_DRIVERS[name] = target


def _load(table: dict, name: str, kind: str):
    if name not in table:
        raise UserError(f"unknown {kind} protocol {name!r} (known: {', '.join(sorted(table))})")
    module, _, cls = table[name].partition(":")
    return getattr(importlib.import_module(module), cls)


def table_driver(name: str):
    return _load(TABLE_DRIVERS, name, "rate-table")


def imu_driver(name: str):
    return _load(IMU_DRIVERS, name, "IMU")


def open_table(url: str, protocol: str = DEFAULT_TABLE_PROTOCOL, settings=None):
    """A connected rate-table driver (use as a context manager to close it)."""
    table = table_driver(protocol)(url, settings)
    table.connect()
    return table


def open_imu(url: str, protocol: str = DEFAULT_IMU_PROTOCOL, settings=None):
    """A connected IMU driver (use as a context manager to close it)."""
    imu = imu_driver(protocol)(url, settings)
    imu.connect()
    return imu
