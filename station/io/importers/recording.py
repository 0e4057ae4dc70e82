"""A continuous IMU recording (a hand calibration: poses held still, turns between them) ->
a capture bundle, with the statics and turns found in it (station/io/segment_detect.py) or
given by hand (a sections file).  Used by every importer of continuous logs (delimited text,
ROS bags).

What is written (docs/real-recordings.md):
  session          kind ``session``: the whole recording as read (ignored by estimation; kept so
                   that no sample is lost and the sections can be found again);
  pose01, pose02.. kind ``static``: the still intervals, in time order (``up_body`` only when a
                   sections file gives it: a hand pose has no commanded attitude);
  turn01, turn02.. kind ``rotation``: everything between two consecutive statics, with
                   ``motion: hand``, ``axis_body`` the direction of the raw gyro integral (less
                   the still-time bias) and no ``angle_deg``/``rate_dps``: no encoder measured
                   the turn; the least-squares model calibrates the gyro by carrying the gravity
                   direction of the pose before through the turn to the pose after.

Checked before anything is written (UserError, naming the file): time strictly increasing and
without gaps, static poses found (and how many a calibration needs), |f| of the static poses
near gravity in the declared unit, the gyro unit against the turns the accelerometers see.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from station.core import units
from station.core.errors import UserError
from station.core import yaml_text
from station.io.capture import MAX_CSV_VALUE, FormattedRows, ImportCaptureWriter, ImuInfo, Site
from station.io.segment_detect import Detection, Interval, detect
from station.model.geometry import ATTITUDE_TOLERANCE_DEG, distinct_directions

SAMPLE_RATE_RANGE_HZ = (0.01, 1e6)   # an implied rate outside this is a wrong time unit or rate:
# refused before windows of window_s / step samples are allocated (a log in s read as ns: MemoryError)
GAP_FACTOR = 1.5            # a time step above GAP_FACTOR times the median is lost samples
MIN_POSES = 9               # accelerometer: 9 unknowns, 3 - 2 = 1 equation per pose of unknown attitude
# ... and per distinct attitude: a pose held twice on the same face repeats its equation.  Below
# MIN_POSES distinct attitudes the misalignments are not written (station/estimate/poses.py);
# below MIN_ATTITUDES not even the scale factors and biases (6 unknowns) can be found
MIN_ATTITUDES = 6
RECOMMENDED_POSES = "36-50"     # imu_tk's advice for hand poses
GRAVITY_TOLERANCE = 0.2     # static |f| within 20 % of g, else the declared unit is wrong
GYRO_RATIO_RANGE = (0.5, 20.0)  # turn seen by the gyro / change of gravity direction seen by the accel
MIN_TILT_FOR_UNIT_CHECK_DEG = 30.0
MAX_SECTIONS = 100_000
IMUCAL_UP = {"x_p": (1, 0, 0), "x_a": (-1, 0, 0), "y_p": (0, 1, 0), "y_a": (0, -1, 0),
             "z_p": (0, 0, 1), "z_a": (0, 0, -1)}
IMUCAL_AXIS = {"x_rot": (1, 0, 0), "y_rot": (0, 1, 0), "z_rot": (0, 0, 1)}


_ImportWriter = ImportCaptureWriter   # an import is redone, not resumed: two manifest writes, no fsync a file


@dataclass
class Recording:
    """Samples as read, in the declared units, with where each came from."""
    source: str                     # file name for messages
    t: np.ndarray                   # (N,) s
    accel: np.ndarray               # (N,3) accel_unit
    gyro: np.ndarray                # (N,3) gyro_unit
    accel_unit: str
    gyro_unit: str
    accel_nominal: float | None = None   # raw: m/s^2 per count (nominal), if known
    gyro_nominal: float | None = None    # raw: deg/s per count (nominal), if known
    lines: np.ndarray | None = None      # (N,) where each sample is in the source ("line 12", ...)
    where: str = "line"                  # what ``lines`` counts
    time_from: str = ""
    time_option: str = ""                # the option that set the time base (--time-unit, --rate-hz)
    info: dict = field(default_factory=dict)

    @property
    def accel_factor(self) -> float | None:
        """m/s^2 per declared unit, None when unknown (raw without a nominal scale)."""
        return units.accel_to_mps2_factor(self.accel_unit) or self.accel_nominal

    @property
    def gyro_factor(self) -> float | None:
        return units.gyro_to_dps_factor(self.gyro_unit) or self.gyro_nominal

    def at(self, k: int) -> str:
        return f"{self.where} {int(self.lines[k])}" if self.lines is not None else f"sample {k}"


@dataclass
class Section:
    name: str
    kind: str                       # static | rotation
    start: int
    stop: int
    up_body: list | None = None
    axis_body: list | None = None
    note: str = ""


@dataclass
class ImportReport:
    path: Path
    rate_hz: float
    samples: int
    duration_s: float
    sections: list
    detection: Detection | None
    lines: list


def check_time(rec: Recording) -> float:
    """Strictly increasing time without gaps; returns the sample rate (1 / median step)."""
    if len(rec.t) < 8:
        raise UserError(f"{rec.source}: {len(rec.t)} samples: a recording needs many more")
    dt = np.diff(rec.t)
    bad = np.flatnonzero(~(dt > 0))
    if len(bad):
        k = int(bad[0]) + 1
        raise UserError(f"{rec.source}: {rec.at(k)}: time does not increase ({rec.t[k - 1]:.9g} s, then "
                        f"{rec.t[k]:.9g} s; time from {rec.time_from})")
    step = float(np.median(dt))
    low, high = SAMPLE_RATE_RANGE_HZ
    if not low <= 1.0 / step <= high:
        option = f"{rec.time_option}: " if rec.time_option else ""
        raise UserError(f"{rec.source}: {option}the time ({rec.time_from}) gives a median step of {step:.3g} s, "
                        f"{1.0 / step:.3g} samples per second: outside {low:g}-{high:g} Hz, the time unit or "
                        "rate is wrong")
    gaps = np.flatnonzero(dt > GAP_FACTOR * step)
    if len(gaps):
        k = int(gaps[0]) + 1
        lost = int(round(dt[k - 1] / step)) - 1
        raise UserError(f"{rec.source}: {rec.at(k)}: a gap in time of {dt[k - 1]:.6g} s (about {lost} samples "
                        f"lost; the step is {step:.6g} s; time from {rec.time_from}); {len(gaps)} gap(s) in "
                        "all: turns through a gap cannot be integrated, record without losses")
    return 1.0 / step


def read_sections(path, rec: Recording) -> list[Section]:
    """A sections file (YAML or JSON): a list of {name, kind, start, end} (rows from 0, end
    exclusive; or start_s/end_s in the recording's time), optional up_body / axis_body; or
    imucal's mapping {label: {start, end}} with its labels (x_p ... z_a, x_rot ...)."""
    path = Path(path)
    from station.io.importers.text import read_text

    text = read_text(path)          # (a FIFO is refused, not read)
    try:
        data = yaml_text.safe_load(text)
    except (yaml.YAMLError, ValueError) as e:
        mark = getattr(e, "problem_mark", None)
        raise UserError(f"{path}: line {mark.line + 1 if mark else '?'}: not YAML/JSON: "
                        f"{yaml_text.error_line(e)}") from None
    if isinstance(data, dict):
        data = [{"name": k, **v} if isinstance(v, dict) else {"name": k, "bad": v} for k, v in data.items()]
    if not isinstance(data, list) or not data:
        raise UserError(f"{path}: expected a list of sections (name, kind, start, end) or imucal's mapping")
    if len(data) > MAX_SECTIONS:
        raise UserError(f"{path}: {len(data)} sections: more than {MAX_SECTIONS}")
    n = len(rec.t)
    out, names = [], set()
    for i, entry in enumerate(data):
        where = f"{path}: section {i + 1}"
        if not isinstance(entry, dict) or "bad" in entry:
            raise UserError(f"{where}: must be a mapping with name, kind, start and end")
        name = str(entry.get("name", f"section{i + 1:02d}"))
        if not name or len(name) > 64 or not all(c.isalnum() or c in "_-." for c in name):
            raise UserError(f"{where}: field 'name': letters, digits, '_', '-', '.' only (1-64)")
        if name in names or name == "session":
            raise UserError(f"{where}: field 'name': {name!r} used twice (or reserved)")
        names.add(name)
        kind = entry.get("kind") or ("rotation" if name in IMUCAL_AXIS else "static")
        if kind not in ("static", "rotation"):
            raise UserError(f"{where} ({name}): field 'kind': static or rotation, not {kind!r}")
        start, stop = _bounds(where, name, entry, rec.t)
        if not (0 <= start < stop <= n):
            raise UserError(f"{where} ({name}): rows {start}..{stop}: outside the recording's {n} rows "
                            "(start from 0, end exclusive)")
        up = _unit_vector(where, name, entry, "up_body", IMUCAL_UP.get(name) if kind == "static" else None)
        axis = _unit_vector(where, name, entry, "axis_body", IMUCAL_AXIS.get(name) if kind == "rotation" else None)
        out.append(Section(name, kind, start, stop, up, axis, f"given by hand in {path.name}"))
    return sorted(out, key=lambda s: s.start)


def _bounds(where, name, entry, t) -> tuple[int, int]:
    def integer(key):
        v = entry[key]
        if isinstance(v, bool) or not isinstance(v, int):
            raise UserError(f"{where} ({name}): field '{key}': must be a whole row number")
        return v
    if "start" in entry and "end" in entry:
        return integer("start"), integer("end")
    if "start_s" in entry and "end_s" in entry:
        try:
            a, b = float(entry["start_s"]), float(entry["end_s"])
        except (TypeError, ValueError):
            raise UserError(f"{where} ({name}): fields 'start_s', 'end_s': must be numbers (s)") from None
        if not (math.isfinite(a) and math.isfinite(b)):
            raise UserError(f"{where} ({name}): fields 'start_s', 'end_s': must be finite")
        return int(np.searchsorted(t, a)), int(np.searchsorted(t, b))
    raise UserError(f"{where} ({name}): needs 'start' and 'end' (rows) or 'start_s' and 'end_s' (s)")


def _unit_vector(where, name, entry, key, default):
    v = entry.get(key, default)
    if v is None:
        return None
    try:
        a = np.asarray(v, dtype=float).reshape(3)
    except (TypeError, ValueError):
        raise UserError(f"{where} ({name}): field '{key}': must be three numbers") from None
    norm = float(np.linalg.norm(a))
    if not (math.isfinite(norm) and norm > 0):
        raise UserError(f"{where} ({name}): field '{key}': must be a non-zero finite vector")
    return (a / norm).tolist()


def detect_sections(rec: Recording, *, window_s: float, min_static_s: float, rate_threshold_dps: float,
                    init_rest_s: float) -> tuple[list[Section], Detection]:
    try:
        det = detect(rec.t, rec.accel, rec.gyro, window_s=window_s, min_static_s=min_static_s,
                     rate_threshold_dps=rate_threshold_dps, accel_mps2_per_unit=rec.accel_factor,
                     gyro_dps_per_unit=rec.gyro_factor, init_rest_s=init_rest_s)
    except ValueError as e:
        raise UserError(f"{rec.source}: {e}") from None
    statics = det.statics()
    if not statics:
        _gyro_unit_at_rest(rec, det, min_static_s)
        th = det.thresholds
        gyro = (f"{th['gyro_std_threshold_dps']:.3g} deg/s" if "gyro_std_threshold_dps" in th
                else f"{th['gyro_std_threshold_raw']:.3g} raw")
        raise UserError(f"{rec.source}: no static pose found (still: every accelerometer's spread <= "
                        f"{th['accel_std_threshold_mps2']:.3g} m/s^2 and every gyro's <= {gyro} over "
                        f"{th['window_s']:.2g} s, for at least {min_static_s:g} s): hold the IMU still on "
                        "each pose, or give the sections with --segments FILE")
    sections = []
    for k, iv in enumerate(statics):
        sections.append(Section(f"pose{k + 1:02d}", "static", iv.start, iv.stop, note="found by segment_detect"))
        if k + 1 < len(statics):
            nxt = statics[k + 1]
            sections.append(Section(f"turn{k + 1:02d}", "rotation", iv.stop, nxt.start,
                                    note=f"hand turn from pose{k + 1:02d} to pose{k + 2:02d}, found by segment_detect"))
    return sections, det


GYRO_AT_REST_DPS = 10.0      # no gyro reads more at rest: a wrong unit
ACCEL_AT_REST_STD_MPS2 = 0.05   # at rest for that check: every accelerometer's spread below this


def _gyro_unit_at_rest(rec: Recording, det: Detection, min_static_s: float) -> None:
    """When no pose was found: if the accelerometers alone are still long enough and the gyro
    reads more than GYRO_AT_REST_DPS there in the declared unit, the gyro unit is wrong."""
    from station.io.moving_average import moving_std

    fg = rec.gyro_factor
    if fg is None or rec.gyro_unit == "raw":     # raw counts: the zero (offset) is unknown
        return
    fa = rec.accel_factor or 1.0
    window = max(3, int(round(det.thresholds["window_s"] * len(rec.t) / max(rec.t[-1] - rec.t[0], 1e-9))) | 1)
    a = rec.accel * fa
    limit = min(det.thresholds["accel_std_threshold_mps2"], ACCEL_AT_REST_STD_MPS2)
    still = moving_std(a, window, mode="nearest").max(axis=1) <= limit
    if still.sum() < min_static_s * len(rec.t) / max(rec.t[-1] - rec.t[0], 1e-9):
        return
    rate = float(np.median(np.linalg.norm(rec.gyro[still], axis=1))) * fg
    if rate > GYRO_AT_REST_DPS:
        unit = rec.gyro_unit if rec.gyro_unit != "raw" else f"raw x {rec.gyro_nominal:g} deg/s"
        guess = " (are the rates in deg/s?)" if rec.gyro_unit == "rad/s" else ""
        raise UserError(f"{rec.source}: where the accelerometers are still the gyro reads {rate:.3g} deg/s "
                        f"(median) in the declared gyro unit ({unit}): no gyro reads that at rest, the unit is "
                        f"wrong{guess}")


def check_units(rec: Recording, sections: list[Section], gravity_mps2: float) -> list[str]:
    """|f| of the statics against gravity; the gyro's turns against the accelerometers'."""
    statics = [s for s in sections if s.kind == "static"]
    notes = []
    fa = rec.accel_factor
    means, centre = pose_means(rec, statics)
    if fa is not None and len(statics) and centre is None:      # raw counts: their offset not found
        notes.append("static |f| not checked: raw counts about an unknown offset and too few "
                     "distinct poses to find it")
    elif fa is not None and len(statics):
        f = float(np.median(np.linalg.norm(means, axis=1))) * fa
        if abs(f / gravity_mps2 - 1.0) > GRAVITY_TOLERANCE:
            unit = rec.accel_unit if rec.accel_unit != "raw" else f"raw x {rec.accel_nominal:g} m/s^2"
            guess = _guess_accel(f, gravity_mps2)
            raise UserError(f"{rec.source}: the static poses read |f| = {f:.4g} m/s^2 (median) in the declared "
                            f"accelerometer unit ({unit}), far from gravity {gravity_mps2:.4g} m/s^2: the unit "
                            f"is wrong{guess}")
        where = (f" about the statics' centre {np.round(centre).astype(int).tolist()} counts"
                 if rec.accel_unit == "raw" else "")
        notes.append(f"static |f| = {f:.4g} m/s^2 (median over the poses{where}), gravity {gravity_mps2:.4g}")
    fg = rec.gyro_factor
    if fg is not None and len(statics) and rec.gyro_unit != "raw":     # raw: the zero is unknown
        rate = float(np.median([np.linalg.norm(rec.gyro[s.start:s.stop].mean(axis=0)) for s in statics])) * fg
        if rate > GYRO_AT_REST_DPS:
            unit = rec.gyro_unit if rec.gyro_unit != "raw" else f"raw x {rec.gyro_nominal:g} deg/s"
            guess = " (are the rates in deg/s?)" if rec.gyro_unit == "rad/s" else ""
            raise UserError(f"{rec.source}: in the static poses the gyro reads {rate:.3g} deg/s (median) in the "
                            f"declared gyro unit ({unit}): no gyro reads that at rest, the unit is wrong{guess}")
    ratios = []
    for s in sections:
        if s.kind != "rotation":
            continue
        before = next((p for p in reversed(statics) if p.stop <= s.start), None)
        after = next((p for p in statics if p.start >= s.stop), None)
        if before is None or after is None:
            continue
        if centre is None:          # raw counts about an offset not found: no direction to compare
            break
        u0 = rec.accel[before.start:before.stop].mean(axis=0) - centre     # gravity's direction
        u1 = rec.accel[after.start:after.stop].mean(axis=0) - centre
        tilt = math.degrees(math.acos(np.clip(u0 @ u1 / np.linalg.norm(u0) / np.linalg.norm(u1), -1, 1)))
        if tilt < MIN_TILT_FOR_UNIT_CHECK_DEG:
            continue
        bias = np.mean([rec.gyro[p.start:p.stop].mean(axis=0) for p in (before, after)], axis=0)
        dt = np.diff(rec.t[s.start - 1:s.stop + 1]) if s.start > 0 else np.diff(rec.t[s.start:s.stop + 1])
        turned = np.linalg.norm(((rec.gyro[s.start:s.stop] - bias) * np.median(dt)).sum(axis=0))
        ratios.append(turned / tilt)
    if fg is not None and len(ratios) >= 3:
        ratio = float(np.median(ratios)) * fg
        if not GYRO_RATIO_RANGE[0] <= ratio <= GYRO_RATIO_RANGE[1]:
            unit = rec.gyro_unit if rec.gyro_unit != "raw" else f"raw x {rec.gyro_nominal:g} deg/s"
            guess = (" (are the rates in rad/s?)" if 0.005 < ratio < 0.05 else
                     " (are the rates in deg/s?)" if 20 < ratio < 200 else "")
            raise UserError(f"{rec.source}: in the declared gyro unit ({unit}) the turns between poses come to "
                            f"{ratio:.3g} times the change of the gravity direction the accelerometers see "
                            f"(median of {len(ratios)} turns; a turn is at least that change): the unit is "
                            f"wrong{guess}")
        notes.append(f"gyro turns / gravity-direction change: {ratio:.3g} (median of {len(ratios)} turns, >= 1)")
    return notes


def _sphere_centre(means: np.ndarray):
    """The centre of the sphere through the static pose means (linear least squares on
    |m|^2 = 2 m.c + k), or None when the poses do not span three dimensions well enough to
    place it (fewer than 4, or nearly coplanar)."""
    if len(means) < 4:
        return None
    A = np.column_stack([2.0 * means, np.ones(len(means))])
    b = np.einsum("ij,ij->i", means, means)
    spread = means - means.mean(axis=0)
    sv = np.linalg.svd(spread, compute_uv=False)
    if sv[-1] < 0.2 * sv[0]:
        return None
    sol, *_ = np.linalg.lstsq(A, b, rcond=None)
    return sol[:3]


def _guess_accel(f, g) -> str:
    ratio = f / g
    if abs(ratio / units.STANDARD_GRAVITY - 1) < GRAVITY_TOLERANCE:
        return " (the data look like m/s^2: declare --accel-unit m/s^2)"
    if abs(ratio * units.STANDARD_GRAVITY - 1) < GRAVITY_TOLERANCE:
        return " (the data look like g: declare --accel-unit g)"
    return " (raw counts? declare --accel-unit raw, with --accel-nominal if the scale is known)"


def write_capture(rec: Recording, out_dir, *, gravity_mps2: float, latitude_deg: float | None = None,
                  sections_path=None, window_s: float = 0.5, min_static_s: float = 2.0,
                  rate_threshold_dps: float = 1.0, init_rest_s: float = 2.0, min_poses: int = MIN_POSES,
                  model: str | None = None, serial: str | None = None, scheme: str = "hand-poses",
                  faces: bool = False, placement_deg: float = 1.0) -> ImportReport:
    """Check the recording, find (or read) its sections and write the capture bundle."""
    if not (math.isfinite(gravity_mps2) and 9.7 < gravity_mps2 < 9.9):
        raise UserError(f"--gravity-mps2 must be a local gravity on Earth (9.7-9.9 m/s^2), got {gravity_mps2!r}")
    if latitude_deg is not None and not (math.isfinite(latitude_deg) and -90 <= latitude_deg <= 90):
        raise UserError(f"--latitude-deg must be within -90..90, got {latitude_deg!r}")
    for name, a in (("accelerometer", rec.accel), ("gyro", rec.gyro)):
        bad = np.flatnonzero(~np.isfinite(a).all(axis=1))
        if len(bad):
            raise UserError(f"{rec.source}: {rec.at(int(bad[0]))}: {name} value not finite (NaN or inf); "
                            f"{len(bad)} sample(s) in all")
        bad = np.flatnonzero((np.abs(a) > MAX_CSV_VALUE).any(axis=1))     # (a flipped byte of a double)
        if len(bad):
            raise UserError(f"{rec.source}: {rec.at(int(bad[0]))}: {name} value out of range "
                            f"(|value| > {MAX_CSV_VALUE:g}); {len(bad)} sample(s) in all")
    rate = check_time(rec)
    det = None
    if sections_path is not None:
        sections = read_sections(sections_path, rec)
    else:
        span = float(rec.t[-1] - rec.t[0])      # (windows of these many samples are allocated)
        for option, value in (("--window-s", window_s), ("--min-static-s", min_static_s),
                              ("--init-rest-s", init_rest_s)):
            if not (math.isfinite(value) and 0 < value <= span):
                raise UserError(f"{option} {value:g}: not within the recording {rec.source} ({span:.6g} s)")
        sections, det = detect_sections(rec, window_s=window_s, min_static_s=min_static_s,
                                        rate_threshold_dps=rate_threshold_dps, init_rest_s=init_rest_s)
    statics = [s for s in sections if s.kind == "static"]
    if not statics:
        raise UserError(f"{sections_path}: no static section: a calibration needs static poses")
    if faces:
        _faces(rec, statics)
    notes = check_units(rec, sections, gravity_mps2)
    known_up = all(s.up_body is not None for s in statics)
    distinct = distinct_attitudes(rec, statics)
    need = 6 if known_up else min_poses
    if len(statics) < need:
        raise UserError(f"{rec.source}: {len(statics)} static pose(s) found; a calibration from hand poses "
                        f"needs at least {need} in different attitudes"
                        + ("" if known_up else f" (9 for the accelerometers' 9 unknowns when the attitudes are "
                           f"unknown; imu_tk recommends {RECOMMENDED_POSES}, with a turn between each two)"))
    if not known_up and distinct is not None and distinct < MIN_ATTITUDES:
        raise UserError(f"{rec.source}: {len(statics)} static poses found in only {distinct} distinct attitude(s) "
                        f"(gravity directions within {ATTITUDE_TOLERANCE_DEG:g} deg are one): a calibration from "
                        f"hand poses of unknown attitude needs at least {MIN_ATTITUDES} for the accelerometers' "
                        f"scale factors and biases and {min_poses} for their misalignments (one equation per "
                        "distinct gravity direction); poses held again on the same face add none")
    if not known_up and distinct is not None and distinct < min_poses:
        notes.append(f"only {distinct} distinct attitudes among the {len(statics)} poses: the accelerometer "
                     f"misalignments need {min_poses} (one equation per distinct gravity direction when the "
                     "attitudes are unknown) and will not be written; the scale factors and biases will")
    imu_extra = {}
    if rec.accel_nominal is not None:
        imu_extra["accel_nominal_mps2_per_count"] = float(rec.accel_nominal)
    if rec.gyro_nominal is not None:
        imu_extra["gyro_nominal_dps_per_count"] = float(rec.gyro_nominal)
    source = {"file": rec.source, "time_from": rec.time_from, **rec.info}
    if det is not None:
        source["thresholds"] = {k: (round(v, 9) if isinstance(v, float) else v) for k, v in det.thresholds.items()}
    extra = {"import": source}
    if known_up:
        if not (math.isfinite(placement_deg) and placement_deg > 0):
            raise UserError(f"--placement-deg must be a positive angle, got {placement_deg!r}")
        extra["table"] = {"angle_error_arcsec": float(placement_deg) * 3600.0}
    writer = _ImportWriter(out_dir, ImuInfo(float(rate), rec.accel_unit, rec.gyro_unit, model=model,
                                            serial=serial, extra=imu_extra),
                           Site(float(gravity_mps2), latitude_deg), scheme=scheme, extra=extra)
    rows = FormattedRows(rec.t, rec.accel, rec.gyro)     # formatted once: the session, then its parts
    with writer.begin_segment("session", "session", note=f"the whole recording as read from {rec.source}; "
                              "the segments below are copies of parts of it") as seg:
        seg.write_rows(rows, 0, rows.count)
        seg.close()
    for s in sections:
        sl = slice(s.start, s.stop)
        span = f"rows {s.start}..{s.stop - 1} of the recording, {rec.at(s.start)} on"
        if s.kind == "static":
            meta = {"note": f"{s.note}; {span}"}
            if s.up_body is not None:
                meta["up_body"] = s.up_body
        else:
            axis = s.axis_body
            how = "given"
            if axis is None:
                rot = (rec.gyro[sl] - _still_bias(rec, statics)).sum(axis=0)
                n = float(np.linalg.norm(rot))
                axis = (rot / n).tolist() if n > 0 else [0.0, 0.0, 1.0]
                how = "the direction of the raw gyro integral (uncalibrated)"
            meta = {"axis_body": [float(v) for v in axis], "motion": "hand",
                    "note": f"{s.note}; {span}; axis_body is {how}; no encoder: angle and rate unknown"}
        with writer.begin_segment(s.name, s.kind, **meta) as seg:
            seg.write_rows(rows, s.start, s.stop)
            seg.close()
    writer.finish()
    lines = _report_lines(rec, sections, det, rate, notes, distinct)
    return ImportReport(writer.path, rate, len(rec.t), float(rec.t[-1] - rec.t[0]), sections, det, lines)


FACE_TOLERANCE_DEG = 20.0


def _faces(rec: Recording, statics: list) -> None:
    """up_body of each static: the case axis (+-x, +-y, +-z) its gravity is within
    FACE_TOLERANCE_DEG of (the IMU laid on a face, as Ferraris' method and imucal assume)."""
    for s in statics:
        if s.up_body is not None:
            continue
        m = rec.accel[s.start:s.stop].mean(axis=0)
        m = m / np.linalg.norm(m)
        k = int(np.argmax(np.abs(m)))
        if abs(m[k]) < math.cos(math.radians(FACE_TOLERANCE_DEG)):
            raise UserError(f"{rec.source}: {rec.at(s.start)} ({s.name}): gravity along ({m[0]:+.2f}, {m[1]:+.2f}, "
                            f"{m[2]:+.2f}) in the IMU's axes, more than {FACE_TOLERANCE_DEG:g} deg from every face: "
                            "--faces needs the IMU laid on its faces")
        up = [0.0, 0.0, 0.0]
        up[k] = float(np.sign(m[k]))
        s.up_body = up
        s.note += f"; up_body the nearest face (--faces)"


def _still_bias(rec, statics) -> np.ndarray:
    return np.mean([rec.gyro[s.start:s.stop].mean(axis=0) for s in statics], axis=0)


def pose_means(rec: Recording, statics: list):
    """(the static poses' accelerometer means about their centre, the centre): zero in physical
    units; for raw counts (offset binary or not) the centre of the sphere through them, and
    (the raw means, None) when it cannot be placed."""
    means = np.array([rec.accel[s.start:s.stop].mean(axis=0) for s in statics]).reshape(-1, 3)
    if rec.accel_unit != "raw":
        return means, np.zeros(3)
    centre = _sphere_centre(means)
    return (means, None) if centre is None else (means - centre, centre)


def distinct_attitudes(rec: Recording, statics: list, centred=None) -> int | None:
    """How many distinct gravity directions the static poses hold (station.model.geometry:
    within ATTITUDE_TOLERANCE_DEG), their accelerometer means taken about their centre
    (pose_means, or ``centred``: its result); None when that centre cannot be found."""
    means, centre = centred if centred is not None else pose_means(rec, statics)
    if centre is None:
        return None
    return int(distinct_directions(means).max()) + 1 if len(means) else 0


def _report_lines(rec, sections, det, rate, notes, distinct=None) -> list[str]:
    statics = [s for s in sections if s.kind == "static"]
    turns = [s for s in sections if s.kind == "rotation"]
    lines = [f"{rec.source}: {len(rec.t)} samples, {rec.t[-1] - rec.t[0]:.1f} s at {rate:.4g} Hz "
             f"(time from {rec.time_from}); accel {rec.accel_unit}, gyro {rec.gyro_unit}"]
    if det is not None:
        th = det.thresholds
        parts = [f"accel spread <= {th['accel_std_threshold_mps2']:.3g} m/s^2"]
        if "gyro_std_threshold_dps" in th:
            parts.append(f"gyro spread <= {th['gyro_std_threshold_dps']:.3g} deg/s, "
                         f"|rate - bias| <= {th['rate_threshold_dps']:.3g} deg/s")
        else:
            parts.append(f"gyro spread <= {th['gyro_std_threshold_raw']:.3g} raw, |rate - bias| <= "
                         f"{th['rate_threshold_raw']:.3g} raw ({th['rate_threshold_from']})")
        if "accel_scale_from" in th:
            parts.append(f"accel scale from the {th['accel_scale_from']}")
        lines.append(f"still: {'; '.join(parts)}; over {th['window_s']:.2g} s windows, for >= "
                     f"{th['min_static_s']:g} s")
    durations = [(s.stop - s.start) / rate for s in statics]
    where = f" in {distinct} distinct attitudes" if distinct is not None else ""
    lines.append(f"found {len(statics)} static poses{where} ({min(durations):.1f}-{max(durations):.1f} s, "
                 f"{sum(durations):.0f} s in all) and {len(turns)} turns between them")
    fa = rec.accel_factor or 1.0
    for s in sections:
        t0 = rec.t[s.start] - rec.t[0]
        dur = (s.stop - s.start) / rate
        if s.kind == "static":
            m = rec.accel[s.start:s.stop].mean(axis=0) * fa
            unit = "m/s^2" if rec.accel_factor else "raw"
            lines.append(f"  {s.name:8s} static   {t0:8.2f} s  {dur:6.2f} s  mean f ({m[0]:+.3f}, {m[1]:+.3f}, "
                         f"{m[2]:+.3f}) {unit}")
        else:
            lines.append(f"  {s.name:8s} rotation {t0:8.2f} s  {dur:6.2f} s")
    return lines + notes
