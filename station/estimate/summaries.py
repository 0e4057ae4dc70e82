"""Segment summaries: what the least-squares fit uses from a capture.

The fit works on a few numbers per segment, weighted by their noise, not on the raw samples:
  static    the mean accelerometer and gyro outputs over the dwell;
  rotation  the accelerometer's mean and first and second harmonics at the rotation frequency,
            over the table angle measured by the encoder, and the gyro integral over the
            segment's window [t0 - dt/2, t_{N-1} + dt/2] (the window of ``angle_deg``).
The noise of every summary comes from the white noise of the static segments (the per-sample
standard deviation, pooled per axis), so no noise figure has to be typed in.
Arrays are in m/s^2 and deg/s after the manifest's unit conversion ("raw" is taken as is).
"""
from __future__ import annotations

import copy
import dataclasses
import weakref
from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np

from station.core import units
from station.core.blas import limited_blas
from station.estimate.arrays import distinct, median
from station.core.errors import UserError
from station.estimate import table_geometry
from station.estimate import data_faults
from station.io.capture import SegmentData

EDGE_SAMPLES = 3
STEADY_SPREAD = 0.3     # a rotation whose rate magnitude varies more (std/mean) is a hand turn


@dataclass
class StaticSummary:
    name: str
    up_body: np.ndarray | None      # commanded, IMU case axes
    accel: np.ndarray               # (3,) mean
    gyro: np.ndarray                # (3,) mean
    samples: int
    duration_s: float
    temp_c: float | None
    t_mid_s: float = float("nan")   # mean sample time (the capture's clock), s
    index: int = -1                 # position of the segment in the capture
    temp_rate_c_per_s: float = 0.0  # temperature slope over the segment, deg C/s
    # the mean of the first half of the samples less that of the second (accel 3, gyro 3): under
    # white noise N(0, sigma^2 (1/n1 + 1/n2)); what exceeds that is the bias moving within the
    # pose (station/estimate/noise_model.py: bias instability over a pose)
    half_diff: np.ndarray | None = None
    lsb: np.ndarray | None = None   # (6,) output step of each column (0: not quantised, see _lsb)


@dataclass
class RotationSummary:
    name: str
    axis_body: np.ndarray           # commanded, unit, IMU case axes
    group: int                      # index of the physical axis (segments about the same axis)
    angle_deg: float                # encoder angle over the window, signed
    duration_s: float               # window length
    samples: int
    accel_dc: np.ndarray            # (3,) mean over the captured angle
    accel_cos: np.ndarray           # (3,) first harmonic: accel ~ dc + cos phi * c + sin phi * s
    accel_sin: np.ndarray           #   + cos 2phi * c2 + sin 2phi * s2
    accel_cos2: np.ndarray          # (3,) second harmonic (nonlinearity, a wobbling axis)
    accel_sin2: np.ndarray
    gyro_integral: np.ndarray       # (3,) integral over the window, deg (SI) or raw*s
    temp_c: float | None
    gyro_start: np.ndarray          # (3,) rate at the window's start and end (mean of the
    gyro_end: np.ndarray            #   first and last EDGE_SAMPLES samples)
    steady: bool = True             # the rate held within STEADY_SPREAD (a table, not a hand)
    table_axis: int | None = None   # the table axis that turned it, as a bench run records it (None: not said)
    rate_sq_factor: float = 1.0     # mean of the squared rate over the square of the mean rate
                                    #   (from the gyro's magnitude: > 1 when the rate ripples)
    t_mid_s: float = float("nan")   # mean sample time (the capture's clock), s
    index: int = -1                 # position of the segment in the capture
    temp_rate_c_per_s: float = 0.0  # temperature slope over the segment, deg C/s
    # The table rate w(t) about the axis (rad/s, signed like the angle), its square and its time
    # derivative, each projected on the same basis as the accelerometer (1, cos phi, sin phi,
    # cos 2phi, sin 2phi): a rate that ripples moves the centripetal and adds a tangential
    # acceleration at the mounting offset.  From the gyro, rescaled to the encoder's mean rate.
    rate_coef: np.ndarray | None = None        # (5,) rad/s
    rate_sq_coef: np.ndarray | None = None     # (5,) rad^2/s^2
    rate_dot_coef: np.ndarray | None = None    # (5,) rad/s^2
    # The basis' Gram matrix over the window divided by the samples (whole revolutions: diag(1,
    # 1/2, 1/2, 1/2, 1/2)); the coefficients' noise covariance is sigma^2 / samples * gram^-1.
    # None: whole revolutions taken.
    gram: np.ndarray | None = None
    # a turn whose recorded window keeps one of the table's ramps (manifest ``record_ramp``: start
    # or end, issue 28 item 3): the table's rate at the window's start and end as the bench
    # reported them (deg/s about axis_body, signed like the angle; None: not said).  gyro_start and
    # gyro_end are then the IMU's own rates at rest and at the steady rate, where the edge means are
    # exact.
    record_ramp: str | None = None
    table_rate_start_dps: float | None = None
    table_rate_end_dps: float | None = None
    # (integral of cos phi dt, integral of sin phi dt) over the window, s, phi the angle turned
    # (tracked by the gyro): what a rate fixed in space across the axis (the Earth's) adds to the
    # gyro integral.  None: T/A (sin A, 1 - cos A), a uniform turn's (every steady segment's)
    earth_weights_s: np.ndarray | None = None
    # the rate's shape (rate_coef ...) at the table's stated steady rate (a recorded ramp: its
    # phase's scale, _ramp_fraction), not at the encoder's mean rate over the window: a window
    # shifted by a time offset does not change it (lsq.Model._rate_shape_factor: 1)
    rate_from_table: bool = False
    # a recorded ramp's (rate_from_table) w^2 and dw/dt times 1, cos phi, sin phi, cos 2phi, sin 2phi,
    # each projected on the basis as the accelerometer ((2, 5, 5): [w^2, dw/dt] x multiplier x
    # harmonic; [:, 0] are rate_sq_coef and rate_dot_coef): the harmonics of a term w^2(t) cos phi(t)
    # are not the product of w^2's with cos phi where w^2 takes several values at one angle (a rest
    # and a ramp before the steady turns; station.model.table_vibration's (5), issue 28,
    # twenty-first session).  None: a steady turn
    ramp_coef: np.ndarray | None = None
    # the 1-sigma of this window's angle beyond the encoder's (deg): a recorded ramp's angle is
    # the table's reads placed on the IMU's clock (manifest ``angle_sigma_deg``, issue 28 review
    # item 1); added in quadrature to the encoder's in the gyro integral's variance.  0: none said
    angle_sigma_deg: float = 0.0
    # (4, 5) a recorded ramp's least-squares harmonics (as accel_dc ... over the same samples) of
    # theta cos theta, theta sin theta, theta^2 cos theta, theta^2 sin theta, theta the phase (rad):
    # what gravity turned further by e theta leaves in them (table_encoder_scale; issue 28,
    # twenty-first session).  None: a uniform turn's (table_encoder_scale.arc_moments)
    turned_moments: np.ndarray | None = None

    @property
    def rate_dps(self) -> float:
        return self.angle_deg / self.duration_s


