"""imucal (mad-lab-fau/imucal) Ferraris sessions -> station capture bundles.

Two layouts are read (docs/imucal-comparison.md):

* ``session``: one continuous recording, header ``n_samples,gyr_x,gyr_y,gyr_z,acc_x,acc_y,acc_z``
  (any column order, extra columns ignored; ``n_samples`` optional), accelerometer in m/s^2 and
  gyro in deg/s, plus a JSON section list ``{"x_p": {"start": 540, "end": 1271}, ...}`` of row
  ranges, start inclusive and end exclusive (imucal's ``data.iloc[start:end]``), rows counted
  from 0 after the header;
* ``annotated``: header ``part,samples,acc_x,acc_y,acc_z,gyr_x,gyr_y,gyr_z``, each row labelled
  with its section; raw ADC counts (units ``raw``).

imucal has no time base: time is the sample number (``n_samples``/``samples``, else the row
index) divided by the rate given.  Section labels (imucal's Ferraris sections):

  x_p, x_a, y_p, y_a, z_p, z_a  static: that IMU axis pointing up (p) or down (a)
                                -> kind static, up_body +-e_axis
  x_rot, y_rot, z_rot           a hand rotation about that axis, held pointing up (the x_p, y_p,
                                z_p attitude), "clockwise (the gyro shows negative values)", which
                                imucal books as -360 deg
                                -> kind rotation, axis_body e_axis

Rotation direction.  A right-handed rotation about +x is counter-clockwise seen from the +x
end; imucal's clockwise turn seen from above with x up is therefore a negative rotation about
+x, and a right-handed gyro reads negative: rate_dps < 0.  The importer checks this against the
data: it integrates the gyro about the axis (minus the mean gyro of the static sections), and
tests over the whole recording whether the gyro turns the same way as the accelerometer axes
(while the IMU is moved between attitudes, df/dt = -w x f; see kinematic_consistency).  The
direction written is the gyro's if the gyro is right-handed against the accelerometers, the
opposite if it reads inverted, and imucal's convention if the check is inconclusive; the
segment's ``note`` says which and why.  |rate_dps| is 360 deg over the section's duration, a nominal figure
(the spec: rate_dps then gives the direction only).  ``angle_deg`` is left out: no encoder
measured the turn, and a hand turn returns to its start attitude only as well as the operator
aligned it (a degree is 0.3 % of 360 deg), which the accelerometers cannot check about a
vertical axis.

All input is untrusted: every problem raises UserError naming the file, the line and the field.
"""
from __future__ import annotations

import hashlib
import json
import math
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from station.io.capture import ImportCaptureWriter, ImuInfo, Site
from station.core.errors import UserError
from station.core.units import ACCEL_UNITS, GYRO_UNITS
from station.io.importers.text import read_text

FORMATS = ("auto", "session", "annotated")
STATIC_UP = {"x_p": (1, 0, 0), "x_a": (-1, 0, 0), "y_p": (0, 1, 0), "y_a": (0, -1, 0),
             "z_p": (0, 0, 1), "z_a": (0, 0, -1)}
ROTATION_AXIS = {"x_rot": (1, 0, 0), "y_rot": (0, 1, 0), "z_rot": (0, 0, 1)}
LABELS = tuple(STATIC_UP) + tuple(ROTATION_AXIS)
IMUCAL_EXPECTED_ANGLE_DEG = -360.0     # imucal FerrarisCalibration's default expected_angle
ACC_COLS = ("acc_x", "acc_y", "acc_z")
GYR_COLS = ("gyr_x", "gyr_y", "gyr_z")
DEFAULT_GRAVITY_MPS2 = 9.81            # imucal's default grav; pass the local value if known


@dataclass
class Section:
    label: str
    first_line: int          # CSV line of the first row (header = line 1)
    t: np.ndarray            # s
    accel: np.ndarray        # (N,3)
    gyro: np.ndarray         # (N,3)


def _read_lines(path: Path) -> list[str]:
    text = read_text(path)
    lines = text.splitlines()
    while lines and not lines[-1].strip():
        lines.pop()
    if not lines:
        raise UserError(f"{path}: empty file")
    return lines


