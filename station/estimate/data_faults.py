"""Data faults found before the fit: samples at a rail, stuck samples, a temperature that changes.

Each complete segment's samples are scanned per sensor axis before they are summarised
(station.estimate.summaries calls ``Scanner.scan`` with each segment's samples, in the
capture's units converted to m/s^2 and deg/s):

* **At a rail** (saturated, clipped).  An output that saturates sits at one extreme value, its
  rail, for as long as the input stays beyond it: a flat top.  Found by its shape: the number
  of samples at the axis' extreme value in the segment (its top or bottom), against the number
  at the next value inside.  Without a rail the extreme is in the tail of the noise and holds no
  more samples than the level next to it (a Gaussian tail falls level by level; a noiseless
  sinusoid quantised to levels puts at most 1 + sqrt 2 = 2.41 times as many samples in its top
  level as in the next, the arcsine law of its values), so more than RAIL_RATIO times the next
  level's count (+1), beyond a Poisson tail of RAIL_ALPHA, is a rail.  With a declared full scale
  (the manifest's ``imu.accel_full_scale`` / ``imu.gyro_full_scale``, +- in the capture's units,
  one number or one per axis) every sample at it is at the rail as well.
* **Stuck** (the output stops updating and repeats its last value).  A run of identical
  consecutive values is compared with what the axis' own noise and output step make likely: for
  independent samples the chance that a run of L equal values starts at a given sample is at most
  p^(L-1), p the largest probability of one output level (for noise sigma and step q,
  erf(q / (2 sqrt 2 sigma)), the level centred on the mean), taken no smaller than the segment's
  own share of repeated samples and of its commonest value (a sensor whose noise is below its
  step, or a logger that writes every frame twice, repeats legitimately).  A run longer than
  1 + log(STUCK_ALPHA / N) / log p (N the segment's samples) is stuck; for a whole sensor (all
  three axes repeating at once) p is the product over the axes, or the segment's own share of
  repeated frames if that is larger.

What is done (each sample left out is counted and said):

* a static segment with samples at a rail is left out whole (the samples left below the rail
  are a truncated sample of the noise: their mean is biased);
* a rotation whose accelerometer reaches a rail keeps its gyro samples and its accelerometer
  harmonics are fitted without the phases of the turn near the rail (the same phases of every
  revolution, chosen from where the rail was reached plus a margin in which the signal is
  within RAIL_GUARD_SIGMA noise sigma of it: a choice made by phase, not by each sample's value,
  leaves the rest unbiased); a rotation whose gyro reaches a rail is left out (its integral is
  not the turn's);
* stuck samples are left out: a static's and a gyro's as lost frames (a rotation that loses more
  than MAX_STUCK_FRACTION of its samples so is left out, like a segment that lost frames),
  an accelerometer's from the rotation's harmonics;
* a hand turn (no encoder) with any of them is left out.

The temperature column, when there is one, is followed over the capture: its range and its
fastest rate.  A change of TEMPERATURE_TESTABLE_C or more is said with the effects that follow
temperature (station.model.LIBRARY's effects that need it): a MEMS scale factor's typical
100 ppm/degC moves it by 100 ppm per degC, about a typical capture's 1-sigma of a MEMS scale, and
a bias's typical 0.1 mg/degC by ten times a static mean's 1-sigma: below 1 degC no library effect
that follows temperature could be told from the noise of a typical capture.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from station.estimate.arrays import median

RAIL_RATIO = 2.5            # > 1 + sqrt 2: a quantised noiseless sinusoid's top level over the next
RAIL_ALPHA = 1e-6           # Poisson tail of a rail by chance, per axis, side and segment
RAIL_GUARD_SIGMA = 8.0      # a rotation's phases within this many noise sigma of a rail are left out
STUCK_ALPHA = 1e-6          # chance of a run this long, per axis (or sensor) and segment
MIN_STUCK_RUN = 4           # shorter runs are never called stuck, whatever the statistics say
MAX_STUCK_FRACTION = 0.01   # a rotation's gyro may lose this share of its samples (as lost frames)
MIN_HARMONIC_SHARE = 0.25   # a rotation keeps at least this share of its accelerometer samples
MAX_LEVELS = 1 << 22        # a static's commonest value is counted on a grid of at most this many levels
TEMPERATURE_TESTABLE_C = 1.0
AXES = "xyz"
SENSORS = (("accelerometer", "accel"), ("gyro", "gyro"))


@dataclass
class Finding:
    """One fault on one sensor axis (or a whole sensor: axis None), summed over the segments."""
    kind: str                   # "rail" | "stuck"
    sensor: str                 # "accelerometer" | "gyro"
    axis: int | None            # 0..2, None: every axis of the sensor at once (frozen frames)
    unit: str
    value: float | None = None  # the rail, in unit
    side: str = ""              # "above" | "below" (rails)
    samples: int = 0            # samples at the rail / in stuck runs
    runs: int = 0
    longest: int = 0            # longest run, samples
    threshold: int = 0          # shortest run called stuck (the largest over the segments)
    segments: list = field(default_factory=list)

    def as_dict(self) -> dict:
        out = {"kind": self.kind, "sensor": self.sensor, "axis": None if self.axis is None else AXES[self.axis],
               "unit": self.unit, "samples": int(self.samples), "segments": list(self.segments)}
        if self.kind == "rail":
            out.update(value=float(self.value), side=self.side)
        else:
            out.update(runs=int(self.runs), longest_run=int(self.longest), shortest_run_called_stuck=int(self.threshold))
            if self.value is not None:
                out["value_of_longest_run"] = float(self.value)
        return out


class TooLittleLeft(Exception):
    """A rotation whose accelerometer harmonics would keep too little of the turn: left out."""


@dataclass
class Verdict:
    """What to do with one segment's samples."""
    drop: str | None = None                 # the reason the segment is left out
    rows: np.ndarray | None = None          # (N,) bool, rows kept (None: all)
    accel_stuck: np.ndarray | None = None   # (N,) bool, accelerometer rows left out of harmonics
    accel_rail: dict | None = None          # accelerometer axis -> (N,) bool, its samples at a rail
    accel_sigma: np.ndarray | None = None   # (3,) accelerometer noise sigma (the statics')

    @property
    def masks(self) -> bool:
        """Some accelerometer samples are to be left out of a rotation's harmonics."""
        return self.accel_stuck is not None or self.accel_rail is not None

    def accel_keep(self, phase: np.ndarray, accel: np.ndarray) -> np.ndarray | None:
        """(N,) bool: the rotation's samples its accelerometer harmonics use (None: all), given
        each sample's phase of the turn (rad) and the accelerometer samples.  Stuck samples are
        left out; for an axis at a rail, every sample whose phase (modulo a revolution) lies
        within the band of phases where the rail was reached, widened to where the signal comes
        within RAIL_GUARD_SIGMA noise sigma of the rail, is left out: the same phases of every
        revolution, whatever each sample's value."""
        keep = None if self.accel_stuck is None else ~self.accel_stuck
        if not self.accel_rail:
            return keep
        keep = np.ones(len(phase), bool) if keep is None else keep
        psi = np.mod(phase, 2.0 * np.pi)
        bins = PHASE_BINS
        width = 2.0 * np.pi / bins
        index = np.minimum((psi / width).astype(int), bins - 1)
        for k, at in self.accel_rail.items():
            if not at.any():
                continue
            column = accel[:, k]
            amplitude = max(0.5 * float(np.max(column) - np.min(column)), 1e-300)
            sigma = 0.0 if self.accel_sigma is None else float(self.accel_sigma[k])
            marked = np.bincount(index[at], minlength=bins) > 0
            for centre, half in _bands(marked, width):
                guard = math.sqrt(half * half + 2.0 * RAIL_GUARD_SIGMA * sigma / amplitude) + width
                distance = np.abs(np.mod(psi - centre + np.pi, 2.0 * np.pi) - np.pi)
                keep &= distance > guard
        if keep.sum() < MIN_HARMONIC_SHARE * len(keep):
            raise TooLittleLeft(f"rotation left out: its accelerometer harmonics would keep {int(keep.sum())} of "
                                f"{len(keep)} samples away from the rail (less than {100 * MIN_HARMONIC_SHARE:g} %)")
        return keep


