"""Moving averages of samples along time (axis 0), in numpy.

The window of ``window`` samples for sample i runs from i - window // 2 to i - window // 2 +
window - 1 (centred; one more before than after for an even window) and is extended past the
ends by repeating the edge sample (``mode="nearest"``) or by mirroring the samples with the edge
one repeated (``mode="reflect"``: d c b a | a b c d | d c b a): what scipy.ndimage's
uniform_filter1d computes (tests/test_moving_average.py compares them), without importing
scipy.ndimage (~0.2 s of CPU through scipy's array-API layer, 31 % of an import's CPU: issue 27).

One cumulative sum of the padded samples, taken about each column's first sample so that the
sums stay small: the rounding of a running sum grows with the sum's size (the sum of n samples
of size s is exact to ~n s eps); about the first sample it is the size of the samples' spread,
not of their value (a raw-count accelerometer reads ~32,768 with a spread of a few counts).
"""
from __future__ import annotations

import numpy as np

MODES = {"nearest": "edge", "reflect": "symmetric"}      # scipy.ndimage's name -> numpy.pad's


def moving_mean(x, window: int, *, mode: str = "reflect") -> np.ndarray:
    """The mean over a centred window of ``window`` samples of every sample of ``x`` (N,) or
    (N, k), float64, the same shape."""
    x = np.asarray(x, dtype=np.float64)
    if window < 1:
        raise ValueError(f"window must be at least 1 sample, got {window}")
    if mode not in MODES:
        raise ValueError(f"mode: one of {', '.join(MODES)}, not {mode!r}")
    if window == 1 or len(x) == 0:
        return x.copy()
    before = window // 2
    after = window - 1 - before
    origin = x[:1]
    pad = [(before, after)] + [(0, 0)] * (x.ndim - 1)
    padded = np.pad(x - origin, pad, mode=MODES[mode])
    sums = np.empty((len(padded) + 1,) + x.shape[1:])
    sums[0] = 0.0
    np.cumsum(padded, axis=0, out=sums[1:])
    out = sums[window:] - sums[:-window]
    out /= window
    out += origin
    return out


def moving_std(x, window: int, *, mode: str = "nearest") -> np.ndarray:
    """The standard deviation (population: divided by the window) over the same windows:
    sqrt(mean of squares - square of mean), about each column's first sample."""
    x = np.asarray(x, dtype=np.float64)
    d = x - x[:1] if len(x) else x
    m = moving_mean(d, window, mode=mode)
    m2 = moving_mean(d * d, window, mode=mode)
    return np.sqrt(np.maximum(m2 - m * m, 0.0))
