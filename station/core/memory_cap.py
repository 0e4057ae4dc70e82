"""A ceiling on the memory a reader of untrusted bytes may take: a decompression bomb (a bz2 or
lz4 chunk of a ROS bag that inflates to gigabytes; rosbags decompresses a chunk whole, before any
size check) becomes one clear refusal instead of an exhausted machine.

The ceiling is the process's address space (``RLIMIT_AS``, soft limit) lowered to what is mapped
now plus a budget, for the duration of the block, and given back after it; an allocation beyond it
fails with ``MemoryError``, which the block turns into a :class:`UserError` naming the file.  On a
system without ``RLIMIT_AS`` (macOS does not enforce it, Windows has no ``resource``) the block only
turns a ``MemoryError`` into that message.  The soft limit is the process's own: the block is meant
for the main thread of a command reading one file, not for a server with other threads allocating.
"""
from __future__ import annotations

import contextlib

from station.core.errors import UserError

BASE_BUDGET_BYTES = 1 << 30      # 1 GiB beyond what is mapped: any real chunk (ROS 1 default 768 KiB,
                                 #   MCAP a few MiB) and the arrays of the messages kept
PER_FILE_BYTE = 4                # plus 4 bytes per byte of the file: arrays of 56 bytes per message kept
                                 #   (grown by doubling) against >= 100 bytes per stored Imu message


def _mapped_bytes() -> int | None:
    """The process's virtual memory size now (Linux /proc), or None."""
    try:
        with open("/proc/self/status", encoding="ascii", errors="replace") as f:
            for line in f:
                if line.startswith("VmSize:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


def budget_for(file_bytes: int) -> int:
    """The memory budget for reading a file of ``file_bytes`` bytes."""
    return BASE_BUDGET_BYTES + PER_FILE_BYTE * max(0, int(file_bytes))


@contextlib.contextmanager
def memory_cap(budget_bytes: int, what: str):
    """Inside the block the process may map at most ``budget_bytes`` more than now; beyond it (or on
    any MemoryError) a UserError: "``what``: reading it needs more than N MiB ..."."""
    try:
        import resource
    except ImportError:          # Windows
        resource = None
    old = None
    mapped = _mapped_bytes()
    if resource is not None and hasattr(resource, "RLIMIT_AS") and mapped is not None:
        soft, hard = resource.getrlimit(resource.RLIMIT_AS)
        ceiling = mapped + int(budget_bytes)
        if hard != resource.RLIM_INFINITY:
            ceiling = min(ceiling, hard)
        if soft == resource.RLIM_INFINITY or ceiling < soft:
            try:
                resource.setrlimit(resource.RLIMIT_AS, (ceiling, hard))
                old = (soft, hard)
            except (ValueError, OSError):
                old = None
    try:
        yield
    except MemoryError:
        raise UserError(f"{what}: reading it needs more than {budget_bytes / 2**20:.0f} MiB beyond what the "
                        "command holds: a damaged or hostile file (a compressed chunk that inflates far beyond "
                        "its size, a decompression bomb?); refused") from None
    finally:
        if old is not None:
            resource.setrlimit(resource.RLIMIT_AS, old)