PHASE_BINS = 720            # a turn's phases are grouped in half degrees to find the rail's bands


def _bands(marked: np.ndarray, width: float):
    """(centre, half-width) in rad of the circular runs of marked phase bins (gaps of up to two
    bins closed)."""
    if marked.all():
        return [(math.pi, math.pi)]
    m = marked.copy()
    for gap in (1, 2):                  # close small gaps (a noisy edge)
        for shift in range(1, gap + 1):
            m |= np.roll(marked, shift) & np.roll(marked, -(gap + 1 - shift))
    start = int(np.flatnonzero(~m)[0])      # rotate so that the sequence starts outside a band
    r = np.roll(m, -start)
    starts, lengths = _true_runs(r)
    out = []
    for a, L in zip(starts, lengths):
        lo = (a + start) * width
        out.append((lo + 0.5 * L * width, 0.5 * L * width))
    return out


def _true_runs(flags: np.ndarray):
    """(start, length) of the runs of True in ``flags``."""
    f = np.concatenate([[False], flags, [False]]).astype(np.int8)
    d = np.diff(f)
    starts = np.flatnonzero(d == 1)
    return starts, np.flatnonzero(d == -1) - starts


def _runs(equal: np.ndarray):
    """(start, length) of the runs of identical values, from ``equal`` (N-1,) (sample i+1 equals
    sample i); length counts samples (a run of L values has L-1 equal steps)."""
    if not len(equal):
        return np.zeros(0, int), np.zeros(0, int)
    e = np.zeros(len(equal) + 2, np.int8)
    e[1:-1] = equal
    d = np.diff(e)
    starts = np.flatnonzero(d == 1)
    ends = np.flatnonzero(d == -1)
    return starts, ends - starts + 1


