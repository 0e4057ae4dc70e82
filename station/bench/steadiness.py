"""Does the IMU agree with the table about a recording?  While a static is recorded the table
holds still, while a rotation is recorded it holds its rate (the sequencer reads the table's
encoders meanwhile: station/bench/sequencer.py).  The IMU measures the same motion: a static
whose gyro changes, or whose gravity direction turns, between the window's first seconds and the
next, or a rotation whose measured rate changes between them, was recorded while the table was
still moving (the end of a move, a rotation's spin-up).  That happens when the IMU's
samples reach this computer late against the table's answer ("at rest", "at rate"): the settle
counts from the newest sample received then (``ImuStream.sync``), so a reader whose frames were
still on their way starts the window too early.  It was seen on the device twins under load
(issue 29: a static recorded while the table turned 90 deg, reduced chi2 of the fit 1.55 up
to "not converged"); a USB adapter's latency or an overloaded computer can do it on a bench.
The disagreement is a finding, never fitted: the recording is kept aside and recorded again
after a fresh settle (station/bench/sequencer.py ``_record_segment``).

The test compares, at the window's start, the mean of a leading span of k samples with the mean
of the next k (k for 1 s, 4 s and 16 s of samples, at most half the window): a move's tail or a
spin-up is where the window began, and a short span is not diluted by a long window (a static of
2 h compared by thirds kept the last 0.2 s of a brake: found by this session's review), while two
adjacent spans of at most 16 s see almost nothing of a slow drift (a horizontal accelerometer
drift of 1 mg over a 2 h noise recording moves 2 ug between them; compared by thirds it was
refused).  The difference of two means of k white samples has 1-sigma ``sigma * sqrt(2 / k)``,
sigma per axis from the median absolute successive difference (``median |x[k+1] - x[k]| = 0.6745
sqrt(2) sigma`` for white noise; a few samples of motion barely move a median).  A difference
beyond ``Z`` of those 1-sigma *and* beyond the table's own tolerance (what the sequencer accepts
from the encoders: the rate tolerance, the position hold) is motion.  Z = 6: a two-sided normal
tail of 2e-9 per axis and span, so a clean recording is never refused by chance.  Only the
window's first ``HEAD_S`` seconds are needed (channels.Recording keeps those, not the window).
"""
from __future__ import annotations

import math

import numpy as np

Z = 6.0
#: the table's tolerances are multiplied by this for the floor (as the sequencer's hold checks)
TOLERANCE_FACTOR = 10.0
SPANS_S = (1.0, 4.0, 16.0)  # leading spans compared with the next span of the same length
HEAD_S = 2 * max(SPANS_S)   # the window's first seconds the test reads
MIN_SPAN = 3                # fewer samples per span: nothing tested


def white_sigma(x: np.ndarray) -> np.ndarray:
    """Per column, the white-noise 1-sigma of ``x`` from its median absolute successive
    difference (robust to a few samples of motion)."""
    d = np.abs(np.diff(np.asarray(x, dtype=float), axis=0))
    return np.median(d, axis=0) / (0.6744897501960817 * math.sqrt(2.0))


