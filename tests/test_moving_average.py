"""station.io.moving_average against scipy.ndimage.uniform_filter1d (what it replaces, issue 27
item 2) and against the explicit window means."""
import numpy as np
import pytest
from scipy.ndimage import uniform_filter1d

from station.io.moving_average import moving_mean, moving_std

EPS = np.finfo(float).eps


def explicit(x, window, mode):
    before = window // 2
    pad = np.pad(x, [(before, window - 1 - before), (0, 0)], mode={"nearest": "edge", "reflect": "symmetric"}[mode])
    return np.array([pad[i:i + window].mean(axis=0) for i in range(len(x))])


@pytest.mark.parametrize("mode", ["nearest", "reflect"])
@pytest.mark.parametrize("n,window", [(1, 1), (1, 4), (2, 3), (7, 7), (50, 4), (50, 51), (300, 9), (300, 1000),
                                      (5000, 51)])
def test_the_same_means_as_scipy_and_as_each_window(mode, n, window):
    rng = np.random.default_rng(n * 1000 + window)
    x = 32768.0 + rng.normal(size=(n, 3)) * np.array([3.0, 0.01, 300.0])   # raw counts: large offset, any spread
    got = moving_mean(x, window, mode=mode)
    # rounding: a sum of up to n + window terms, each off by eps times the largest |x|; scipy's
    # running sum is in the samples' own size (~32768), ours about the first sample
    tol = 4 * (n + window) * EPS * np.abs(x).max()
    np.testing.assert_allclose(got, uniform_filter1d(x, window, axis=0, mode=mode), rtol=0, atol=tol)
    np.testing.assert_allclose(got, explicit(x, window, mode), rtol=0, atol=tol)
    assert got.shape == x.shape
    one = moving_mean(x[:, 1], window, mode=mode)
    np.testing.assert_allclose(one, got[:, 1], rtol=0, atol=tol)


def test_the_spread_is_kept_where_the_value_is_large():
    """A still raw-count accelerometer (32768 counts, spread 0.3): the windows' standard deviation
    to 1e-6 of the spread, where a running sum of the counts themselves is off by ~1e-12 of
    32768 x 50,000 samples' sum."""
    rng = np.random.default_rng(5)
    x = 32768.0 + 0.3 * rng.standard_normal((50_000, 3))
    got = moving_std(x, 101)
    k = np.arange(1000, 1010)
    want = np.array([x[i - 50:i + 51].std(axis=0) for i in k])
    np.testing.assert_allclose(got[k], want, rtol=1e-6)


def test_bad_windows_are_refused():
    with pytest.raises(ValueError):
        moving_mean(np.zeros(3), 0)
    with pytest.raises(ValueError):
        moving_mean(np.zeros(3), 3, mode="wrap")
