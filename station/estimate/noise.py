"""Noise of a still IMU from the overlapping Allan deviation (IEEE Std 952/1554 terms).

For each axis of the (unit-converted, otherwise raw) output of one static recording:
  * the overlapping Allan deviation sigma(tau) (NIST SP 1065 eq. 11, from the phase x_k, the
    cumulative sum of the mean-removed samples) at about ten taus per decade from one sample
    to a fifth of the recording, with a 68.3 % confidence interval from the chi-square
    distribution (SP 1065 eq. 45) with the equivalent degrees of freedom of the estimator for
    white noise, computed exactly (``white_noise_edf``; Greenhall's tables approximate the same
    sum: 17 % high at one sample, 5-12 % low at two to ten: tests/test_allan.py checks both it and
    the deviation against allantools and a Monte Carlo);
  * white noise N (sigma = N / sqrt(tau), slope -1/2): the density (ug/sqrt(Hz), deg/h/sqrt(Hz)),
    i.e. velocity / angle random walk (m/s/sqrt(h), deg/sqrt(h)), read where the local slope is
    within 1/4 of -1/2 at the tau with the most degrees of freedom; its 1 sigma from that
    point's confidence interval;
  * bias random walk K (sigma = K sqrt(tau / 3), slope +1/2) where the local slope after the
    minimum is within 1/4 of +1/2 and the curve lies significantly above the white-noise line,
    the white part there taken away; otherwise an upper bound from the longest tau;
  * bias instability B (flicker floor, slope 0) = sqrt(what remains of sigma^2 once the white
    and random-walk parts are taken away) / 0.664 at the lowest point where the curve is flat
    (local slope within 1/4 of 0) and that remainder is significant (3 sigma); otherwise an
    upper bound, the upper end of the interval at the minimum / 0.664.
Kalibr's four numbers are the white-noise densities and random walks in SI (rad for the gyro),
the largest of the three axes per triad.

Written here rather than imported from allantools (which computes the same deviation): its
import pulls in scipy.stats, interpolate, signal and integrate, 0.3 s of the 0.7 s a
``diagnose --report`` may take (issue 15); allantools stays the tests' reference.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from station.core import units
from station.core.errors import UserError

FLICKER_FACTOR = math.sqrt(2.0 * math.log(2.0) / math.pi)    # 0.664: sigma floor of flicker noise
CONFIDENCE = 0.682689492137086                              # 1 sigma of a normal distribution
MIN_SAMPLES = 200
TAUS_PER_DECADE = 10
CHUNK = 1 << 16         # second differences summed this many at a time (bounded temporaries)
SLOPE_TOLERANCE = 0.25


@dataclass
class AxisNoise:
    sensor: str                  # "accel" or "gyro"
    axis: str                    # "x", "y", "z"
    unit: str                    # the unit sigma(tau) is in: m/s^2 or deg/s
    taus: np.ndarray             # s
    adev: np.ndarray             # overlapping Allan deviation, unit
    lo: np.ndarray               # 68.3 % confidence interval of adev
    hi: np.ndarray
    white: float                 # N, unit * sqrt(s)
    white_sigma: float
    white_tau: float             # where N was read
    bias_instability: float | None      # B, unit
    bias_instability_tau: float | None
    bias_instability_upper: float       # B is below this (the value itself when resolved)
    random_walk: float | None           # K, unit / sqrt(s)
    random_walk_sigma: float | None
    random_walk_tau: float | None
    random_walk_upper: float            # K is below this (the value itself when resolved)

    def report(self) -> dict:
        """The figures in engineering units, for the calibration file's ``noise`` block."""
        if self.sensor == "accel":
            per = 1.0 / units.UG_MPS2          # ug per m/s^2
            out = {"white_noise_ug_rthz": self.white * per,
                   "white_noise_sigma_ug_rthz": self.white_sigma * per,
                   "velocity_random_walk_mps_rth": self.white * 60.0}
            bi_unit, rw_unit, rw_factor = "ug", "ug_rth", per * 60.0
        else:
            per = 3600.0                       # deg/h per deg/s
            out = {"white_noise_dph_rthz": self.white * per,
                   "white_noise_sigma_dph_rthz": self.white_sigma * per,
                   "angle_random_walk_deg_rth": self.white * 60.0}
            bi_unit, rw_unit, rw_factor = "dph", "dph_rth", per * 60.0
        out["white_noise_tau_s"] = self.white_tau
        out[f"bias_instability_{bi_unit}"] = (None if self.bias_instability is None
                                              else self.bias_instability * per)
        out["bias_instability_tau_s"] = self.bias_instability_tau
        out[f"bias_instability_upper_{bi_unit}"] = self.bias_instability_upper * per
        out[f"random_walk_{rw_unit}"] = None if self.random_walk is None else self.random_walk * rw_factor
        out[f"random_walk_sigma_{rw_unit}"] = (None if self.random_walk_sigma is None
                                               else self.random_walk_sigma * rw_factor)
        out["random_walk_tau_s"] = self.random_walk_tau
        out[f"random_walk_upper_{rw_unit}"] = self.random_walk_upper * rw_factor
        return {k: (None if v is None else float(v)) for k, v in out.items()}


