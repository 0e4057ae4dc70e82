"""Reading a file a user names (a scheme, station.yaml, a simulated truth, a faults file, a noise
file, an import's sections): refused in one line, never read, when it is not a regular file.

A FIFO named as a file blocked ``open()`` until some writer came (the command hung: issue 26,
found again in the thirteenth session for ``--scheme``, ``--config``, ``--sim-truth``,
``--faults`` and ``export --noise`` after ``import`` had been guarded); a device such as
/dev/zero never ends.  The file is opened without blocking (O_NONBLOCK), checked to be a regular
file on the open descriptor (no race with a swap after a check by name), bounded in size and
decoded as UTF-8 (a byte-order mark allowed); each failure is a ``UserError`` naming the file and
what it was to be.  Only the standard library.
"""
from __future__ import annotations

import os
import stat

from station.core.errors import UserError

MAX_BYTES = 1 << 30             # 1 GiB: a YAML file larger than this is not one of station's


def read_user_bytes(path, what: str, *, limit: int = MAX_BYTES) -> bytes:
    """The bytes of the regular file ``path`` (``what`` names it in messages: "scheme file")."""
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0))
    except OSError as e:
        raise UserError(f"{path}: cannot read {what}: {e.strerror}") from None
    try:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode):
            raise UserError(f"{path}: not a regular file (a FIFO, device or folder): cannot read {what}")
        if info.st_size > limit:
            raise UserError(f"{path}: {info.st_size} bytes: too large for a {what} (at most {limit} bytes)")
        with os.fdopen(fd, "rb", closefd=True) as f:
            fd = None
            data = f.read(limit + 1)
    except OSError as e:
        raise UserError(f"{path}: cannot read {what}: {e.strerror}") from None
    finally:
        if fd is not None:
            os.close(fd)
    if len(data) > limit:
        raise UserError(f"{path}: too large for a {what} (at most {limit} bytes)")
    return data


def read_user_text(path, what: str, *, limit: int = MAX_BYTES) -> str:
    """The text of the regular file ``path``, UTF-8 (a byte-order mark allowed); a byte that is
    not UTF-8 is a UserError naming its line."""
    data = read_user_bytes(path, what, limit=limit)
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        line = data[:e.start].count(b"\n") + 1
        raise UserError(f"{path}: line {line}: not UTF-8 text: cannot read {what}") from None