def _share_outside_longest(equal: np.ndarray, runs=None, repeats: int | None = None) -> float:
    """The share of samples repeating the previous one, the longest run of repeats left out (a
    fault's own repeats do not make it look like chance).  ``runs``: _runs(equal) and
    ``repeats``: the count of True in ``equal``, when known."""
    if not len(equal):
        return 0.0
    _, lengths = _runs(equal) if runs is None else runs
    longest = int(lengths.max()) - 1 if len(lengths) else 0
    repeats = int(np.count_nonzero(equal)) if repeats is None else repeats
    return float(repeats - longest) / max(len(equal) - longest, 1)


def _mode_share(column: np.ndarray, step: float, bounds=None) -> float:
    """The share of the samples at the commonest value (0 when the values are not on a grid of
    ``step`` with fewer than MAX_LEVELS levels: continuous outputs, which do not repeat).
    ``bounds``: the column's (min, max), when known."""
    if step <= 0.0:
        return 0.0
    lo, hi = (float(column.min()), float(column.max())) if bounds is None else bounds
    levels = (hi - lo) / step
    if not levels < MAX_LEVELS:
        return 0.0
    index = np.rint((column - lo) / step).astype(np.int64)
    if levels > 8 * len(column):
        # far more levels than samples (floating-point output on a fine grid: up to 1.5 M levels
        # for 10,000 samples): the longest run of the sorted levels, not a count of every level
        # (bincount's array of up to 32 MB, most of a 100 Hz estimate's scan: 60 ms of 21
        # segments), the same count
        index.sort()
        edges = np.flatnonzero(index[1:] != index[:-1])
        runs = np.diff(edges, prepend=-1, append=len(index) - 1)
        return float(runs.max()) / len(column)
    return float(np.bincount(index).max()) / len(column)


def _next_count(column: np.ndarray, at: np.ndarray, top: bool) -> int:
    """The count of samples at the next value inside the extreme (``at``: the samples at the
    extreme; 0 when there is none) (O(N))."""
    inside = column[~at]
    if not len(inside):
        return 0
    nxt = inside.max() if top else inside.min()
    return int(np.count_nonzero(inside == nxt))


def _level_probability(sigma: float, step: float) -> float:
    """The largest probability of one output level for Gaussian noise ``sigma`` and output step
    ``step`` (the level centred on the mean)."""
    if step <= 0.0:
        return 0.0
    if sigma <= 0.0:
        return 1.0
    return math.erf(step / (2.0 * math.sqrt(2.0) * sigma))


def _longest_chance_run(p: float, n: int) -> int:
    """The shortest run called stuck: runs of that length have a chance below STUCK_ALPHA in
    ``n`` samples with level probability ``p``."""
    if p <= 0.0:
        return MIN_STUCK_RUN
    if p >= 1.0:
        return n + 1                        # nothing can be told from a sensor that never moves
    return max(MIN_STUCK_RUN, int(math.ceil(1.0 + math.log(STUCK_ALPHA / max(n, 1)) / math.log(p))))


def _poisson_tail_bound(k: int, lam: float) -> float:
    """Chernoff bound on P(Poisson(lam) >= k) (1 for k <= lam)."""
    if k <= lam:
        return 1.0
    return math.exp(-lam + k * (1.0 + math.log(lam / k)))


