"""Delimited text logs (CSV, ';'-separated, tab- or space-separated) of a continuous IMU
recording -> a Recording (station/io/importers/recording.py), which becomes a capture bundle.

The layout is told, not guessed from names (docs/real-recordings.md):
  columns     role -> column, by header name or by index from 0: ax ay az gx gy gz, and for time
              either ``t`` (a time column, in ``time_unit``: s, ms, us, ns) or ``index`` (a sample
              counter, times the period 1 / ``rate_hz``); with neither, the row number / rate_hz;
  delimiter   ',', ';', tab, 'space' (any run of blanks) or None: from the first data line;
  header      'auto' (a first line with a field that is not a number), 'yes', 'no';
  units       per triad: m/s^2 | g | raw and deg/s | rad/s | raw; raw with an optional nominal
              scale (m/s^2 and deg/s per count).
Lines starting with '#' or '%' and blank lines are skipped.  Presets fill these in for common
layouts: ``station`` (t,ax,ay,az,gx,gy,gz; s, m/s^2, deg/s), ``imu_tk`` (two files of
``t x y z``, accelerometer and gyro, blank-separated, as imu_tk's importAsciiData reads them),
``imucal`` (imucal's session header, time from n_samples / rate).

All input is untrusted: a bad field raises UserError naming the file, the line and the column.
"""
from __future__ import annotations

import io
import math
import re
from pathlib import Path

import numpy as np

from station.core.errors import UserError
from station.core.units import ACCEL_UNITS, GYRO_UNITS
from station.io.importers.recording import Recording
from station.io.importers.text import read_text

ROLES = ("t", "index", "ax", "ay", "az", "gx", "gy", "gz")
TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "µs": 1e-6, "ns": 1e-9}
DELIMITERS = {",": ",", ";": ";", "tab": "\t", "\t": "\t", "space": None, " ": None}
PRESETS = {
    "station": {"columns": {"t": "t", "ax": "ax", "ay": "ay", "az": "az", "gx": "gx", "gy": "gy", "gz": "gz"},
                "units": ("m/s^2", "deg/s"), "time_unit": "s"},
    "t-a-g": {"columns": {"t": 0, "ax": 1, "ay": 2, "az": 3, "gx": 4, "gy": 5, "gz": 6},
              "units": ("m/s^2", "deg/s"), "time_unit": "s"},
    "imu_tk": {"columns": {"t": 0, "ax": 1, "ay": 2, "az": 3}, "gyro_columns": {"t": 0, "gx": 1, "gy": 2, "gz": 3},
               "units": ("raw", "raw"), "time_unit": "s", "delimiter": "space", "header": "no"},
    "imucal": {"columns": {"index": "n_samples", "ax": "acc_x", "ay": "acc_y", "az": "acc_z",
                           "gx": "gyr_x", "gy": "gyr_y", "gz": "gyr_z"}, "units": ("m/s^2", "deg/s"),
               "delimiter": ","},
}


def parse_columns(text: str) -> dict:
    """'t=time,ax=acc_x,...' or 'ax=1,...' -> {role: name or index}."""
    out = {}
    for part in text.split(","):
        if not part.strip():
            continue
        role, eq, col = part.partition("=")
        role, col = role.strip(), col.strip()
        if not eq or role not in ROLES or not col:
            raise UserError(f"--columns: {part.strip()!r}: use ROLE=COLUMN with ROLE one of {', '.join(ROLES)}")
        if role in out:
            raise UserError(f"--columns: role {role!r} given twice")
        out[role] = int(col) if col.isdigit() else col
    return out


# characters str.splitlines() ends a line at besides "\n": a text with any of them is split the
# slow way, so that line numbers are always splitlines()' (what a user's editor shows)
_OTHER_LINE_ENDS = re.compile("[\r\x0b\x0c\x1c\x1d\x1e\x85\u2028\u2029]")
# a line that holds no data: blank (whitespace only), or a comment ('#' or '%' after blanks)
_SKIPPED_LINE = re.compile(r"^[^\S\n]*(?:[#%][^\n]*)?$", re.M)
_INNER_BLANK_LINE = re.compile(r"\n[^\S\n]*\n")


def _other_line_ends(text: str) -> bool:
    """Whether `text` has a character str.splitlines() ends a line at besides "\n" (ASCII
    text: six substring searches, a fifth of the regular expression's time)."""
    if text.isascii():
        return any(c in text for c in "\r\x0b\x0c\x1c\x1d\x1e")
    return _OTHER_LINE_ENDS.search(text) is not None


