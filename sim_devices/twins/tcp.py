"""A TCP end point on 127.0.0.1 with the interface of :class:`PtyEndpoint`: a twin listening
where a controller would (the Acutrol ACL server, TCP port 9878 on a bench).

One client at a time: the next connection is accepted once the present one has closed.
"""
from __future__ import annotations

import errno
import socket

from sim_devices.twins.endpoint import QueuedEndpoint


class TcpEndpoint(QueuedEndpoint):
    def __init__(self, port: int = 0, host: str = "127.0.0.1", max_backlog_bytes: int = 1 << 20):
        super().__init__(max_backlog_bytes)
        self._listener = socket.create_server((host, port), reuse_port=False)
        self._listener.setblocking(False)
        self.host, self.port = self._listener.getsockname()[:2]
        self.path = f"socket://{self.host}:{self.port}"
        self._client: socket.socket | None = None

    def fileno(self) -> int:
        return (self._client or self._listener).fileno()

    def read(self) -> bytes:
        if self.closed:
            return b""
        if self._client is None:
            try:
                self._client, _ = self._listener.accept()
                self._client.setblocking(False)
                self._out.clear()
            except (BlockingIOError, InterruptedError):
                pass
            return b""
        try:
            data = self._client.recv(65536)
        except (BlockingIOError, InterruptedError):
            return b""
        except OSError:
            data = b""
        if not data:                    # the client went away
            self._drop_client()
        return data

    def _connected(self) -> bool:
        return self._client is not None

    def _send(self, data: bytearray) -> int | None:
        try:
            return self._client.send(data)
        except (BlockingIOError, InterruptedError):
            return None
        except OSError as e:
            if e.errno in (errno.EPIPE, errno.ECONNRESET):
                self._drop_client()
                return None
            raise

    def _drop_client(self) -> None:
        if self._client is not None:
            try:
                self._client.close()
            except OSError:
                pass
        self._client = None
        self._out.clear()

    def close(self) -> None:
        if not self.closed:
            self.closed = True
            self._drop_client()
            self._listener.close()
