"""A pseudo-terminal end point: the twin holds the master side, a driver opens ``path``.

The slave side is put in raw mode (no echo, no line editing) at once and kept open by the
twin, so the line settings hold and the master never reads EIO while no driver is attached.
Output goes through a small queue like a UART transmit buffer (sim_devices/twins/endpoint.py).
"""
from __future__ import annotations

import errno
import fcntl
import os
import struct
import termios
import tty

from sim_devices.twins.endpoint import QueuedEndpoint


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

    def read(self) -> bytes:
        if self.closed:
            return b""
        try:
            return os.read(self.master, 65536)
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