@dataclass
class Summaries:
    gravity_mps2: float
    latitude_deg: float | None
    accel_factor: float             # m/s^2 per raw unit (1 for raw)
    gyro_factor: float              # deg/s per raw unit (1 for raw)
    sample_rate_hz: float
    statics: list
    rotations: list
    accel_sigma: np.ndarray         # (3,) per-sample white noise, m/s^2
    gyro_sigma: np.ndarray          # (3,) per-sample white noise, deg/s
    table_angle_sigma_deg: float    # 1-sigma of one encoder angle
    mounting_offset_m: np.ndarray | None   # IMU reference point from the table's rotation centre, if known
    skipped: list = field(default_factory=list)
    hand_rotations: list = field(default_factory=list)   # hand_rotation.HandRotation: turns of unknown
                                                         #   angle between statics (no encoder)
    gyro_nominal: float | None = None   # raw gyro: nominal counts per deg/s from the manifest, if any
    gyro_raw: bool = False
    accel_raw: bool = False
    accel_nominal: float | None = None  # raw accelerometer: nominal counts per m/s^2 from the manifest, if any
    stamp_jitter_s: float = 0.0     # 1-sigma jitter of the time stamps (robust spread of the sample
                                    #   intervals over sqrt 2, median over the segments), s
    # (statics, noise_model.NoiseModel) computed from them (station/estimate/noise_model.of)
    noise_model: object = field(default=None, repr=False, compare=False)
    geometry: object = None         # table_geometry.TableGeometry: which rotations share a mounting
                                    #   offset, the axes' elevation (None: not stated, as before)
    data_faults: dict | None = None     # station.estimate.data_faults: what was found and left out
    data_fault_notes: list = field(default_factory=list)   # the same in words (also in skipped)

    @property
    def groups(self) -> int:
        return 1 + max((r.group for r in self.rotations), default=-1)


def _slope(t, y) -> float:
    """Least-squares slope of y over t (0 without y or with fewer than 2 samples)."""
    if y is None or len(t) < 2 or np.ptp(t) == 0:
        return 0.0
    tc = t - t.mean()
    return float(tc @ (y - y.mean()) / (tc @ tc))


JITTER_INTERVALS = 1 << 17  # the stamp jitter is read from at most this many intervals per segment


