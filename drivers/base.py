"""The abstract device interfaces, :class:`RateTable` (``drivers.table``) and :class:`Imu`
(``drivers.imu``), with their settings and results, in one place.

Drivers are looked up by protocol name in :mod:`drivers.registry`; the transport is any
pyserial URL (:mod:`drivers.transport`).
"""
from .imu import Imu, ImuSettings
from .samples import ImuCounters, ImuSamples
from .table import AxisLimits, RateTable, TableSettings, TableStatus, angle_diff_deg, wrap_deg

__all__ = ["AxisLimits", "Imu", "ImuCounters", "ImuSamples", "ImuSettings", "RateTable",
           "TableSettings", "TableStatus", "angle_diff_deg", "wrap_deg"]
