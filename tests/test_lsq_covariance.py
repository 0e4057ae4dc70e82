"""The least-squares covariance and the 1-sigma read from it (station/estimate/lsq.py: _ScaledSVD,
covariance, _null_columns, FitResult.covariance_of, reported, _reported_index/_columns,
_held_by_weak_priors, _gauss_newton_step), on hand-made Jacobians whose answers are known in
closed form (issue 30 item 6: what mutation testing of the covariance needs; each test < 0.1 s).

Tolerances: (J^T J)^-1 from numpy's inverse of a Jacobian of condition number < 1e3 (columns
scaled) agrees with the SVD's to ~1e-13 relative; 1e-9 is far above that rounding and far below
any changed formula (a factor, a square, a threshold: >= 1e-6 relative).  The thresholds
(1e-13, 1e-9 of the largest singular value, 1e-6 of a null vector's component) are checked on
either side by a factor of 2 to 10.
"""
from __future__ import annotations

import types

import numpy as np
import pytest
from scipy.sparse import csr_matrix

from station.core import units
from station.estimate import lsq

RTOL = 1e-9


def _J(rows=40, cols=5, seed=3):
    rng = np.random.default_rng(seed)
    return rng.standard_normal((rows, cols)) * np.logspace(-4, 4, cols)     # columns of very different sizes


def test_covariance_is_the_inverse_of_the_normal_matrix():
    J = _J()
    expected = np.linalg.inv(J.T @ J)
    np.testing.assert_allclose(lsq.covariance(J), expected, rtol=RTOL, atol=0)
    svd = lsq._ScaledSVD(J)
    np.testing.assert_allclose(svd.covariance(), expected, rtol=RTOL, atol=0)
    assert svd.null().shape == (0, 5) and svd.null_columns() == [] and lsq._null_columns(J) == []
    np.testing.assert_array_equal(svd.J, J)


def test_a_given_scale_does_not_change_the_covariance_and_a_zero_scale_is_one():
    J = _J()
    expected = np.linalg.inv(J.T @ J)
    np.testing.assert_allclose(lsq.covariance(J, np.linalg.norm(J, axis=0) * 7.0), expected, rtol=RTOL, atol=0)
    scale = np.linalg.norm(J, axis=0)
    scale[2] = 0.0
    svd = lsq._ScaledSVD(J, scale)
    assert svd.norms[2] == 1.0 and svd.norms[0] == scale[0]
    np.testing.assert_allclose(svd.covariance(), expected, rtol=1e-6, atol=0)


def test_a_zero_column_gets_zero_variance_and_leaves_the_others_alone():
    J = _J()
    J0 = np.insert(J, 2, 0.0, axis=1)
    cov = lsq.covariance(J0)
    assert np.max(np.abs(cov[2])) < 1e-12 * np.max(np.abs(cov)) and np.max(np.abs(cov[:, 2])) < 1e-12 * np.max(np.abs(cov))
    np.testing.assert_allclose(np.delete(np.delete(cov, 2, 0), 2, 1), np.linalg.inv(J.T @ J), rtol=RTOL, atol=0)
    assert lsq._null_columns(J0) == [2]


def _nearly_aliased(eps, rows=30, seed=4):
    """Columns a and a + eps b (a, b orthonormal): scaled singular values ~sqrt(2) and
    ~eps/sqrt(2), a ratio of ~eps/2; a third column orthogonal to both."""
    rng = np.random.default_rng(seed)
    q, _ = np.linalg.qr(rng.standard_normal((rows, 3)))
    a, b, c = q.T
    return np.column_stack([a, a + eps * b, 3.0 * c])


@pytest.mark.parametrize("eps, kept", [(4e-13, True), (2e-14, False)])
def test_the_smallest_direction_kept_in_the_covariance(eps, kept):
    """Kept above 1e-13 of the largest singular value (variance ~1/eps^2), dropped below it
    (the direction takes no variance: ~1/4 each, from the large one only)."""
    cov = lsq.covariance(_nearly_aliased(eps))
    if kept:
        assert cov[0, 0] > 1e20
    else:
        assert 0.2 < cov[0, 0] < 0.3 and 0.2 < cov[1, 1] < 0.3
    # (rounding from the 1e20 direction leaks ~1e-8 of it into the third column when kept)
    assert cov[2, 2] == pytest.approx(1 / 9.0, rel=1e-6)