@dataclass
class NoiseResult:
    axes: list                   # AxisNoise, accel x y z then gyro x y z
    sample_rate_hz: float
    duration_s: float
    source: str                  # what was analysed, in words
    segment: str | None = None   # the capture's segment analysed (None: a CSV file)

    def axis(self, sensor: str, axis: str) -> AxisNoise:
        return next(a for a in self.axes if a.sensor == sensor and a.axis == axis)

    def kalibr(self) -> dict:
        """Kalibr's imu.yaml numbers: SI, continuous time, largest axis per triad."""
        acc = [a for a in self.axes if a.sensor == "accel"]
        gyr = [a for a in self.axes if a.sensor == "gyro"]
        rad = math.radians(1.0)

        def walk(axes, factor):
            resolved = all(a.random_walk is not None for a in axes)
            value = max((a.random_walk if a.random_walk is not None else a.random_walk_upper)
                        for a in axes)
            return float(value * factor), not resolved

        arw, arw_upper = walk(acc, 1.0)
        grw, grw_upper = walk(gyr, rad)
        return {"accelerometer_noise_density": float(max(a.white for a in acc)),
                "accelerometer_random_walk": arw,
                "accelerometer_random_walk_is_upper_bound": arw_upper,
                "gyroscope_noise_density": float(max(a.white for a in gyr) * rad),
                "gyroscope_random_walk": grw,
                "gyroscope_random_walk_is_upper_bound": grw_upper,
                "update_rate": float(self.sample_rate_hz)}

    def block(self) -> dict:
        """The ``noise`` block of a calibration file (docs/calibration-file.md)."""
        return {
            "method": ("overlapping Allan deviation (NIST SP 1065 eq. 11), 68.3 % confidence from "
                       "chi-square with the exact degrees of freedom for white noise; N at slope "
                       "-1/2, B = min/0.664, K at slope +1/2 (sigma = K sqrt(tau/3))"),
            "source": self.source,
            "sample_rate_hz": float(self.sample_rate_hz),
            "duration_s": float(self.duration_s),
            "accel": {a.axis: a.report() for a in self.axes if a.sensor == "accel"},
            "gyro": {a.axis: a.report() for a in self.axes if a.sensor == "gyro"},
            "kalibr": self.kalibr(),
        }


