"""A pseudo-terminal end point: the twin holds the master side, a driver opens ``path``.

The slave side is put in raw mode (no echo, no line editing) at once and kept open by the
twin, so the line settings hold and the master never reads EIO while no driver is attached.
Output goes through a small queue like a UART transmit buffer: when the reader does not keep
up, droppable data (stream frames) is dropped whole and counted, replies never are.
"""
from __future__ import annotations

import errno
import fcntl
import os
import struct
import termios
import tty


class PtyEndpoint:
    def __init__(self, max_backlog_bytes: int = 8192):
        self.master, self._slave = os.openpty()
        tty.setraw(self._slave)
        attrs = termios.tcgetattr(self._slave)
        attrs[3] &= ~(termios.ECHO | termios.ECHONL | termios.ICANON | termios.ISIG | termios.IEXTEN)
        termios.tcsetattr(self._slave, termios.TCSANOW, attrs)
        os.set_blocking(self.master, False)
        self.path = os.ttyname(self._slave)
        self.max_backlog = max_backlog_bytes
        self._out = bytearray()
        self.dropped_bytes = 0
        self.closed = False

    def fileno(self) -> int:
        return self.master

    @property
    def backlog(self) -> int:
        return len(self._out)

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

    def write(self, data: bytes, droppable: bool = False) -> bool:
        """Queue ``data``; a droppable block that does not fit in the backlog is dropped."""
        if self.closed or not data:
            return False
        if droppable and len(self._out) + len(data) > self.max_backlog:
            self.dropped_bytes += len(data)
            return False
        self._out += data
        self.flush()
        return True

    def flush(self) -> None:
        while self._out and not self.closed:
            try:
                n = os.write(self.master, self._out)
            except (BlockingIOError, InterruptedError):
                return
            except OSError as e:
                if e.errno == errno.EIO:
                    return
                raise
            del self._out[:n]

    def clear_output(self) -> None:
        self._out.clear()

    def close(self) -> None:
        """Hang up: the driver's next read or write fails (a disconnect)."""
        if not self.closed:
            self.closed = True
            for fd in (self.master, self._slave):
                try:
                    os.close(fd)
                except OSError:
                    pass
