"""A pseudo-terminal end point: the twin holds the master side, a driver opens ``path``.

The slave side is put in raw mode (no echo, no line editing) at once and kept open by the
twin, so the line settings hold and the master never reads EIO while no driver is attached.
Output goes through a small queue like a UART transmit buffer (sim_devices/twins/endpoint.py).

With :meth:`PtyEndpoint.emulate_baud` the end point behaves like a serial line between a device
at one baud rate and a driver at another: the driver's baud rate is the one it set on the
pseudo-terminal (termios, read back with TCGETS2), the device's is given; when they differ,
bytes each way come out as a UART at the other rate would receive them
(sim_devices/twins/uart.py): garbage, fewer or more bytes by the ratio of the rates.
"""
from __future__ import annotations

import array
import errno
import fcntl
import os
import struct
import termios
import tty
from typing import Callable

from sim_devices.twins.endpoint import QueuedEndpoint
from sim_devices.twins.uart import reframe

#: ioctl reading ``struct termios2`` (Linux): its c_ispeed and c_ospeed hold any baud rate
TCGETS2 = getattr(termios, "TCGETS2", 0x802C542A)
_TERMIOS2_WORDS = 11          # 4 flags, c_line + 19 c_cc (5 words), c_ispeed, c_ospeed


class PtyEndpoint(QueuedEndpoint):
    def __init__(self, max_backlog_bytes: int = 8192):
        super().__init__(max_backlog_bytes)
        self.master, self._slave = os.openpty()
        tty.setraw(self._slave)
        attrs = termios.tcgetattr(self._slave)
        attrs[3] &= ~(termios.ECHO | termios.ECHONL | termios.ICANON | termios.ISIG | termios.IEXTEN)
        termios.tcsetattr(self._slave, termios.TCSANOW, attrs)
        os.set_blocking(self.master, False)
        self.path = os.ttyname(self._slave)
        self._device_baud: Callable[[], int] | None = None
        self._line_seen: int | None = None

    # ---------------------------------------------------------------- baud rates
    def emulate_baud(self, device_baud: Callable[[], int]) -> None:
        """From now on the device's side of the line runs at ``device_baud()``; the line starts
        at that rate (a driver that sets another one gets garbage)."""
        self._device_baud = device_baud
        self.set_line_baud(device_baud())
        self._line_seen = self.line_baud()

    def line_baud(self) -> int | None:
        """The baud rate the driver has set on the pseudo-terminal (None: unknown)."""
        try:
            words = array.array("I", [0] * (_TERMIOS2_WORDS + 8))
            fcntl.ioctl(self._slave, TCGETS2, words)
            return int(words[10]) or None
        except OSError:
            return None

    def set_line_baud(self, baud: int) -> None:
        """Set the pseudo-terminal's baud rate as a driver opening it at ``baud`` would."""
        speed = getattr(termios, f"B{int(baud)}", None)
        if speed is None:
            return
        attrs = termios.tcgetattr(self._slave)
        attrs[4] = attrs[5] = speed
        termios.tcsetattr(self._slave, termios.TCSANOW, attrs)

    def _mismatch(self, device: int | None = None) -> tuple[int, int] | None:
        """(device baud, line baud) when they differ, else None."""
        if self._device_baud is None:
            return None
        device = device or self._device_baud()
        line = self.line_baud()
        if line != self._line_seen and self._out:
            self.flush()                  # drops what was made for the old rate
        self._line_seen = line
        return (device, line) if line and line != device else None

    def flush(self) -> None:
        """Send what the line takes; bytes queued for a driver that has since changed its baud
        rate are dropped (they were made for the old rate: in flight, they would be garbage)."""
        if self._device_baud is not None and self._out:
            line = self.line_baud()
            if line != self._line_seen:
                self._line_seen = line
                self.dropped_bytes += len(self._out)
                self.clear_output()
        super().flush()

    def write(self, data: bytes, droppable: bool = False, baud: int | None = None) -> bool:
        """Queue ``data`` sent by the device at ``baud`` (default: its present rate), as the
        driver's UART receives it."""
        m = self._mismatch(baud) if data else None
        if m is not None:
            data = reframe(data, *m)
            if not data:
                return True
        return super().write(data, droppable)

    def fileno(self) -> int:
        return self.master

    def unread(self) -> int:
        """Bytes written that the driver has not read yet and that the line already holds
        (FIONREAD on the slave side: the line discipline's buffer, up to 4 KiB)."""
        if self.closed:
            return 0
        try:
            return struct.unpack("i", fcntl.ioctl(self._slave, termios.FIONREAD, b"\0\0\0\0"))[0]
        except OSError:
            return 0

    def discard_unread(self) -> int:
        """Drop what was written and not read yet, queued here or held by the line (the slave
        side's input queue: tcflush TCIFLUSH); returns the bytes dropped.  A real serial line
        loses what a device sends while no program has the port open; here the twin holds the
        slave side open, so a reply nobody read would wait for the next reader."""
        if self.closed:
            return 0
        dropped = self.unread() + len(self._out)
        self.clear_output()
        try:
            termios.tcflush(self._slave, termios.TCIFLUSH)
        except termios.error:
            return 0
        return dropped

    def read(self) -> bytes:
        if self.closed:
            return b""
        try:
            data = os.read(self.master, 65536)
            m = self._mismatch() if data else None
            return reframe(data, m[1], m[0]) if m is not None else data
        except (BlockingIOError, InterruptedError):
            return b""
        except OSError as e:
            if e.errno == errno.EIO:
                return b""
            raise

    def _send(self, data: bytearray) -> int | None:
        try:
            return os.write(self.master, data)
        except (BlockingIOError, InterruptedError):
            return None
        except OSError as e:
            if e.errno == errno.EIO:
                return None
            raise

    def close(self) -> None:
        """Hang up: the driver's next read or write fails (a disconnect)."""
        if not self.closed:
            self.closed = True
            for fd in (self.master, self._slave):
                try:
                    os.close(fd)
                except OSError:
                    pass
