"""Byte transport: any pyserial URL, serial settings from a :class:`SerialSettings`.

``/dev/ttyUSB0``, ``/dev/pts/7``, ``socket://host:port``, ``spy:///dev/ttyUSB0`` ... are all
opened with :func:`serial.serial_for_url`.  :class:`Port` adds what every driver needs on top
of pyserial: reads bounded by a deadline, pyserial and OS errors turned into
:class:`~drivers.errors.DeviceDisconnected` naming the device, and debug logging.
"""
from __future__ import annotations

import logging
import socket
import struct
import time
from dataclasses import dataclass

import serial
from serial.urlhandler import protocol_socket

from .errors import DeviceDisconnected, DeviceError, DeviceTimeout, ProtocolError

PARITIES = {"N": serial.PARITY_NONE, "E": serial.PARITY_EVEN, "O": serial.PARITY_ODD,
            "M": serial.PARITY_MARK, "S": serial.PARITY_SPACE}

#: longest a single pyserial read blocks, s (deadlines are checked between reads)
READ_SLICE_S = 0.05
#: read_waiting looks again after this long before it takes "nothing waiting" for an answer
WAITING_RECHECK_S = 0.002


#: pyserial's socket:// port sleeps this long in close() "in case of quick reconnects, give the
#: server some time"; :class:`SocketPort` waits it out only when the same address is opened again
#: that soon (a close followed by nothing, the usual case, costs no wait)
SOCKET_RECONNECT_S = 0.3
_socket_closed_at: dict[str, float] = {}     # socket:// URL -> time.monotonic() of its last close


try:    # a port that hangs up mid-call: tcdrain (a write's flush) raises termios.error, not OSError
    import fcntl
    import termios
    PORT_ERRORS: tuple = (serial.SerialException, OSError, termios.error)
except ImportError:     # not on Windows
    fcntl = termios = None
    PORT_ERRORS = (serial.SerialException, OSError)


class SocketPort(protocol_socket.Serial):
    """pyserial's ``socket://`` port with two changes: ``in_waiting`` is the number of bytes
    received (FIONREAD; pyserial's says 0 or 1, so a reply was read one byte, one select and one
    recv at a time), and ``close()`` does not sleep: the pause pyserial gives a server before a
    quick reconnect (SOCKET_RECONNECT_S) is taken when the same address is opened again."""

    @property
    def in_waiting(self) -> int:
        n = protocol_socket.Serial.in_waiting.fget(self)
        if n and termios is not None:
            try:
                got = struct.unpack("i", fcntl.ioctl(self._socket.fileno(), termios.FIONREAD, b"\0\0\0\0"))[0]
            except OSError:
                return n
            return got or n     # readable with nothing to read: end of file, for read() to see
        return n

    def open(self) -> None:
        wait = _socket_closed_at.get(self.portstr, -1e9) + SOCKET_RECONNECT_S - time.monotonic()
        if wait > 0:
            time.sleep(wait)
        super().open()

    def close(self) -> None:
        if self.is_open:
            if self._socket:
                try:
                    self._socket.shutdown(socket.SHUT_RDWR)
                except OSError:
                    pass
                try:
                    self._socket.close()
                except OSError:
                    pass
                self._socket = None
            self.is_open = False
            _socket_closed_at[self.portstr] = time.monotonic()


@dataclass(frozen=True)
class SerialSettings:
    """Serial line settings (ignored by pyserial for socket:// URLs).

    ``timeout_s`` is the default wait for a reply or a frame before
    :class:`~drivers.errors.DeviceTimeout`; ``write_timeout_s`` bounds a blocked write.
    """

    baudrate: int = 115200
    bytesize: int = 8
    parity: str = "N"
    stopbits: float = 1
    rtscts: bool = False
    xonxoff: bool = False
    timeout_s: float = 1.0
    write_timeout_s: float = 1.0

    def __post_init__(self):
        if self.parity not in PARITIES:
            raise ValueError(f"parity must be one of {', '.join(PARITIES)}, got {self.parity!r}")
        if self.bytesize not in (5, 6, 7, 8):
            raise ValueError(f"bytesize must be 5..8, got {self.bytesize!r}")
        if self.stopbits not in (1, 1.5, 2):
            raise ValueError(f"stopbits must be 1, 1.5 or 2, got {self.stopbits!r}")
        if not (self.baudrate > 0 and self.timeout_s > 0 and self.write_timeout_s > 0):
            raise ValueError("baudrate and timeouts must be > 0")


