"""Estimation: from a capture bundle to a calibration."""
from __future__ import annotations

import hashlib
import math
from pathlib import Path

import numpy as np

from station.model.calibration import Calibration
from station.io.capture import Capture, read_capture, stamp_gaps

METHODS = ("auto", "lsq", "zhang2010", "fourier", "fourier-high")
# "auto": fourier when any complete rotation segment has no angle_deg (no encoder) and is not a
# hand turn between statics, lsq otherwise (hand turns of unknown angle are terms of its model).  "lsq" is the weighted least-squares fit of the full measurement model, started
# from the 2010 algebraic solution ("zhang2010", which is also available alone).  "fourier" is
# the Fourier method's low-grade variant (Earth rate neglected),
# "fourier-high" its high-grade variant (Earth rate along each shaft estimated; only |Omega_E|).


def capture_digest(capture: Capture) -> str:
    """sha256 over the manifest's bytes followed by the sha256 (32 bytes) of every complete
    segment file, in manifest order.  A file's sha256 is the one taken when its samples were read
    (Segment.content_sha256), so no file is read or hashed twice."""
    from station.io.capture import open_regular_file

    h = hashlib.sha256()
    h.update((capture.path / "manifest.yaml").read_bytes())
    for seg in capture.complete():
        file_sha256 = seg.content_sha256
        if file_sha256 is None:         # not read: hashed here, a buffer at a time
            with open_regular_file(capture.path / seg.file) as f:
                file_sha256 = hashlib.file_digest(f, "sha256").hexdigest()
        h.update(bytes.fromhex(file_sha256))
    return h.hexdigest()


def choose_method(capture: Capture) -> str:
    """The method "auto" stands for: fourier if any complete rotation lacks angle_deg and is
    not a hand turn (a steady rotation about a shaft); lsq otherwise (hand turns between statics
    enter its model: station/estimate/hand_rotation.py)."""
    from station.estimate.hand_rotation import is_hand

    # a capture read without samples: read those that tell (kept: a hand turn is short, and the
    # Fourier method needs every sample anyway)
    capture.load_samples([seg for seg in capture.complete("rotation")
                          if seg.angle_deg is None and seg.extra.get("motion") != "hand"])
    if any(seg.angle_deg is None and not is_hand(seg) for seg in capture.complete("rotation")):
        return "fourier"
    return "lsq"


COLUMNS = ("ax", "ay", "az", "gx", "gy", "gz")
# data-loss limits per segment (the defaults of station.yaml's run.max_missing_fraction, run.max_gap_s)
MAX_MISSING_FRACTION = 0.01
MAX_GAP_S = 1.0


def data_loss(seg, sample_rate_hz: float) -> tuple[int, float, float]:
    """(frames missing, their share of the frames, the longest stretch without a frame in s) of
    a segment's samples, from its time stamps (station.io.capture.stamp_gaps: counted where the
    stamps jump, so that stamps that jitter or a device a few % off its stated rate lose
    nothing)."""
    t = seg.data.t
    n = len(t)
    if n < 2:
        return 0, 0.0, 0.0
    _, missing, period = stamp_gaps(t, sample_rate_hz)
    longest = float(np.diff(t).max()) - period
    return missing, missing / (n + missing), max(longest, 0.0)


def exclude_lossy_segments(capture: Capture, max_missing_fraction: float = MAX_MISSING_FRACTION,
                           max_gap_s: float = MAX_GAP_S) -> list[str]:
    """Mark complete segments that lost more than the limits as ``excluded`` (so that
    ``capture.complete()`` leaves them out); returns a note for each."""
    notes = []
    for seg in capture.complete():
        with capture.lent_samples(seg):          # a capture read without its samples: each in turn
            notes.append(_exclude_if_lossy(seg, capture.imu.sample_rate_hz, max_missing_fraction, max_gap_s))
    return [note for note in notes if note]