def _nothing_skipped(text: str, lines: list) -> bool:
    """True when no line of `text` (split into `lines` at "\n", the final empty one dropped) is
    blank or a comment: no '#' or '%' anywhere, and no line of blanks only.  Then every line is
    a data line and _SKIPPED_LINE, which tries every line start (~16 ms for 51,000 lines), is
    not needed (issue 27, item 2)."""
    return (bool(lines) and "#" not in text and "%" not in text and bool(lines[0].strip())
            and bool(lines[-1].strip()) and _INNER_BLANK_LINE.search(text) is None)


class _Table:
    """The data lines of one file, split into fields, with their line numbers.

    Parsed by numpy's C reader (``np.loadtxt``: 10 ms for 50,000 lines, where splitting every
    line in Python took ~0.15 s of CPU per file: issue 27, item 2) when the file is all numbers
    with the same number of fields on every data line; any other file, and every error, takes
    the line-by-line path, which names the file, line and column at fault (the same messages)."""

    def __init__(self, path: Path, delimiter, header: str):
        self.path = path
        text = read_text(path)
        self.values = None            # (lines, width) float64, read by the C reader, or None
        self.fields = None            # the fields of each data line (the line-by-line path)
        lines = None if _other_line_ends(text) else text.split("\n")
        if lines is not None:
            if lines and lines[-1] == "":
                lines.pop()           # (splitlines: a final "\n" ends the last line, starts none)
            if _nothing_skipped(text, lines):
                index = np.arange(len(lines))
            else:
                starts = np.zeros(len(lines) + 1, dtype=np.int64)
                np.cumsum(np.fromiter(map(len, lines), np.int64, len(lines)) + 1, out=starts[1:])
                # the line each blank or comment line starts in (one past the last: the final "\n")
                skipped = np.searchsorted(starts, [m.start() for m in _SKIPPED_LINE.finditer(text)],
                                          side="right") - 1
                keep = np.ones(len(lines), bool)
                keep[skipped[skipped < len(lines)]] = False
                index = np.flatnonzero(keep)
            rows = None
        else:
            rows = [(i, line) for i, line in enumerate(text.splitlines(), start=1)
                    if line.strip() and not line.lstrip().startswith(("#", "%"))]
            index = None
        count = len(index) if rows is None else len(rows)
        if not count:
            raise UserError(f"{path}: no data lines")

        def line(k):                  # the k-th data line's text
            return lines[index[k]] if rows is None else rows[k][1]

        if delimiter is None:
            first = line(count - 1) if count > 1 else line(0)
            delimiter = ";" if ";" in first else "," if "," in first else "\t" if "\t" in first else None
        elif delimiter not in DELIMITERS:
            raise UserError(f"--delimiter: use one of ',', ';', tab, space (not {delimiter!r})")
        else:
            delimiter = DELIMITERS[delimiter]
        self.delimiter = delimiter
        fields0 = self._split(line(0))
        if header == "auto":
            header = "yes" if any(not _is_number(f) for f in fields0) else "no"
        if header not in ("yes", "no"):
            raise UserError(f"--header: yes, no or auto, not {header!r}")
        self.names = [f.strip() for f in fields0] if header == "yes" else None
        first = 1 if header == "yes" else 0
        if count <= first:
            raise UserError(f"{path}: a header and no data lines")
        if rows is None:
            self.numbers = index[first:] + 1
            self._lines = lines
            width = len(self.names) if self.names else len(fields0)
            self.values = self._parse_whole(text, lines, index[first:], width)
        if self.values is None:       # the line-by-line path
            if rows is None:
                rows = [(int(i) + 1, lines[i]) for i in index]
            rows = rows[first:]
            self.numbers = np.array([i for i, _ in rows])
            self.fields = [self._split(text) for _, text in rows]
            width = len(self.names) if self.names else len(self.fields[0])
            counts = np.fromiter((len(f) for f in self.fields), int, len(self.fields))
            bad = np.flatnonzero(counts != width)
            if len(bad):
                k = int(bad[0])
                raise UserError(f"{path}: line {self.numbers[k]}: {counts[k]} fields, "
                                f"{'the header has' if self.names else 'the first line has'} {width} "
                                f"(delimiter {_show_delimiter(self.delimiter)})")
        self.width = width
        self.count = len(self.numbers)

    def _parse_whole(self, text: str, lines: list, index: np.ndarray, width: int):
        """Every data line's fields as float64 by numpy's C reader, or None where it refuses
        (a field that is not a number to it, another count of fields, an empty field), or where
        it could read a line differently from the line-by-line path (quotes)."""
        if width < 1 or '"' in text:
            return None
        block = text if len(index) == len(lines) else "\n".join([lines[i] for i in index])
        try:
            values = np.loadtxt(io.StringIO(block), dtype=np.float64, delimiter=self.delimiter, comments=None,
                                ndmin=2, quotechar=None)
        except (ValueError, TypeError):
            return None
        if values.shape != (len(index), width):
            return None
        return values

    def _split(self, line: str) -> list[str]:
        return line.split(self.delimiter) if self.delimiter else line.split()

    def _text(self, k: int, j: int) -> str:
        """Field j of the k-th data line, as written."""
        if self.fields is not None:
            return self.fields[k][j]
        return self._split(self._lines[self.numbers[k] - 1])[j]

    def index_of(self, role: str, col) -> int:
        if isinstance(col, int):
            if not 0 <= col < self.width:
                raise UserError(f"{self.path}: column {col} for {role}: the lines have {self.width} fields "
                                f"(indices 0-{self.width - 1})")
            return col
        if self.names is None:
            raise UserError(f"{self.path}: column {col!r} for {role}: the file has no header; give indices")
        if col not in self.names:
            raise UserError(f"{self.path}: line {self.numbers[0] - 1}: no column {col!r} for {role} "
                            f"(header: {', '.join(self.names)[:200]})")
        return self.names.index(col)

    def column(self, role: str, col) -> np.ndarray:
        j = self.index_of(role, col)
        if self.values is not None:
            values = self.values[:, j].copy()
        else:
            texts = [f[j] for f in self.fields]
            try:
                values = np.array(texts, dtype=float)
            except ValueError:
                for k, text in enumerate(texts):
                    if not _is_number(text):
                        raise UserError(f"{self.path}: line {self.numbers[k]}: column {_name(self, j)}: not a "
                                        f"number: {text.strip()[:40]!r}") from None
                raise
        bad = np.flatnonzero(~np.isfinite(values))
        if len(bad):
            k = int(bad[0])
            raise UserError(f"{self.path}: line {self.numbers[k]}: column {_name(self, j)}: not finite "
                            f"({self._text(k, j).strip()[:20]!r}); {len(bad)} such value(s) in this column")
        return values