@pytest.mark.parametrize("eps, null", [(4e-9, False), (1e-10, True)])
def test_null_space_below_1e_9_of_the_largest_singular_value(eps, null):
    svd = lsq._ScaledSVD(_nearly_aliased(eps))
    assert len(svd.null()) == (1 if null else 0)
    assert svd.null_columns() == ([0, 1] if null else [])


@pytest.mark.parametrize("delta, in_null", [(1e-7, False), (1e-5, True)])
def test_a_column_takes_part_in_the_null_direction_above_1e_6(delta, in_null):
    """c2 = c0 + delta c1 exactly: the null vector (c0 + delta c1 - c2) has a component of
    ~delta/sqrt(2) on c1 (0.7e-7 or 0.7e-5, either side of 1e-6)."""
    rng = np.random.default_rng(5)
    q, _ = np.linalg.qr(rng.standard_normal((30, 2)))
    c0, c1 = q.T
    J = np.column_stack([c0, c1, c0 + delta * c1])
    assert lsq._null_columns(J) == ([0, 1, 2] if in_null else [0, 2])


def test_zero_columns_and_null_directions_together_sorted():
    rng = np.random.default_rng(6)
    q, _ = np.linalg.qr(rng.standard_normal((30, 3)))
    J = np.column_stack([q[:, 0], np.zeros(30), q[:, 1], 2 * q[:, 1], q[:, 2]])
    assert lsq._null_columns(J) == [1, 2, 3]
    assert lsq._ScaledSVD(J).null_columns() == [1, 2, 3]


# ----------------------------------------------------------------------- FitResult, reported


def _result(covariance_columns=None, effects=(), n_extra=0, seed=7):
    L = lsq.Layout()
    L.add("nuisance", 2)
    for block in ("accel_scale", "accel_misalignment", "accel_bias", "gyro_scale", "gyro_misalignment",
                  "gyro_bias", "inter_triad"):
        L.add(block, 3)
    for e in effects:
        L.add(f"effect:{e.id}", len(e.params))
    L.add("more", n_extra)
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((L.size, L.size))
    cov = A @ A.T + L.size * np.eye(L.size)
    x = rng.standard_normal(L.size)
    model = types.SimpleNamespace(layout=L, effects=list(effects))
    full_cov = cov
    if covariance_columns is not None:
        cov = cov[np.ix_(covariance_columns, covariance_columns)]
    return lsq.FitResult(x=x, covariance=cov, model=model, chi2=1.0, dof=1, residuals=np.zeros(1),
                         covariance_columns=covariance_columns), full_cov


def test_covariance_of_picks_the_columns_asked_for_in_their_order():
    res, full = _result()
    cols = [5, 2, 9]
    np.testing.assert_array_equal(res.covariance_of(cols), full[np.ix_(cols, cols)])
    kept = np.array([1, 2, 5, 9, 20])
    res, full = _result(covariance_columns=kept)
    np.testing.assert_array_equal(res.covariance_of(cols), full[np.ix_(cols, cols)])
    np.testing.assert_array_equal(res.covariance_of(np.array([20, 1])), full[np.ix_([20, 1], [20, 1])])


class _Param(types.SimpleNamespace):
    pass


class _Effect:
    id = "size_effect_like"
    params = [_Param(name="p_one", scale=1e3, unit="mm"), _Param(name="p_two", scale=2.0, unit="s")]