def _exclude_if_lossy(seg, sample_rate_hz, max_missing_fraction, max_gap_s) -> str | None:
    """Mark one segment (samples in seg.data) ``excluded`` if it lost more than the limits; the
    note that says so, or None."""
    if seg.data is None or len(seg.data.t) < 2:
        return None
    missing, share, gap = data_loss(seg, sample_rate_hz)
    problems = []
    if share > max_missing_fraction:
        problems.append(f"{missing} frames missing ({100 * share:.2f} %, limit {100 * max_missing_fraction:g} %)")
    if gap > max_gap_s:
        problems.append(f"no frame for {gap:.2f} s (limit {max_gap_s:g} s)")
    if not problems:
        return None
    seg.status = "excluded"
    return f"segment {seg.name} excluded: {'; '.join(problems)}"


def check_resolution(capture: Capture) -> None:
    """Refuse (UserError naming the file and column) static data quantised coarser than their
    noise: when the samples' standard deviation is below half the output step, the mean is set
    by the rounding, not by the sensor, and the noise (the fit's weights) reads as zero."""
    for seg in capture.complete("static"):
        with capture.lent_samples(seg):          # a capture read without its samples: each in turn
            check_static_resolution(capture, seg)


def check_static_resolution(capture: Capture, seg) -> None:
    """check_resolution for one static segment (samples in seg.data)."""
    from station.core.errors import UserError
    from station.estimate.arrays import distinct

    if len(seg.data.t) >= 2:
        for k, name in enumerate(COLUMNS):
            column = seg.data.accel[:, k] if k < 3 else seg.data.gyro[:, k - 3]
            spread = float(np.std(column))
            if _finer_than(column, 2.0 * spread):
                continue
            values = distinct(column)
            step = float(np.min(np.diff(values))) if len(values) > 1 else math.inf
            if len(values) == 1 and _at_declared_rail(capture, k, float(values[0])):
                continue        # at the manifest's full scale: the data-fault scan leaves it out and says so
            if spread < 0.5 * step:
                what = ("the same value in every sample: a dead axis, or one at its rail throughout" if len(values) == 1
                        else f"output step {step:.3g}, sample spread {spread:.3g}")
                raise UserError(f"{capture.path / seg.file}: column '{name}': quantised coarser than its "
                                f"noise ({what}, in {capture.imu.accel_unit if k < 3 else capture.imu.gyro_unit}): "
                                "the averages would be set by the rounding; record with a finer output "
                                "resolution (or floating-point output)")


def _at_declared_rail(capture: Capture, k: int, value: float) -> bool:
    """``value`` of column k (accel x, y, z, gyro x, y, z) is at the manifest's declared full
    scale (imu.accel_full_scale / imu.gyro_full_scale, station/estimate/data_faults.py)."""
    from station.estimate.data_faults import declared_full_scale

    fs = declared_full_scale(capture, "accel_full_scale" if k < 3 else "gyro_full_scale", 1.0)
    return fs is not None and abs(value) >= float(fs[k % 3]) * (1.0 - 1e-9)


def _finer_than(column: np.ndarray, step: float) -> bool:
    """True if two distinct values of ``column`` lie closer than ``step``, found among its first
    thousand samples (cheap; False means "not shown so", not "no")."""
    from station.estimate.arrays import distinct

    head = distinct(column[:1000])
    return len(head) > 1 and float(np.min(np.diff(head))) < step


def estimate_with(capture: Capture, method: str = "auto", effects=(), registry=None, *,
                  turn_sigma_deg: float | None = None) -> tuple[Calibration, str]:
    """Estimate from a capture already read; returns the calibration and the method used.

    ``effects``: ids of effects to add to the model (least squares only), created by ``registry``
    (station.model.registry.EffectRegistry: the library, entry points, loaded plugins).
    ``turn_sigma_deg``: the hand turns' stated 1-sigma per turn, degrees (None: estimated from
    their scatter; station/estimate/noise_model.py).
    A fit that breaks down numerically (LinAlgError, overflow) is a UserError naming the capture."""
    from station.core.errors import UserError

    try:
        return _estimate_with(capture, method, effects, registry, turn_sigma_deg)
    except (np.linalg.LinAlgError, OverflowError) as e:
        raise UserError(f"{capture.path / 'manifest.yaml'}: the fit breaks down numerically "
                        f"({type(e).__name__}: {str(e)[:80]}): the capture cannot determine the model "
                        "(too few attitudes or rotations for the effects asked for, or values out of "
                        "range)") from None


