"""Static intervals and turns in a continuous IMU recording (hand calibration, ``table: none``).

``detect(t, accel, gyro)`` splits a recording into still intervals and the motions between
them; ``match(detection, specs)`` assigns them to a scheme's segments.  No calibration is
needed: only how the raw outputs vary.

1. Over a sliding window (``window_s``), the standard deviation of every accelerometer and
   gyro channel.  The noise floor is a low percentile of those (``QUIET_PERCENTILE``: most of a
   hand calibration is spent still).  A sample is a candidate for "still" when both deviations
   are below ``NOISE_FACTOR`` times the floor (never below the absolute floors, for quantised
   outputs).
2. The gyro bias is the median gyro output over the candidates; a candidate is still when its
   windowed mean rate, less the bias, is also below ``rate_threshold_dps`` (a slow, steady turn
   has a small spread but a large mean).
3. Runs of still samples at least ``min_static_s`` long are static intervals (trimmed by half
   a window at each end); shorter pauses, e.g. between the quarter turns of a hand turn, belong
   to the motion around them.  Each motion between two static intervals gets its rotation
   vector, the integral of (gyro - bias): for a turn about a fixed axis its direction is the
   axis and its length the angle turned.

Units.  The thresholds are physical (m/s^2, deg/s): the outputs are first converted with
``accel_mps2_per_unit`` and ``gyro_dps_per_unit`` (1 for m/s^2 and deg/s; the declared unit's
factor, or a raw output's nominal scale).  A raw output of unknown scale (``None``) is scaled
from the initial rest, the first ``init_rest_s`` seconds, which must be still (as imu_tk asks
for): the accelerometer by |mean| = standard gravity there (its bias and scale errors move the
thresholds by a few per cent at most); the gyro's rate threshold becomes ``RAW_RATE_NOISE_FACTOR``
times the largest per-sample standard deviation of the gyro there.  ``Detection.thresholds``
says which were used.  Interval means and rotation vectors stay in the input's units.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from station.io.moving_average import moving_mean, moving_std

QUIET_PERCENTILE = 20.0
NOISE_FACTOR = 4.0
ACCEL_STD_FLOOR_MPS2 = 0.005
GYRO_STD_FLOOR_DPS = 0.02
STANDARD_GRAVITY_MPS2 = 9.80665
RAW_RATE_NOISE_FACTOR = 10.0   # raw gyro of unknown scale: rate threshold / rest noise (per sample)
DEFAULT_INIT_REST_S = 2.0


@dataclass
class Interval:
    kind: str                   # "static" or "motion"
    start: int                  # first sample
    stop: int                   # one past the last sample
    accel_mean: np.ndarray      # (3,) raw units
    gyro_mean: np.ndarray       # (3,) raw units
    rotation: np.ndarray        # (3,) integral of (gyro - bias), gyro units x s

    @property
    def angle(self) -> float:
        return float(np.linalg.norm(self.rotation))

    @property
    def axis(self) -> np.ndarray:
        n = np.linalg.norm(self.rotation)
        return self.rotation / n if n > 0 else np.zeros(3)

    @property
    def up(self) -> np.ndarray:
        """Direction of the mean specific force (local up for a static interval)."""
        return self.accel_mean / np.linalg.norm(self.accel_mean)


@dataclass
class Detection:
    intervals: list             # Interval, in time order, statics and motions alternating
    gyro_bias: np.ndarray
    accel_noise: float          # noise floor: windowed standard deviation
    gyro_noise: float
    still: np.ndarray           # (N,) bool
    thresholds: dict = None     # what "still" meant, in physical units where known

    def statics(self) -> list:
        return [i for i in self.intervals if i.kind == "static"]

    def motions(self) -> list:
        return [i for i in self.intervals if i.kind == "motion"]


def still_mask(accel, gyro, window: int, *, accel_threshold: float, gyro_threshold: float,
               bias=None, rate_threshold_dps: float | None = None) -> np.ndarray:
    """Samples whose window has every channel's spread below the thresholds (and, with a
    ``bias``, a mean rate within ``rate_threshold_dps`` of it)."""
    sa = _moving_std(accel, window).max(axis=1)
    sg = _moving_std(gyro, window).max(axis=1)
    still = (sa <= accel_threshold) & (sg <= gyro_threshold)
    if bias is not None:
        mean = moving_mean(gyro, window, mode="nearest")
        still &= np.linalg.norm(mean - bias, axis=1) <= rate_threshold_dps
    return still


def detect(t, accel, gyro, *, window_s: float = 0.5, min_static_s: float = 2.0,
           rate_threshold_dps: float = 1.0, accel_mps2_per_unit: float | None = 1.0,
           gyro_dps_per_unit: float | None = 1.0, init_rest_s: float = DEFAULT_INIT_REST_S) -> Detection:
    """Static intervals and the motions between them (module docstring).  ``accel`` and
    ``gyro`` in any unit, with the factors to m/s^2 and deg/s (``None``: raw of unknown scale,
    scaled from the initial rest)."""
    t = np.asarray(t, float)
    accel = np.asarray(accel, float)
    gyro = np.asarray(gyro, float)
    if len(t) < 4:
        raise ValueError("a recording of at least 4 samples is needed")
    dt = float(np.median(np.diff(t)))
    window = max(3, int(round(window_s / dt)) | 1)
    rest = slice(0, max(window, int(round(init_rest_s / dt))))
    thresholds = {"window_s": window * dt, "min_static_s": float(min_static_s)}
    if accel_mps2_per_unit is None:
        norm = float(np.linalg.norm(accel[rest].mean(axis=0)))
        if not norm > 0:
            raise ValueError("the initial rest has a zero mean specific force: the accelerometer "
                             "scale cannot be found from it")
        accel_mps2_per_unit = STANDARD_GRAVITY_MPS2 / norm
        # (no '|' in what the manifest keeps: a '|' sends the whole manifest to the pure-Python
        # YAML loader, station.core.yaml_text; issue 27)
        thresholds["accel_scale_from"] = "initial rest (the norm of its mean = standard gravity)"
    a = accel * accel_mps2_per_unit
    if gyro_dps_per_unit is None:
        rest_sigma = float(np.max(np.std(gyro[rest], axis=0)))
        steps = np.abs(np.diff(gyro[rest], axis=0))
        step = float(steps[steps > 0].min()) if (steps > 0).any() else 0.0
        rate_threshold = RAW_RATE_NOISE_FACTOR * max(rest_sigma, step)
        g, gyro_floor, g_factor = gyro, step, 1.0
        thresholds["rate_threshold_raw"] = rate_threshold
        thresholds["rate_threshold_from"] = (f"initial rest noise ({RAW_RATE_NOISE_FACTOR:g} x "
                                             f"{max(rest_sigma, step):.3g} raw)")
    else:
        g_factor = float(gyro_dps_per_unit)
        g, gyro_floor = gyro * g_factor, GYRO_STD_FLOOR_DPS
        rate_threshold = float(rate_threshold_dps)
        thresholds["rate_threshold_dps"] = rate_threshold
    sa = _moving_std(a, window).max(axis=1)
    sg = _moving_std(g, window).max(axis=1)
    noise_a = max(float(np.percentile(sa, QUIET_PERCENTILE)), ACCEL_STD_FLOOR_MPS2 / NOISE_FACTOR)
    noise_g = max(float(np.percentile(sg, QUIET_PERCENTILE)), gyro_floor / NOISE_FACTOR)
    thresholds["accel_std_threshold_mps2"] = NOISE_FACTOR * noise_a
    thresholds["gyro_std_threshold" + ("_raw" if gyro_dps_per_unit is None else "_dps")] = NOISE_FACTOR * noise_g
    candidate = (sa <= NOISE_FACTOR * noise_a) & (sg <= NOISE_FACTOR * noise_g)
    bias = np.median(g[candidate], axis=0) if candidate.any() else np.zeros(3)
    mean = moving_mean(g, window, mode="nearest")
    still = candidate & (np.linalg.norm(mean - bias, axis=1) <= rate_threshold)

    runs = [(a0, b0) for a0, b0 in _runs(still) if t[b0 - 1] - t[a0] + dt >= min_static_s]
    half = window // 2
    intervals = []
    bias_in_units = bias / g_factor
    for k, (a0, b0) in enumerate(runs):
        if k:
            prev = runs[k - 1][1]
            intervals.append(_interval("motion", prev, a0, dt, accel, gyro, bias_in_units))
        s0, s1 = a0 + half, max(a0 + half + 1, b0 - half)
        intervals.append(_interval("static", s0, s1, dt, accel, gyro, bias_in_units))
    return Detection(intervals, bias_in_units, noise_a / accel_mps2_per_unit, noise_g / g_factor, still,
                     thresholds)


def match(detection: Detection, specs, *, max_tilt_deg: float = 30.0, turn_tolerance: float = 0.25,
          max_axis_deg: float = 30.0) -> dict:
    """{segment name: (Interval, sign)} for the scheme's ``specs`` (StaticSpec/RotationSpec).

    A static segment gets the longest static interval whose up direction is within
    ``max_tilt_deg`` of its ``up_body``; a rotation the motion whose angle is within
    ``turn_tolerance`` of its ``turn_deg`` (default 360) and whose axis is within
    ``max_axis_deg`` of +-``axis_body``; ``sign`` is the direction found (+1 right-handed
    about axis_body).  Each interval serves one segment; segments without a match are left out."""
    used, out = set(), {}
    cos_tilt, cos_axis = np.cos(np.radians(max_tilt_deg)), np.cos(np.radians(max_axis_deg))
    for spec in specs:
        if spec.kind == "static":
            found = [iv for iv in detection.statics()
                     if id(iv) not in used and float(iv.up @ np.asarray(spec.up_body)) >= cos_tilt]
            if found:
                best = max(found, key=lambda iv: iv.stop - iv.start)
                used.add(id(best))
                out[spec.name] = (best, 1.0)
        else:
            turn = spec.turn_deg or 360.0
            axis = np.asarray(spec.axis_body, float)
            found = [iv for iv in detection.motions()
                     if id(iv) not in used and abs(iv.angle - turn) <= turn_tolerance * turn
                     and abs(float(iv.axis @ axis)) >= cos_axis]
            if found:
                best = min(found, key=lambda iv: abs(iv.angle - turn))
                used.add(id(best))
                out[spec.name] = (best, float(np.sign(best.axis @ axis)))
    return out


def _interval(kind, a, b, dt, accel, gyro, bias) -> Interval:
    rotation = (gyro[a:b] - bias).sum(axis=0) * dt          # sample k stands for dt around t_k
    return Interval(kind, int(a), int(b), accel[a:b].mean(axis=0), gyro[a:b].mean(axis=0), rotation)


def _moving_std(x, window: int) -> np.ndarray:
    return moving_std(x, window, mode="nearest")


def _runs(mask) -> list:
    """(start, stop) of the runs of True in ``mask``."""
    padded = np.concatenate([[False], np.asarray(mask, bool), [False]])
    edges = np.flatnonzero(np.diff(padded.astype(np.int8)))
    return list(zip(edges[::2], edges[1::2]))