class _Column:
    """One axis' samples in one segment and what the scan takes from their first differences:
    which samples repeat the previous one (and how many), the output step (from above: the
    smallest change between consecutive samples, 0 when the column never changes; at least the
    true step, so the level probability it gives is not understated) and the white noise (their
    spread over sqrt 2: drifts do not enter).  One pass, no sort of a long segment.  What the
    rail and stuck tests ask of it more than once (its extremes, its runs of repeats) is computed
    once, when first asked (issue 27: the scan was a third of a 100 Hz estimate's summaries)."""

    def __init__(self, column):
        self.values = np.ascontiguousarray(column)
        d = np.diff(self.values)
        n = len(d)
        self.equal = d == 0
        self.repeats = int(np.count_nonzero(self.equal))
        if self.repeats < n:
            # the smallest |change| over the changes: the repeats set to infinity, not removed
            # (the same minimum, without a boolean selection's copy; a NaN stays a NaN)
            change = np.abs(d)
            change[self.equal] = np.inf
            self.step = float(change.min())
        else:
            self.step = 0.0
        # np.mean's own arithmetic (the pairwise sum, then over the count), without its Python layer
        self.sigma = (float(np.sqrt((d * d).sum(dtype=np.float64) / n - (d.sum(dtype=np.float64) / n) ** 2)
                            / math.sqrt(2.0)) if n else 0.0)
        self._bounds = None
        self._runs = None

    def bounds(self) -> tuple[float, float]:
        """(min, max) of the samples."""
        if self._bounds is None:
            self._bounds = (float(self.values.min()), float(self.values.max()))
        return self._bounds

    def runs(self):
        """_runs(self.equal): (start, length) of the runs of identical values."""
        if self._runs is None:
            # none (a floating-point output's usual case): no pass over the column
            self._runs = _runs(self.equal) if self.repeats else (np.zeros(0, int), np.zeros(0, int))
        return self._runs


def rail_mask(column: np.ndarray, full_scale: float | None = None, stats: "_Column | None" = None):
    """(mask of samples at a rail, [(side, value, count)]) of one axis' samples in one segment."""
    n = len(column)
    mask = np.zeros(n, bool)
    rails = []
    if n < 8:
        return mask, rails
    # one value throughout (to floating-point rounding: a noise-free simulation's axis along the
    # turn's axis varies in its 15th digit): a dead or stuck axis, not a rail, unless
    lo, hi = stats.bounds() if stats is not None else (float(column.min()), float(column.max()))
    constant = hi - lo <= 1e-12 * max(1.0, abs(hi), abs(lo))
    step = (stats.step if stats is not None else _Column(column).step) if full_scale else 0.0   # declared
    for side, top in (("above", True), ("below", False)):
        value = hi if top else lo
        at = column == value
        count = int(np.count_nonzero(at))
        declared = (full_scale is not None and full_scale > 0
                    and abs(value) >= full_scale - max(step, 1e-9 * full_scale)
                    and (value > 0) == (side == "above"))
        # the next level's count only where it can decide (3 or more at the extreme: a
        # floating-point output's extreme is one sample)
        shaped = (not constant and count >= 3
                  and _poisson_tail_bound(count, RAIL_RATIO * (_next_count(column, at, top) + 1)) < RAIL_ALPHA)
        if declared or shaped:
            mask |= at
            rails.append((side, value, count))
    return mask, rails


def declared_full_scale(capture, key: str, factor: float) -> np.ndarray | None:
    """The manifest's imu.<key> (+- full scale, one number or one per axis, in the capture's
    units) times ``factor``, (3,); None when absent or not three positive finite numbers."""
    value = capture.imu.extra.get(key)
    if value is None or isinstance(value, (bool, str)):
        return None
    try:
        fs = np.broadcast_to(np.asarray(value, float), (3,)) * factor
    except (TypeError, ValueError):
        return None
    if not np.all(np.isfinite(fs)) or np.any(fs <= 0):
        return None
    return fs