def averaging_factors(n: int) -> np.ndarray:
    """The averaging factors m (tau = m / rate): about ten per decade from 1 to n // 5."""
    top = max(n // 5, 2)
    m = np.unique(np.round(np.logspace(0, math.log10(top), int(TAUS_PER_DECADE * math.log10(top)) + 1)))
    return m[m >= 1].astype(np.int64)


def overlapping_adev(y: np.ndarray, rate: float, m: np.ndarray, scale: float = 1.0) -> np.ndarray:
    """The overlapping Allan deviation of the samples ``y`` times ``scale`` (a rate, e.g. deg/s,
    at ``rate`` Hz) at tau = m / rate, NIST SP 1065 eq. (11): with the phase
    x_k = sum_{i<k} (y_i - mean) scale / rate (k = 0..n),
    sigma^2(tau) = sum_k (x_{k+2m} - 2 x_{k+m} + x_k)^2 / (2 tau^2 (n + 1 - 2m)).
    Memory: the phase (8 bytes a sample) and pieces of CHUNK second differences, whatever the
    length (``y`` may be a column of a larger array: it is not copied)."""
    n = len(y)
    x = np.empty(n + 1)
    x[0] = 0.0
    phase = x[1:]
    phase[:] = y
    phase -= phase.mean()
    phase *= scale / rate
    np.cumsum(phase, out=phase)
    out = np.empty(len(m))
    piece = np.empty(min(CHUNK, n + 1))
    for i, k in enumerate(np.asarray(m, np.int64)):
        k = int(k)
        count = n + 1 - 2 * k                   # second differences at this m
        if count <= 0:
            raise ValueError(f"averaging factor {k}: needs at least {2 * k} samples, got {n}")
        total = 0.0
        for a in range(0, count, CHUNK):
            b = min(a + CHUNK, count)
            v = piece[:b - a]
            np.multiply(x[a + k:b + k], -2.0, out=v)
            v += x[a + 2 * k:b + 2 * k]
            v += x[a:b]
            total += float(np.dot(v, v))
        out[i] = math.sqrt(total / (2.0 * count)) * rate / k
    return out


def white_noise_edf(m: np.ndarray, n: int) -> np.ndarray:
    """The equivalent degrees of freedom 2 E[s^2]^2 / Var[s^2] of the overlapping Allan variance
    s^2 at averaging factor m from n samples of white noise, exactly.

    The second differences v_k = x_{k+2m} - 2 x_{k+m} + x_k (M = n + 1 - 2m of them) are a
    moving sum of the samples with weights -1 (m of them) then +1 (m): their autocovariance at a
    lag of j samples is, in units of the samples' variance / rate^2, R_j = 2m - 3j for j <= m,
    j - 2m for m <= j <= 2m, 0 beyond.  s^2 is proportional to sum_k v_k^2, a Gaussian quadratic
    form: E = M R_0, Var = 2 sum_{|j|<M} (M - |j|) R_j^2, so edf = M^2 R_0^2 / sum_{|j|<M} (M - |j|) R_j^2.
    R_j being piecewise linear, the sum is a polynomial in m and M (power sums), computed here in
    exact integers: no array of 2m lags (hours of samples give m in the millions).
    (Greenhall and Riley's algorithm approximates this sum; it tends to 3 M / (2 m) for M >> m.)"""
    out = np.empty(len(m))
    for i, k in enumerate(np.asarray(m, np.int64)):
        k, big_m = int(k), n + 1 - 2 * int(k)
        out[i] = big_m * big_m * 4 * k * k / _weighted_square_sum(k, big_m)
    return out


def _power_sums(m: int) -> tuple[int, int, int]:
    """sum j, sum j^2, sum j^3 for j = 1..m."""
    s1 = m * (m + 1) // 2
    return s1, m * (m + 1) * (2 * m + 1) // 6, s1 * s1


def _weighted_square_sum(m: int, big_m: int) -> int:
    """sum_{|j|<M} (M - |j|) R_j^2 of white_noise_edf, in integers."""
    if big_m <= 2 * m:            # fewer differences than the autocovariance is long: the sum itself
        return big_m * 4 * m * m + 2 * sum((big_m - j) * (2 * m - 3 * j if j <= m else j - 2 * m) ** 2
                                           for j in range(1, big_m))
    s1, s2, s3 = _power_sums(m)               # j = 1..m: (M - j)(2m - 3j)^2
    first = big_m * (4 * m * m * m - 12 * m * s1 + 9 * s2) - (4 * m * m * s1 - 12 * m * s2 + 9 * s3)
    _, t2, t3 = _power_sums(m - 1)            # j = 2m - i, i = 1..m-1: (M - 2m + i) i^2
    second = (big_m - 2 * m) * t2 + t3
    return big_m * 4 * m * m + 2 * (first + second)


def deviation_interval(dev: np.ndarray, edf: np.ndarray, confidence: float = CONFIDENCE) -> tuple:
    """(lower, upper) ends of the two-sided ``confidence`` interval of deviations ``dev`` with
    ``edf`` degrees of freedom, from the chi-square distribution (NIST SP 1065 eq. 45)."""
    from scipy.special import chdtri       # the chi-square quantile, without scipy.stats' import

    tail = (1.0 - confidence) / 2.0
    var = np.asarray(dev, float) ** 2
    edf = np.asarray(edf, float)
    return (np.sqrt(edf * var / chdtri(edf, tail)),         # chi2 quantile 1 - tail
            np.sqrt(edf * var / chdtri(edf, 1.0 - tail)))   # chi2 quantile tail


@dataclass
class AllanCurve:
    """One axis's overlapping Allan deviation: numpy only (computed where the samples are)."""
    sensor: str
    axis: str
    unit: str
    m: np.ndarray                # averaging factors (tau = m / rate)
    adev: np.ndarray
    edf: np.ndarray              # equivalent degrees of freedom for white noise


def allan_curve(y: np.ndarray, rate: float, sensor: str, axis: str, unit: str,
                scale: float = 1.0) -> AllanCurve:
    """The curve of the samples ``y`` times ``scale`` (into ``unit``)."""
    m = averaging_factors(len(y))
    adev = overlapping_adev(y, rate, m, scale)
    keep = np.isfinite(adev) & (adev > 0)
    m, adev = m[keep], adev[keep]
    if len(m) < 3:
        raise UserError(f"{sensor} {axis}: the signal is constant: no noise to characterise")
    return AllanCurve(sensor, axis, unit, m, adev, white_noise_edf(m, len(y)))


def axis_terms(curve: AllanCurve, rate: float) -> AxisNoise:
    """The noise terms of one axis's curve (see the module doc)."""
    m, adev, edf = curve.m, curve.adev, curve.edf
    taus = m / rate
    lo, hi = deviation_interval(adev, edf)
    slope = np.gradient(np.log(adev), np.log(taus))

    white_ok = np.flatnonzero(np.abs(slope + 0.5) <= SLOPE_TOLERANCE)
    k = int(white_ok[np.argmax(edf[white_ok])]) if len(white_ok) else 0
    white = adev[k] * math.sqrt(taus[k])
    white_sigma = 0.5 * (hi[k] - lo[k]) * math.sqrt(taus[k])

    half = 0.5 * (hi - lo)
    i_min = int(np.argmin(adev))
    # the random walk: slope +1/2 after the minimum, significantly above the white line
    white_line = white / np.sqrt(taus)
    walk_ok = np.flatnonzero((np.abs(slope - 0.5) <= SLOPE_TOLERANCE) & (np.arange(len(taus)) > i_min)
                             & (lo > white_line))
    if len(walk_ok) >= 2:        # one point at the end of the curve is no slope
        j = int(walk_ok[np.argmax(edf[walk_ok])])
        walk_var = max(adev[j] ** 2 - white_line[j] ** 2, 0.0)      # less the white part there
        walk, walk_tau = math.sqrt(3.0 * walk_var / taus[j]), taus[j]
        walk_sigma = 3.0 * adev[j] * half[j] / (taus[j] * max(walk, 1e-300))
        walk_upper = walk
    else:
        walk = walk_sigma = walk_tau = None
        walk_upper = hi[-1] * math.sqrt(3.0 / taus[-1])
    # the flicker floor: where the curve is flat, what remains of sigma^2 once the white and
    # random-walk parts are taken away, if significant (3 sigma of the variance there); the
    # lowest such point, as IEEE reads B at the minimum of the curve
    floor_var = adev ** 2 - white_line ** 2 - (walk or 0.0) ** 2 * taus / 3.0
    flat = (np.abs(slope) <= SLOPE_TOLERANCE) & (floor_var > 3.0 * 2.0 * adev * half)
    if np.any(flat):
        i = int(np.flatnonzero(flat)[np.argmin(adev[flat])])
        bias, bias_tau = math.sqrt(floor_var[i]) / FLICKER_FACTOR, taus[i]
        bias_upper = bias
    else:
        bias, bias_tau, bias_upper = None, None, hi[i_min] / FLICKER_FACTOR
    return AxisNoise(curve.sensor, curve.axis, curve.unit, taus, adev, lo, hi, float(white), float(white_sigma),
                     float(taus[k]), bias, bias_tau, float(bias_upper), walk, walk_sigma, walk_tau,
                     float(walk_upper))


def allan_curves(accel: np.ndarray, gyro: np.ndarray, rate: float, source: str,
                 accel_scale=(1.0, 1.0, 1.0), gyro_scale=(1.0, 1.0, 1.0)) -> list:
    """AllanCurve per axis of (N,3) accelerometer samples times ``accel_scale`` (per axis, into
    m/s^2) and gyro samples times ``gyro_scale`` (into deg/s), accel x y z then gyro x y z.  The
    samples are neither copied nor scaled whole: one axis's phase at a time."""
    accel, gyro = np.asarray(accel), np.asarray(gyro)
    n = len(accel)
    if n < MIN_SAMPLES:
        raise UserError(f"{source}: {n} samples: the Allan deviation needs at least {MIN_SAMPLES} "
                        "(a long static recording: hours for the bias instability)")
    if not (math.isfinite(rate) and rate > 0):
        raise UserError(f"{source}: sample rate {rate!r} Hz: must be a positive number")
    curves = [allan_curve(accel[:, i], rate, "accel", a, "m/s^2", float(accel_scale[i]))
              for i, a in enumerate("xyz")]
    return curves + [allan_curve(gyro[:, i], rate, "gyro", a, "deg/s", float(gyro_scale[i]))
                     for i, a in enumerate("xyz")]


def from_curves(curves: list, rate: float, samples: int, source: str, segment: str | None = None) -> NoiseResult:
    return NoiseResult([axis_terms(c, rate) for c in curves], rate, samples / rate, source, segment)


def characterise(accel: np.ndarray, gyro: np.ndarray, rate: float, source: str,
                 accel_scale=(1.0, 1.0, 1.0), gyro_scale=(1.0, 1.0, 1.0)) -> NoiseResult:
    """Allan analysis of (N,3) accelerometer samples times ``accel_scale`` (into m/s^2) and gyro
    samples times ``gyro_scale`` (into deg/s)."""
    return from_curves(allan_curves(accel, gyro, rate, source, accel_scale, gyro_scale), rate, len(accel), source)


class LongestStatic:
    """from_capture's noise computed where a capture is read without its samples (station.
    estimate.summarise_while_importing: diagnose --report): ``check`` (a check_segment) keeps the
    samples of the longest complete static segment as the segments go by; ``curves`` (its
    ``then``) computes their Allan curves there, numpy only; ``noise(value)`` finishes them where
    scipy is: (NoiseResult or None, note).  The same segment and numbers as from_capture."""

    def __init__(self, capture, cal_doc=None):
        self.capture, self.cal_doc = capture, cal_doc
        self.seg = self.data = None

    def check(self, seg) -> None:
        if seg.kind == "static" and seg.status == "complete" and (
                self.data is None or len(seg.data.t) > len(self.data.t)):
            self.seg, self.data = seg, seg.data

    def curves(self) -> tuple:
        if self.seg is None:
            some = any(s.kind == "static" for s in self.capture.segments)
            return None, (f"Not characterised: {self.capture.path}: no {'complete ' if some else ''}static "
                          "segment to characterise")
        try:
            return segment_curves(self.capture, self.seg, self.data, self.cal_doc), None
        except UserError as e:
            return None, f"Not characterised: {e}"
        finally:
            self.seg = self.data = None

    @staticmethod
    def noise(value) -> tuple:
        curves, note = value
        return (None, note) if curves is None else (from_curves(*curves), None)


def _factors(imu, cal_doc, where: str) -> tuple[np.ndarray, np.ndarray]:
    """Per-axis factors turning the raw output into m/s^2 and deg/s (the calibration's scale
    factors for raw counts; the unit's factor otherwise: a scale error of < 0.1 % does not
    matter for noise figures)."""
    fa, fg = units.accel_to_mps2_factor(imu.accel_unit), units.gyro_to_dps_factor(imu.gyro_unit)
    comp = (cal_doc or {}).get("compensation") or {}
    if fa is None:
        if comp.get("accel_matrix") is None:
            raise UserError(f"{where}: accelerometer output in raw counts: give the calibration "
                            "(--cal) to turn it into m/s^2")
        fa = np.abs(np.diag(np.asarray(comp["accel_matrix"], float)))
    if fg is None:
        if comp.get("gyro_matrix") is None:
            raise UserError(f"{where}: gyro output in raw counts: give a calibration with a gyro "
                            "block (--cal) to turn it into deg/s")
        fg = np.abs(np.diag(np.asarray(comp["gyro_matrix"], float)))
    return np.broadcast_to(np.asarray(fa, float), (3,)), np.broadcast_to(np.asarray(fg, float), (3,))


def from_capture(capture, segment: str | None = None, cal_doc: dict | None = None) -> NoiseResult:
    """Characterise the named static segment of a capture, or its longest complete one; without
    a complete one, the longest incomplete one (a noise recording that was stopped or killed:
    the rows it holds before the recording stopped), which the result's source says.  Static
    segments not loaded are read one at a time and only the longest is kept (a capture with
    several long recordings is never held whole); the one characterised is left loaded (its
    ``data``: its gaps, for instance)."""
    statics = capture.complete("static")
    if segment is not None:
        seg = capture.segment(segment)
        if seg.kind != "static" or seg.status not in ("complete", "incomplete"):
            raise UserError(f"{capture.path}: segment {segment!r} is not a static segment")
        candidates = [seg]
    else:
        candidates = statics or [s for s in capture.segments if s.kind == "static" and s.status == "incomplete"]
        if not candidates:
            raise UserError(f"{capture.path}: no static segment to characterise")
    seg, data = None, None
    for candidate in candidates:
        samples = capture.read_samples(candidate)     # segment.data when loaded; None: no readable row
        if samples is not None and (data is None or len(samples.t) > len(data.t)):
            seg, data = candidate, samples
        del samples
    if seg is None:
        problem = candidates[0].problem or "no readable row"
        raise UserError(f"{capture.path}: static segment {candidates[0].name!r} is incomplete: {problem}")
    seg.data = data
    return from_curves(*segment_curves(capture, seg, seg.data, cal_doc))


def segment_curves(capture, seg, data, cal_doc: dict | None = None) -> tuple:
    """(curves, rate, samples, source, segment name) of one static segment's samples ``data`` (SegmentData):
    the part of from_capture that needs the samples, and no scipy (a process that reads the
    capture computes it: station diagnose --report); from_curves(*...) finishes it."""
    fa, fg = _factors(capture.imu, cal_doc, str(capture.path))
    rate = capture.imu.sample_rate_hz
    stopped = ", incomplete: the recording stopped there" if seg.status == "incomplete" else ""
    source = f"{capture.path}: static segment {seg.name} ({len(data.t)} samples{stopped})"
    return allan_curves(data.accel, data.gyro, rate, source, fa, fg), rate, len(data.t), source, seg.name


def from_samples(path, data, rate: float | None, accel_unit: str, gyro_unit: str,
                 cal_doc: dict | None = None) -> NoiseResult:
    """Characterise a still recording read from a CSV (``read_segment_csv``)."""
    from types import SimpleNamespace

    if rate is None:
        steps = np.diff(data.t)
        if len(steps) == 0 or not np.median(steps) > 0:
            raise UserError(f"{path}: cannot tell the sample rate from the t column: give --rate-hz")
        rate = 1.0 / float(np.median(steps))
    fa, fg = _factors(SimpleNamespace(accel_unit=accel_unit, gyro_unit=gyro_unit), cal_doc, str(path))
    return characterise(data.accel, data.gyro, rate, f"{path} ({len(data.t)} samples)", fa, fg)