def _header(path: Path, line: str, required: tuple[str, ...]) -> dict[str, int]:
    names = [c.strip() for c in line.split(",")]
    if names and names[0] == "":
        names[0] = "index"                        # pandas writes an unnamed index column
    dup = sorted({n for n in names if names.count(n) > 1 and n})
    if dup:
        raise UserError(f"{path}: line 1: column '{dup[0]}' appears twice")
    for col in required:
        if col not in names:
            raise UserError(f"{path}: line 1: column '{col}': required, missing (header: {line.strip()[:120]})")
    return {n: i for i, n in enumerate(names)}


def _number(path: Path, lineno: int, column: str, text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise UserError(f"{path}: line {lineno}: column '{column}': not a number: {text.strip()[:40]!r}") from None
    if not math.isfinite(value):
        raise UserError(f"{path}: line {lineno}: column '{column}': not finite: {text.strip()[:40]!r}")
    return value


def _rows(path: Path, lines: list[str], cols: dict[str, int], wanted: tuple[str, ...]):
    """Yield (line number, {column: text}) for every data line, checking the field count."""
    width = len(cols)
    for i, line in enumerate(lines[1:], start=2):
        if '"' in line:
            raise UserError(f"{path}: line {i}: quoted fields are not supported")
        fields = line.split(",")
        if len(fields) != width:
            raise UserError(f"{path}: line {i}: {len(fields)} fields, the header has {width}")
        yield i, {c: fields[cols[c]] for c in wanted}


def _parsed_fast(lines: list[str], cols: dict[str, int], wanted: tuple[str, ...]) -> np.ndarray | None:
    """The data lines' wanted columns by numpy's C reader (np.loadtxt: correctly rounded, as
    float()), or None whenever the line-by-line reader might say something else: a quote, a blank
    line, a field count other than the header's, text that is not a number, a value that is not
    finite (that reader then names the line and column).  ~10 ms for imucal's example session,
    where splitting and converting every field in Python took ~60 ms."""
    import io

    body = lines[1:]
    if not body or any('"' in line or not line.strip() for line in body):
        return None
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            data = np.loadtxt(io.StringIO("\n".join(body)), dtype=np.float64, delimiter=",", comments=None,
                              usecols=[cols[c] for c in wanted], ndmin=2)
    except (ValueError, Warning):
        return None
    width = len(cols)
    if data.shape[0] != len(body) or not np.all(np.isfinite(data)) or any(line.count(",") != width - 1
                                                                          for line in body):
        return None
    return data


def _times(path: Path, lines_numbers, counter, rate_hz: float, column: str | None) -> np.ndarray:
    t = np.asarray(counter, float) / rate_hz
    bad = np.nonzero(np.diff(t) <= 0)[0]
    if len(bad):
        where = f"column '{column}'" if column else "row order"
        raise UserError(f"{path}: line {lines_numbers[bad[0] + 1]}: {where}: sample number does not "
                        "increase")
    return t


def read_session(csv_path, sections_path, rate_hz: float) -> tuple[list[Section], Section]:
    """The continuous-recording layout with a JSON section list: (sections, whole recording)."""
    csv_path, sections_path = Path(csv_path), Path(sections_path)
    lines = _read_lines(csv_path)
    cols = _header(csv_path, lines[0], ACC_COLS + GYR_COLS)
    counter_col = "n_samples" if "n_samples" in cols else None
    wanted = ACC_COLS + GYR_COLS + ((counter_col,) if counter_col else ())
    data = _parsed_fast(lines, cols, wanted)
    if data is not None:
        numbers = list(range(2, len(lines) + 1))
    else:           # line by line: the same values, or the message naming the line and column
        numbers, values = [], []
        for lineno, row in _rows(csv_path, lines, cols, wanted):
            numbers.append(lineno)
            values.append([_number(csv_path, lineno, c, row[c]) for c in wanted])
        if not values:
            raise UserError(f"{csv_path}: no data rows")
        data = np.array(values)
    counter = data[:, 6] if counter_col else np.arange(len(data))
    t = _times(csv_path, numbers, counter, rate_hz, counter_col)
    spans = read_section_list(sections_path, len(data))
    out = []
    for label, (start, end) in spans:
        sl = slice(start, end)
        out.append(Section(label, numbers[start], t[sl], data[sl, 0:3], data[sl, 3:6]))
    return out, Section("all", 2, t, data[:, 0:3], data[:, 3:6])


def read_section_list(path: Path, rows: int) -> list[tuple[str, tuple[int, int]]]:
    """{label: {start, end}} -> [(label, (start, end))] in time order, checked."""
    from station.core.user_files import read_user_text

    text = read_user_text(path, "sections file")              # (a FIFO is refused, not read)
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as e:
        raise UserError(f"{path}: line {e.lineno}: not valid JSON: {e.msg}") from None
    if not isinstance(doc, dict) or not doc:
        raise UserError(f"{path}: must be a JSON object mapping section labels to {{start, end}}")
    spans = []
    for label, span in doc.items():
        where = f"{path}: field '{label}'"
        if label not in LABELS:
            raise UserError(f"{where}: unknown section label (imucal's are {', '.join(LABELS)})")
        if not isinstance(span, dict):
            raise UserError(f"{where}: must be an object with 'start' and 'end'")
        bounds = []
        for key in ("start", "end"):
            v = span.get(key)
            if isinstance(v, float) and v.is_integer():
                v = int(v)
            if isinstance(v, bool) or not isinstance(v, int):
                raise UserError(f"{path}: field '{label}.{key}': must be a whole row number, got {v!r}")
            bounds.append(v)
        start, end = bounds
        if not 0 <= start < end <= rows:
            raise UserError(f"{path}: field '{label}': rows [{start}, {end}) out of range: the CSV has "
                            f"{rows} data rows (start inclusive, end exclusive, from 0)")
        spans.append((label, (start, end)))
    spans.sort(key=lambda s: s[1][0])
    for (a, (_, ea)), (b, (sb, _)) in zip(spans, spans[1:]):
        if sb < ea:
            raise UserError(f"{path}: field '{b}': overlaps section '{a}' (rows {sb} < {ea})")
    return spans


def read_annotated(csv_path, rate_hz: float) -> tuple[list[Section], Section]:
    """The annotated layout, a ``part`` label and a ``samples`` number on every row:
    (sections, all rows in time order)."""
    csv_path = Path(csv_path)
    lines = _read_lines(csv_path)
    cols = _header(csv_path, lines[0], ("part",) + ACC_COLS + GYR_COLS)
    counter_col = "samples" if "samples" in cols else None
    wanted = ("part",) + ACC_COLS + GYR_COLS + ((counter_col,) if counter_col else ())
    runs: list[tuple[str, list[int], list[list[float]]]] = []
    seen: dict[str, int] = {}
    for lineno, row in _rows(csv_path, lines, cols, wanted):
        label = row["part"].strip()
        if label not in LABELS:
            raise UserError(f"{csv_path}: line {lineno}: column 'part': unknown section label "
                            f"{label[:40]!r} (imucal's are {', '.join(LABELS)})")
        if not runs or runs[-1][0] != label:
            if label in seen:
                raise UserError(f"{csv_path}: line {lineno}: column 'part': section '{label}' starts again "
                                f"(it already ran from line {seen[label]})")
            seen[label] = lineno
            runs.append((label, [], []))
        values = [_number(csv_path, lineno, c, row[c]) for c in wanted[1:]]
        runs[-1][1].append(lineno)
        runs[-1][2].append(values)
    if not runs:
        raise UserError(f"{csv_path}: no data rows")
    out = []
    for label, numbers, values in runs:
        data = np.array(values)
        counter = data[:, 6] if counter_col else np.array(numbers, float) - 2
        t = _times(csv_path, numbers, counter, rate_hz, counter_col)
        out.append(Section(label, numbers[0], t, data[:, 0:3], data[:, 3:6]))
    out.sort(key=lambda s: s.t[0])
    for a, b in zip(out, out[1:]):
        if b.t[0] <= a.t[-1]:
            raise UserError(f"{csv_path}: line {b.first_line}: column '{counter_col or 'part'}': section "
                            f"'{b.label}' overlaps section '{a.label}' in time")
    whole = Section("all", 2, np.concatenate([s.t for s in out]), np.vstack([s.accel for s in out]),
                    np.vstack([s.gyro for s in out]))
    return out, whole


def detect_format(csv_path) -> str:
    lines = _read_lines(Path(csv_path))[:1]
    names = [c.strip() for c in lines[0].split(",")]
    return "annotated" if "part" in names else "session"


KINEMATIC_CONCLUSIVE = 0.2    # |correlation| from which the gyro's sense counts as checked


def rotation_note(section: Section, bias: np.ndarray, gyro_unit: str, kinematic: float) -> tuple[float, str]:
    """(direction of the rotation about axis_body, right-handed in the accelerometer axes: +-1,
    note for the manifest).

    imucal's protocol says clockwise (negative); the gyro integral says what the gyro saw, which
    is the direction only if the gyro turns the right way round against the accelerometers: the
    kinematic check (df/dt = -w x f over the whole recording) says whether it does.
    """
    axis = np.array(ROTATION_AXIS[section.label], float)
    dt = np.diff(section.t)
    step = np.median(dt) if len(dt) else 0.0
    integral = float(((section.gyro - bias) @ axis).sum() * step)
    gyro_sign = 1.0 if integral > 0 else -1.0
    unit = "deg" if gyro_unit == "deg/s" else f"{gyro_unit}*s"
    head = (f"imucal hand rotation '{section.label}': {IMUCAL_EXPECTED_ANGLE_DEG:+.0f} deg in imucal's convention "
            "(clockwise seen from the upper end of axis_body), a negative right-handed rotation; the gyro "
            f"integral about the axis, less the static-section mean, is {integral:+.4g} {unit}; ")
    if kinematic >= KINEMATIC_CONCLUSIVE:
        sign = gyro_sign
        why = (f"the gyro turns the same way as the accelerometer axes (kinematic correlation {kinematic:+.2f}), "
               + ("so the turn was indeed clockwise" if sign < 0 else
                  "so the turn was counter-clockwise, against imucal's convention"))
    elif kinematic <= -KINEMATIC_CONCLUSIVE:
        sign = -gyro_sign
        why = (f"the gyro reads inverted against the accelerometer axes (kinematic correlation {kinematic:+.2f}), "
               + ("so the turn was clockwise, as imucal's convention says" if sign < 0 else
                  "so the turn was counter-clockwise, against imucal's convention"))
    else:
        sign = -1.0
        why = (f"the kinematic check is inconclusive (correlation {kinematic:+.2f}): imucal's convention is "
               "kept" + ("" if gyro_sign < 0 else ", although the gyro integral is positive"))
    tail = ("; rate_dps is 360 deg over the section's duration with that sign, nominal: it gives the direction "
            "only; angle_deg is left out (no encoder; imucal assumes exactly 360 deg)")
    return sign, head + why + tail


def kinematic_consistency(t, accel, gyro, window_s: float = 0.1) -> float:
    """Correlation of d(accel)/dt with -w x accel while the IMU turns, in [-1, 1].

    A body turning in a fixed gravity field sees its specific force obey df/dt = -w x f (in its
    own axes).  Both signals are smoothed over window_s, and only the samples where |w x f| is
    in the upper half of its range are used (the moves between attitudes).  +1: the gyro axes and
    sense agree with the accelerometer axes; -1: the gyro sense is inverted.  Units do not
    matter (a positive scale factor is assumed for raw units).
    """
    from station.io.moving_average import moving_mean

    t = np.asarray(t, float)
    if len(t) < 8:
        return 0.0
    win = max(1, int(round(window_s / np.median(np.diff(t)))))
    f = moving_mean(accel, win)          # (scipy.ndimage's default mode: reflect)
    w = moving_mean(gyro, win)
    df = np.gradient(f, t, axis=0)
    pred = -np.cross(w, f)
    size = np.linalg.norm(pred, axis=1)
    mask = size > 0.5 * np.percentile(size, 99)
    den = math.sqrt(np.sum(df[mask] ** 2) * np.sum(pred[mask] ** 2))
    return float(np.sum(df[mask] * pred[mask]) / den) if den > 0 else 0.0


def import_imucal(csv_path, out_dir, *, rate_hz: float, sections_path=None, fmt: str = "auto",
                  gravity_mps2: float = DEFAULT_GRAVITY_MPS2, accel_unit: str | None = None,
                  gyro_unit: str | None = None, model: str | None = None, serial: str | None = None,
                  turn_deg: float | None = None, placement_deg: float = 1.0) -> Path:
    """Write an imucal session as a station capture bundle in ``out_dir``; returns its path.

    ``turn_deg``: the protocol's turn of every rotation section (imucal's Ferraris protocol: 360),
    recorded as ``angle_deg`` with a note that no encoder measured it; then the least-squares
    model can use the sections.  ``placement_deg``: how well a hand puts the IMU on a face and
    turns it (1-sigma), recorded as the bench's angle error."""
    csv_path = Path(csv_path)
    if not (isinstance(rate_hz, (int, float)) and math.isfinite(rate_hz) and rate_hz > 0):
        raise UserError(f"--rate-hz must be a positive number, got {rate_hz!r}")
    if not (math.isfinite(gravity_mps2) and 9.7 < gravity_mps2 < 9.9):
        raise UserError(f"--gravity-mps2 must be a local gravity on Earth (9.7-9.9 m/s^2), got {gravity_mps2!r}")
    if fmt not in FORMATS:
        raise UserError(f"unknown imucal format {fmt!r}: use one of {', '.join(FORMATS)}")
    if fmt == "auto":
        fmt = detect_format(csv_path)
    if fmt == "session":
        if sections_path is None:
            raise UserError(f"{csv_path}: a continuous imucal session needs its section list (--sections JSON)")
        sections, whole = read_session(csv_path, sections_path, rate_hz)
        units = ("m/s^2", "deg/s")
    else:
        if sections_path is not None:
            raise UserError(f"{csv_path}: an annotated session carries its sections in column 'part'; "
                            "--sections is not used with it")
        sections, whole = read_annotated(csv_path, rate_hz)
        units = ("raw", "raw")
    accel_unit = accel_unit or units[0]
    gyro_unit = gyro_unit or units[1]
    if accel_unit not in ACCEL_UNITS or gyro_unit not in GYRO_UNITS:
        raise UserError(f"units must be one of {', '.join(ACCEL_UNITS)} and {', '.join(GYRO_UNITS)}")
    statics = [s for s in sections if s.label in STATIC_UP]
    bias = np.mean(np.vstack([s.gyro for s in statics]), axis=0) if statics else np.zeros(3)
    kinematic = kinematic_consistency(whole.t, whole.accel, whole.gyro - bias)
    source = {"from": "imucal", "format": fmt, "csv": csv_path.name,
              "csv_sha256": hashlib.sha256(csv_path.read_bytes()).hexdigest(),
              "gyro_kinematic_correlation": round(kinematic, 4)}
    if sections_path is not None:
        source["sections"] = Path(sections_path).name
    if turn_deg is not None and not (math.isfinite(turn_deg) and turn_deg > 0):
        raise UserError(f"--turn-deg must be a positive angle in degrees, got {turn_deg!r}")
    if not (math.isfinite(placement_deg) and placement_deg > 0):
        raise UserError(f"--placement-deg must be a positive angle in degrees, got {placement_deg!r}")
    # an import is redone, not resumed: the manifest written at the start and at the end, no
    # fsync of each file (ImportCaptureWriter)
    writer = ImportCaptureWriter(out_dir, ImuInfo(float(rate_hz), accel_unit, gyro_unit, model=model, serial=serial),
                                 Site(float(gravity_mps2)), scheme="imucal-ferraris",
                                 extra={"import": source, "table": {"angle_error_arcsec": placement_deg * 3600.0}})
    try:
        _write_sections(writer, sections, bias, gyro_unit, kinematic, rate_hz, turn_deg)
    finally:
        writer.finish()         # (stopped by an error: the manifest of what was written)
    return writer.path


def _write_sections(writer, sections, bias, gyro_unit, kinematic, rate_hz, turn_deg) -> None:
    for s in sections:
        if s.label in STATIC_UP:
            meta = {"up_body": list(STATIC_UP[s.label]),
                    "note": f"imucal static section '{s.label}' (CSV line {s.first_line} on)"}
            kind = "static"
        else:
            sign, note = rotation_note(s, bias, gyro_unit, kinematic)
            duration = len(s.t) / rate_hz
            meta = {"axis_body": list(ROTATION_AXIS[s.label]), "rate_dps": sign * 360.0 / duration,
                    "note": note + f" (CSV line {s.first_line} on)"}
            if turn_deg is not None:
                meta["angle_deg"] = sign * float(turn_deg)
                meta["note"] += (f"; angle_deg {sign * turn_deg:g} is the protocol's turn (--turn-deg), "
                                 "not an encoder reading")
            kind = "rotation"
        with writer.begin_segment(s.label, kind, **meta) as seg:
            seg.write(s.t, s.accel, s.gyro)
            seg.close()
