"""The Fourier method's 1-sigma (fourier.propagate: the source of that method's test tolerances in
tests/test_fourier.py) against its Monte Carlo spread, and its coverage (issue 30 item 2).

A screwdriver session (four mountings, each turned both ways, 10 s per direction at 720 deg/s,
the rate falling 20 % over each turn, no encoder), MEMS noise (150 ug/rtHz, 10 deg/h/rtHz),
the "high" variant (the Earth rate along each shaft estimated: the low variant's gyro biases
carry it by design, a known bias that no 1-sigma covers).  RUNS runs with seeds 1..RUNS on two
processes.

Bands (the derivations of tests/test_honest_sigma.py): the rms of k standardised errors with
correlation R over n runs has relative sd s = sqrt(tr(R^2) / 2n) / k; R is taken from the runs
themselves (at least the identity's k: a sample correlation of 30 runs can only understate it
by chance).  Per group (k = 3) s is about 8 % (band +-0.26); pooled over the 21 parameters,
whose errors correlate (one shaft's phase moves several), s is 4.7 % (band +-0.155): a 1-sigma
off by 35 % or more fails, 20 % does not reliably (that would take some 70 runs, 23 s of CPU:
the least-squares method carries the 20 % requirement, tests/test_honest_sigma.py).  Coverage:
the fraction inside 1 and 2 sigma against 99.9 % binomial bands on the pooled draws.
"""
from __future__ import annotations

import math
import multiprocessing

import numpy as np
import pytest
from scipy import stats

from station.core import units
from station.estimate import fourier
from station.io.scheme import load_scheme
from station.model.calibration import parameter_errors
from station.simulate import dryrun

SCHEME = load_scheme("screwdriver", {"rotation_s": 10.0})
RUNS = 30
Z999 = stats.norm.isf(0.0005)
VARIANT = "high"
GROUPS = {"accelerometer scale factors": [0, 1, 2], "accelerometer misalignments": [3, 4, 5],
          "gyro scale factors": [6, 7, 8], "gyro misalignments": [9, 10, 11],
          "accelerometer biases": [12, 13, 14], "gyro biases": [15, 16, 17], "inter-triad angles": [18, 19, 20]}
ALL = {"all parameters": list(range(21))}


def truth_for(accel_ug=150.0, gyro_dph=10.0):
    truth = dryrun.load_truth(None, 0)
    truth.accel.noise_density = accel_ug
    truth.gyro.noise_density = gyro_dph
    truth.bench.rate_drift_fraction = -0.2
    return truth


def one_run(seed: int) -> np.ndarray:
    truth = truth_for()
    cal = fourier.estimate(dryrun.simulate_capture(SCHEME, truth, seed), VARIANT)
    return np.array([e[3] for e in parameter_errors(cal, dryrun.truth_calibration(truth))])


@pytest.fixture(scope="module")
def runs():
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1, user_api="blas"):
        with multiprocessing.get_context("fork").Pool(2) as pool:
            errors = np.array(pool.map(one_run, range(1, RUNS + 1)))
    return errors


@pytest.fixture(scope="module")
def predicted():
    """fourier.propagate's 1-sigma (as tests/test_fourier.py computes its tolerances)."""
    quiet = truth_for(0.0, 0.0)
    s = fourier.summarise(dryrun.simulate_capture(SCHEME, quiet, 0))
    truth = truth_for()
    sigma = fourier.propagate(s, VARIANT, truth.accel.noise_density * units.UG_MPS2,
                              truth.gyro.noise_density / 3600, truth.sample_rate_hz)
    cal = fourier.estimate(dryrun.simulate_capture(SCHEME, quiet, 0), VARIANT)
    names = [e[0] for e in parameter_errors(cal, dryrun.truth_calibration(quiet))]
    return np.array([sigma[n] for n in names])


def relative_sd(z: np.ndarray) -> float:
    k = z.shape[1]
    R = np.corrcoef(z, rowvar=False) if k > 1 else np.ones((1, 1))
    return math.sqrt(max(np.trace(R @ R), k) / (2.0 * len(z))) / k


def spread_failures(errors, sigma, groups) -> list:
    out = []
    for group, idx in groups.items():
        z = errors[:, idx] / sigma[idx]
        ratio = math.sqrt(np.mean(z ** 2))
        band = Z999 * relative_sd(z)
        if abs(ratio - 1.0) > band:
            out.append(f"{group}: Monte Carlo rms / 1-sigma = {ratio:.3f} (band 1 +- {band:.3f})")
    return out


def coverage_failures(errors, sigma, groups) -> list:
    out = []
    for group, idx in groups.items():
        z = errors[:, idx] / sigma[idx]
        k = len(idx)
        R = np.corrcoef(z, rowvar=False)
        n_eff = len(z) * k * k / max(np.trace(R @ R), k)
        for m in (1.0, 2.0):
            p = 2 * stats.norm.cdf(m) - 1
            frac = float(np.mean(np.abs(z) < m))
            band = Z999 * math.sqrt(p * (1 - p) / n_eff) + 0.5 / n_eff
            if abs(frac - p) > band:
                out.append(f"{group}: {frac:.3f} inside {m:g} sigma, expected {p:.3f} +- {band:.3f}")
    return out


def test_the_fourier_sigma_matches_its_monte_carlo_spread(runs, predicted):
    failures = spread_failures(runs, predicted, {**GROUPS, **ALL})
    assert not failures, failures


def test_the_fourier_coverage(runs, predicted):
    failures = coverage_failures(runs, predicted, ALL)
    assert not failures, failures


@pytest.mark.parametrize("factor", [3.0, 1.5, 1 / 1.5])
def test_the_fourier_checks_fail_a_wrong_sigma(runs, predicted, factor):
    """The issue's planted bug (the Fourier 1-sigma tripled) fails every group and the coverage;
    a 1-sigma 50 % too large or a third too small fails the pooled spread."""
    assert spread_failures(runs, predicted * factor, ALL)
    if factor == 3.0:
        assert len(spread_failures(runs, predicted * factor, GROUPS)) == len(GROUPS)
        assert coverage_failures(runs, predicted * factor, ALL)