class Scanner:
    """Scans a capture's segments one at a time (statics first) and keeps what it found."""

    def __init__(self, capture, accel_factor: float, gyro_factor: float):
        from station.core import units

        # a noise-free simulated capture (a prediction's: station/design, montecarlo.cramer_rao says
        # so in its extra): nothing to find, and its turns would be taken for rails -- a noise-free
        # turn repeats its extreme value once a revolution, the flat top the rail test looks for
        # (sizeeffect's 200 deg/s turns lost their cross-axis gyro to it, and with them the turn)
        self.noise_free = bool(getattr(capture, "extra", {}).get("noise_free"))
        # a temperature chamber's cross-checks that disagreed (station.core.chamber.finding: the
        # IMU's temperature against the setpoint), written into the capture by the run: said again
        self.chamber_findings = [{"segment": seg.name, "finding": str(seg.extra["chamber"]["finding"])}
                                 for seg in getattr(capture, "segments", [])
                                 if isinstance(getattr(seg, "extra", {}).get("chamber"), dict)
                                 and seg.extra["chamber"].get("finding")]
        self.units = ("m/s^2" if units.accel_to_mps2_factor(capture.imu.accel_unit) else capture.imu.accel_unit,
                      "deg/s" if units.gyro_to_dps_factor(capture.imu.gyro_unit) else capture.imu.gyro_unit)
        self.factors = (accel_factor, gyro_factor)
        self.full_scale = tuple(declared_full_scale(capture, key, factor)
                                for key, factor in (("accel_full_scale", accel_factor), ("gyro_full_scale", gyro_factor)))
        self.static_sigma = [[], []]        # per sensor: (3,) noise sigma of each static scanned
        self.static_p = [[], []]            # per sensor: ((3,) level probability, (3,) step) per static
        # their medians and maxima kept as the statics come (computed over every static scanned at
        # every segment, they made the scan quadratic in the statics: 3,600 segments 38 s of 127)
        self._sigma_median = [_RunningMedian(3), _RunningMedian(3)]
        self._reference = [None, None]      # per sensor: (len(static_p), max p, steps' median, min)
        self.findings: dict = {}
        self.left_out: list = []            # {"segment", "reason"}
        self.harmonics_left_out: list = []  # {"segment", "samples", "of"}
        self.rows_left_out: dict = {}       # segment -> rows removed (stuck)
        self.samples = 0
        self.segments = 0
        self.temp = {"min": math.inf, "max": -math.inf, "rate": 0.0, "t0": math.inf, "t1": -math.inf,
                     "segments": 0}

    # ------------------------------------------------------------------ the scan

    def scan(self, seg, t, accel, gyro, temp) -> Verdict:
        """The verdict on one segment's samples (accel, gyro in m/s^2, deg/s or raw)."""
        n = len(t)
        self.samples += n
        self.segments += 1
        self._temperature(t, temp)
        verdict = Verdict()
        if n < 8 or self.noise_free:
            return verdict
        static = seg.kind == "static"
        encoder = seg.kind == "rotation" and seg.angle_deg is not None and seg.extra.get("motion") != "hand"
        rail = [np.zeros(n, bool), np.zeros(n, bool)]
        stuck = [np.zeros(n, bool), np.zeros(n, bool)]
        rail_words, stuck_words = [], []
        rail_axes = {}
        accel_columns = None
        for s, (sensor, _) in enumerate(SENSORS):
            data = accel if s == 0 else gyro
            fs = self.full_scale[s]
            columns = [_Column(data[:, k]) for k in range(3)]
            if s == 0:
                accel_columns = columns
            for k, c in enumerate(columns):
                mask, rails = rail_mask(c.values, None if fs is None else float(fs[k]), c)
                if rails:
                    rail[s] |= mask
                    if s == 0:
                        rail_axes[k] = mask
                for side, value, count in rails:
                    f = self._finding("rail", sensor, k, value=value, side=side)
                    f.samples += count
                    f.segments.append(seg.name)
                    rail_words.append(f"{AXES[k]} {sensor} at its rail {value:.4g} {self.units[s]} in {count} "
                                      f"of {n} samples")
            if static:
                self.static_sigma[s].append(np.array([c.sigma for c in columns]))
                self._sigma_median[s].add(self.static_sigma[s][-1])
            stuck[s] = self._stuck(seg, s, columns, static, rail[s])
            if stuck[s].any():
                stuck_words.append(f"{sensor} stuck in {int(stuck[s].sum())} samples")
        if static:
            if rail[0].any() or rail[1].any():
                verdict.drop = ("static left out: " + "; ".join(rail_words)
                                + " (the samples below a rail are a truncated sample: their mean is biased)")
            else:
                keep = ~(stuck[0] | stuck[1])
                if not keep.all():
                    if keep.sum() < n // 2:
                        verdict.drop = f"static left out: {'; '.join(stuck_words)} of {n} (more than half)"
                    else:
                        verdict.rows = keep
        elif not encoder:
            if rail[0].any() or rail[1].any() or stuck[0].any() or stuck[1].any():
                verdict.drop = ("turn without an encoder left out: " + "; ".join(rail_words + stuck_words)
                                + " (its samples are integrated whole)")
        else:
            if rail[1].any():
                verdict.drop = ("rotation left out: " + "; ".join(w for w in rail_words if " gyro " in w)
                                + " (the gyro integral over the turn is not the turn's)")
            elif stuck[1].sum() > MAX_STUCK_FRACTION * n:
                verdict.drop = (f"rotation left out: gyro stuck in {int(stuck[1].sum())} of {n} samples "
                                f"(more than {100 * MAX_STUCK_FRACTION:g} %, the limit of frames lost)")
            else:
                if stuck[1].any():
                    verdict.rows = ~stuck[1]
                if stuck[0].any():
                    verdict.accel_stuck = stuck[0]
                if rail_axes:
                    verdict.accel_rail = rail_axes
                    verdict.accel_sigma = self._sigma(0, accel_columns)
        if verdict.drop:
            self.left_out.append({"segment": seg.name, "reason": verdict.drop})
        elif verdict.rows is not None:
            self.rows_left_out[seg.name] = int((~verdict.rows).sum())
        return verdict

    def restrict(self, verdict: Verdict, rows: np.ndarray):
        """The verdict's accelerometer masks on the rows kept."""
        if verdict.accel_stuck is not None:
            verdict.accel_stuck = verdict.accel_stuck[rows]
        if verdict.accel_rail is not None:
            verdict.accel_rail = {k: at[rows] for k, at in verdict.accel_rail.items()}

    def _finding(self, kind, sensor, axis, value=None, side=""):
        key = (kind, sensor, axis, side, None if value is None else float(value))
        if key not in self.findings:
            unit = self.units[0 if sensor == "accelerometer" else 1]
            self.findings[key] = Finding(kind, sensor, axis, unit, value, side)
        return self.findings[key]

    def _sigma(self, s, columns) -> np.ndarray:
        """The noise of sensor ``s``: the median over the statics scanned, or this segment's own."""
        if self.static_sigma[s]:
            return self._sigma_median[s].median()      # np.median(static_sigma[s], axis=0)
        return np.array([c.sigma for c in columns])

    def _reference_of(self, s):
        """(max level probability, median step, least step) per axis over the statics scanned,
        made once per count of statics (rotations come after the statics: once in all)."""
        reference = self.static_p[s]
        kept = self._reference[s]
        if kept is None or kept[0] != len(reference):
            p = np.array([r[0] for r in reference])
            steps = np.array([r[1] for r in reference])
            kept = (len(reference), p.max(axis=0), median(steps, axis=0), steps.min(axis=0))
            self._reference[s] = kept
        return kept[1:]

    def _stuck(self, seg, s, columns, static, at_rail) -> np.ndarray:
        """(N,) bool: the samples in runs of identical values longer than chance (rows at a rail
        are not counted: a rail is its own fault)."""
        n = len(columns[0].values)
        sigma = self._sigma(s, columns)
        stuck = np.zeros(n, bool)
        sensor = SENSORS[s][0]
        equal_axes = [c.equal for c in columns]
        reference = self.static_p[s]                # the level probabilities the statics showed
        p_axes, limits = [], []
        for k, c in enumerate(columns):
            step = c.step
            if step == 0.0:
                # one value throughout: stuck only if the statics show this axis moving (a static
                # at one value is the resolution check's; without statics it cannot be told)
                if not static and reference:
                    _, median_step, least_step = self._reference_of(s)
                    step = float(median_step[k]) if least_step[k] > 0.0 else 0.0
                else:
                    step = 0.0
                if step == 0.0:
                    p_axes.append(1.0)
                    limits.append(n + 1)
                    continue
            p = max(_level_probability(float(sigma[k]), step), _share_outside_longest(c.equal, c.runs(), c.repeats))
            if static:
                p = max(p, _mode_share(c.values, c.step, c.bounds()))
            elif reference:
                p = max(p, float(self._reference_of(s)[0][k]))
            p_axes.append(p)
            limits.append(_longest_chance_run(p, n))
        if static:
            self.static_p[s].append((np.array(p_axes), np.array([c.step for c in columns])))
        # frozen frames (all three axes repeating at once) first, then single axes
        joint = equal_axes[0] & equal_axes[1] & equal_axes[2]
        joint_runs = _runs(joint) if all(c.repeats for c in columns) else (np.zeros(0, int), np.zeros(0, int))
        p_joint = max(float(np.prod(p_axes)), _share_outside_longest(joint, joint_runs))
        self._mark(stuck, joint_runs, _longest_chance_run(p_joint, n), at_rail, sensor, None, seg.name)
        for k in range(3):
            self._mark(stuck, columns[k].runs(), limits[k], at_rail, sensor, k, seg.name, columns[k].values)
        return stuck

    def _mark(self, stuck, runs, limit, at_rail, sensor, axis, name, values=None):
        """Mark the runs (``runs``: _runs of the repeats) of ``limit`` samples or more as stuck."""
        starts, lengths = runs
        long = lengths >= limit
        if not long.any():
            return
        runs = 0
        samples = 0
        longest = 0
        for a, L in zip(starts[long], lengths[long]):
            if at_rail[a:a + L].any():
                continue
            if stuck[a:a + L].all():
                continue        # part of frozen frames already counted
            samples += int((~stuck[a:a + L]).sum())
            stuck[a:a + L] = True
            runs += 1
            if L > longest and values is not None:
                value = float(values[a])
            longest = max(longest, int(L))
        if runs:
            f = self._finding("stuck", sensor, axis)
            f.runs += runs
            f.samples += samples
            if longest > f.longest and values is not None:
                f.value = value
            f.longest = max(f.longest, longest)
            f.threshold = max(f.threshold, int(limit))
            if name not in f.segments:
                f.segments.append(name)

    def _temperature(self, t, temp):
        if temp is None or not len(temp):
            return
        tr = self.temp
        tr["min"] = min(tr["min"], float(np.min(temp)))
        tr["max"] = max(tr["max"], float(np.max(temp)))
        tr["t0"], tr["t1"] = min(tr["t0"], float(t[0])), max(tr["t1"], float(t[-1]))
        tr["segments"] += 1
        if len(t) > 2 and np.ptp(t) > 0:
            tc = t - t.mean()
            slope = float(tc @ (temp - temp.mean()) / (tc @ tc))
            tr["rate"] = max(tr["rate"], abs(slope) * 60.0)

    def drop(self, seg_name: str, reason: str) -> None:
        """A segment left out after its scan (a rotation with too little left away from a rail)."""
        self.left_out.append({"segment": seg_name, "reason": reason})

    def harmonics(self, seg_name: str, used: int, of: int) -> None:
        """A rotation's accelerometer harmonics were fitted over ``used`` of ``of`` samples."""
        if used < of:
            self.harmonics_left_out.append({"segment": seg_name, "samples": int(of - used), "of": int(of)})

    # ------------------------------------------------------------------ what is said

    def report(self) -> dict:
        """The findings as plain data (the calibration file's fit.data_faults)."""
        out = {"segments_scanned": self.segments, "samples_scanned": self.samples,
               "faults": [f.as_dict() for f in self.findings.values()],
               "segments_left_out": list(self.left_out),
               "stuck_samples_left_out": dict(self.rows_left_out),
               "harmonics_left_out": list(self.harmonics_left_out)}
        if self.chamber_findings:
            out["chamber_findings"] = list(self.chamber_findings)
        tr = self.temp
        if tr["segments"]:
            out["temperature"] = {"min_c": tr["min"], "max_c": tr["max"], "range_c": tr["max"] - tr["min"],
                                  "max_rate_c_per_min": tr["rate"],
                                  "testable": tr["max"] - tr["min"] >= TEMPERATURE_TESTABLE_C}
        return out

    def notes(self) -> list[str]:
        return notes_of(self.report())


