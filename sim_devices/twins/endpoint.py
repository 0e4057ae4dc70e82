"""What every twin end point does with its output: a transmit queue like a UART's.

When the reader does not keep up, droppable data (stream frames) is dropped whole and counted;
replies never are.  A subclass says whether a peer is there to write to and sends bytes.
"""
from __future__ import annotations


class QueuedEndpoint:
    def __init__(self, max_backlog_bytes: int):
        self.max_backlog = max_backlog_bytes
        self._out = bytearray()
        self.dropped_bytes = 0
        self.sent_bytes = 0           # taken by the transport since the end point was made
        self.closed = False

    @property
    def backlog(self) -> int:
        return len(self._out)

    def _connected(self) -> bool:
        """Whether a peer is there to take output (subclasses with one client override it)."""
        return not self.closed

    def _send(self, data: bytearray) -> int | None:
        """Send what the transport takes now: bytes taken, or None when nothing more can go."""
        raise NotImplementedError

    def write(self, data: bytes, droppable: bool = False) -> bool:
        """Queue ``data``; a droppable block that does not fit in the backlog is dropped."""
        if self.closed or not data or not self._connected():
            return False
        if droppable and len(self._out) + len(data) > self.max_backlog:
            self.dropped_bytes += len(data)
            return False
        self._out += data
        self.flush()
        return True

    def flush(self) -> None:
        while self._out and self._connected():
            n = self._send(self._out)
            if n is None:
                return
            del self._out[:n]
            self.sent_bytes += n

    def clear_output(self) -> None:
        self._out.clear()

    def discard_front(self, n: int) -> None:
        """Drop the first ``n`` queued bytes (the oldest), counted as dropped."""
        n = min(n, len(self._out))
        del self._out[:n]
        self.dropped_bytes += n
