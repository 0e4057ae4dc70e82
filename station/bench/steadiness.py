"""Does the IMU agree with the table about a recording?  While a static is recorded the table
holds still, while a rotation is recorded it holds its rate (the sequencer reads the table's
encoders meanwhile: station/bench/sequencer.py).  The IMU measures the same motion: a static
whose gyro changes, or whose gravity direction turns, between the first and the last third of
the window, or a rotation whose measured rate changes between them, was recorded while the
table was still moving (the end of a move, a rotation's spin-up).  That happens when the IMU's
samples reach this computer late against the table's answer ("at rest", "at rate"): the settle
counts from the newest sample received then (``ImuStream.sync``), so a reader whose frames were
still on their way starts the window too early.  It was seen on the device twins under load
(issue 29: a static recorded while the table turned 90 deg, reduced chi2 of the fit 1.55 up
to "not converged"); a USB adapter's latency or an overloaded computer can do it on a bench.
The disagreement is a finding, never fitted: the recording is kept aside and recorded again
after a fresh settle (station/bench/sequencer.py ``_record_segment``).

The test compares the means of the first and the last third of the window (m samples each):
their difference of white noise has 1-sigma ``sigma * sqrt(2 / m)``, sigma per axis from the
median absolute successive difference (``median |x[k+1] - x[k]| = 0.6745 sqrt(2) sigma`` for
white noise; a few samples of motion barely move a median).  A difference beyond ``Z`` of those
1-sigma *and* beyond the table's own tolerance (what the sequencer accepts from the encoders:
the rate tolerance, the position hold) is motion.  Z = 6: a two-sided normal tail of 2e-9 per
axis, so a clean recording is never refused by chance; a bias that drifts (temperature, bias
instability) moves far less than the floors (0.1 deg/s; 0.02 deg of gravity's direction, 340 ug
at 1 g) within one segment.
"""
from __future__ import annotations

import math

import numpy as np

Z = 6.0
#: the table's tolerances are multiplied by this for the floor (as the sequencer's hold checks)
TOLERANCE_FACTOR = 10.0
MIN_THIRD = 3               # fewer samples per third: nothing tested


def white_sigma(x: np.ndarray) -> np.ndarray:
    """Per column, the white-noise 1-sigma of ``x`` from its median absolute successive
    difference (robust to a few samples of motion)."""
    d = np.abs(np.diff(np.asarray(x, dtype=float), axis=0))
    return np.median(d, axis=0) / (0.6744897501960817 * math.sqrt(2.0))


def motion_found(kind: str, accel: np.ndarray, gyro: np.ndarray, *, rate_tolerance_dps: float,
                 hold_deg: float) -> str | None:
    """Why the IMU says the table was not holding during this recording (words for the note of
    a bad recording), or None.  ``kind``: "static" or "rotation"; ``accel`` (n, 3) in m/s^2 and
    ``gyro`` (n, 3) in deg/s (the driver's units); ``rate_tolerance_dps`` and ``hold_deg``: the
    table's rate tolerance and the position hold the sequencer allows while recording."""
    accel, gyro = np.asarray(accel, dtype=float), np.asarray(gyro, dtype=float)
    m = len(gyro) // 3
    if m < MIN_THIRD:
        return None
    scale = math.sqrt(2.0 / m)                 # the difference of two means of m white samples
    rate_floor = TOLERANCE_FACTOR * rate_tolerance_dps
    if kind == "rotation":
        w = np.linalg.norm(gyro, axis=1)
        change = float(w[-m:].mean() - w[:m].mean())
        limit = max(Z * float(white_sigma(w[:, None])[0]) * scale, rate_floor)
        if abs(change) > limit:
            return (f"the IMU's rate changed by {change:+.3g} deg/s between the window's first and last "
                    f"third (limit {limit:.3g} deg/s) while the table held its rate: recorded before the "
                    "table was at rate")
        return None
    if kind != "static":
        return None
    change = gyro[-m:].mean(axis=0) - gyro[:m].mean(axis=0)
    limits = np.maximum(Z * white_sigma(gyro) * scale, rate_floor)
    if np.any(np.abs(change) > limits):
        i = int(np.argmax(np.abs(change) / limits))
        return (f"the IMU's {'xyz'[i]} gyro changed by {change[i]:+.3g} deg/s between the window's first "
                f"and last third (limit {limits[i]:.3g} deg/s) while the table held still: recorded while "
                "it was moving")
    a0, a1 = accel[:m].mean(axis=0), accel[-m:].mean(axis=0)
    n0, n1 = float(np.linalg.norm(a0)), float(np.linalg.norm(a1))
    if n0 > 0 and n1 > 0:
        turned = math.degrees(math.acos(max(-1.0, min(1.0, float(a0 @ a1) / (n0 * n1)))))
        limit = max(Z * math.degrees(float(np.linalg.norm(white_sigma(accel) * scale)) / n0), hold_deg)
        if turned > limit:
            return (f"the IMU's gravity direction turned {turned:.3g} deg between the window's first and "
                    f"last third (limit {limit:.3g} deg) while the table held still: recorded while it "
                    "was moving")
    return None