class Port:
    """An open pyserial port with deadlines, error translation and logging.

    ``name`` (e.g. ``"imu /dev/pts/3 (vectornav)"``) starts every error message.
    """

    def __init__(self, url: str, settings: SerialSettings, name: str, log: logging.Logger):
        self.url = url
        self.settings = settings
        self.name = name
        self.log = log
        try:
            ser = serial.serial_for_url(url, do_not_open=True)
            if type(ser) is protocol_socket.Serial:        # socket://host:port
                ser = SocketPort(None)
                ser.port = url
            ser.baudrate = settings.baudrate
            ser.bytesize = settings.bytesize
            ser.parity = PARITIES[settings.parity]
            ser.stopbits = settings.stopbits
            ser.rtscts = settings.rtscts
            ser.xonxoff = settings.xonxoff
            ser.timeout = READ_SLICE_S
            ser.write_timeout = settings.write_timeout_s
            ser.open()
        except (*PORT_ERRORS, ValueError) as e:
            raise DeviceError(name, f"cannot open {url}: {e}") from None
        self._ser = ser
        self.bytes_received = 0           # every byte read from the port (line diagnostics)

    # ------------------------------------------------------------------ basics
    def close(self) -> None:
        try:
            self._ser.close()
        except PORT_ERRORS:
            pass

    @property
    def is_open(self) -> bool:
        return bool(self._ser.is_open)

    def set_baudrate(self, baudrate: int) -> None:
        """Switch the line to ``baudrate`` (after the device was told to)."""
        try:
            self._ser.baudrate = int(baudrate)
        except (*PORT_ERRORS, ValueError) as e:
            raise DeviceDisconnected(self.name, f"cannot switch to {baudrate} baud ({e})") from None

    def write(self, data: bytes) -> None:
        self.log.debug("%s <- %r", self.name, data)
        try:
            self._ser.write(data)
            self._ser.flush()
        except serial.SerialTimeoutException:
            raise DeviceTimeout(self.name, f"write blocked for {self.settings.write_timeout_s} s") from None
        except PORT_ERRORS as e:
            raise DeviceDisconnected(self.name, f"disconnected while writing ({e})") from None

    def read_waiting(self, max_bytes: int = 1 << 22) -> bytes:
        """Every byte already waiting in the port (at most ``max_bytes``): reads until nothing
        is waiting twice, WAITING_RECHECK_S apart."""
        out = bytearray()
        quiet = 0
        try:
            while len(out) < max_bytes and quiet < 2:
                n = self._ser.in_waiting
                if n:
                    out += self._ser.read(min(n, max_bytes - len(out)))
                    quiet = 0
                else:               # a pty passes on what waits in its flip buffers after a
                    quiet += 1      #   read, asynchronously: look once more, a moment later
                    if quiet < 2:
                        time.sleep(WAITING_RECHECK_S)
        except PORT_ERRORS as e:
            raise DeviceDisconnected(self.name, f"disconnected ({e})") from None
        if out:
            self.bytes_received += len(out)
            self.log.debug("%s -> %d bytes (waiting)", self.name, len(out))
        return bytes(out)

    def read_some(self, max_bytes: int = 65536) -> bytes:
        """What is waiting (at least 1 byte), or b'' after one read slice (<= 50 ms)."""
        try:
            n = self._ser.in_waiting
            data = self._ser.read(min(max(n, 1), max_bytes))
        except PORT_ERRORS as e:
            raise DeviceDisconnected(self.name, f"disconnected ({e})") from None
        if data:
            self.bytes_received += len(data)
            self.log.debug("%s -> %d bytes", self.name, len(data))
        return data

    def discard_input(self) -> None:
        """Drop everything received so far (stale replies, old frames)."""
        try:
            self._ser.reset_input_buffer()
        except PORT_ERRORS as e:
            raise DeviceDisconnected(self.name, f"disconnected ({e})") from None

    # ----------------------------------------------------------- terminated reads
    def read_until(self, terminator: bytes, timeout_s: float | None, what: str,
                   buffer: bytearray | None = None, max_bytes: int = 4096) -> bytes:
        """Bytes up to and including ``terminator``; extra bytes stay in ``buffer``.

        Raises DeviceTimeout naming ``what`` when nothing complete arrives in time, and
        ProtocolError when more than ``max_bytes`` arrive without it.
        """
        buf = buffer if buffer is not None else bytearray()
        timeout = self.settings.timeout_s if timeout_s is None else timeout_s
        deadline = time.monotonic() + timeout
        while True:
            i = buf.find(terminator)
            if i >= 0:
                end = i + len(terminator)
                out = bytes(buf[:end])
                del buf[:end]
                self.log.debug("%s -> %r", self.name, out)
                return out
            if len(buf) > max_bytes:
                junk = bytes(buf[:64])
                buf.clear()
                raise ProtocolError(self.name, f"no {terminator!r} in {max_bytes} bytes while waiting "
                                               f"for {what} (starts {junk!r})")
            if time.monotonic() >= deadline:
                raise DeviceTimeout(self.name, f"no reply to {what} within {timeout:g} s")
            buf += self.read_some()

    def read_exact(self, n: int, timeout_s: float | None, what: str,
                   buffer: bytearray | None = None) -> bytes:
        """Exactly ``n`` bytes (extra bytes stay in ``buffer``); DeviceTimeout naming ``what``."""
        buf = buffer if buffer is not None else bytearray()
        timeout = self.settings.timeout_s if timeout_s is None else timeout_s
        deadline = time.monotonic() + timeout
        while len(buf) < n:
            if time.monotonic() >= deadline:
                raise DeviceTimeout(self.name, f"no reply to {what} within {timeout:g} s "
                                               f"({len(buf)} of {n} bytes)")
            buf += self.read_some()
        out = bytes(buf[:n])
        del buf[:n]
        return out