def scan_capture(capture) -> dict:
    """Scan a capture whose samples are loaded, statics first, and report what is found without
    leaving anything out (the methods that read every sample themselves: Fourier, 2010): the
    report's ``left_out`` is False and its words say so."""
    from station.core import units

    ca = units.accel_to_mps2_factor(capture.imu.accel_unit) or 1.0
    cg = units.gyro_to_dps_factor(capture.imu.gyro_unit) or 1.0
    scanner = Scanner(capture, ca, cg)
    order = capture.complete("static") + [seg for seg in capture.complete() if seg.kind != "static"]
    for seg in order:
        d = seg.data
        if d is None or seg.kind not in ("static", "rotation"):
            continue
        scanner.scan(seg, d.t, d.accel * ca, d.gyro * cg, d.temp)
    report = scanner.report()
    report.update(left_out=False, segments_left_out=[], stuck_samples_left_out={}, harmonics_left_out=[])
    return report


def temperature_effects() -> list[str]:
    """The library's effects that follow the temperature column."""
    from station.model import LIBRARY

    return sorted(eid for eid, cls in LIBRARY.items() if "temperature" in getattr(cls, "needs", ()))


def notes_of(report: dict) -> list[str]:
    """The words of a data-fault report (Scanner.report, or scan_capture's: found, not left out)."""
    notes = []
    kept = report.get("left_out", True) is False
    harmonics = {h["segment"]: h for h in report.get("harmonics_left_out", [])}
    dropped = {d["segment"]: d["reason"] for d in report.get("segments_left_out", [])}
    for f in report.get("faults", []):
        what = f"{f['axis']} {f['sensor']}" if f["axis"] else f"{f['sensor']} (all three axes at once)"
        segs = ", ".join(f["segments"][:6]) + (f" and {len(f['segments']) - 6} more" if len(f["segments"]) > 6 else "")
        if kept:
            detail = (f"{f['samples']} samples at the rail" if f["kind"] == "rail"
                      else f"{f['samples']} samples in {f['runs']} runs of identical values")
            side = f" {f['side']} {f['value']:.4g} {f['unit']}" if f["kind"] == "rail" else ""
            notes.append(f"{what} {'saturates' if f['kind'] == 'rail' else 'stuck'}{side}: {detail} ({segs}): "
                         "NOT left out (this method uses every sample; the least-squares method, --method lsq, "
                         "leaves them out)")
            continue
        if f["kind"] == "rail":
            left = sum(harmonics[s]["samples"] for s in set(f["segments"]) if s in harmonics)
            gone = [s for s in dict.fromkeys(f["segments"]) if s in dropped]
            parts = []
            if left:
                parts.append(f"{left} samples left out of the rotations' accelerometer harmonics (the phases "
                             f"of the turn within {RAIL_GUARD_SIGMA:g} sigma of the rail)")
            if gone:
                parts.append(f"segments left out: {', '.join(gone)}")
            notes.append(f"{what} saturates {f['side']} {f['value']:.4g} {f['unit']}: {f['samples']} samples at "
                         f"the rail ({segs}); " + ("; ".join(parts) if parts else "left out"))
        else:
            runs = f"{f['runs']} run{'s' if f['runs'] != 1 else ''}"
            how = ("frozen (all three axes repeat the previous sample)" if f["axis"] is None
                   else "stuck (repeats the previous sample)")
            at = (f", at {f['value_of_longest_run']:.4g} {f['unit']}" if "value_of_longest_run" in f else "")
            notes.append(f"{what.replace(' (all three axes at once)', '')} {how}: {f['samples']} samples in {runs} "
                         f"(longest {f['longest_run']} samples{at}; by chance no run reaches "
                         f"{f['shortest_run_called_stuck']} here) in {segs}: left out")
    for d in report.get("segments_left_out", []):
        notes.append(f"{d['segment']}: {d['reason']}")
    for c in report.get("chamber_findings", []):
        notes.append(f"the temperature chamber before {c['segment']}: {c['finding']} (the run's cross-check; "
                     "the fit uses the IMU's own temperatures)")
    temp = report.get("temperature")
    if temp and temp["testable"]:
        effects = temperature_effects()
        offer = (": effects that follow temperature can be tested: " + ", ".join(f"--add {e}" for e in effects)
                 if effects else "")
        notes.append(f"temperature {temp['min_c']:.1f}–{temp['max_c']:.1f} °C over the capture "
                     f"({temp['range_c']:.1f} °C, at most {temp['max_rate_c_per_min']:.2g} °C/min within a segment)"
                     + offer)
    return notes


class _RunningMedian:
    """np.median(rows, axis=0) of (width,) rows added one at a time, each column's two halves in
    two heaps: O(log n) an addition, O(width) a median (the median of an even count the mean of
    the two middle values, as numpy's)."""

    def __init__(self, width: int):
        self.low = [[] for _ in range(width)]      # max-heaps (negated): the lower half
        self.high = [[] for _ in range(width)]     # min-heaps: the upper half

    def add(self, row) -> None:
        import heapq

        for low, high, v in zip(self.low, self.high, map(float, row)):
            if low and v > -low[0]:
                heapq.heappush(high, v)
            else:
                heapq.heappush(low, -v)
            if len(low) > len(high) + 1:
                heapq.heappush(high, -heapq.heappop(low))
            elif len(high) > len(low):
                heapq.heappush(low, -heapq.heappop(high))

    def median(self) -> np.ndarray:
        out = []
        for low, high in zip(self.low, self.high):
            if len(low) > len(high):
                out.append(-low[0])
            else:
                out.append(float(np.mean([-low[0], high[0]])))
        return np.array(out)
