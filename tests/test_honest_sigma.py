"""The least-squares 1-sigma checked from both sides (issue 30 items 1 and 2).

* Against an independent Cramér–Rao bound (tests/independent_crb.py: the Fisher information of the
  raw samples from the simulator's own forward model, sharing no code with station.model or
  station.estimate): the reported 1-sigma and the Monte Carlo spread must each lie within a band
  around the bound that an error of 20 % in either direction leaves.
* Coverage: the fraction of errors inside +-1 sigma and +-2 sigma (sigma as reported) against
  binomial bands, per parameter group: an overstated sigma fails as an understated one does.

One Monte Carlo study serves both (the station's own machinery, station.simulate.montecarlo, on
two worker processes).  Its size is derived here:

  The sample standard deviation of n normal draws has a relative sd of about 1/sqrt(2 (n - 1)).
  For a 20 % error to be at least 3 of those: 1/sqrt(2 (n - 1)) <= 0.2 / 3, n >= 114.  The
  checks pool the 3 parameters of a group (accelerometer scale factors, ...), which sharpens
  them: for k standardised errors with correlation matrix R (from the bound's covariance) the
  mean square over n runs has variance 2 tr(R^2) / n, so the rms ratio has relative sd
  s = sqrt(tr(R^2) / (2 n)) / k (1/sqrt(6 n) = 3.8 % for 3 independent parameters, n = 114).
  The band is +-3.29 s (99.9 % two-sided) and a 20 % error is then >= 5 s away (see
  test_the_spread_check_fails_a_20_percent_error).
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from independent_crb import NAMES, IndependentBound
from station.io.scheme import load_scheme
from station.simulate import montecarlo as mc

SCHEME = load_scheme("optimal9", {"dwell_s": 10.0, "rotation_s": 36.0})
SETTINGS = mc.Settings()          # 100 ug/rtHz, 0.03 deg/h/rtHz, 2 arcsec table, 50 ug disturbance
RUNS = 114                        # 1/sqrt(2 (n - 1)) <= 0.2 / 3 (the docstring)
FIRST_SEED = 1000
Z999 = stats.norm.isf(0.0005)     # 3.29: a 99.9 % two-sided band
ALL = list(range(21))
GROUPS = {
    "accelerometer scale factors": [0, 1, 2],
    "accelerometer misalignments": [3, 4, 5],
    "gyro scale factors": [6, 7, 8],
    "gyro misalignments": [9, 10, 11],
    "accelerometer biases": [12, 13, 14],
    "gyro biases": [15, 16, 17],
    "inter-triad angles": [18, 19, 20],
}
# The reported 1-sigma against the bound: each run's sigma rests on its own noise estimate (the
# first differences of every segment, N >= 1,000 samples: relative sd 1/sqrt(2 N) <= 2.2 %, so
# 3 of those is 6.7 %), and the station's model leaves some bench quantities freer than the bound
# does (the Earth rate along each table axis, a start phase per segment: measured +1.2 to +2.5 %
# on the gyro parameters).  +-10 %: a 1-sigma 22 % too large or 20 % too small fails.
REPORTED_BAND = 0.10


@pytest.fixture(scope="module")
def bound():
    b = IndependentBound(SCHEME, mc.make_truth(SETTINGS), FIRST_SEED)
    assert b.condition < 1e12                    # the gauge fixed: the information is invertible
    return b


@pytest.fixture(scope="module")
def study():
    result = mc.study(SCHEME, SETTINGS, RUNS, first_seed=FIRST_SEED, workers=2)
    assert [n for n, _ in result.names] == NAMES
    return result


def spread_sd(cov: np.ndarray, idx: list, runs: int) -> float:
    """Relative sd of the rms of standardised errors pooled over ``idx`` (the docstring)."""
    c = cov[np.ix_(idx, idx)]
    d = np.sqrt(np.diag(c))
    R = c / np.outer(d, d)
    return math.sqrt(np.trace(R @ R) / (2.0 * runs)) / len(idx)


def spread_failures(errors: np.ndarray, bound_sigma: np.ndarray, cov: np.ndarray,
                    groups: dict | None = None) -> list:
    """Groups whose Monte Carlo rms error, relative to the bound, is outside 1 +- 3.29 s."""
    out = []
    for group, idx in (groups or GROUPS).items():
        z = errors[:, idx] / bound_sigma[idx]
        ratio = math.sqrt(np.mean(z ** 2))
        s = spread_sd(cov, idx, len(errors))
        if abs(ratio - 1.0) > Z999 * s:
            out.append(f"{group}: Monte Carlo rms / bound = {ratio:.3f} (band 1 +- {Z999 * s:.3f})")
    return out


def reported_failures(sigmas: np.ndarray, bound_sigma: np.ndarray) -> list:
    ratio = sigmas / bound_sigma
    return [f"{n}: reported / bound = {r:.3f}" for n, r in zip(NAMES, ratio) if abs(r - 1.0) > REPORTED_BAND]


def test_the_bound_shares_no_code_with_the_estimator():
    """independent_crb imports neither station.model nor station.estimate (checked in a fresh
    interpreter: this process has them loaded already)."""
    import subprocess
    import sys
    from pathlib import Path

    code = ("import sys; sys.path.insert(0, 'tests'); import independent_crb; "
            "print(sorted(m for m in sys.modules if m.startswith(('station.model', 'station.estimate'))))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         cwd=Path(__file__).resolve().parents[1])
    assert out.stdout.strip() == "[]"


def test_the_reported_sigma_matches_the_independent_bound(study, bound):
    """Every run's reported 1-sigma, every parameter: within +-10 % of the bound."""
    failures = [f"seed {FIRST_SEED + i}: {f}" for i, row in enumerate(study.sigmas)
                for f in reported_failures(row, bound.sigma)]
    assert not failures, failures


