"""Reading another tool's text file: bounded in size, UTF-8 (a byte-order mark allowed), one line on failure."""
from __future__ import annotations

from pathlib import Path

from station.core.errors import UserError

MAX_BYTES = 2_000_000_000       # a text recording larger than this is refused before it is read


def read_text(path: Path) -> str:
    """The file's text; a missing, unreadable, oversized, non-regular (FIFO, device) or non-UTF-8
    file is a UserError naming it
    (and the line of the first bad byte)."""
    from station.io.capture import read_regular_file

    try:                    # (a FIFO or device in its place is refused, not read: it hung)
        raw = read_regular_file(path, limit=MAX_BYTES)
    except OSError as e:
        raise UserError(f"{path}: cannot read: {e.strerror}") from None
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        line = raw[:e.start].count(b"\n") + 1
        raise UserError(f"{path}: line {line}: not UTF-8 text") from None
