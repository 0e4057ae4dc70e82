"""The complex-step safe rotation helpers (station/model/rotation.py) against scipy's Rotation on
real input, and their complex-step derivatives against central differences.

Tolerances: the real results are products of a few trigonometric values and additions: 1e-15
of their size (unit vectors and rotation matrices), i.e. a few rounding units.  A complex-step
derivative carries no subtraction error (its own rounding is ~1e-16 relative); the central
difference with step h has truncation h^2/6 |f'''| (f''' = O(1) for these bounded functions of
angles up to pi) and rounding eps/h: with h = 1e-5 both are below 2e-11, so 1e-9 is a bound with
a margin of 50, and far below the 1e-5 that forward differences reach."""
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from station.model import rotation as rot
from station.model.geometry import analytic_abs, normalised, positive_part


def rotvecs(rng, n=200):
    """Rotation vectors of every size: tiny (the series), around the switch, large (to pi)."""
    direction = normalised(rng.standard_normal((n, 3)))
    size = np.concatenate([[0.0, 1e-12, 1e-8], 10 ** rng.uniform(-8, np.log10(np.pi), n - 6),
                           np.sqrt(rot.SERIES_BELOW) * np.array([1 - 1e-9, 1.0, 1 + 1e-9])])
    return direction * size[:, None]


def test_real_input_matches_scipy():
    v = rotvecs(np.random.default_rng(1))
    R = Rotation.from_rotvec(v)
    np.testing.assert_allclose(rot.matrix_from_rotvec(v), R.as_matrix(), rtol=0, atol=1e-15)
    q, q_ref = rot.quat_from_rotvec(v), R.as_quat()
    q_ref *= np.sign(q_ref[:, 3:4] + (q_ref[:, 3:4] == 0))       # scipy may return -q
    np.testing.assert_allclose(q, q_ref, rtol=0, atol=1e-15)
    np.testing.assert_allclose(rot.matrix_from_quat(q), R.as_matrix(), rtol=0, atol=1e-15)
    a, b = R[:100], R[100:]
    np.testing.assert_allclose(rot.matrix_from_quat(rot.quat_product(a.as_quat(), b.as_quat())),
                               (a * b).as_matrix(), rtol=0, atol=1e-15)
    # the batch shape is kept
    assert rot.matrix_from_rotvec(v.reshape(2, 100, 3)).shape == (2, 100, 3, 3)


def test_series_and_closed_forms_join():
    t2 = rot.SERIES_BELOW * np.array([1 - 1e-12, 1 + 1e-12])
    assert abs(rot.sinc(t2)[0] - rot.sinc(t2)[1]) < 1e-15
    assert abs(rot.cos_half(t2)[0] - rot.cos_half(t2)[1]) < 1e-15
    theta = np.sqrt(t2)
    np.testing.assert_allclose(rot.sinc(t2), np.sin(theta) / theta, rtol=1e-15)
    np.testing.assert_allclose(rot.cos_half(t2), np.cos(theta / 2), rtol=1e-15)


def complex_step(f, v, h=1e-20):
    """df(v)/dv_j for every j by complex step: (..., j) stacked last."""
    return np.stack([np.imag(f(v + 1j * h * e)) / h for e in np.eye(v.shape[-1])], axis=-1)


def central(f, v, h=1e-5):
    return np.stack([(f(v + h * e) - f(v - h * e)) / (2 * h) for e in np.eye(v.shape[-1])], axis=-1)


@pytest.mark.parametrize("f", [rot.matrix_from_rotvec, rot.quat_from_rotvec,
                               lambda v: rot.matrix_from_quat(rot.quat_from_rotvec(v)),
                               lambda v: rot.quat_product(rot.quat_from_rotvec(v), rot.quat_from_rotvec(2 * v[::-1]))])
def test_complex_step_derivatives_equal_central_differences(f):
    rng = np.random.default_rng(2)
    v = rotvecs(rng, 60)[6:]        # central differences need |v| well above their step
    v = v[np.linalg.norm(v, axis=1) > 1e-3]
    v = np.concatenate([v, [[0.0, 0.0, 0.0]]])      # zero: the series, whose derivative is exact
    for vi in v:
        np.testing.assert_allclose(complex_step(f, vi.astype(complex)), central(f, vi), rtol=0, atol=1e-9)


def test_complex_helpers_of_the_model():
    v = np.array([0.3, -1.2, 0.5])
    np.testing.assert_allclose(complex_step(normalised, v.astype(complex)), central(normalised, v), atol=1e-9)
    z = np.array([-2.0, 3.0])
    np.testing.assert_allclose(complex_step(analytic_abs, z.astype(complex)), np.diag([-1.0, 1.0]), atol=1e-15)
    np.testing.assert_allclose(complex_step(positive_part, z.astype(complex)), np.diag([0.0, 1.0]), atol=1e-15)
    # np.abs on the same input would give the modulus: no imaginary part, a zero derivative
    assert np.all(np.imag(np.abs(z + 1e-20j)) == 0)