def spans(n: int, rate_hz: float) -> list[int]:
    """The leading spans' lengths (samples) tested in a window of ``n`` samples."""
    out = sorted({min(int(round(s * rate_hz)), n // 2) for s in SPANS_S})
    return [k for k in out if k >= MIN_SPAN]


def motion_found(kind: str, accel: np.ndarray, gyro: np.ndarray, *, rate_hz: float, rate_tolerance_dps: float,
                 hold_deg: float) -> str | None:
    """Why the IMU says the table was not holding at the start of this recording (words for the
    note of a bad recording), or None.  ``kind``: "static" or "rotation"; ``accel`` (n, 3) in
    m/s^2 and ``gyro`` (n, 3) in deg/s (the driver's units): the window's samples from its start
    (its first HEAD_S seconds are enough), at ``rate_hz``; ``rate_tolerance_dps`` and
    ``hold_deg``: the table's rate tolerance and the position hold the sequencer allows while
    recording."""
    accel, gyro = np.asarray(accel, dtype=float), np.asarray(gyro, dtype=float)
    head = int(math.ceil(HEAD_S * rate_hz))
    accel, gyro = accel[:head], gyro[:head]
    ks = spans(len(gyro), rate_hz)
    if not ks or kind not in ("static", "rotation"):
        return None
    rate_floor = TOLERANCE_FACTOR * rate_tolerance_dps
    if kind == "rotation":
        w = np.linalg.norm(gyro, axis=1)
        sigma = float(white_sigma(w[:, None])[0])
        for k in ks:
            change = float(w[k:2 * k].mean() - w[:k].mean())
            limit = max(Z * sigma * math.sqrt(2.0 / k), rate_floor)
            if abs(change) > limit:
                return (f"the IMU's rate changed by {change:+.3g} deg/s between the window's first {k / rate_hz:.3g} s "
                        f"and the next (limit {limit:.3g} deg/s) while the table held its rate: recorded before "
                        "the table was at rate")
        return None
    sg, sa = white_sigma(gyro), white_sigma(accel)
    for k in ks:
        scale = math.sqrt(2.0 / k)
        change = gyro[k:2 * k].mean(axis=0) - gyro[:k].mean(axis=0)
        limits = np.maximum(Z * sg * scale, rate_floor)
        if np.any(np.abs(change) > limits):
            i = int(np.argmax(np.abs(change) / limits))
            return (f"the IMU's {'xyz'[i]} gyro changed by {change[i]:+.3g} deg/s between the window's first "
                    f"{k / rate_hz:.3g} s and the next (limit {limits[i]:.3g} deg/s) while the table held still: "
                    "recorded while it was moving")
        a0, a1 = accel[:k].mean(axis=0), accel[k:2 * k].mean(axis=0)
        n0, n1 = float(np.linalg.norm(a0)), float(np.linalg.norm(a1))
        if n0 > 0 and n1 > 0:
            turned = math.degrees(math.acos(max(-1.0, min(1.0, float(a0 @ a1) / (n0 * n1)))))
            limit = max(Z * math.degrees(float(np.linalg.norm(sa * scale)) / n0), hold_deg)
            if turned > limit:
                return (f"the IMU's gravity direction turned {turned:.3g} deg between the window's first "
                        f"{k / rate_hz:.3g} s and the next (limit {limit:.3g} deg) while the table held still: "
                        "recorded while it was moving")
    return None


#: a recorded ramp's check allows the IMU's clock this far from the table's reads as placed (s):
#: a time offset is what the estimator measures from these windows (station/model/time_offset.py:
#: 1-10 ms over USB and serial links, buffered MEMS), not a disagreement; five times the largest
RAMP_OFFSET_ALLOWANCE_S = 0.05
#: the gyro's bias may differ between the window's rest and its turns by this much (deg/s): a
#: MEMS gyro's g-sensitivity (up to ~0.1 deg/s/g) moves its bias with the attitude, and the rest
#: is at one attitude while the turns sweep gravity round (0.1 deg/s/g coupled into the axis: 8 deg
#: over an 82 s window at 5 deg/s, every good window refused before; review of issue 28)
RAMP_BIAS_SHIFT_DPS = 0.1
#: of the window's compiled rest and turns at the rate, the part whose samples the check takes as
#: at rest or at the rate (the rest before a late command, the turns after a late one: the rest
#: of each is the margin)
RAMP_PART = 0.5


def ramp_disagreement(ramp: str, head: np.ndarray, tail: np.ndarray, gyro_sum: np.ndarray, samples: int, *,
                      window_s: float, rate_hz: float, rest_s: float, turning_s: float, table_rate_dps: float,
                      table_angle_deg: float, angle_sigma_deg: float, position_tolerance_deg: float) -> str | None:
    """Why the IMU's gyro says a recorded ramp's window did not turn through the table's angle
    (words for a bad recording's note), or None.  The IMU's angle over the window, from its own
    samples and nothing the calibration is to find: the integral of the gyro (``gyro_sum`` over
    ``samples`` frames, times ``window_s``), less its bias (the mean of the window's rest: its first
    ``RAMP_PART`` x ``rest_s`` s for ramp "start", ``head``; its last for "end", ``tail``) over the
    window, along the rate's direction in the IMU's frame (the mean of the samples at the rate: the
    last or first ``RAMP_PART`` x ``turning_s`` s), scaled to the table's rate (their norm against
    ``table_rate_dps``: the gyro's scale and misalignment cancel).  Against the table's angle
    (``table_angle_deg``, its magnitude), a difference beyond Z of its 1-sigma (the window's
    angle_sigma_deg; the gyro's white noise over the window, its bias and scale from the samples
    taken; two encoder reads), the time offset allowed (RAMP_OFFSET_ALLOWANCE_S at the rate) and the bias shift
    allowed (RAMP_BIAS_SHIFT_DPS over the window: a gyro's g-sensitivity between rest and turns) is
    a finding: the table's reads misplaced on the IMU's clock, the IMU's frames late against them,
    or a window that does not hold what the table says."""
    head, tail = np.asarray(head, dtype=float), np.asarray(tail, dtype=float)
    at_rest, at_rate = (head, tail) if ramp == "start" else (tail, head)
    # as many of those samples as the recording kept of its ends (HEAD_S each): a longer rest or
    # turns are taken in part (before, a window with more than 2 HEAD_S of turns went unchecked)
    n_rest = min(int(RAMP_PART * rest_s * rate_hz), len(at_rest))
    n_turn = min(int(RAMP_PART * turning_s * rate_hz), len(at_rate))
    if samples < 1 or n_rest < MIN_SPAN or n_turn < MIN_SPAN:
        return None
    rest, turn = (head[:n_rest], tail[-n_turn:]) if ramp == "start" else (tail[-n_rest:], head[:n_turn])
    bias = rest.mean(axis=0)
    w = turn.mean(axis=0) - bias
    gain = float(np.linalg.norm(w)) / abs(float(table_rate_dps))
    if not gain > 0:
        return "the IMU's gyro saw no turn where the table turned"
    u = w / np.linalg.norm(w)
    imu_deg = float((np.asarray(gyro_sum, dtype=float) / samples - bias) @ u) * window_s / gain
    table_deg = abs(float(table_angle_deg))
    sigma_g = float(np.sqrt(white_sigma(rest) ** 2 @ u ** 2))       # one sample along u, deg/s
    period = 1.0 / rate_hz
    sigma = math.sqrt(float(angle_sigma_deg) ** 2
                      + ((sigma_g * period) ** 2 * samples                      # white noise integrated
                         + (sigma_g / math.sqrt(n_rest) * window_s) ** 2) / gain ** 2     # the bias taken
                      + (table_deg * sigma_g / math.sqrt(n_turn) / float(np.linalg.norm(w))) ** 2   # the gain
                      + 2.0 * float(position_tolerance_deg) ** 2)
    shift_deg = RAMP_BIAS_SHIFT_DPS * window_s / gain
    limit = Z * sigma + abs(float(table_rate_dps)) * RAMP_OFFSET_ALLOWANCE_S + shift_deg
    if abs(imu_deg - table_deg) > limit:
        return (f"the IMU's gyro turned {imu_deg:.4g} deg over the recorded ramp's window where the table's reads "
                f"say {table_deg:.4g} deg (limit {limit:.3g} deg: {Z:g} x its 1-sigma {sigma:.3g} deg, "
                f"{RAMP_OFFSET_ALLOWANCE_S * 1e3:g} ms of time offset at {abs(table_rate_dps):g} deg/s and "
                f"{RAMP_BIAS_SHIFT_DPS:g} deg/s of bias shift over {window_s:.3g} s)")
    return None
