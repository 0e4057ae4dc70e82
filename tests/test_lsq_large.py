"""The fit of a large model (many segments: Model.is_large) works on the sparse Jacobian
(least_squares' trust-region method with LSMR steps) and computes the covariance, the null
space and the blind effect parameters from the Jacobian with each segment's own nuisances
eliminated (lsq._Reduced): the same calibration as the dense path (MINPACK's
Levenberg-Marquardt and the whole Jacobian's SVD), which is forced here on small captures by
lowering the threshold.

Tolerances: both solvers stop when a step changes the parameters by less than 1e-10 of their
size (xtol) or chi2 by less than 1e-10 of itself (ftol), so the two solutions differ by a
fraction of that step, far below 1e-4 of a 1-sigma (a 1-sigma is ~1e-3 to 1e-6 of the
parameter's size here); the covariances come from the same Jacobian at (so nearly) the same x:
1e-6 relative; the sets of unobservable and rank-deficient parameters must be equal."""
import numpy as np
import pytest

from sim_devices.hand import hand_session
from sim_devices.truth import mems_truth
from station import cli
from station.estimate import lsq
from station.io.capture import read_capture
from station.io.scheme import load_scheme
from station.model import LIBRARY
from station.simulate import dryrun


@pytest.fixture(scope="module")
def captures(tmp_path_factory):
    truth = dryrun.load_truth(None, 0)
    truth.sample_rate_hz = 50.0
    out = {"optimal9": lsq.summarise(dryrun.simulate_capture(load_scheme("optimal9"), truth, 3))}
    tmp = tmp_path_factory.mktemp("hand-large")
    truth = mems_truth(5)
    truth.gyro.noise_density = 2.0        # sees the Earth turn in a pose: full attitudes
    hs = hand_session(truth, 7, poses=12, dwell_s=(3.0, 3.5), turn_s=(1.0, 1.4))
    log = tmp / "hand.csv"
    np.savetxt(log, np.column_stack([hs.t, hs.accel, hs.gyro]), delimiter=",", header="t,ax,ay,az,gx,gy,gz",
               comments="", fmt="%.10g")
    assert cli.main(["import", "csv", str(log), "--preset", "station", "-o", str(tmp / "hand"),
                     "--gravity-mps2", str(hs.truth["gravity_mps2"]),
                     "--latitude-deg", f"{hs.truth['latitude_deg']:g}"]) == 0
    out["hand"] = lsq.summarise(read_capture(tmp / "hand"))
    return out


def fitted(s, effects, monkeypatch, large: bool):
    monkeypatch.setattr(lsq, "LARGE_MODEL", 0 if large else 10**9)
    result = lsq.fit(s, [LIBRARY[e]() for e in effects])
    assert result.model.is_large is large
    return result


@pytest.mark.parametrize("name, effects", [("optimal9", ()), ("optimal9", ("accel_nonlinearity", "accel_lever_arm")),
                                           ("hand", ("accel_nonlinearity",))])
def test_the_sparse_fit_gives_the_dense_fits_calibration(captures, monkeypatch, name, effects):
    s = captures[name]
    dense, large = (fitted(s, effects, monkeypatch, flag) for flag in (False, True))
    names, v_dense, _, cov_dense = lsq.reported(dense, "m/s^2", "deg/s")
    names_l, v_large, _, cov_large = lsq.reported(large, "m/s^2", "deg/s")
    assert names == names_l
    sigma = np.sqrt(np.diag(cov_dense))
    assert np.all(sigma > 0)
    assert np.max(np.abs(v_large - v_dense) / sigma) < 1e-4
    np.testing.assert_allclose(np.sqrt(np.diag(cov_large)), sigma, rtol=1e-6)
    np.testing.assert_allclose(cov_large, cov_dense, rtol=1e-6, atol=1e-6 * np.outer(sigma, sigma).max())
    assert large.model.unobservable == dense.model.unobservable
    assert sorted(large.rank_deficient) == sorted(c for c in dense.rank_deficient
                                                  if c not in set(large.model.local_columns()))
    assert large.chi2 == pytest.approx(dense.chi2, rel=1e-8) and large.dof == dense.dof
    # the calibration file's numbers: the same
    c_dense, c_large = (lsq.to_calibration(r, "m/s^2", "deg/s") for r in (dense, large))
    for key in c_dense.sigma:
        assert c_large.sigma[key] == pytest.approx(c_dense.sigma[key], rel=1e-6), key
    if "accel_lever_arm" in effects:      # six of its parameters cannot be seen: the same six
        assert large.model.unobservable


def test_a_parameter_the_segments_nuisances_produce_exactly_is_found_null():
    """A column of the calibration that the segments' own nuisances reproduce exactly is
    rounding after the reduction: measured against its size before it (not its own norm), it
    is in the null space, as the whole Jacobian's SVD finds (found by a review: it was blown up
    to a unit column, the aliasing missed and a 1-sigma of 1e14 reported)."""
    import scipy.sparse as sp

    rng = np.random.default_rng(1)
    segments, own, rows, calibration = 200, 2, 6, 4
    J_L = sp.block_diag([rng.normal(size=(rows, own)) for _ in range(segments)]).toarray()
    J_G = rng.normal(size=(segments * rows, calibration))
    J_G[:, 3] = J_L @ rng.normal(size=segments * own)          # aliased with the nuisances
    J_G[:, 2] *= 1e4                                            # and columns of unequal sizes
    J = np.hstack([J_G, J_L])

    class Layout:
        size = J.shape[1]

    class Large:
        is_large, layout = True, Layout

        @staticmethod
        def local_columns():
            return np.arange(calibration, J.shape[1])

    reduced = lsq._Reduced(Large(), sp.csr_matrix(J))
    assert reduced.full(lsq._null_columns(reduced.J, reduced.scale)) == \
        [c for c in lsq._null_columns(J) if c < calibration] == [3]
    full = lsq.covariance(J)[:3, :3]
    np.testing.assert_allclose(lsq.covariance(reduced.J, reduced.scale)[:3, :3], full, rtol=1e-8)


