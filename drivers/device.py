"""What every serial device driver shares: the port, its opening and closing."""
from __future__ import annotations

import abc
import logging

from .errors import DeviceError
from .transport import Port


class Device(abc.ABC):
    """A device on a pyserial URL.  Subclasses set ``kind`` and ``protocol`` and fill
    ``_on_connect`` (identify, configure; returns the log line) and, if needed, ``_before_close``."""

    kind: str = "device"
    protocol: str = ""

    def __init__(self, url: str, settings):
        self.url = url
        self.settings = settings
        self.name = f"{self.kind} {url} ({self.protocol})"
        self.log = logging.getLogger(f"drivers.{self.protocol}")
        self._port: Port | None = None
        self._bytes_closed = 0            # bytes received through ports since closed
        self.identity = ""

    @property
    def bytes_received(self) -> int:
        """Bytes received from the device since this driver was made (also after close():
        line diagnostics after a failed connect)."""
        now = getattr(self._port, "bytes_received", 0) if self._port is not None else 0
        return self._bytes_closed + now

    @property
    def port(self) -> Port:
        """The open port; DeviceError before ``connect()`` or after ``close()``."""
        if self._port is None:
            raise DeviceError(self.name, "not connected (call connect(), or use it in a with block)")
        return self._port

    def connect(self) -> str:
        """Open the port and bring the device up; on any failure the port is closed again."""
        self._port = self._open_port()
        try:
            line = self._on_connect()
        except BaseException:
            self.close()
            raise
        self.log.info("%s: %s", self.name, line)
        return self.identity

    def _open_port(self):
        """The transport: a pyserial :class:`Port` on ``url`` (drivers may choose others)."""
        return Port(self.url, self.settings.serial, self.name, self.log)

    @abc.abstractmethod
    def _on_connect(self) -> str: ...

    def _before_close(self) -> None:
        """Leave the device quiet before the port closes (best effort)."""

    def close(self) -> None:
        if self._port is not None:
            self._before_close()
            self._port.close()
            self._bytes_closed += getattr(self._port, "bytes_received", 0)
            self._port = None

    def __enter__(self):
        if self._port is None:
            self.connect()
        return self

    def __exit__(self, *exc):
        self.close()
