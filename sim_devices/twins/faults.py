"""Fault injection: the ``--faults`` YAML file and the faults applied to the IMU stream.

File (``station.core.yaml_text``; every key optional; times are device seconds since the twins
started; unknown keys and bad values raise UserError naming the file and the field)::

    version: 1
    imu:
      garbage: {every_s: 1.0, bytes: 32}      # random bytes between two frames, every every_s
      corrupt: {probability: 0.01}            # per frame: one byte of it overwritten
      drop: {probability: 0.01}               # per frame: not sent
      stall: {at_s: 20.0, duration_s: 5.0}    # no frames (duration_s omitted: for ever)
      disconnect: {at_s: 30.0}                # the pseudo-terminal hangs up
      mute: {at_s: 0.0, duration_s: 60.0}     # commands unanswered, no frames (a sensor without
                                              #   power behind a live adapter; duration_s omitted:
                                              #   for ever); at_s 0: no reply to its start-up
    table:
      interlock_trip: {axis: 1, at_s: 10.0}   # interlock opens, fault latched, axis brakes
      stuck_axis: {axis: 2, shortfall_deg: 0.5}   # every position move ends short
      stall: {at_s: 20.0, duration_s: 5.0}    # commands get no reply
      disconnect: {at_s: 30.0}
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from station.core.errors import UserError
from station.core import yaml_text

from .table import TableFaults


@dataclass
class ImuFaults:
    garbage_every_s: float | None = None
    garbage_bytes: int = 32
    corrupt_probability: float = 0.0
    drop_probability: float = 0.0
    stall_at_s: float | None = None
    stall_duration_s: float | None = None
    disconnect_at_s: float | None = None
    mute_at_s: float | None = None
    mute_duration_s: float | None = None

    def muted(self, t: float) -> bool:
        """Whether the sensor is mute at device time ``t`` (its commands unanswered, no frames)."""
        if self.mute_at_s is None or t < self.mute_at_s:
            return False
        return self.mute_duration_s is None or t < self.mute_at_s + self.mute_duration_s

    @property
    def active(self) -> bool:
        return (self.garbage_every_s is not None or self.corrupt_probability > 0
                or self.drop_probability > 0 or self.stall_at_s is not None)

    def stalled(self, t):
        """Mask of the device times inside the stall window."""
        t = np.asarray(t, dtype=float)
        if self.stall_at_s is None:
            return np.zeros(t.shape, dtype=bool)
        end = math.inf if self.stall_duration_s is None else self.stall_at_s + self.stall_duration_s
        return (t >= self.stall_at_s) & (t < end)


@dataclass
class Faults:
    imu: ImuFaults = field(default_factory=ImuFaults)
    table: TableFaults = field(default_factory=TableFaults)


# ------------------------------------------------------------------------------ the file

class _Fields:
    def __init__(self, source: str):
        self.source = source

    def fail(self, name: str, msg: str):
        raise UserError(f"{self.source}: field '{name}': {msg}")

    def mapping(self, value, name: str, allowed: set[str]) -> dict:
        if value is None:
            return {}
        if not isinstance(value, dict):
            self.fail(name, f"expected a mapping, got {type(value).__name__}")
        for k in value:
            if not isinstance(k, str) or k not in allowed:
                self.fail(f"{name}.{k}" if name else str(k),
                          f"unknown field (allowed: {', '.join(sorted(allowed))})")
        return value

    def number(self, d: dict, key: str, name: str, *, lo=None, hi=None, integer=False,
               required=True, default=None):
        if key not in d or d[key] is None:
            if required:
                self.fail(f"{name}.{key}", "required, missing")
            return default
        v = d[key]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or (integer and not isinstance(v, int)):
            self.fail(f"{name}.{key}", f"expected {'an integer' if integer else 'a number'}, got {v!r}")
        if not math.isfinite(v):
            self.fail(f"{name}.{key}", f"must be finite, got {v!r}")
        if lo is not None and v < lo:
            self.fail(f"{name}.{key}", f"must be >= {lo}, got {v!r}")
        if hi is not None and v > hi:
            self.fail(f"{name}.{key}", f"must be <= {hi}, got {v!r}")
        return v


def faults_from_dict(data, source: str = "<faults>", n_axes: int = 3) -> Faults:
    c = _Fields(source)
    if data is None:
        data = {}
    if not isinstance(data, dict):
        c.fail("(top level)", f"expected a mapping, got {type(data).__name__}")
    top = c.mapping(data, "", {"version", "imu", "table"})
    if top.get("version", 1) != 1:
        c.fail("version", f"unsupported version {top['version']!r} (expected 1)")
    out = Faults()
    imu = c.mapping(top.get("imu"), "imu", {"garbage", "corrupt", "drop", "stall", "disconnect", "mute"})
    f = out.imu
    if "garbage" in imu:
        d = c.mapping(imu["garbage"], "imu.garbage", {"every_s", "bytes"})
        f.garbage_every_s = c.number(d, "every_s", "imu.garbage", lo=1e-3)
        f.garbage_bytes = c.number(d, "bytes", "imu.garbage", lo=1, hi=4096, integer=True,
                                   required=False, default=32)
    if "corrupt" in imu:
        d = c.mapping(imu["corrupt"], "imu.corrupt", {"probability"})
        f.corrupt_probability = float(c.number(d, "probability", "imu.corrupt", lo=0.0, hi=1.0))
    if "drop" in imu:
        d = c.mapping(imu["drop"], "imu.drop", {"probability"})
        f.drop_probability = float(c.number(d, "probability", "imu.drop", lo=0.0, hi=1.0))
    if "stall" in imu:
        d = c.mapping(imu["stall"], "imu.stall", {"at_s", "duration_s"})
        f.stall_at_s = c.number(d, "at_s", "imu.stall", lo=0.0)
        f.stall_duration_s = c.number(d, "duration_s", "imu.stall", lo=0.0, required=False)
    if "disconnect" in imu:
        d = c.mapping(imu["disconnect"], "imu.disconnect", {"at_s"})
        f.disconnect_at_s = c.number(d, "at_s", "imu.disconnect", lo=0.0)
    if "mute" in imu:
        d = c.mapping(imu["mute"], "imu.mute", {"at_s", "duration_s"})
        f.mute_at_s = c.number(d, "at_s", "imu.mute", lo=0.0, required=False, default=0.0)
        f.mute_duration_s = c.number(d, "duration_s", "imu.mute", lo=0.0, required=False)

    table = c.mapping(top.get("table"), "table", {"interlock_trip", "stuck_axis", "stall", "disconnect"})
    t = out.table
    if "interlock_trip" in table:
        d = c.mapping(table["interlock_trip"], "table.interlock_trip", {"axis", "at_s"})
        t.trip_axis = c.number(d, "axis", "table.interlock_trip", lo=1, hi=n_axes, integer=True)
        t.trip_at_s = c.number(d, "at_s", "table.interlock_trip", lo=0.0)
    if "stuck_axis" in table:
        d = c.mapping(table["stuck_axis"], "table.stuck_axis", {"axis", "shortfall_deg"})
        t.stuck_axis = c.number(d, "axis", "table.stuck_axis", lo=1, hi=n_axes, integer=True)
        t.shortfall_deg = float(c.number(d, "shortfall_deg", "table.stuck_axis", lo=0.0, hi=180.0))
    if "stall" in table:
        d = c.mapping(table["stall"], "table.stall", {"at_s", "duration_s"})
        t.stall_at_s = c.number(d, "at_s", "table.stall", lo=0.0)
        t.stall_duration_s = c.number(d, "duration_s", "table.stall", lo=0.0, required=False)
    if "disconnect" in table:
        d = c.mapping(table["disconnect"], "table.disconnect", {"at_s"})
        t.disconnect_at_s = c.number(d, "at_s", "table.disconnect", lo=0.0)
    return out


def load_faults(path, n_axes: int = 3) -> Faults:
    path = Path(path)
    from station.core.user_files import read_user_text

    text = read_user_text(path, "faults file")                # (a FIFO is refused, not read: it hung)
    data = yaml_text.load_text(text, path)
    return faults_from_dict(data, str(path), n_axes)


def load_faults_per_imu(paths, n_imus: int, n_axes: int = 3) -> tuple[Faults, tuple]:
    """``sim serve --imus N --faults F ...``: one file (the table's faults and the first IMU's,
    as with one IMU), or N files, file k for IMU k (its ``imu:``; the table's from the first
    file: a ``table:`` in another is refused, naming it).  Returns (faults, per-IMU faults)."""
    paths = list(paths or ())
    if not paths:
        return Faults(), ()
    if len(paths) not in (1, n_imus):
        raise UserError(f"--faults: give it once (the table and the first IMU) or once per IMU ({n_imus}), "
                        f"got {len(paths)}")
    loaded = [load_faults(p, n_axes) for p in paths]
    for k, (path, f) in enumerate(zip(paths, loaded)):
        if k and f.table != type(f.table)():
            raise UserError(f"{path}: field 'table': the table's faults belong in the first --faults file "
                            f"({paths[0]}); this one is IMU {k + 1}'s")
    return loaded[0], tuple(f.imu for f in loaded) if len(loaded) > 1 else ()


# ------------------------------------------------------------------------------ the stream

class StreamFaulter:
    """Applies the IMU stream faults to a block of frames and keeps the tally.

    ``line_protocol``: garbage is ended by a line end and a corrupted byte becomes ``x``, so
    that csv lines other than the hit one stay intact (see docs/twins.md).
    ``record``: keep the device times of the frames sent intact (for tests).
    """

    def __init__(self, faults: ImuFaults, rng, *, line_protocol: bool = False, record: bool = False):
        self.faults = faults
        self.rng = rng
        self.line_protocol = line_protocol
        self.record = record
        self.intact_times: list[np.ndarray] = []
        self.frames_sent = 0
        self.frames_dropped = 0
        self.frames_corrupted = 0
        self.frames_stalled = 0
        self.garbage_blocks = 0
        self.frames_overflowed = 0
        self._last_t: float | None = None

    def apply(self, t: np.ndarray, frames: list[bytes]) -> tuple[bytes, np.ndarray]:
        """The bytes to send for frames at device times ``t``, and the mask of those sent
        intact."""
        f = self.faults
        n = len(frames)
        keep = ~f.stalled(t)
        self.frames_stalled += int((~keep).sum())
        drop = self.rng.random(n) < f.drop_probability if f.drop_probability else np.zeros(n, bool)
        drop &= keep
        corrupt = (self.rng.random(n) < f.corrupt_probability) & keep & ~drop \
            if f.corrupt_probability else np.zeros(n, bool)
        garbage = np.zeros(n, bool)
        if f.garbage_every_s is not None:
            tick = np.floor(t / f.garbage_every_s)
            prev = np.concatenate([[np.floor(self._last_t / f.garbage_every_s)
                                    if self._last_t is not None else tick[0]], tick[:-1]])
            garbage = (tick > prev) & keep
        if n:
            self._last_t = float(t[-1])
        out = []
        for i in range(n):
            if garbage[i]:
                out.append(self._garbage())
            if not keep[i] or drop[i]:
                continue
            frame = frames[i]
            if corrupt[i]:
                frame = self._corrupt(frame)
            out.append(frame)
        self.frames_dropped += int(drop.sum())
        self.frames_corrupted += int(corrupt.sum())
        intact = keep & ~drop & ~corrupt
        self.frames_sent += int((keep & ~drop).sum())
        if self.record:
            self.intact_times.append(t[intact])
        return b"".join(out), intact

    def overflowed(self, n_frames: int, recorded: bool = True) -> None:
        """The last block (``recorded``: it went through :meth:`apply`) did not fit in the
        port's transmit buffer: nothing of it was sent."""
        self.frames_overflowed += n_frames
        if recorded:
            self.frames_sent -= n_frames
            if self.record and self.intact_times:
                self.intact_times.pop()

    def _garbage(self) -> bytes:
        self.garbage_blocks += 1
        junk = self.rng.integers(0, 256, self.faults.garbage_bytes, dtype=np.uint8).tobytes()
        return junk.replace(b"\n", b"?") + b"\n" if self.line_protocol else junk

    def _corrupt(self, frame: bytes) -> bytes:
        b = bytearray(frame)
        last = len(b) - 1 if self.line_protocol else len(b)     # keep the line end
        i = int(self.rng.integers(0, max(last, 1)))
        if self.line_protocol:
            b[i] = ord("x")
        else:
            b[i] ^= int(self.rng.integers(1, 256))
        return bytes(b)
