"""Errors raised by the device drivers.

All derive from :class:`station.core.errors.UserError`, so the command line prints them as one
line (exit status 2).  Every message starts with the device it concerns, e.g.
``"imu /dev/ttyUSB0 (vectornav): no valid frame for 1.0 s"``.
"""
from __future__ import annotations

from station.core.errors import UserError


class DeviceError(UserError):
    """Something went wrong talking to a device; ``str()`` names the device."""

    def __init__(self, device: str, message: str):
        self.device = device
        self.message = message
        super().__init__(f"{device}: {message}".replace("\r", " ").replace("\n", " "))


class DeviceTimeout(DeviceError):
    """A wait ended without the expected reply or frame."""


class DeviceDisconnected(DeviceError):
    """The port went away (USB unplugged, peer closed, pseudo-terminal closed)."""


class ProtocolError(DeviceError):
    """The device rejected a command or answered something we cannot understand."""


class TableFault(DeviceError):
    """The table reports a fault or an open interlock, or an axis did not reach its demand."""


class LimitError(DeviceError):
    """A demand outside the axis or device limits (refused before anything is sent)."""


class NotSupported(DeviceError):
    """The protocol has no command for the requested operation."""
