"""The overlapping Allan deviation, its degrees of freedom and its confidence interval
(station/estimate/noise.py) against allantools (the reference implementation), against the
estimator's definition built as a matrix, and against a Monte Carlo."""
import math

import allantools
import numpy as np
import pytest

from station.estimate.noise import (CHUNK, CONFIDENCE, averaging_factors, deviation_interval, overlapping_adev,
                                    white_noise_edf)


@pytest.mark.parametrize("n, rate, kind", [(201, 1.0, "white"), (3000, 100.0, "white"),
                                           (20000, 400.0, "walk"), (5001, 7.5, "drift"),
                                           (3 * CHUNK + 17, 1000.0, "walk")])     # summed in pieces
def test_the_deviation_is_allantools_oadev(n, rate, kind):
    rng = np.random.default_rng(n)
    y = rng.standard_normal(n) * 0.3 + 12.0
    if kind == "walk":
        y += np.cumsum(rng.standard_normal(n)) * 0.01
    elif kind == "drift":
        y += np.linspace(0.0, 2.0, n)
    m = averaging_factors(n)
    taus, ref, _, _ = allantools.oadev(y - y.mean(), rate=rate, data_type="freq", taus=m / rate)
    np.testing.assert_array_equal(np.round(taus * rate), m)
    np.testing.assert_allclose(overlapping_adev(y, rate, m), ref, rtol=1e-9)


def test_a_scaled_column_is_the_deviation_of_the_scaled_samples():
    """overlapping_adev(column, rate, m, scale) of a column of a larger (integer) array, not
    copied: the deviation of the column times scale (what the noise of raw counts uses)."""
    rng = np.random.default_rng(5)
    counts = rng.integers(-3000, 3000, size=(2 * CHUNK + 5, 6))
    m = averaging_factors(len(counts))
    np.testing.assert_allclose(overlapping_adev(counts[:, 4], 200.0, m, 0.0123),
                               overlapping_adev(counts[:, 4] * 0.0123, 200.0, m), rtol=1e-12)


def test_averaging_factors_are_ten_per_decade_up_to_a_fifth():
    m = averaging_factors(30000)
    assert m[0] == 1 and m[-1] == 6000 and np.all(np.diff(m) > 0)
    assert 35 <= len(m) <= 38        # log10(6000) = 3.78 decades, duplicates at small m merged


@pytest.mark.parametrize("n", [12, 40, 97])
def test_the_degrees_of_freedom_are_those_of_the_estimator_built_as_a_matrix(n):
    """edf = 2 E^2 / Var of sum v_k^2 with v = A y, y white: tr(C)^2 / tr(C^2) with C = A A^T;
    A written from the definition (the phase differences), not from the autocovariance."""
    m = np.arange(1, (n - 1) // 2 + 1)
    for k in m:
        x_of_y = np.tril(np.ones((n + 1, n)), -1)             # x_j = sum_{i<j} y_i
        a = x_of_y[2 * k:] - 2 * x_of_y[k:n + 1 - k] + x_of_y[:n + 1 - 2 * k]
        c = a @ a.T
        exact = np.trace(c) ** 2 / np.sum(c * c)
        assert white_noise_edf(np.array([k]), n)[0] == pytest.approx(exact, rel=1e-12)


def test_the_degrees_of_freedom_match_a_monte_carlo():
    """2 mean^2 / variance of the Allan variance over many white-noise records; the tolerance is
    four standard errors of that ratio, estimated from the same records (delta method)."""
    rng = np.random.default_rng(7)
    records, n = 6000, 300
    y = rng.standard_normal((records, n))
    x = np.concatenate([np.zeros((records, 1)), np.cumsum(y, axis=1)], axis=1)
    for k in (1, 2, 5, 20, 60):
        v = x[:, 2 * k:] - 2 * x[:, k:n + 1 - k] + x[:, :n + 1 - 2 * k]
        s2 = np.mean(v * v, axis=1)
        mean, var = s2.mean(), s2.var(ddof=1)
        edf_mc = 2 * mean ** 2 / var
        # relative standard error of the ratio: var's (sqrt((kurtosis - 1) / records)) and twice
        # the mean's, correlated: take the sum (an upper bound)
        kurt = np.mean((s2 - mean) ** 4) / var ** 2
        rel = math.sqrt((kurt - 1) / records) + 2 * s2.std() / mean / math.sqrt(records)
        edf = white_noise_edf(np.array([k]), n)[0]
        assert abs(edf_mc / edf - 1) < 4 * rel, (k, edf_mc, edf, rel)


def test_allantools_greenhall_is_the_large_m_approximation_of_the_same_sum():
    """For m >> 1 Greenhall's edf (allantools.edf_greenhall) and the exact sum agree to the
    discretisation term: sum_j R_j^2 / R_0^2 = (2m/3)(1 + 5/(4m^2)) exactly, their table 2m/3.
    Below (one to 33 samples) Greenhall is 17 % high at one, 3-12 % low from two to 33, and the
    Monte Carlo above sides with the sum."""
    for n in (1000, 30000, 1000000):
        for k in averaging_factors(n):
            if k < 34:           # allantools' case 2.1 (J <= 100): the continuous-time model
                continue
            greenhall = allantools.edf_greenhall(alpha=0, d=2, m=int(k), N=n + 1, overlapping=True,
                                                 modified=False)
            assert white_noise_edf(np.array([k]), n)[0] == pytest.approx(greenhall, rel=2.0 / k ** 2), (n, k)
    assert white_noise_edf(np.array([1]), 1000)[0] == pytest.approx(2 * 999 / 3, rel=1e-3)   # allantools: 782


@pytest.mark.parametrize("edf", [1.2, 3.0, 41.9, 1500.0, 2.0e6])
def test_the_interval_is_allantools_confidence_interval(edf):
    lo, hi = deviation_interval(np.array([0.37]), np.array([edf]))
    ref = allantools.confidence_interval(0.37, edf, ci=CONFIDENCE)
    assert (lo[0], hi[0]) == pytest.approx(ref, rel=1e-10)
    assert lo[0] < 0.37 < hi[0]


def test_the_closed_form_is_the_sum_over_the_lags():
    """white_noise_edf's power sums against the sum over the 2m lags written out (as the
    estimator's definition above), for every m of a few lengths and the short-record case."""
    def by_lags(k, n):
        big_m = n + 1 - 2 * k
        j = np.arange(min(2 * k, big_m), dtype=float)
        r = np.where(j <= k, 2.0 * k - 3.0 * j, j - 2.0 * k)
        weight = 2.0 * (big_m - j)
        weight[0] = big_m
        return big_m * big_m * r[0] * r[0] / float(np.dot(weight, r * r))

    for n in (7, 40, 1001, 30000):
        for k in range(1, (n - 1) // 2 + 1) if n < 2000 else averaging_factors(n):
            assert white_noise_edf(np.array([k]), n)[0] == pytest.approx(by_lags(int(k), n), rel=1e-12), (n, k)
    # ten hours at 1 kHz (m up to 7.2 million, no array of lags): Greenhall's large-m form
    # r / (2/3 - 1/(3r)), r = M / m, to its discretisation term, which is ~5/(4m^2)
    n = 36_000_000
    m = averaging_factors(n)
    r = (n + 1 - 2 * m) / m
    assert np.all(np.abs(white_noise_edf(m, n) * (2 / 3 - 1 / (3 * r)) / r - 1) < 1.5 / m.astype(float) ** 2)
