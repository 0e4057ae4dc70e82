"""Command lines arriving at a twin: split off the complete ones, keep the rest."""
from __future__ import annotations

import re


def take_lines(buffer: bytearray, ends: bytes = b"\n") -> list[bytes]:
    """Remove every complete line (ended by any byte of ``ends``) from ``buffer`` and return
    them without their terminator; an unfinished line stays in ``buffer``."""
    pattern = re.compile(b"[" + re.escape(ends) + b"]")
    lines = []
    while (m := pattern.search(buffer)) is not None:
        lines.append(bytes(buffer[:m.start()]))
        del buffer[:m.end()]
    return lines
