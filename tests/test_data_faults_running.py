"""The data-fault scan keeps the statics' noise median as they come (issue 27 item 4: the median
over every static scanned, at every segment, made the scan quadratic in the statics): the
running median is numpy's median of the rows so far, exactly, ties and even counts included."""
import numpy as np
import pytest

from station.estimate.data_faults import _RunningMedian


@pytest.mark.parametrize("decimals", [None, 1, 0])
def test_running_median_is_numpys_median_of_the_rows_so_far(decimals):
    rng = np.random.default_rng(5)
    rows = rng.standard_normal((301, 3)) * [1e-3, 1.0, 1e3]
    if decimals is not None:                  # many ties
        rows = np.round(rows, decimals)
    running = _RunningMedian(3)
    for i, row in enumerate(rows):
        running.add(row)
        np.testing.assert_array_equal(running.median(), np.median(rows[:i + 1], axis=0))