def test_reported_names_values_units_and_covariance():
    res, full = _result(effects=[_Effect()], n_extra=2)
    names, values, units_, cov = lsq.reported(res, "m/s^2", "deg/s")
    L = res.model.layout
    expected_names = (["accel_scale_x", "accel_scale_y", "accel_scale_z",
                       "accel_misalignment_yz", "accel_misalignment_zy", "accel_misalignment_zx",
                       "gyro_scale_x", "gyro_scale_y", "gyro_scale_z",
                       "gyro_misalignment_yz", "gyro_misalignment_zy", "gyro_misalignment_zx",
                       "accel_bias_x", "accel_bias_y", "accel_bias_z", "gyro_bias_x", "gyro_bias_y", "gyro_bias_z",
                       "inter_triad_x", "inter_triad_y", "inter_triad_z", "p_one", "p_two"])
    assert names == expected_names
    columns = [L[b].start + k for b in ("accel_scale", "accel_misalignment", "gyro_scale", "gyro_misalignment",
                                        "accel_bias", "gyro_bias", "inter_triad") for k in range(3)]
    columns += [L["effect:size_effect_like"].start, L["effect:size_effect_like"].start + 1]
    arcsec, ug = 180 * 3600 / np.pi, 1e6 / 9.80665
    factors = np.array([1.0] * 3 + [arcsec] * 3 + [1.0] * 3 + [arcsec] * 3 + [ug] * 3 + [3600.0] * 3
                       + [arcsec] * 3 + [1e3, 2.0])
    assert abs(1 / units.UG_MPS2 - ug) < 1e-9 * ug and abs(1 / units.ARCSEC_RAD - arcsec) < 1e-9 * arcsec
    np.testing.assert_allclose(values, res.x[columns] * factors, rtol=1e-12)
    np.testing.assert_allclose(cov, full[np.ix_(columns, columns)] * np.outer(factors, factors), rtol=1e-12)
    assert units_ == ["1"] * 3 + ["arcsec"] * 3 + ["1"] * 3 + ["arcsec"] * 3 + ["ug"] * 3 + ["deg/h"] * 3 \
        + ["arcsec"] * 3 + ["mm", "s"]
    np.testing.assert_array_equal(lsq._reported_columns(res), columns)
    n2, index, f2, u2 = lsq._reported_index(res, "m/s^2", "deg/s")
    assert n2 == names and index.tolist() == columns and index.dtype.kind == "i" and u2 == units_
    np.testing.assert_allclose(f2, factors, rtol=1e-15)


def test_reported_in_raw_units():
    res, full = _result()
    names, values, units_, cov = lsq.reported(res, "raw", "raw")
    assert units_[0:3] == ["raw/(m/s^2)"] * 3 and units_[6:9] == ["raw/(deg/s)"] * 3
    assert units_[12:15] == ["raw"] * 3 and units_[15:18] == ["raw"] * 3 and units_[3:6] == ["arcsec"] * 3
    L = res.model.layout
    np.testing.assert_array_equal(values[12:15], res.x[L["accel_bias"]])
    np.testing.assert_array_equal(values[15:18], res.x[L["gyro_bias"]])
    np.testing.assert_array_equal(values[0:3], res.x[L["accel_scale"]])
    np.testing.assert_array_equal(values[6:9], res.x[L["gyro_scale"]])
    # one raw, one physical
    _, _, u_a, _ = lsq.reported(res, "raw", "deg/s")
    _, _, u_g, _ = lsq.reported(res, "m/s^2", "raw")
    assert u_a[15] == "deg/h" and u_a[12] == "raw" and u_a[6] == "1" and u_a[0] == "raw/(m/s^2)"
    assert u_g[12] == "ug" and u_g[15] == "raw" and u_g[0] == "1" and u_g[6] == "raw/(deg/s)"


# ----------------------------------------------------------------------- degrees of freedom


def test_a_parameter_held_only_by_a_weak_prior_takes_no_degree_of_freedom():
    """Rows: 6 data rows that see parameters 0 and 1, and 2 weak-prior rows, one on parameter 1
    (determined by the data: takes ~0) and one on parameter 2 (seen by nothing else: takes 1)."""
    rng = np.random.default_rng(8)
    data = np.column_stack([rng.standard_normal((6, 2)), np.zeros(6)])
    weak = np.array([[0.0, 1e-3, 0.0], [0.0, 0.0, 1e-3]])
    J = np.vstack([data, weak])
    cov = np.linalg.inv(J.T @ J)
    s = types.SimpleNamespace(groups=1, rotations=[])
    model = types.SimpleNamespace(is_large=False, s=s, data_rows=np.array([True] * 6 + [False] * 2))
    reduced = types.SimpleNamespace(J=J)
    assert lsq._held_by_weak_priors(model, reduced, cov) == 1
    # every row data: no weak rows, nothing held
    model_none = types.SimpleNamespace(is_large=False, s=s, data_rows=np.ones(8, bool))
    assert lsq._held_by_weak_priors(model_none, reduced, cov) == 0
    weak2 = np.array([[0.0, 0.0, 1e-3], [0.0, 0.0, 1e-3], [5.0, 0.0, 0.0]])
    J2 = np.vstack([data, weak2])
    cov2 = np.linalg.inv(J2.T @ J2)
    share = float(np.sum((weak2 @ cov2) * weak2))
    model2 = types.SimpleNamespace(is_large=False, s=s, data_rows=np.array([True] * 6 + [False] * 3))
    assert lsq._held_by_weak_priors(model2, types.SimpleNamespace(J=J2), cov2) == int(round(share)) == 2


