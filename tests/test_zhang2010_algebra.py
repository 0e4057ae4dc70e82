"""The algebraic steps of the 2010 method on exact (noise-free) synthetic summaries.

The data here are made with a few lines of forward model written in the test, so these check the
algebra alone; tests/test_estimate_sim.py checks the whole chain against the simulated bench.
"""
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from station.core.errors import UserError
from station.estimate import zhang2010 as z

ARCSEC = np.radians(1 / 3600)


def lower_unit_rows(a_yz, a_zy, a_zx):
    T = np.array([[1, 0, 0], [np.sin(a_yz), 1, 0], [-np.sin(a_zy), np.sin(a_zx), 1.0]])
    T[1, 1] = np.sqrt(1 - T[1, 0] ** 2)
    T[2, 2] = np.sqrt(1 - T[2, 0] ** 2 - T[2, 1] ** 2)
    return T


UPS = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1],
                [1, 1, 0], [1, 0, 1], [0, 1, 1]], float)
UPS /= np.linalg.norm(UPS, axis=1)[:, None]


def test_lower_factor_reproduces_matrix():
    rng = np.random.default_rng(0)
    L = np.tril(rng.normal(size=(3, 3))) + 3 * np.eye(3)
    L[np.diag_indices(3)] = np.abs(L[np.diag_indices(3)])
    assert np.allclose(z.lower_factor(L.T @ L), L)


def test_accelerometer_ellipsoid_exact_from_nine_positions():
    g = 9.80665
    k = np.array([1.0004, 0.9993, 1.0011])
    T = lower_unit_rows(-180 * ARCSEC, 60 * ARCSEC, 330 * ARCSEC)
    b = np.array([0.006, -0.02, -0.01])
    # arbitrary headings: only the norm of the input matters
    f_p = np.array([Rotation.from_rotvec([0.1 * i, -0.2, 0.3 * i]).apply(u * g) for i, u in enumerate(UPS)])
    raw = f_p @ (np.diag(k) @ T).T + b
    L, b_hat = z.fit_accelerometers(raw, g)
    k_hat, T_hat = z.scale_and_T(L)
    assert np.allclose(k_hat, k, rtol=1e-10)
    assert np.allclose(T_hat, T, atol=1e-10)
    assert np.allclose(b_hat, b, atol=1e-10)


def test_gyro_pairs_and_bias_exact():
    k = np.array([1.0002, 0.9998, 1.0001])
    T = lower_unit_rows(300 * ARCSEC, -360 * ARCSEC, 48 * ARCSEC)
    KT = np.diag(k) @ T
    axes = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 0], [1, 0, 1], [0, 1, 1]], float)
    axes /= np.linalg.norm(axes, axis=1)[:, None]

    class P:  # a rotation pair reduced to what the fit uses
        def __init__(self, axis):
            self.phi, self.swept_deg = KT @ (3600.0 * axis), 3600.0

    L = z.fit_gyro_matrix([P(a) for a in axes])
    assert np.allclose(L, np.linalg.inv(KT), atol=1e-12)

    b = np.array([0.12, -0.20, 0.05]) / 3600
    omega = z.EARTH_RATE_DPS
    w_o = np.array([Rotation.from_rotvec([0.4 * i, 1.0 - 0.3 * i, 0.2]).apply([0, omega, 0]) for i in range(9)])
    b_hat = z.fit_gyro_bias(L, w_o @ KT.T + b)
    assert np.allclose(b_hat, b, atol=1e-12)


def test_accel_axis_null_vector_and_vertical_axis_detected():
    g, n = 9.8, 2000
    angle = np.linspace(0, 4 * np.pi, n)
    axis = np.array([0.3, -0.5, 0.81])
    axis /= np.linalg.norm(axis)
    gravity_dir = np.cross(axis, [1, 0, 0])
    gravity_dir /= np.linalg.norm(gravity_dir)
    f = np.array([Rotation.from_rotvec(-a * axis).apply(g * gravity_dir) for a in angle])
    l_hat, cond = z.accel_rotation_axis(f + 0.05 * np.cross(axis, [0, 1, 0]))  # centripetal: constant, normal to axis
    assert abs(abs(l_hat @ axis) - 1) < 1e-12 and cond > 1e6
    rng = np.random.default_rng(1)
    vertical = np.tile(g * axis, (n, 1)) + 1e-3 * rng.normal(size=(n, 3))
    assert z.accel_rotation_axis(vertical)[1] < z.MIN_AXIS_CONDITION


def test_too_few_attitudes_is_a_user_error():
    with pytest.raises(UserError, match="at least 9 static"):
        z.fit_accelerometers(np.ones((5, 3)), 9.8)