def _estimate_with(capture: Capture, method: str, effects, registry, turn_sigma_deg=None) -> tuple[Calibration, str]:
    from station.core.errors import UserError
    from station.model.registry import EffectRegistry

    if method not in METHODS:
        raise UserError(f"unknown estimation method {method!r}: use one of {', '.join(METHODS)}")
    if method == "auto":
        method = choose_method(capture)
    registry = registry if registry is not None else EffectRegistry()
    instances = [registry.create(e) for e in effects]
    if effects and method != "lsq":
        raise UserError(f"--add needs the least-squares method (lsq); this capture uses {method}")
    if method == "lsq":
        from station.estimate import poses, profile

        pending = [e for e in instances if profile.is_profiled(e) and getattr(e, "step_time_s", 0.0) is None]
        if pending:     # a bias step's time: located at the fit without it (station/estimate/profile.py)
            from station.estimate import lsq

            s = lsq.summarise(capture)
            base = lsq.fit(s, [e for e in instances if e not in pending])
            for e in pending:
                profile.locate(base, e)

        # the joint fit, checked against the poses' own accelerometer fit (station/estimate/poses.py)
        return poses.estimate(capture, instances, turn_sigma_deg=turn_sigma_deg), method
    if method == "zhang2010":
        from station.estimate import zhang2010

        return zhang2010.estimate(capture), method
    from station.estimate import fourier

    return fourier.estimate(capture, "high" if method == "fourier-high" else "low"), method


# what the fit needs once the capture is summarised: ~7 ms of imports since the fit imports no scipy
# (issue 27), less than a forked reader costs (below): estimate_capture reads in its own process
FIT_MODULES = ("station.estimate.lsq", "station.estimate.verdict", "station.io.calfile")
READ_IN_PROCESS = "STATION_READ_IN_PROCESS"     # set (to anything): no forked reader
# estimate_capture reads in its own process, its files from right after the manifest on reading
# threads (Capture.read_ahead); True: in a forked reader instead (diagnose's way), no early reader
ESTIMATE_FORKS = False


def summarise_while_importing(capture, check_segment=None, notes: dict | None = None,
                              modules=FIT_MODULES, then=None, meanwhile=None, fork: bool = True):
    """summarise(capture, check_segment=...) and import ``modules``; then ``then()`` where the
    capture was read (what check_segment kept of the samples is there), and its value returned.
    ``meanwhile()`` is called here once the reading has begun (after the fork: whatever threads
    it starts are not in the child).
    On Linux the capture is read and summarised in a forked child (station.core.forked) while
    this process imports: the child sends back what reading made (the summaries, kept with the
    capture; the segments, with their status, sha256, problem and the hand turns' samples; the
    warnings; the notes; what ``then`` returned), or the error it raised, raised here.
    Elsewhere, with $STATION_READ_IN_PROCESS set, with ``fork`` False (what is imported meanwhile
    costs less than the child: the pages it copies from this process as it touches them, its
    result pickled, its exit), for a small capture without ``then``
    (station.io.capture.is_small), or when no child can be forked or it is lost, here, one after
    the other."""
    import importlib
    import os

    from station.estimate import summaries

    notes = {} if notes is None else notes

    def read():
        summaries.summarise(capture, check_segment=check_segment)
        return (summaries.kept(capture), capture.segments, capture.warnings, notes,
                then() if then is not None else None)

    from station.io.capture import is_small

    child = None
    # a small capture is read here when nothing else is to be computed with it: its rows take
    # milliseconds, less than forking this process (imucal's session in one process: 0.95 x the
    # CPU, 0.87 x the wall time; issue 27)
    small = then is None and is_small(capture)
    if fork and not os.environ.get(READ_IN_PROCESS) and not small:
        from station.core import forked

        if forked.available():
            # no reading thread of this process at the fork (the child would wait for ever for
            # the reads of threads it does not have): an early reader (Capture.read_ahead) is
            # closed, the child reads every file itself
            capture.stop_reading_ahead()
            try:
                child = forked.Forked(read)     # it imports the CSV engine (pyarrow): this one never needs it
            except OSError:                     # no process to be had (EAGAIN, ENOMEM): read here
                child = None
    try:
        if meanwhile is not None:
            meanwhile()
        for name in modules:
            importlib.import_module(name)
        if child is not None:
            try:
                parts, capture.segments, capture.warnings, child_notes, value = child.result()
            except forked.ChildLost:
                pass                    # read here instead
            else:
                notes.update(child_notes)
                summaries.keep(capture, parts)
                return value
    finally:
        if child is not None:
            child.close()
    summaries.summarise(capture, check_segment=check_segment)
    return then() if then is not None else None