def test_what_the_model_cannot_produce_is_the_whole_jacobians_complement():
    """_Reduced.outside (the score tests' projection, linear in the segments) against the whole
    Jacobian's SVD, on columns of every kind: random, produced by the model (nothing is left),
    produced by the nuisances only, and a mixture."""
    import scipy.sparse as sp

    rng = np.random.default_rng(2)
    segments, own, rows, calibration = 150, 2, 6, 5
    J_L = sp.block_diag([rng.normal(size=(rows, own)) for _ in range(segments)]).toarray()
    J_G = rng.normal(size=(segments * rows, calibration))
    J_G[:, 4] = J_L @ rng.normal(size=segments * own)          # aliased with the nuisances
    J_G[:, 1] *= 1e4
    J = np.hstack([J_G, J_L])

    class Large:
        is_large = True

        class layout:
            size = J.shape[1]

        @staticmethod
        def local_columns():
            return np.arange(calibration, J.shape[1])

    M = np.column_stack([rng.normal(size=J.shape[0]), J @ rng.normal(size=J.shape[1]),
                         J_L @ rng.normal(size=segments * own),
                         rng.normal(size=J.shape[0]) + J_G @ rng.normal(size=calibration)])
    u, sv, _ = np.linalg.svd(J, full_matrices=False)
    u = u[:, sv > 1e-10 * sv[0]]
    dense = M - u @ (u.T @ M)
    got = lsq._Reduced(Large(), sp.csr_matrix(J)).outside(M)
    size = np.linalg.norm(M, axis=0)
    assert np.all(np.linalg.norm(got - dense, axis=0) < 1e-9 * size)
    assert np.linalg.norm(got[:, 1]) < 1e-9 * size[1] and np.linalg.norm(got[:, 2]) < 1e-9 * size[2]
    assert np.linalg.norm(got[:, 0]) > 0.5 * size[0]


def test_the_diagnosis_of_a_large_model_is_the_dense_ones(monkeypatch):
    """The score tests, the terms found outside the library and the leave-one-segment-out
    scores at one fit, computed as a large model's (sparse Jacobian, nuisances eliminated) and
    as a small one's (the whole Jacobian), on optimal9 of an IMU with a non-linearity the model
    lacks: the same numbers to rounding (1e-8: the two differ in the order of their sums)."""
    import dataclasses

    from station.diagnose import holdout, terms
    from station.diagnose.core import diagnose

    truth = dryrun.load_truth(None, 4)
    truth.sample_rate_hz = 50.0
    truth.accel.nonlinearity_ug_per_g2 = np.array([300.0, -200.0, 400.0])
    s = lsq.summarise(dryrun.simulate_capture(load_scheme("optimal9"), truth, 5))
    fit = fitted(s, (), monkeypatch, False)
    found = {}
    for large in (False, True):
        monkeypatch.setattr(lsq, "LARGE_MODEL", 0 if large else 10**9)
        result = dataclasses.replace(fit)             # the same fit, nothing computed from it yet
        assert result.model.is_large is large
        d = diagnose(result)
        found[large] = ({c.effect: (c.predicted_chi2_drop, c.sigma, c.significant) for c in d.candidates},
                        holdout.leave_one_segment_out(result).per_segment,
                        [(f.term.name, f.value) for f in terms.search(result)])
    (cands_d, hold_d, terms_d), (cands_l, hold_l, terms_l) = found[False], found[True]
    assert cands_d["accel_nonlinearity"][2] and cands_l.keys() == cands_d.keys()
    for effect, (drop, sigma, significant) in cands_d.items():
        assert cands_l[effect][0] == pytest.approx(drop, rel=1e-8, abs=1e-8), effect
        np.testing.assert_allclose(cands_l[effect][1], sigma, rtol=1e-8, err_msg=effect)
        assert cands_l[effect][2] == significant, effect
    assert hold_l.keys() == hold_d.keys()
    for name, score in hold_d.items():
        assert hold_l[name] == pytest.approx(score, rel=1e-8, abs=1e-10), name
    assert [n for n, _ in terms_l] == [n for n, _ in terms_d] and terms_d
    np.testing.assert_allclose([v for _, v in terms_l], [v for _, v in terms_d], rtol=1e-8)


@pytest.mark.parametrize("large", [False, True])
def test_a_fit_stopped_at_its_evaluation_limit_says_so(captures, monkeypatch, large):
    """least_squares stopping at max_nfev (status 0) was silent; the fit's notes (on screen and
    in the file) now say the values are those where it stopped.  (The limit of 2 evaluations is
    the fit's own, lsq.MAX_EVALUATIONS, which both solvers, the numpy LM of small fits and scipy's
    trf of large ones, are given; this test patched lsq.least_squares, which the solver27-b
    branch replaced by solver.LevenbergMarquardt: it failed there with an AttributeError.)"""
    monkeypatch.setattr(lsq, "MAX_EVALUATIONS", 2)
    result = fitted(captures["optimal9"], (), monkeypatch, large)
    assert not result.model.converged
    assert sum("stopped at its limit" in n for n in result.model.notes) == 1
    monkeypatch.undo()
    assert not any("stopped at its limit" in n for n in fitted(captures["optimal9"], (), monkeypatch, large).model.notes)
