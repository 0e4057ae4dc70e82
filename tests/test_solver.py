"""The estimate path without scipy (issue 27, item 1): station/estimate/solver.py's
Levenberg–Marquardt against scipy's MINPACK on the fit's own models, the distributions' tails
and the rotation helpers against scipy's, and `station estimate` importing no scipy."""
import copy
import os
import subprocess
import sys

import numpy as np
import pytest
from scipy import optimize, special
from scipy.spatial.transform import Rotation

from station.estimate import distributions, lsq, solver
from station.estimate.summaries import summarise
from station.io.capture import read_capture
from station.model import LIBRARY
from station.model.rotation import align_vectors, rotvec_from_matrix


def scipy_lm(fun, x0, jac, *, xtol, ftol, gtol, max_nfev=None):
    return optimize.least_squares(fun, x0, jac=jac, method="lm", x_scale="jac", xtol=xtol, ftol=ftol,
                                  gtol=gtol, max_nfev=max_nfev)


@pytest.mark.parametrize("effects", [[], ["accel_nonlinearity"]])
def test_the_fit_with_this_solver_is_the_fit_with_minpack(optimal9_run, monkeypatch, effects):
    """Both stop where the relative reduction of chi2 is below ftol = 1e-10: chi2 (~200 for
    optimal9's ~200 rows) is then within ~2e-8 of its minimum, and a parameter within
    sqrt(2 x 2e-8) ~ 2e-4 of its 1-sigma of the minimum (chi2 rises by (dx / sigma)^2 / ... along
    a parameter's direction): the two fits agree within twice that, 5e-4 sigma, and so do the 1-sigma."""
    if effects and effects[0] not in LIBRARY:
        pytest.skip(f"no effect {effects[0]} in the library")
    s = summarise(read_capture(optimal9_run))
    calls = []

    def minpack(model, start, evaluations=lsq.MAX_EVALUATIONS):
        """lsq._lm's solve by scipy's MINPACK (lmder) with the same scaling and tolerances."""
        calls.append(evaluations)
        return scipy_lm(model.residuals, start, model.jacobian, xtol=1e-10, ftol=1e-10, gtol=1e-10,
                        max_nfev=evaluations)

    results = []
    for how in ("numpy", "minpack"):
        if how == "minpack":
            monkeypatch.setattr(lsq, "_lm", minpack)
        results.append(lsq.fit(copy.deepcopy(s), [LIBRARY[e]() for e in effects]))
    assert calls, "the fit never called lsq._lm: the comparison would compare the numpy LM with itself"
    ours, theirs = results
    assert ours.model.converged and theirs.model.converged
    sigma = np.sqrt(np.diag(theirs.covariance))
    assert ours.x.shape == theirs.x.shape
    cols = np.arange(len(sigma)) if theirs.covariance_columns is None else theirs.covariance_columns
    dx = np.abs(ours.x[cols] - theirs.x[cols]) / np.where(sigma > 0, sigma, np.inf)
    assert dx.max() < 5e-4, dx.max()
    np.testing.assert_allclose(np.sqrt(np.diag(ours.covariance)), sigma, rtol=5e-4)
    assert ours.chi2 == pytest.approx(theirs.chi2, rel=1e-8)


def test_curve_fits_and_the_evaluation_limit():
    rng = np.random.default_rng(0)
    t = np.linspace(0, 4, 60)
    y = 2.5 * np.exp(-1.3 * t) + 0.5 + 0.01 * rng.normal(size=60)

    def fun(p):
        return p[0] * np.exp(-p[1] * t) + p[2] - y

    def jac(p):
        e = np.exp(-p[1] * t)
        return np.column_stack([e, -p[0] * t * e, np.ones_like(t)])

    for x0 in ([1, 1, 0], [10, 0.1, 5], [0.1, 5, -3]):
        ours = solver.least_squares(fun, x0, jac, xtol=1e-10, ftol=1e-10, gtol=1e-10)
        ref = scipy_lm(fun, x0, jac, xtol=1e-10, ftol=1e-10, gtol=1e-10, max_nfev=None)
        assert ours.success and ours.status in (1, 2, 3, 4)
        # relative reduction below 1e-10 at both: the same minimum to ~1e-5 of the parameters'
        # 1-sigma (0.01 noise over 60 points: sigma ~1e-3), far below 1e-7 absolute
        np.testing.assert_allclose(ours.x, ref.x, atol=1e-7)
        np.testing.assert_allclose(ours.jac, jac(ours.x))
        assert ours.cost == pytest.approx(0.5 * np.sum(fun(ours.x) ** 2))
    stopped = solver.least_squares(fun, [0.1, 5, -3], jac, xtol=1e-10, ftol=1e-10, gtol=1e-10, max_nfev=3)
    assert stopped.status == 0 and not stopped.success and stopped.nfev <= 4


