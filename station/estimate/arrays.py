"""numpy's unique and median of the estimate's path, the same numbers without importing
numpy.ma: np.unique asks ``np.ma.is_masked`` and np.median ``np.ma.isMaskedArray``, and numpy.ma
costs ~7 ms in each process of a small estimate (issue 27; tests/test_estimate_imports.py
compares them with numpy's)."""
from __future__ import annotations

import numpy as np


def distinct(a) -> np.ndarray:
    """``np.unique(a)`` of a 1-D array, the same values in the same order (one NaN kept, as
    np.unique's equal_nan), without importing numpy.ma: np.unique asks ``np.ma.is_masked``, and
    numpy.ma is ~7 ms of an estimate's start in each of its two processes (issue 27)."""
    s = np.sort(np.asarray(a).ravel())
    keep = np.empty(s.shape, bool)
    if not len(s):
        return s
    keep[0] = True
    np.not_equal(s[1:], s[:-1], out=keep[1:])
    if s.dtype.kind in "cf" and np.isnan(s[-1]):       # NaNs sort last: keep the first of them
        first = int(np.searchsorted(s, s[-1], side="left"))
        keep[first] = True
        keep[first + 1:] = False
    return s[keep]


def median(a, axis: int | None = None):
    """``np.median(a)`` (a float) or ``np.median(a, axis=0)`` of a 2-D array, the same numbers
    (the middle value, or the mean of the two middle values; NaN when any is NaN), without
    importing numpy.ma: np.median's NaN check asks ``np.ma.isMaskedArray`` (issue 27)."""
    a = np.asarray(a, float)
    if axis is None:
        a = a.ravel()
    elif axis != 0 or a.ndim != 2:
        raise ValueError("median: a 1-D array, or axis=0 of a 2-D one")
    n = a.shape[0]
    if n == 0:
        return np.median(a, axis=axis)      # numpy's warning and NaN
    half = n // 2
    kth = [half - 1, half, n - 1] if n % 2 == 0 else [half, n - 1]
    part = np.partition(a, sorted(set(kth)), axis=0)
    middle = part[half] if n % 2 else np.mean(part[half - 1:half + 1], axis=0)
    result = np.where(np.isnan(part[n - 1]), np.nan, middle)
    return float(result) if axis is None else result