def _stamp_jitter(t) -> float:
    """1-sigma jitter of a segment's time stamps: the robust spread (1.4826 MAD, blind to a few
    lost samples) of the intervals between them, over sqrt 2 (an interval is the difference of two
    independently jittered stamps).  A long segment's intervals are taken evenly spaced,
    JITTER_INTERVALS of them (the spread to 0.3 %; the medians of millions cost more than the
    segment's summary)."""
    dt = np.diff(np.asarray(t, float))
    if len(dt) > JITTER_INTERVALS:
        dt = dt[::len(dt) // JITTER_INTERVALS]
    return float(1.4826 * median(np.abs(dt - median(dt))) / np.sqrt(2.0))


def _window(t: np.ndarray) -> tuple[float, float]:
    dt_first, dt_last = t[1] - t[0], t[-1] - t[-2]
    return t[0] - 0.5 * dt_first, t[-1] + 0.5 * dt_last


CHUNK_SAMPLES = 1 << 15     # the per-sample work of a rotation summary is done this many samples at a time


def _chunks(n):
    """(start, stop) of the consecutive chunks of CHUNK_SAMPLES samples covering n samples."""
    return [(i, min(i + CHUNK_SAMPLES, n)) for i in range(0, n, CHUNK_SAMPLES)]


def _turned_fraction(t, gyro, start, duration, gyro_mean) -> np.ndarray:
    """Fraction of the segment's turn reached at each sample, from the gyro's own integral about
    its mean rate direction (scale errors cancel in the ratio; a rate that ripples or drifts is
    followed, where a uniform rate would smear the harmonics).  Computed chunk by chunk into the
    one array it returns (the running sum carried from chunk to chunk: the same sums)."""
    n = len(t)
    norm = np.linalg.norm(gyro_mean)
    if norm == 0:
        return _uniform_fraction(t, start, duration)
    direction = gyro_mean / norm
    turned = np.empty(n)
    turned[0] = 0.0
    for i, j in _chunks(n - 1):         # the steps between samples i..j
        rate = gyro[i:j + 1] @ direction
        steps = np.empty(j - i + 1)
        steps[0] = turned[i]            # the running sum so far, then this chunk's trapezoids
        np.multiply(rate[1:] + rate[:-1], 0.5, out=steps[1:])
        steps[1:] *= np.diff(t[i:j + 1])
        turned[i + 1:j + 1] = np.cumsum(steps)[1:]
    rate_first, rate_last = gyro[0] @ direction, gyro[-1] @ direction
    turned += 0.5 * rate_first * (t[1] - t[0])                  # from the window's start
    total = turned[-1] + 0.5 * rate_last * (t[-1] - t[-2])
    if total == 0:
        return _uniform_fraction(t, start, duration)
    turned /= total
    return turned


def _uniform_fraction(t, start, duration):
    return (t - start) / duration


def _phase_fraction(t, gyro, start, duration, gyro_sigma_dps, gyro_mean):
    """Fraction of the turn at each sample: from the gyro when the rate really varies, else
    uniform in time.  Integrating the gyro adds its noise as a random walk of the phase (pinned
    at both ends: RMS sigma sqrt(dt T / 6)); over a few revolutions that wander projects onto the
    harmonics.  So the gyro-tracked phase is used only where its departure from a uniform phase is
    more than three times that noise, i.e. where the rate ripples or drifts."""
    tracked = _turned_fraction(t, gyro, start, duration, gyro_mean)
    if gyro_sigma_dps is None:
        return tracked
    rate = np.linalg.norm(gyro_mean)
    if rate == 0:
        return tracked
    n = len(t)
    dt = duration / n
    noise_deg = float(np.max(gyro_sigma_dps)) * np.sqrt(dt * duration / 6.0)
    squares = 0.0
    for i, j in _chunks(n):
        departure = tracked[i:j] - _uniform_fraction(t[i:j], start, duration)
        departure *= rate * duration
        squares += float(departure @ departure)
    departure_deg = float(np.sqrt(squares / n))
    if departure_deg > 3.0 * noise_deg:
        return tracked
    np.subtract(t, start, out=tracked)      # uniform, in the same array
    tracked /= duration
    return tracked


def _rate(gyro, gyro_bias, angle_deg, duration, gyro_mean):
    """The table rate (rad/s, signed like the angle) at each sample: the gyro along its mean
    direction (bias removed), rescaled to the encoder's mean rate."""
    bias = np.zeros(3) if gyro_bias is None else np.asarray(gyro_bias, float)
    direction = gyro_mean - bias
    norm = np.linalg.norm(direction)
    mean_rate = np.radians(angle_deg) / duration
    if norm == 0:
        return np.full(len(gyro), mean_rate)
    direction /= norm
    along = gyro @ direction            # (gyro - bias) @ direction without an (N, 3) temporary
    along -= bias @ direction
    along *= mean_rate / along.mean()
    return along


MAX_GRAM_CONDITION = 1e8    # normal equations lose about cond * 1e-16 of relative precision


def _column_means(x):
    """The mean of each column of x (N, k): column by column (numpy's pairwise sum, 10x faster
    than x.mean(axis=0), which adds the rows one after the other), as np.mean computes it (the
    sum over the count) without its Python layer (~400 calls in a 100 Hz estimate)."""
    n = x.shape[0]
    if not n or x.dtype != np.float64:
        return np.array([x[:, k].mean() for k in range(x.shape[1])])
    return np.array([np.add.reduce(x[:, k]) / n for k in range(x.shape[1])])


def _half_sum_sq_diff(x):
    """Half the sum of the squared first differences of each column of x (N, k), chunk by chunk."""
    total = np.zeros(x.shape[1])
    for i, j in _chunks(len(x) - 1):
        step = x[i + 1:j + 1] - x[i:j]
        total += np.einsum("ij,ij->j", step, step)
    return total / 2


def _half_difference(x) -> np.ndarray:
    """Mean of the first half of the rows of x (N, k) less that of the second half."""
    h = len(x) // 2
    return _column_means(x[:h]) - _column_means(x[h:2 * h]) if h >= 1 else np.full(x.shape[1], np.nan)


def _lsb(x, head: int = 2000) -> np.ndarray:
    """The output step of each column of x (N, k) from its first ``head`` samples: the smallest
    gap between distinct values when every gap is a whole multiple of it (within 2 %), else 0
    (not quantised on a grid the samples show: floating-point output)."""
    out = np.zeros(x.shape[1])
    for k in range(x.shape[1]):
        values = distinct(x[:head, k])
        if len(values) < 2:
            continue
        gaps = np.diff(values)
        q = float(gaps.min())
        if q > 0 and np.all(np.abs(gaps / q - np.round(gaps / q)) < 0.02):
            out[k] = q
    return out


def _harmonic_basis(phase):
    """Rows 1, cos phi, sin phi, cos 2phi, sin 2phi at the given phases (5, n)."""
    basis = np.empty((5, len(phase)))
    basis[0] = 1.0
    np.cos(phase, out=basis[1])
    np.sin(phase, out=basis[2])
    np.multiply(basis[1], basis[1], out=basis[3])
    basis[3] -= basis[2] * basis[2]
    np.multiply(basis[1], basis[2], out=basis[4])
    basis[4] *= 2.0
    return basis


def _gradient_chunk(w, t, i, j):
    """np.gradient(w, t)[i:j] (t None: unit spacing), computed from w[i-1:j+1] only (the same
    values: the gradient at a sample uses its two neighbours, and the end formula at the
    segment's ends)."""
    lo, hi = max(i - 1, 0), min(j + 1, len(w))
    part = np.gradient(w[lo:hi]) if t is None else np.gradient(w[lo:hi], t[lo:hi])
    return part[i - lo:i - lo + (j - i)]


def _ramp_fraction(t, gyro, gyro_mean, angle_deg, steady_rate_dps, gyro_sigma_dps=None) -> np.ndarray:
    """A recorded ramp's phase (issue 28 item 3) as a fraction of ``angle_deg``: the table's angle
    turned since the window's start, from the gyro along its mean direction with its bias and
    scale taken from the window itself -- its mean at rest (the run of samples at the slower edge
    within five times the gyro's noise of it: bias and the Earth rate along the axis) and at the
    rate (the run at the faster edge: the table's stated ``steady_rate_dps``).  Not the encoder's angle over
    the window: under a time offset dt the IMU's samples turn angle + dt (w_end - w_start) (0.5 deg
    at 100 deg/s and 5 ms), and phases scaled to the encoder's angle drift by up to that within the
    window, which the accelerometer's harmonics see as a gravity error of g sin(0.5 deg), 8.7 mg;
    nor the raw gyro's turn: its bias integrates to a phase error growing with time (a MEMS
    0.1 deg/s: 0.6 deg over 6 s), which a uniform turn's phase absorbs and a ramp's cannot (the
    designer's noiseless fit of ramp turns was left at chi2 5 per turn in the harmonics).  A time
    offset only shifts these phases, which the fit's phase takes.  Returns (fraction, the table's
    rate at each sample along the turn, deg/s; None where the edges' runs were not found and the
    fraction is the gyro's turn over the window)."""
    direction = gyro_mean / np.linalg.norm(gyro_mean)
    along = gyro @ direction
    head, tail = along[:EDGE_SAMPLES].mean(), along[-EDGE_SAMPLES:].mean()
    span = abs(tail - head)
    noise = 0.0 if gyro_sigma_dps is None else float(np.max(gyro_sigma_dps))
    level = max(5.0 * noise, 1e-3 * span)

    def run_from(edge_first: bool, value: float) -> np.ndarray:
        """The samples of the run at one edge within ``level`` of ``value``, less EDGE_SAMPLES at
        its inner end (the ramp's first or last samples: 50 deg/s^2 is 0.5 deg/s per sample at 100
        Hz, and one such sample in the rest's mean tilts the phase by 0.1 deg over 6 s)."""
        off = np.abs(along - value) >= level
        inner = np.flatnonzero(off if edge_first else off[::-1])
        n = (inner[0] if len(inner) else len(along)) - EDGE_SAMPLES
        if n < EDGE_SAMPLES:
            return np.zeros(0)
        return along[:n] if edge_first else along[len(along) - n:]

    start_is_rest = abs(head) < abs(tail)
    rest_run = run_from(start_is_rest, head if start_is_rest else tail)
    rate_run = run_from(not start_is_rest, tail if start_is_rest else head)
    if span == 0 or not len(rest_run) or not len(rate_run):
        return _turned_fraction(t, gyro, *_window_start_duration(t), gyro_mean), None
    rest, rate = float(rest_run.mean()), float(rate_run.mean())
    w = (along - rest) * (abs(steady_rate_dps) / (rate - rest))       # the table's rate, deg/s
    turned = np.empty(len(t))
    turned[0] = 0.5 * w[0] * (t[1] - t[0])                            # from the window's start
    turned[1:] = turned[0] + np.cumsum(0.5 * (w[1:] + w[:-1]) * np.diff(t))
    return turned / abs(angle_deg), w


def _window_start_duration(t):
    start, end = _window(t)
    return start, end - start


def rotation_summary(name, axis_body, group, angle_deg, t, accel, gyro, temp,
                     gyro_sigma_dps=None, gyro_bias=None, accel_mask=None,
                     steady_rate_dps=None) -> RotationSummary:
    """``accel_mask(phase, accel)``: the samples (N,) bool the accelerometer harmonics use, or None
    for all (station.estimate.data_faults.Verdict.accel_keep: samples near a rail or stuck left
    out); the basis is then summed over those samples only.
    ``gyro_sigma_dps``: per-sample white gyro noise (deg/s); with it the phase is tracked by
    the gyro only where the rate varies beyond what that noise would make it seem to.
    ``gyro_bias``: a rough gyro bias (the statics' mean), removed before the rate's shape is taken.

    The accelerometer, the rate, its square and its derivative are projected on the harmonic
    basis CHUNK_SAMPLES samples at a time (the Gram matrix and the projections summed over the
    chunks, then one 5 x 5 solve): the same least-squares coefficients as with whole arrays, to
    rounding, with temporaries that fit in the processor's cache instead of five to ten copies
    of the segment's length."""
    n = len(t)
    if n < 8:
        raise UserError(f"segment '{name}': a rotation segment needs at least 8 samples")
    start, end = _window(t)
    duration = end - start
    spans = _chunks(n)
    gyro_mean = _column_means(gyro)
    fraction = _phase_fraction(t, gyro, start, duration, gyro_sigma_dps, gyro_mean)
    earth_weights = table_rate = None
    if steady_rate_dps is not None:     # a recorded ramp: the phase at the table's steady rate
        fraction, table_rate = _ramp_fraction(t, gyro, gyro_mean, angle_deg, steady_rate_dps, gyro_sigma_dps)
        # the Earth rate's weights over the window from the same phase as the harmonics' (a rest
        # and a ramp spend longer at some angles than a uniform turn; issue 28 review item 5:
        # one phase per window, not the raw gyro's turn beside it)
        phase = np.radians(angle_deg) * fraction
        weights = np.gradient(t)        # each sample's share of the window (as the gyro integral's)
        earth_weights = np.array([weights @ np.cos(phase), weights @ np.sin(phase)])
        del phase, weights
    # the table rate w(t) about the axis, its square and its time derivative are projected on the
    # same basis as the accelerometer (one solve for all of them)
    rate_from_table = table_rate is not None
    if table_rate is None:
        w = _rate(gyro, gyro_bias, angle_deg, duration, gyro_mean)
    else:   # a recorded ramp: at the table's steady rate, as its phase (issue 28, twentieth session)
        # -- not at the encoder's mean rate over the window, A / T: the window's angle is the
        # table's reads placed on the IMU's clock (uncertain by its angle_sigma_deg) and the
        # samples of a window shifted by a time offset dt turn A + dt (w_end - w_start); scaled
        # to A / T the rates, and the centripetal and tangential forces the accelerometer rows
        # take from them, were off by (A + dt dw) / A and by the placement's error
        w = np.radians(table_rate) * np.sign(angle_deg)
    del table_rate
    angle_rad = np.radians(angle_deg)
    keep = None if accel_mask is None else accel_mask(angle_rad * fraction, accel)
    used = n if keep is None else int(keep.sum())
    if used < 8:
        raise UserError(f"segment '{name}': fewer than 8 accelerometer samples left for its harmonics")
    gram = np.zeros((5, 5))
    # accel x, y, z; w, w^2, dw/dt; a recorded ramp's also theta cos, theta sin, theta^2 cos, theta^2
    # sin (its turned moments, RotationSummary.turned_moments) and w^2 and dw/dt times cos, sin,
    # cos 2, sin 2 of the phase (RotationSummary.ramp_coef), chunk by chunk as the rest; steady
    # turns: nothing more to project
    width = 18 if rate_from_table else 6
    projections = np.zeros((5, width))
    sum_m = sum_m2 = np.float64(0.0)    # the gyro's magnitude: its sum and sum of squares
    columns = np.empty((CHUNK_SAMPLES, width))
    # the gyro integral over the window: the trapezoid over the samples plus half a sample at each
    # end, i.e. each sample weighted by half the time between its neighbours (np.gradient(t): a
    # whole step at the ends)
    gyro_integral = np.zeros(3)
    for i, j in spans:
        gyro_integral += _gradient_chunk(t, None, i, j) @ gyro[i:j]
        basis = _harmonic_basis(angle_rad * fraction[i:j])
        c = columns[:j - i]
        c[:, :3] = accel[i:j]
        c[:, 3] = w[i:j]
        np.multiply(c[:, 3], c[:, 3], out=c[:, 4])
        c[:, 5] = _gradient_chunk(w, t, i, j)
        if rate_from_table:
            _ramp_products(c, basis, angle_rad * fraction[i:j])
        if keep is not None:
            basis *= keep[i:j]
        gram += basis @ basis.T
        projections += basis @ c
        g = gyro[i:j]
        m2 = np.einsum("ij,ij->i", g, g)
        sum_m2 += m2.sum()
        sum_m += np.sqrt(m2, out=m2).sum()
    gram_per_sample = gram / used
    if np.linalg.cond(gram) < MAX_GRAM_CONDITION:
        coefs = np.linalg.solve(gram, projections)
    else:   # a short sweep: the SVD solver on the whole basis
        basis = _harmonic_basis(angle_rad * fraction)
        rows = slice(None) if keep is None else keep
        c = np.empty((n, width))
        c[:, :3], c[:, 3], c[:, 4], c[:, 5] = accel, w, w * w, np.gradient(w, t)
        if rate_from_table:
            _ramp_products(c, basis, angle_rad * fraction)
        coefs = np.linalg.lstsq(basis.T[rows], c[rows], rcond=None)[0]
    # a recorded ramp: not a uniform turn (RotationSummary.turned_moments)
    moments = coefs[:, 6:10].T.copy() if rate_from_table else None
    del w, fraction
    coef, rate_coefs = coefs[:, :3], (coefs[:, 3], coefs[:, 4], coefs[:, 5])
    ramp_coef = None
    if rate_from_table:     # (2, 5, 5): [w^2, dw/dt] x [1, cos, sin, cos 2, sin 2 of the phase] x harmonic
        ramp_coef = np.empty((2, 5, 5))
        ramp_coef[:, 0] = np.stack([coefs[:, 4], coefs[:, 5]])
        ramp_coef[:, 1:] = coefs[:, 10:18].T.reshape(2, 4, 5)
    edge = min(EDGE_SAMPLES, n // 4)
    mean_m, mean_m2 = sum_m / n, sum_m2 / n
    spread = np.sqrt(max(mean_m2 - mean_m * mean_m, 0.0))     # the magnitude's standard deviation
    steady = bool(spread < STEADY_SPREAD * mean_m)
    rate_sq_factor = float(mean_m2 / mean_m ** 2)
    return RotationSummary(name=name, axis_body=axis_body, group=group, angle_deg=float(angle_deg),
                           duration_s=float(duration), samples=used, accel_dc=coef[0],
                           accel_cos=coef[1], accel_sin=coef[2], accel_cos2=coef[3],
                           accel_sin2=coef[4], gyro_integral=gyro_integral,
                           temp_c=None if temp is None else float(np.mean(temp)),
                           gyro_start=gyro[:edge].mean(axis=0), gyro_end=gyro[-edge:].mean(axis=0),
                           steady=steady, rate_sq_factor=rate_sq_factor,
                           rate_coef=rate_coefs[0], rate_sq_coef=rate_coefs[1], rate_dot_coef=rate_coefs[2],
                           gram=gram_per_sample, earth_weights_s=earth_weights, rate_from_table=rate_from_table,
                           turned_moments=moments, ramp_coef=ramp_coef)


def _ramp_products(columns, basis, theta) -> None:
    """A recorded ramp's columns 6-17 (rotation_summary), to be projected as the samples are:
    6-9 theta cos, theta sin, theta^2 cos, theta^2 sin of the phase theta (rad; the turned
    moments, RotationSummary.turned_moments), 10-17 w^2 (column 4) and dw/dt (column 5) times
    cos p, sin p, cos 2p, sin 2p (the basis' rows 1-4 at the samples' phases; RotationSummary.ramp_coef)."""
    np.multiply(theta, basis[1], out=columns[:, 6])
    np.multiply(theta, basis[2], out=columns[:, 7])
    np.multiply(theta, columns[:, 6], out=columns[:, 8])
    np.multiply(theta, columns[:, 7], out=columns[:, 9])
    columns[:, 10:14] = columns[:, 4:5] * basis[1:].T
    columns[:, 14:18] = columns[:, 5:6] * basis[1:].T


def _scaled(values, factor):
    """values * factor, without a copy when the factor is 1 (the arrays are only read)."""
    return values if factor == 1.0 else values * factor


@dataclass
class _SegmentSummaries:
    """What summarise keeps of a capture's samples (small: the samples themselves are freed)."""
    statics: list
    static_spans: list          # _Span per static, in the order of statics (for the hand turns)
    accel_diff_sq: np.ndarray   # (3,) sum over the statics of squared first differences / 2
    gyro_diff_sq: np.ndarray
    diff_count: int
    rotations: list
    skipped: list
    hands: list                 # complete hand-turn segments, their (short) samples loaded
    stamp_jitters: list         # _stamp_jitter of each static and rotation with more than 8 samples
    data_faults: dict | None = None     # data_faults.Scanner.report()


@dataclass
class _TimeStamps:
    t: np.ndarray


@dataclass
class _Span:
    """A static segment's first and last sample time, standing in for its samples where only those
    are needed (hand_rotation.collect reads seg.data.t[0] and seg.data.t[-1])."""
    name: str
    data: _TimeStamps


# Summaries of captures read without their samples, kept so that a second summarise of the same
# capture object (e.g. estimate_capture's pass, then lsq.estimate) reads no file again.
_KEPT = weakref.WeakKeyDictionary()


def kept(capture):
    """What summarise() computed and kept for ``capture`` (None if nothing): a picklable object
    that keep() gives to another Capture object of the same capture (one read in another
    process: station.estimate.estimate_capture)."""
    return _KEPT.get(capture)


def keep(capture, parts) -> None:
    """Keep ``parts`` (from kept()) for ``capture``: summarise(capture) then reads nothing."""
    _KEPT[capture] = parts


def summarise(capture, *, table_angle_arcsec: float | None = None, check_segment=None) -> Summaries:
    """The summaries of ``capture``'s complete static and rotation segments.

    A capture read without its samples (read_capture(..., load_data=False)) is summarised one
    segment at a time: each file is read once (the statics first: the rotation summaries use their
    noise and gyro bias), summarised, and its samples freed, so memory does not grow with the
    capture's length; what was computed is kept with the capture object, so calling summarise
    again reads nothing.  ``check_segment(seg)`` is called for each complete segment while its
    samples are in seg.data, before they are used: it may refuse the capture (raise) or leave the
    segment out (seg.status = "excluded").  A capture whose samples are loaded is summarised from
    them, as they are now (nothing kept)."""
    ca = units.accel_to_mps2_factor(capture.imu.accel_unit) or 1.0
    cg = units.gyro_to_dps_factor(capture.imu.gyro_unit) or 1.0
    streamed = any(seg.data is None for seg in capture.complete())
    kept = _KEPT.get(capture) if streamed and check_segment is None else None
    if kept is None:
        # one BLAS thread: vector operations over the samples, which a BLAS thread pool only
        # slows down (4x on a busy 2-core machine: docs/performance.md)
        with limited_blas(1):
            parts = _summarise_segments(capture, ca, cg, check_segment)
        if streamed:
            _KEPT[capture] = parts
            parts = _copy(parts)
    else:
        parts = _copy(kept)
    return _assemble(capture, parts, ca, cg, table_angle_arcsec)


def _copy(parts: _SegmentSummaries) -> _SegmentSummaries:
    """Kept summaries as new objects (the caller may change what it gets)."""
    return dataclasses.replace(parts, statics=copy.deepcopy(parts.statics),
                               rotations=copy.deepcopy(parts.rotations), skipped=list(parts.skipped))


def _recorded_elevation(seg) -> float | None:
    """The elevation of a rotation's axis_body above the horizontal the capture records (deg;
    None: not recorded, older captures and imports)."""
    e = seg.extra.get("axis_elevation_deg")
    ok = isinstance(e, (int, float)) and not isinstance(e, bool) and np.isfinite(e)
    return float(e) if ok else None


def _summarise_segments(capture, ca, cg, check_segment) -> _SegmentSummaries:
    order = {seg.name: k for k, seg in enumerate(capture.segments)}
    statics, spans = [], []
    diff_sq_a, diff_sq_g, diff_count = np.zeros(3), np.zeros(3), 0
    rotations, skipped, axes, hands, jitters = [], [], [], [], []
    gyro_sigma = static_gyro_mean = None
    scanner = data_faults.Scanner(capture, ca, cg)     # rails, stuck samples, the temperature
    # statics first (the rotation summaries use their noise and gyro bias), then the rotations,
    # then the segments estimation does not use (only checked); each file is read while the
    # previous segment is summarised (ReaderAhead)
    queue = capture.summary_order(every=check_segment is not None)
    with capture.reader_ahead(queue) as reader:
        for seg in queue:
            if seg.kind != "static" and gyro_sigma is None:
                _statics_left(capture, statics, scanner)
                gyro_sigma, static_gyro_mean = _static_noise(capture, statics, diff_sq_g, diff_count)
            d = reader.take(seg)
            if check_segment is not None:
                with _holding(seg, d):
                    check_segment(seg)
            reader.ahead()
            if seg.status != "complete" or seg.kind not in ("static", "rotation"):
                continue
            if len(d.t) > 8:
                jitters.append(_stamp_jitter(d.t))
            d, verdict = _scanned(scanner, seg, d, ca, cg)
            if d is None:
                continue
            if seg.kind == "static":
                a, g = _scaled(d.accel, ca), _scaled(d.gyro, cg)
                statics.append(StaticSummary(seg.name, seg.up_body, _column_means(a), _column_means(g), len(d.t),
                                             float(d.t[-1] - d.t[0]), None if d.temp is None else float(d.temp.mean()),
                                             t_mid_s=float(np.mean(d.t)), index=order[seg.name],
                                             temp_rate_c_per_s=_slope(d.t, d.temp),
                                             half_diff=np.concatenate([_half_difference(a), _half_difference(g)]),
                                             lsb=np.concatenate([_lsb(a), _lsb(g)])))
                spans.append(_Span(seg.name, _TimeStamps(np.array([d.t[0], d.t[-1]]))))
                # white noise: first differences remove slow drifts (temperature) from the estimate
                diff_sq_a += _half_sum_sq_diff(a)
                diff_sq_g += _half_sum_sq_diff(g)
                diff_count += len(d.t) - 1
                del a, g, d
                continue
            if seg.angle_deg is None:
                from station.estimate import hand_rotation     # only for turns without an encoder

                with _holding(seg, d):
                    hand = hand_rotation.is_hand(seg)
                if hand:
                    hands.append((seg, d))
                    continue
                skipped.append(f"{seg.name}: no encoder angle (angle_deg); not used by the least-squares fit")
                continue
            axis = np.asarray(seg.axis_body, float) / np.linalg.norm(seg.axis_body)
            # one group per physical axis: rotations about one body axis share its direction on the
            # table (elevation, heading: the gravity angle and the Earth rate's phase the fit gives
            # each group), but not across an extension recorded later (``appended: N``, run
            # --append): the table may start that axis elsewhere; nor at another recorded elevation
            # (axis_elevation_deg: a level turn and a vertical one about the same body axis have
            # different gravity angles; in one group the fit gave a capture with both a reduced
            # chi2 of 2.2e6, twentieth session)
            session = seg.extra.get("appended", 0)
            session = session if isinstance(session, int) and not isinstance(session, bool) else 0
            elevation = _recorded_elevation(seg)
            group = next((i for i, (a, s, e) in enumerate(axes)
                          if s == session and np.allclose(a, axis, atol=1e-6) and table_geometry.same_elevation(e, elevation)),
                         None)
            if group is None:
                axes.append((axis, session, elevation))
                group = len(axes) - 1
            try:
                summary = rotation_summary(seg.name, axis, group, seg.angle_deg, d.t, _scaled(d.accel, ca),
                                           _scaled(d.gyro, cg), d.temp, gyro_sigma_dps=gyro_sigma,
                                           gyro_bias=static_gyro_mean,
                                           accel_mask=verdict.accel_keep if verdict.masks else None,
                                           steady_rate_dps=_ramp_rate(seg))
            except data_faults.TooLittleLeft as e:
                scanner.drop(seg.name, str(e))
                continue
            scanner.harmonics(seg.name, summary.samples, len(d.t))
            if seg.extra.get("motion") == "hand":      # the writer says so (manual schemes)
                summary.steady = False
            _ramp_keys(summary, seg)
            summary.t_mid_s, summary.index = float(np.mean(d.t)), order[seg.name]
            summary.temp_rate_c_per_s = _slope(d.t, d.temp)
            axis_no = seg.extra.get("table_axis")
            if isinstance(axis_no, int) and not isinstance(axis_no, bool):
                summary.table_axis = axis_no
            rotations.append(summary)
            del d
    # incomplete segments (a run stopped or killed) are read for what reading them says (the rows
    # they hold, what is wrong with their last line: capture.warnings), as a loaded capture's
    # are; their rows counted, not kept
    for seg in capture.segments:
        if seg.status == "incomplete" and seg.data is None:
            capture.check_incomplete(seg)
    if gyro_sigma is None:
        _statics_left(capture, statics, scanner)
        _static_noise(capture, statics, diff_sq_g, diff_count)
    for seg, d in hands:
        seg.data = d                    # hand turns are short: their samples are kept for the fit
    return _SegmentSummaries(statics, spans, diff_sq_a, diff_sq_g, diff_count, rotations, skipped,
                             [seg for seg, _ in hands], jitters, scanner.report())


def _ramp_rate(seg) -> float | None:
    """A recorded ramp's steady rate (deg/s): the table's at the window's end (a ramp up recorded)
    or start (a brake recorded), else the commanded rate; None for a segment without a ramp."""
    ramp = seg.extra.get("record_ramp")
    if ramp not in ("start", "end"):
        return None
    x = seg.extra.get("rate_end_dps" if ramp == "start" else "rate_start_dps")
    if isinstance(x, (int, float)) and not isinstance(x, bool) and np.isfinite(x) and x != 0:
        return float(x)
    return seg.rate_dps if seg.rate_dps else None


def _ramp_keys(summary, seg) -> None:
    """A recorded ramp's manifest keys onto its summary: the turn is the table's (steady: its
    accelerometer harmonics are used, the phase tracked by the gyro through the ramp), the
    table's rates at the window's edges are kept (a key that is not a finite number: not said),
    and the window's own angle 1-sigma (``angle_sigma_deg``: its reads' placement).  The Earth
    rate's weights over the window (a rest and a ramp spend longer at some angles than a uniform
    turn: on the simulated bench at 100 deg/s and 50 deg/s^2 the uniform weights left 0.006 deg
    in the integral, 144 sigma of its noise) are rotation_summary's, from the phase the harmonics
    use (_ramp_fraction)."""
    ramp = seg.extra.get("record_ramp")
    if ramp not in ("start", "end"):
        return
    summary.record_ramp = ramp
    summary.steady = True
    for key, attr in (("rate_start_dps", "table_rate_start_dps"), ("rate_end_dps", "table_rate_end_dps")):
        x = seg.extra.get(key)
        if isinstance(x, (int, float)) and not isinstance(x, bool) and np.isfinite(x):
            setattr(summary, attr, float(x))
    sigma = seg.extra.get("angle_sigma_deg")
    if sigma is not None:
        if isinstance(sigma, bool) or not isinstance(sigma, (int, float)) or not np.isfinite(sigma) or sigma < 0:
            raise UserError(f"{seg.name}: angle_sigma_deg: must be a finite number >= 0 (the 1-sigma of the "
                            f"window's angle from its reads, deg), got {sigma!r}")
        summary.angle_sigma_deg = float(sigma)


def _scanned(scanner, seg, d, ca, cg):
    """(the samples to summarise, the verdict) of one segment after the data-fault scan
    (station.estimate.data_faults); (None, verdict) when the segment is left out.  Rows of stuck
    samples are removed as frames lost would be."""
    verdict = scanner.scan(seg, d.t, _scaled(d.accel, ca), _scaled(d.gyro, cg), d.temp)
    if verdict.drop:
        return None, verdict
    if verdict.rows is not None:
        rows = verdict.rows
        d = SegmentData(t=d.t[rows], accel=d.accel[rows], gyro=d.gyro[rows],
                        temp=None if d.temp is None else d.temp[rows], gaps=d.gaps)
        scanner.restrict(verdict, rows)
    return d, verdict


def _statics_left(capture, statics, scanner) -> None:
    """UserError saying why when every static segment was left out for a data fault."""
    left = [d for d in scanner.left_out if d["reason"].startswith("static left out")]
    if not statics and left:
        raise UserError(f"{capture.path}: every static segment was left out for a data fault, and the "
                        f"least-squares fit needs them: {left[0]['segment']}: {left[0]['reason']}"
                        + (f" (and {len(left) - 1} more)" if len(left) > 1 else ""))


def _static_noise(capture, statics, diff_sq_g, diff_count):
    """(per-sample gyro white noise, mean gyro output) of the statics summarised; UserError
    without any."""
    if not statics:
        raise UserError(f"{capture.path}: no complete static segment: the least-squares fit needs "
                        "static segments (biases and the noise level come from them)")
    with np.errstate(invalid="ignore", divide="ignore"):
        gyro_sigma = np.sqrt(diff_sq_g / diff_count)
    return gyro_sigma, np.mean([st.gyro for st in statics], axis=0)   # ~ the bias (Earth rate averages out)


@contextmanager
def _holding(seg, data):
    """seg.data holds ``data`` inside the block (for code that reads seg.data), as it was after."""
    if seg.data is not None:
        yield
        return
    seg.data = data
    try:
        yield
    finally:
        if seg.data is data:
            seg.data = None


def _assemble(capture, parts: _SegmentSummaries, ca, cg, table_angle_arcsec) -> Summaries:
    with np.errstate(invalid="ignore", divide="ignore"):
        accel_sigma = np.sqrt(parts.accel_diff_sq / parts.diff_count)
        gyro_sigma = np.sqrt(parts.gyro_diff_sq / parts.diff_count)
    statics, rotations, skipped = parts.statics, parts.rotations, list(parts.skipped)

    if parts.hands:
        from station.estimate import hand_rotation     # only for turns without an encoder

        hand_rotations, hand_skipped = hand_rotation.collect(parts.static_spans, parts.hands, cg)
        skipped += hand_skipped
    else:
        hand_rotations = []
    nominal = capture.imu.extra.get("gyro_nominal_dps_per_count") if capture.imu.gyro_unit == "raw" else None
    nominal = 1.0 / float(nominal) if isinstance(nominal, (int, float)) and nominal > 0 else None
    accel_nominal = capture.imu.extra.get("accel_nominal_mps2_per_count") if capture.imu.accel_unit == "raw" else None
    accel_nominal = (1.0 / float(accel_nominal) if isinstance(accel_nominal, (int, float)) and 0 < accel_nominal < np.inf
                     else None)
    table = capture.extra.get("table") if isinstance(capture.extra.get("table"), dict) else {}
    if table_angle_arcsec is None:
        table_angle_arcsec = table.get("angle_error_arcsec", 0.0)
    mounting = capture.extra.get("mounting") if isinstance(capture.extra.get("mounting"), dict) else {}
    offset = mounting.get("offset_m")
    try:
        offset = None if offset is None else np.asarray(offset, dtype=float).reshape(3)
        angle_sigma = float(table_angle_arcsec) / 3600.0
    except (TypeError, ValueError):
        raise UserError(f"{capture.path}/manifest.yaml: field 'mounting.offset_m' or "
                        "'table.angle_error_arcsec': must be numbers") from None
    jitter = parts.stamp_jitters        # from every segment summarised, read whole or streamed
    report = getattr(parts, "data_faults", None)
    fault_notes = data_faults.notes_of(report) if report else []
    skipped += fault_notes
    return Summaries(gravity_mps2=capture.site.gravity_mps2, latitude_deg=capture.site.latitude_deg,
                     accel_factor=ca, gyro_factor=cg, sample_rate_hz=capture.imu.sample_rate_hz,
                     statics=statics, rotations=rotations, accel_sigma=accel_sigma, gyro_sigma=gyro_sigma,
                     table_angle_sigma_deg=angle_sigma, mounting_offset_m=offset, skipped=skipped,
                     hand_rotations=hand_rotations, gyro_nominal=nominal,
                     gyro_raw=capture.imu.gyro_unit == "raw", accel_raw=capture.imu.accel_unit == "raw",
                     accel_nominal=accel_nominal, stamp_jitter_s=median(jitter) if jitter else 0.0,
                     geometry=table_geometry.read(capture, rotations),
                     data_faults=report, data_fault_notes=fault_notes)