@pytest.mark.parametrize("factor", [1.22, 0.8])
def test_a_20_percent_error_in_the_reported_sigma_fails(monkeypatch, bound, factor):
    """The bug planted in issue 30 (every least-squares 1-sigma 22 % too large), and its mirror
    (20 % too small): the check above fails for them."""
    from station.estimate import lsq

    real = lsq.to_calibration

    def scaled(*args, **kw):
        cal = real(*args, **kw)
        cal.sigma = {n: s * factor for n, s in cal.sigma.items()}
        return cal

    monkeypatch.setattr(lsq, "to_calibration", scaled)
    _, sigmas = mc.one_run((SCHEME, SETTINGS, FIRST_SEED))
    assert len(reported_failures(sigmas, bound.sigma)) == len(NAMES)
    monkeypatch.setattr(lsq, "to_calibration", real)
    _, sigmas = mc.one_run((SCHEME, SETTINGS, FIRST_SEED))
    assert not reported_failures(sigmas, bound.sigma)


def test_the_monte_carlo_spread_matches_the_independent_bound(study, bound):
    """The errors' rms per group, against the bound (the estimator is efficient: it reaches it)."""
    failures = spread_failures(study.errors, bound.sigma, bound.covariance)
    assert not failures, failures


def test_the_monte_carlo_spread_of_all_parameters_matches_the_bound(study, bound):
    """All 21 standardised errors pooled: s = sqrt(tr(R^2) / 2n) / 21, about 1.5 %, so the band is
    about +-5 % and a 20 % error is some 13 s away."""
    failures = spread_failures(study.errors, bound.sigma, bound.covariance, {"all parameters": ALL})
    assert not failures, failures


@pytest.mark.parametrize("factor", [1.2, 1 / 1.2])
def test_the_spread_check_fails_a_20_percent_error(study, bound, factor):
    """The same errors against a bound 20 % off (as an estimator 20 % less or more precise than
    the bound says would be): the pooled check fails, and so does every group once the error is
    8 of its s (30 %; at 20 %, 5.2 s, a group whose own draws happen to sit 1.9 s the other way
    passes: measured, 6 of 7 groups fail at x1.2 and 7 of 7 at /1.2, docs/testing.md)."""
    assert spread_failures(study.errors, bound.sigma * factor, bound.covariance, {"all parameters": ALL})
    big = 1.3 if factor > 1 else 1 / 1.3
    failures = spread_failures(study.errors, bound.sigma * big, bound.covariance)
    assert len(failures) == len(GROUPS), failures


# ------------------------------------------------------------------------------ coverage

def coverage_failures(errors: np.ndarray, sigmas: np.ndarray, cov: np.ndarray, groups: dict) -> list:
    """Per group: the fraction of |error| < k sigma (k = 1, 2; sigma as reported) against the
    normal's 68.27 % and 95.45 %, inside a 99.9 % two-sided binomial band.  Correlated errors
    within a group count as fewer draws: n k^2 / tr(R^2) (the design effect of pooling k
    correlated ones), and a continuity correction of 1/2 draw."""
    out = []
    for group, idx in groups.items():
        z = np.abs(errors[:, idx] / sigmas[:, idx])
        c = cov[np.ix_(idx, idx)]
        d = np.sqrt(np.diag(c))
        R = c / np.outer(d, d)
        n_eff = len(errors) * len(idx) ** 2 / np.trace(R @ R)
        for k in (1.0, 2.0):
            p = 2 * stats.norm.cdf(k) - 1
            frac = float(np.mean(z < k))
            band = Z999 * math.sqrt(p * (1 - p) / n_eff) + 0.5 / n_eff
            if abs(frac - p) > band:
                out.append(f"{group}: {frac:.3f} inside {k:g} sigma, expected {p:.3f} +- {band:.3f}")
    return out


def test_lsq_coverage_per_group(study, bound):
    failures = coverage_failures(study.errors, study.sigmas, bound.covariance, {**GROUPS, "all parameters": ALL})
    assert not failures, failures


@pytest.mark.parametrize("factor", [1.22, 0.8])
def test_pooled_coverage_fails_a_sigma_20_percent_off(study, bound, factor):
    """All 21 parameters pooled (about 2,400 draws, fewer once correlated): the band on the
    fraction inside 1 sigma is about +-0.03; a 1-sigma 22 % too large puts P(|z| < 1.22) = 78 %
    of the errors inside it, one 20 % too small P(|z| < 0.8) = 58 %, against 68 %: both fail."""
    assert coverage_failures(study.errors, study.sigmas * factor, bound.covariance, {"all parameters": ALL})


def test_the_coverage_check_fails_a_sigma_40_percent_off(study, bound):
    """Coverage has less power than the bound (a fraction, not a variance): with 342 draws per
    group a 1-sigma 40 % too large or too small fails every group (measured: docs/testing.md)."""
    for factor in (1.4, 1 / 1.4):
        failures = coverage_failures(study.errors, study.sigmas * factor, bound.covariance, GROUPS)
        assert {f.split(":")[0] for f in failures} == set(GROUPS), (factor, failures)