def _distinct_columns(table: _Table, cols: dict) -> None:
    """Every role its own column: one column read as two axes (or as time and an axis) is a mistake."""
    seen: dict[int, str] = {}
    for role, col in cols.items():
        j = table.index_of(role, col)
        if j in seen:
            raise UserError(f"--columns: {role} and {seen[j]} are both column {_name(table, j)} of {table.path}: "
                            "every role needs its own column")
        seen[j] = role


def _name(table, j) -> str:
    return repr(table.names[j]) if table.names else str(j)


def _show_delimiter(d) -> str:
    return {None: "blanks", "\t": "tab"}.get(d, repr(d))


def _is_number(text: str) -> bool:
    try:
        float(text)
        return True
    except ValueError:
        return False


def _times(table: _Table, cols: dict, time_unit: str, rate_hz: float | None) -> tuple[np.ndarray, str]:
    if "t" in cols and "index" in cols:
        raise UserError("--columns: give either a time column 't' or a sample counter 'index', not both")
    if "t" in cols:
        if time_unit not in TIME_UNITS:
            raise UserError(f"--time-unit: one of {', '.join(TIME_UNITS)}, not {time_unit!r}")
        t = table.column("t", cols["t"]) * TIME_UNITS[time_unit]
        return t - t[0], f"column {_name(table, table.index_of('t', cols['t']))} in {time_unit}"
    if rate_hz is None:
        raise UserError(f"{table.path}: no time column: give --rate-hz (with a sample counter 'index' or the "
                        "row number), or a time column 't'")
    if "index" in cols:
        n = table.column("index", cols["index"])
        return (n - n[0]) / rate_hz, f"column {_name(table, table.index_of('index', cols['index']))} / {rate_hz:g} Hz"
    return np.arange(table.count) / rate_hz, f"row number / {rate_hz:g} Hz"