def estimate_capture(path, method: str = "auto", effects=(), registry=None, *,
                     max_missing_fraction: float = MAX_MISSING_FRACTION,
                     max_gap_s: float = MAX_GAP_S, turn_sigma_deg: float | None = None
                     ) -> tuple[Calibration, Capture, dict]:
    """Read a capture, estimate, judge the fit (station.estimate.verdict: verdict, honest 1-sigma,
    parameters not determined) and return the calibration, the capture and its provenance."""
    capture = read_capture(path, load_data=False)
    resolved = method
    if method == "auto":
        resolved = choose_method(capture)
    if resolved == "lsq":
        # one pass: each segment file read, hashed, parsed, checked, summarised and freed in turn
        # (station.estimate.summaries keeps the summaries with the capture for lsq.estimate)
        notes = {}

        def check_segment(seg):
            if seg.kind == "static":
                check_static_resolution(capture, seg)
            note = _exclude_if_lossy(seg, capture.imu.sample_rate_hz, max_missing_fraction, max_gap_s)
            if note:
                notes[seg.name] = note

        # in this process: the fit's modules (~7 ms) are too little to overlap with a forked reader,
        # which cost more (the 100 Hz optimal9 capture: 0.95 x the CPU read here, interleaved pairs;
        # docs/performance.md, the fifteenth session); the files are read from here on, on reading
        # threads, while the summaries' modules are imported (issue 27, seventeenth session)
        from station.io.capture import is_small

        try:
            if not ESTIMATE_FORKS and not is_small(capture):
                capture.read_ahead(capture.summary_order(every=True))
            summarise_while_importing(capture, check_segment, notes, fork=ESTIMATE_FORKS)
        except KeyboardInterrupt:
            capture.stop_reading_ahead(wait=False)      # at once: not after the files being read
            raise
        finally:
            capture.stop_reading_ahead()
        excluded = [notes[seg.name] for seg in capture.segments if seg.name in notes]
    else:
        capture.load_samples()
        check_resolution(capture)
        excluded = exclude_lossy_segments(capture, max_missing_fraction, max_gap_s)
        from station.estimate import data_faults

        # found and said, not left out: these methods read every sample themselves
        fault_report = data_faults.scan_capture(capture)
    cal, method = estimate_with(capture, resolved, effects, registry, turn_sigma_deg=turn_sigma_deg)
    from station.estimate.verdict import judge

    cal.fit.setdefault("notes", []).extend(excluded)
    if excluded:
        cal.fit["excluded_segments"] = [n.split()[1] for n in excluded]
    if resolved == "lsq":
        from station.estimate import summaries

        # what the data-fault scan found and left out (station/estimate/data_faults.py): its words
        # are among the notes already (the summaries' skipped)
        parts = summaries.kept(capture)
        report = getattr(parts, "data_faults", None) if parts is not None else None
        if report is not None:
            cal.fit["data_faults"] = report
    else:
        cal.fit["data_faults"] = fault_report
        cal.fit["notes"].extend(data_faults.notes_of(fault_report))
    judge(cal)
    firmware = capture.imu.extra.get("firmware")
    lot = capture.imu.extra.get("lot")
    provenance = {
        "capture": str(Path(capture.path).resolve()),
        "capture_sha256": capture_digest(capture),
        "method": method,
        "imu_model": capture.imu.model,
        "imu_serial": capture.imu.serial,
        "imu_firmware": firmware if isinstance(firmware, str) else None,
        "imu_lot": str(lot) if isinstance(lot, (str, int)) and not isinstance(lot, bool) else None,
        "scheme": capture.scheme,
    }
    return cal, capture, provenance
