"""The plain ASCII line protocol of microcontroller IMUs (protocol ``csv``).

One sample a line: ``t,ax,ay,az,gx,gy,gz[,temp]``, ended by ``\\n`` (``\\r\\n`` accepted).
The units are a setting (:class:`CsvFormat`), since every firmware picks its own.  Blank
lines, ``#`` comments and a header line (first field ``t``) are skipped without counting.
A line that is not 7 or 8 finite numbers is a bad frame (the protocol has no checksum: a line
that does not parse is its only detectable corruption).  No device commands: the stream runs
from power-up.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..samples import ImuSamples

COLUMNS = ("t", "ax", "ay", "az", "gx", "gy", "gz", "temp")
TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9}
ACCEL_UNITS = {"m/s^2": 1.0, "g": 9.80665, "mg": 9.80665e-3}
GYRO_UNITS = {"deg/s": 1.0, "rad/s": 180.0 / math.pi, "mdeg/s": 1e-3}
MAX_LINE_BYTES = 512


@dataclass(frozen=True)
class CsvFormat:
    """Units of the columns: t in ``time_unit``, ax..az in ``accel_unit``, gx..gz in
    ``gyro_unit``, temp in °C."""

    time_unit: str = "s"
    accel_unit: str = "m/s^2"
    gyro_unit: str = "deg/s"

    def __post_init__(self):
        for value, table, what in ((self.time_unit, TIME_UNITS, "time"),
                                   (self.accel_unit, ACCEL_UNITS, "accel"),
                                   (self.gyro_unit, GYRO_UNITS, "gyro")):
            if value not in table:
                raise ValueError(f"{what} unit must be one of {', '.join(table)}, got {value!r}")

    @classmethod
    def parse(cls, spec: str) -> "CsvFormat":
        """``"t=ms,accel=g,gyro=rad/s"`` (any subset) -> CsvFormat; ValueError if invalid."""
        kw = {}
        names = {"t": "time_unit", "time": "time_unit", "accel": "accel_unit", "gyro": "gyro_unit"}
        for part in filter(None, (p.strip() for p in spec.split(","))):
            key, sep, value = part.partition("=")
            if not sep or key.strip() not in names:
                raise ValueError(f"expected t=UNIT, accel=UNIT or gyro=UNIT, got {part!r}")
            kw[names[key.strip()]] = value.strip()
        return cls(**kw)


def encode_lines(fmt: CsvFormat, t_s, accel_mps2, gyro_dps, temp_c=None) -> bytes:
    """Lines for N samples (values in SI/deg/s, written in ``fmt``'s units)."""
    t = np.asarray(t_s, dtype=float).reshape(-1) / TIME_UNITS[fmt.time_unit]
    a = np.asarray(accel_mps2, dtype=float).reshape(-1, 3) / ACCEL_UNITS[fmt.accel_unit]
    g = np.asarray(gyro_dps, dtype=float).reshape(-1, 3) / GYRO_UNITS[fmt.gyro_unit]
    tfmt = "%.6f" if fmt.time_unit == "s" else "%.0f"
    if temp_c is None:
        cols, pattern = np.column_stack([t, a, g]), tfmt + ",%.9g,%.9g,%.9g,%.9g,%.9g,%.9g\n"
    else:
        cols = np.column_stack([t, a, g, np.asarray(temp_c, dtype=float).reshape(-1)])
        pattern = tfmt + ",%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.3f\n"
    return "".join(pattern % tuple(row) for row in cols.tolist()).encode("ascii")


class CsvDecoder:
    """Incremental decoder of csv lines.  :meth:`feed` never raises.

    Starts unsynchronised: the bytes before the first line end are dropped (a resync), as is
    a "line" longer than 512 bytes.
    """

    def __init__(self, fmt: CsvFormat = CsvFormat()):
        self.fmt = fmt
        self._scale = (TIME_UNITS[fmt.time_unit], ACCEL_UNITS[fmt.accel_unit],
                       GYRO_UNITS[fmt.gyro_unit])
        self._buf = b""
        self._synced = False
        self.frames = 0
        self.checksum_errors = 0
        self.resyncs = 0
        self.bytes_discarded = 0

    def feed(self, data: bytes) -> ImuSamples:
        buf = self._buf + bytes(data)
        if not self._synced:
            i = buf.find(b"\n")
            if i < 0:
                if len(buf) > MAX_LINE_BYTES:
                    self._discard(len(buf))
                    buf = b""
                self._buf = buf
                return ImuSamples.empty()
            if i > 0:
                self._discard(i)
            buf = buf[i + 1:]
            self._synced = True
        end = buf.rfind(b"\n")
        if end < 0:
            if len(buf) > MAX_LINE_BYTES:          # no line end: not a line protocol stream
                self._discard(len(buf))
                self._synced = False
                buf = b""
            self._buf = buf
            return ImuSamples.empty()
        block, self._buf = buf[:end], buf[end + 1:]
        return self._decode_lines(block.split(b"\n"))

    def _discard(self, n: int) -> None:
        self.resyncs += 1
        self.bytes_discarded += n

    def _decode_lines(self, lines: list[bytes]) -> ImuSamples:
        by_count: dict[int, list[bytes]] = {7: [], 8: []}
        for line in lines:
            c = line.count(b",") + 1
            if c in by_count and len(line) <= MAX_LINE_BYTES:
                by_count[c].append(line)
                continue
            if _skippable(line):
                continue
            self.checksum_errors += 1
            self.bytes_discarded += len(line) + 1
        rows = []
        for count, group in by_count.items():
            if group:
                rows.append(self._parse(group, count))
        rows = [r for r in rows if r.shape[0]]
        if not rows:
            return ImuSamples.empty()
        arr = rows[0] if len(rows) == 1 else np.concatenate(rows)
        if len(rows) > 1:
            arr = arr[np.argsort(arr[:, 0], kind="stable")]
        self.frames += arr.shape[0]
        st, sa, sg = self._scale
        return ImuSamples(t_s=arr[:, 0] * st, accel_mps2=arr[:, 1:4] * sa,
                          gyro_dps=arr[:, 4:7] * sg, temp_c=arr[:, 7].copy())

    def _parse(self, group: list[bytes], count: int) -> np.ndarray:
        """(n, 8) rows, temp NaN for 7-field lines; bad lines counted and dropped."""
        try:
            arr = np.array(b",".join(group).split(b","), dtype=np.float64).reshape(-1, count)
        except ValueError:
            parsed = []
            for line in group:
                try:
                    parsed.append([float(x) for x in line.split(b",")])
                except ValueError:
                    if not _skippable(line):
                        self.checksum_errors += 1
                        self.bytes_discarded += len(line) + 1
            arr = np.array(parsed, dtype=np.float64).reshape(-1, count)
        finite = np.isfinite(arr).all(axis=1)
        if not finite.all():
            bad = int((~finite).sum())
            self.checksum_errors += bad
            arr = arr[finite]
        if count == 7:
            arr = np.column_stack([arr, np.full(arr.shape[0], np.nan)])
        return arr


def _skippable(line: bytes) -> bool:
    """A blank line, a ``#`` comment or a header line (first field ``t``)."""
    s = line.strip()
    return not s or s.startswith(b"#") or s.split(b",", 1)[0].strip() == b"t"