def read_delimited(path, *, preset: str | None = None, columns: dict | None = None, delimiter=None,
                   header: str | None = None, accel_unit: str | None = None, gyro_unit: str | None = None,
                   accel_nominal: float | None = None, gyro_nominal: float | None = None,
                   time_unit: str | None = None, rate_hz: float | None = None, gyro_path=None) -> Recording:
    path = Path(path)
    if preset is not None and preset not in PRESETS:
        raise UserError(f"--preset: one of {', '.join(PRESETS)}, not {preset!r}")
    p = PRESETS.get(preset, {})
    cols = dict(p.get("columns", {}))
    if columns:
        cols.update(columns)
    if not cols:
        cols = dict(PRESETS["t-a-g"]["columns"])
    header = header or p.get("header", "auto")
    delimiter = delimiter if delimiter is not None else p.get("delimiter")
    time_unit = time_unit or p.get("time_unit", "s")
    units = p.get("units", ("m/s^2", "deg/s"))
    accel_unit, gyro_unit = accel_unit or units[0], gyro_unit or units[1]
    if accel_unit not in ACCEL_UNITS or gyro_unit not in GYRO_UNITS:
        raise UserError(f"units: accelerometer one of {', '.join(ACCEL_UNITS)}, gyro one of {', '.join(GYRO_UNITS)}")
    for name, unit, nominal in (("--accel-nominal", accel_unit, accel_nominal), ("--gyro-nominal", gyro_unit, gyro_nominal)):
        if nominal is not None and unit != "raw":
            raise UserError(f"{name} is the scale of raw counts: it needs the unit raw (declared: {unit})")
        if nominal is not None and not (math.isfinite(nominal) and nominal > 0):
            raise UserError(f"{name} must be a positive number, got {nominal!r}")
    if rate_hz is not None and not (math.isfinite(rate_hz) and rate_hz > 0):
        raise UserError(f"--rate-hz must be a positive number, got {rate_hz!r}")
    table = _Table(path, delimiter, header)
    _distinct_columns(table, cols)
    t, time_from = _times(table, cols, time_unit, rate_hz)
    time_option = "--time-unit" if "t" in cols else "--rate-hz"
    accel_roles = ("ax", "ay", "az")
    gyro_roles = ("gx", "gy", "gz")
    missing = [r for r in accel_roles if r not in cols]
    if missing:
        raise UserError(f"--columns: no column for {', '.join(missing)}")
    accel = np.column_stack([table.column(r, cols[r]) for r in accel_roles])
    info = {"preset": preset, "delimiter": _show_delimiter(table.delimiter), "header": table.names is not None}
    if gyro_path is not None or preset == "imu_tk":
        if gyro_path is None:
            raise UserError(f"{path}: the imu_tk layout has the gyro in a second file: give --gyro-file")
        gcols = dict(p.get("gyro_columns", {"t": 0, "gx": 1, "gy": 2, "gz": 3}))
        gtable = _Table(Path(gyro_path), delimiter, header)
        tg, _ = _times(gtable, {k: v for k, v in gcols.items() if k in ("t", "index")}, time_unit, rate_hz)
        gyro_raw = np.column_stack([gtable.column(r, gcols[r]) for r in gyro_roles])
        gyro, how = _align(path, Path(gyro_path), table, gtable, cols, gcols, time_unit, gyro_raw, rate_hz)
        info.update({"gyro_file": Path(gyro_path).name, "gyro_alignment": how})
    else:
        missing = [r for r in gyro_roles if r not in cols]
        if missing:
            raise UserError(f"--columns: no column for {', '.join(missing)}")
        gyro = np.column_stack([table.column(r, cols[r]) for r in gyro_roles])
    return Recording(source=str(path), t=t, accel=accel, gyro=gyro, accel_unit=accel_unit, gyro_unit=gyro_unit,
                     accel_nominal=accel_nominal, gyro_nominal=gyro_nominal, lines=table.numbers, where="line",
                     time_from=time_from, time_option=time_option, info=info)


def _align(path, gpath, table, gtable, cols, gcols, time_unit, gyro, rate_hz):
    """Gyro samples at the accelerometer's times: the same rows when the stamps agree (imu_tk's
    files from one IMU), else linear interpolation within the common span."""
    if "t" not in cols or "t" not in gcols:
        if gtable.count != table.count:
            raise UserError(f"{gpath}: {gtable.count} data lines, {path} has {table.count}: without "
                            "time stamps the two files must have one line per sample each")
        return gyro, "row by row"
    ta = table.column("t", cols["t"]) * TIME_UNITS[time_unit]
    tg = gtable.column("t", gcols["t"]) * TIME_UNITS[time_unit]
    if len(ta) == len(tg):
        step = np.median(np.diff(ta)) if len(ta) > 1 else 1.0
        if np.all(np.abs(ta - tg) <= 0.5 * step):
            return gyro, "row by row (same stamps)"
    if not (np.all(np.diff(tg) > 0)):
        k = int(np.flatnonzero(~(np.diff(tg) > 0))[0]) + 1
        raise UserError(f"{gpath}: line {gtable.numbers[k]}: time does not increase")
    if ta[0] < tg[0] or ta[-1] > tg[-1]:
        raise UserError(f"{gpath}: the gyro's time stamps ({tg[0]:.6g}-{tg[-1]:.6g} s) do not cover the "
                        f"accelerometer's ({ta[0]:.6g}-{ta[-1]:.6g} s)")
    return np.column_stack([np.interp(ta, tg, gyro[:, i]) for i in range(3)]), "interpolated to the accelerometer's stamps"
