"""Issue 28 (honesty): a located bias step's 1-sigma counts where the step may have been.

The reference shares no code with the estimator: a change point in segment means written here
in numpy (16 segments of unit noise, the bias steps by ``size`` before segment 8), each run's
step located at the boundary of largest score (the chi2 drop of the step there) and its size
and base level read there, as station.estimate.profile locates a bias step.  The 1-sigma a fit
states with the time taken as known is too small where the capture cannot tell the time (size
1, two sigma: 0.76 of the RMS error over the runs); with profile.location_spread added (a
parametric bootstrap of the location on the linear model) it is the RMS error.  Both sides: the
spread counted twice fails as the time taken as known does.  The product-level Monte Carlo (the
twins, the MEMS IMU, optimal9) is benchmarks/bias_step_honesty.py; its figures are in
docs/diagnose.md ("Twenty-first session")."""
import numpy as np

from station.estimate.profile import location_spread

SEGMENTS, STEP_AT = 16, 8


def operators(j, m):
    """location_spread's operators of the step before segment j: its column M less the base
    level's (the mean), the inverse normal matrix, what reads (base level's move, size) from
    Jp^T r, and the residual the step found there makes at the fit without it."""
    M = (np.arange(SEGMENTS) >= j).astype(float)
    Jp = (M - M.mean())[:, None]
    Ainv = np.array([[1.0 / float(Jp[:, 0] @ Jp[:, 0])]])
    size = float((Ainv @ (Jp.T @ (m - m.mean())))[0])
    return {"Jp": Jp, "Ainv": Ainv, "W": np.array([[-M.mean()], [1.0]]) @ Ainv, "signal": M * size}


def located_runs(size, runs, seed):
    """Per run: (size error, base error, the time-known 1-sigma of size and base, and the
    location_spread's variances of size and base)."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(runs):
        m = 10.0 + size * (np.arange(SEGMENTS) >= STEP_AT) + rng.standard_normal(SEGMENTS)
        cands = {(float(j), f"s{j - 1}", f"s{j}"): operators(j, m) for j in range(2, SEGMENTS - 1)}
        r = m - m.mean()
        best = max(cands, key=lambda c: float((cands[c]["Jp"].T @ r) @ cands[c]["Ainv"] @ (cands[c]["Jp"].T @ r)))
        j = int(best[0])
        before, after = m[:j].mean(), m[j:].mean()
        spread = location_spread(cands, best, draws=100, seed=int(rng.integers(1 << 30)))
        out.append((after - before - size, before - 10.0, np.sqrt(1 / j + 1 / (SEGMENTS - j)), np.sqrt(1 / j),
                    spread[1, 1], spread[0, 0]))
    return np.array(out)


def rms(v):
    return float(np.sqrt(np.mean(np.square(v))))


def test_a_located_step_states_the_scatter_of_its_size_and_base_where_its_time_is_uncertain():
    runs = 300
    out = located_runs(1.0, runs, seed=28)
    tol = 3 / np.sqrt(2 * runs)                  # 3x the sampling error of a ratio of RMS values
    for err, known, extra in ((out[:, 0], out[:, 2], out[:, 4]), (out[:, 1], out[:, 3], out[:, 5])):
        actual = rms(err)
        stated = np.sqrt(np.mean(known ** 2 + extra))
        assert abs(stated / actual - 1) < tol, (stated, actual)
        # the time taken as known: too small; the spread counted twice: too large
        assert rms(known) / actual < 1 - tol, (rms(known), actual)
        assert np.sqrt(np.mean(known ** 2 + 2 * extra)) / actual > 1 + tol


def test_a_step_well_above_the_noise_adds_nothing():
    """The located time is certain (size 6, 12 sigma): the spread is nil."""
    out = located_runs(6.0, 100, seed=5)
    assert np.mean(out[:, 4]) < 1e-3 * np.mean(out[:, 2] ** 2), np.mean(out[:, 4])


def test_a_failing_fits_over_dispersion_is_counted_once_in_the_spread():
    """Issue 28 review: the noise is twice the nominal (over-dispersion phi = 4, a failing fit).
    location_spread draws its noise times sqrt(phi), and the verdict (station.estimate.verdict)
    then multiplies a failing fit's whole covariance, the spread with it, by its reduced chi2: the
    spread must be in the fit's nominal units for phi to be counted once.  The reference is the
    RMS error of the located size and base over the runs (the same change point as above, the
    size 2 against a noise of 2: as size 1 against 1)."""
    phi, runs = 4.0, 300
    rng = np.random.default_rng(29)
    out = []
    for _ in range(runs):
        m = 10.0 + 2.0 * (np.arange(SEGMENTS) >= STEP_AT) + 2.0 * rng.standard_normal(SEGMENTS)
        cands = {(float(j), f"s{j - 1}", f"s{j}"): operators(j, m) for j in range(2, SEGMENTS - 1)}
        r = m - m.mean()
        best = max(cands, key=lambda c: float((cands[c]["Jp"].T @ r) @ cands[c]["Ainv"] @ (cands[c]["Jp"].T @ r)))
        j = int(best[0])
        before, after = m[:j].mean(), m[j:].mean()
        spread = location_spread(cands, best, phi, draws=100, seed=int(rng.integers(1 << 30)))
        out.append((after - before - 2.0, before - 10.0, np.sqrt(1 / j + 1 / (SEGMENTS - j)), np.sqrt(1 / j),
                    spread[1, 1], spread[0, 0]))
    out = np.array(out)
    tol = 3 / np.sqrt(2 * runs)
    for err, known, extra in ((out[:, 0], out[:, 2], out[:, 4]), (out[:, 1], out[:, 3], out[:, 5])):
        stated = np.sqrt(phi * np.mean(known ** 2 + extra))      # the verdict's scaling of a failing fit
        assert abs(stated / rms(err) - 1) < tol, (stated, rms(err))
