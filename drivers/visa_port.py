"""A transport through pyvisa (backend pyvisa-py): GPIB, TCPIP SOCKET and serial VISA resources.

``visa://GPIB0::1::INSTR``, ``visa://TCPIP0::192.168.53.1::9878::SOCKET``,
``visa://ASRL/dev/ttyUSB0::INSTR``: the part after ``visa://`` is the VISA resource string.
It offers what the Acutrol driver uses of :class:`drivers.transport.Port` (write, reads of a
line or of n bytes with a deadline, discard, close), with pyvisa's errors turned into the
drivers' errors naming the device.
"""
from __future__ import annotations

import logging

from .errors import DeviceDisconnected, DeviceError, DeviceTimeout
from .transport import SerialSettings

SCHEME = "visa://"


class VisaPort:
    def __init__(self, resource: str, settings: SerialSettings, name: str, log: logging.Logger,
                 backend: str = "@py"):
        try:
            import pyvisa
        except ImportError as e:           # declared in pyproject; a broken install
            raise DeviceError(name, f"pyvisa is not installed ({e})") from None
        self._pyvisa = pyvisa
        self.url = SCHEME + resource
        self.settings = settings
        self.name = name
        self.log = log
        try:
            self._rm = pyvisa.ResourceManager(backend)
            inst = self._rm.open_resource(resource)
            inst.timeout = int(settings.timeout_s * 1000)
            inst.read_termination = None
            inst.write_termination = ""
            if resource.upper().startswith("ASRL"):
                inst.baud_rate = settings.baudrate
                inst.data_bits = settings.bytesize
        except Exception as e:             # pyvisa raises many kinds (VisaIOError, ValueError, OSError)
            raise DeviceError(name, f"cannot open {resource}: {e}") from None
        self._inst = inst

    @property
    def is_open(self) -> bool:
        return self._inst is not None

    def close(self) -> None:
        if self._inst is not None:
            try:
                self._inst.close()
                self._rm.close()
            except Exception:          # closing anyway
                pass
            self._inst = None

    def write(self, data: bytes) -> None:
        self.log.debug("%s <- %r", self.name, data)
        try:
            self._inst.write_raw(data)
        except self._pyvisa.errors.VisaIOError as e:
            raise self._error(e, "writing") from None

    def discard_input(self) -> None:
        try:
            self._inst.flush(self._pyvisa.constants.BufferOperation.discard_read_buffer)
        except Exception:                # not every resource has a read buffer to flush
            pass

    def read_until(self, terminator: bytes, timeout_s, what: str, buffer=None, max_bytes: int = 4096) -> bytes:
        self._timeout(timeout_s)
        try:
            self._inst.read_termination = terminator.decode("ascii")
            out = self._inst.read_raw()
        except self._pyvisa.errors.VisaIOError as e:
            raise self._error(e, f"waiting for the reply to {what}") from None
        finally:
            self._inst.read_termination = None
        self.log.debug("%s -> %r", self.name, out)
        return out

    def read_exact(self, n: int, timeout_s, what: str, buffer=None) -> bytes:
        self._timeout(timeout_s)
        try:
            out = self._inst.read_bytes(n)
        except self._pyvisa.errors.VisaIOError as e:
            raise self._error(e, f"waiting for the reply to {what}") from None
        self.log.debug("%s -> %r", self.name, out)
        return out

    def _timeout(self, timeout_s) -> None:
        t = self.settings.timeout_s if timeout_s is None else timeout_s
        self._inst.timeout = max(1, int(t * 1000))

    def _error(self, e, doing: str):
        if e.error_code == self._pyvisa.constants.StatusCode.error_timeout:
            return DeviceTimeout(self.name, f"timeout {doing} ({self._inst.timeout} ms)")
        return DeviceDisconnected(self.name, f"VISA error {doing}: {e}")