def test_tails_and_quantiles_are_scipys():
    worst = 0.0
    for dof in (1, 2, 3, 5, 10, 31, 100, 183, 1000, 12345):
        for r in (0.01, 0.1, 0.5, 0.9, 0.99, 1.0, 1.01, 1.1, 1.5, 2, 5, 20):
            x = dof * r
            for ours, ref in ((distributions.chi2_sf(dof, x), special.chdtrc(dof, x)),
                              (distributions.chi2_cdf(dof, x), special.chdtr(dof, x))):
                if ref > 1e-300:
                    worst = max(worst, abs(ours - ref) / ref)
    # the prefactor x^a e^-x / Gamma(a) in logarithms: ~a eps relative (a = dof / 2 <= 6e3)
    assert worst < 1e-10
    for p in (1e-10, 1e-5, 0.01, 0.3, 0.5, 0.9, 1 - 1e-6, 1 - 0.001 / 18):
        assert distributions.norm_ppf(p) == pytest.approx(special.ndtri(p), rel=1e-14, abs=1e-14)
    for n in (1, 5, 9, 20, 38, 100, 1000):
        for k in range(n + 2):
            ref = special.betainc(k, n - k + 1, 0.05) if 0 < k <= n else (1.0 if k <= 0 else 0.0)
            assert distributions.binom_sf(k, n, 0.05) == pytest.approx(ref, rel=1e-11, abs=1e-300)


def test_huber_is_the_minimum_scipy_approaches():
    rng = np.random.default_rng(1)

    def cost(r, c=2.0):
        a = np.abs(r)
        return np.sum(np.where(a <= c, a * a, 2 * c * a - c * c))

    for _ in range(50):
        n = int(rng.integers(6, 40))
        A = np.column_stack([np.ones(n), rng.normal(size=n)])
        y = A @ [1, 2] + rng.normal(size=n) * 2
        y[rng.integers(0, n)] += 30
        c0 = np.linalg.lstsq(A, y, rcond=None)[0]
        ref = optimize.least_squares(lambda c: A @ c - y, c0, loss="huber", f_scale=2.0).x
        ours = solver.huber_linear(A, y, 2.0, c0)
        assert cost(A @ ours - y) <= cost(A @ ref - y) * (1 + 1e-14)
        np.testing.assert_allclose(ours, ref, rtol=1e-5, atol=1e-6)     # scipy stops at its 1e-8 tolerances


def test_rotations_are_scipys():
    rng = np.random.default_rng(2)
    for _ in range(300):
        v = rng.normal(size=3) * rng.choice([1e-9, 1e-4, 0.1, 1.0, 3.1])
        if np.linalg.norm(v) > np.pi:
            v *= (np.pi - 1e-3) / np.linalg.norm(v)
        R = Rotation.from_rotvec(v).as_matrix()
        np.testing.assert_allclose(rotvec_from_matrix(R), Rotation.from_matrix(R).as_rotvec(), atol=1e-14)
        a = rng.normal(size=(int(rng.integers(2, 8)), 3))
        b = a @ R + 1e-3 * rng.normal(size=a.shape)
        w = rng.uniform(0.1, 10, len(a))
        np.testing.assert_allclose(align_vectors(a, b, w), Rotation.align_vectors(a, b, w)[0].as_matrix(), atol=1e-12)


@pytest.mark.parametrize("in_process", ["0", "1"])
def test_estimate_imports_no_scipy(optimal9_run, tmp_path, in_process):
    code = ("import sys; from station.cli.app import main\n"
            "status = main(sys.argv[1:])\n"
            "print('SCIPY', sorted(m for m in sys.modules if m.split('.')[0] == 'scipy'))\n"
            "sys.exit(status)\n")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path), STATION_READ_IN_PROCESS=in_process)
    done = subprocess.run([sys.executable, "-c", code, "estimate", str(optimal9_run), "-o", str(tmp_path / "c.yaml")],
                          capture_output=True, text=True, env=env, timeout=120)
    assert done.returncode == 0, done.stderr
    assert "SCIPY []" in done.stdout, done.stdout[-500:]


@pytest.mark.parametrize("f, lo, hi", [
    (lambda x: (x - 0.3) ** 2, -1.0, 1.0),
    (lambda x: np.cosh(3.0 * (x + 0.71)), -2.0, 0.5),
    (lambda x: abs(x - 0.123456), 0.0, 1.0),                      # a kink: no parabola helps
    (lambda x: x, 0.2, 0.9),                                      # the minimum at a bound
    (lambda x: -np.exp(-((x - 0.05) / 0.2) ** 2) + 0.01 * x, -0.47, 0.47),
])
def test_the_bounded_search_finds_brents_minimum(f, lo, hi):
    """solver.minimise_bounded (the hand-rotation start's 1-D search, golden section) against
    scipy's bounded Brent: the same minimum within the tolerance asked of both (xatol 1e-3,
    as start_scale asks), and a narrower tolerance brings them nearer."""
    for xatol in (1e-3, 1e-6):
        ours = solver.minimise_bounded(f, lo, hi, xatol=xatol)
        ref = optimize.minimize_scalar(f, bounds=(lo, hi), method="bounded", options={"xatol": xatol}).x
        assert lo <= ours <= hi
        assert abs(ours - ref) < 3 * xatol, (xatol, ours, ref)


def test_the_bounded_search_refuses_an_empty_bracket():
    with pytest.raises(ValueError):
        solver.minimise_bounded(lambda x: x * x, 1.0, 1.0)