def test_a_large_model_counts_the_axes_without_a_steady_rotation():
    rot = lambda group, steady: types.SimpleNamespace(group=group, steady=steady)    # noqa: E731
    s = types.SimpleNamespace(groups=5, rotations=[rot(0, True), rot(1, False), rot(1, False), rot(2, True),
                                                   rot(2, False)])
    model = types.SimpleNamespace(is_large=True, s=s)
    assert lsq._held_by_weak_priors(model, None, None) == 3          # groups 1, 3 and 4


# ----------------------------------------------------------------------- the step left


def test_the_step_left_is_the_least_squares_step():
    J = _J(seed=9)
    r = np.random.default_rng(10).standard_normal(J.shape[0])
    expected = np.linalg.lstsq(J, -r, rcond=None)[0]
    np.testing.assert_allclose(lsq._gauss_newton_step(J, r), expected, rtol=1e-8)
    # a zero column takes no step (minimum norm), the others are unchanged
    J0 = np.insert(J, 1, 0.0, axis=1)
    d = lsq._gauss_newton_step(J0, r)
    assert abs(d[1]) < 1e-12 * np.max(np.abs(d))
    np.testing.assert_allclose(np.delete(d, 1), expected, rtol=1e-8)
    # the sparse path (large models) gives the same step
    Js = _J(cols=4, seed=11) / np.logspace(-4, 4, 4) * np.logspace(-1, 1, 4)
    expected = np.linalg.lstsq(Js, -r, rcond=None)[0]
    np.testing.assert_allclose(lsq._gauss_newton_step(csr_matrix(Js), r), expected, rtol=1e-6)


def test_the_scale_given_decides_what_is_kept_and_what_is_null():
    """Measured against a scale of 1e-6 for the third column (its own size is 3), the nearly
    aliased pair's small direction falls below 1e-13 and 1e-9 of the largest singular value:
    dropped from the covariance and null."""
    J = _nearly_aliased(4e-9)
    assert lsq._null_columns(J) == [] and lsq._null_columns(J, np.array([1.0, 1.0, 1e-6])) == [0, 1]
    J = _nearly_aliased(4e-13)
    assert lsq.covariance(J)[0, 0] > 1e20 > 1.0 > lsq.covariance(J, np.array([1.0, 1.0, 1e-6]))[0, 0]


@pytest.mark.parametrize("consistent", [True, False])
def test_the_sparse_step_is_solved_to_rounding(consistent):
    """LSMR to 1e-14 on both of its stopping rules (atol: the normal equations, for residuals
    the model cannot reach; btol: the residual, for ones it can): at its defaults (1e-6) the step
    is off by up to its own size on this Jacobian (columns 1e-3 to 1e3)."""
    rng = np.random.default_rng(1)
    J = rng.standard_normal((40, 4)) * np.logspace(-3, 3, 4)
    x = rng.standard_normal(4)
    r = -(J @ x) + (0.0 if consistent else 0.1 * rng.standard_normal(40))
    expected = np.linalg.lstsq(J, -r, rcond=None)[0]
    np.testing.assert_allclose(lsq._gauss_newton_step(csr_matrix(J), r), expected, rtol=1e-9)


def test_the_dense_step_ignores_directions_below_1e_12():
    """Two columns equal to 1e-13 (scaled): below rcond 1e-12 the pair is one direction and the
    step is shared between them (minimum norm), not 1e13 times larger."""
    J = _nearly_aliased(1e-13)
    r = np.random.default_rng(2).standard_normal(J.shape[0])
    d = lsq._gauss_newton_step(J, r)
    assert np.max(np.abs(d)) < 10 * np.linalg.norm(r)
    assert d[0] == pytest.approx(d[1], rel=1e-6)
