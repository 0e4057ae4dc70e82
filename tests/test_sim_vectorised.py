"""The simulated bench's attitudes composed as quaternion arrays (sim_devices.world.quat_product,
issue 27 item 5) give the samples the scipy composition gave: the physics is unchanged.

The reference is the code it replaced, kept here: scipy's ``Rotation.__mul__`` composing the
start attitude with the stack of turns (table_attitude) and with the stacked wobble product
(wobbling_table).  A whole capture is simulated with each on the same seed and every sample
compared.

Tolerance: the two compose the same unit quaternions in a different order of floating-point
operations; each attitude then differs by a few ulps (~1e-16 rad), which moves a sample by
~1e-16 of its size (gravity's 9.8 m/s^2, the rates), then through the sensor model's scale and
cross-coupling (~1) and the sums of its terms: ~1e-15 relative to the largest sample (measured:
7e-15 without the wobble, 7e-16 with it; the default truth does not quantise).  The test allows
1e-12 relative to the largest sample of each segment, a hundred times that; a wrong composition
(the product's order swapped, a sign) moves samples by the attitude's error times g, 1e-6 and up.
"""
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from sim_devices import world
from station.io.scheme import load_scheme
from station.simulate import dryrun


def _table_attitude_scipy(C_bn0, axis_enu, theta):
    a_n = world._unit(axis_enu, "axis_enu")
    theta = np.asarray(theta, dtype=float).reshape(-1)
    return C_bn0 * Rotation.from_rotvec(-theta[:, None] * a_n[None, :])


_wobbling_new = world.wobbling_table


def _wobbling_table_scipy(C_bn0, axis_enu, theta, theta_dot, theta_ddot, wobble_rad, phase_rad=0.0, harmonic=1):
    """The replaced composition: C_bn0 * Rotation(q_e (x) q_theta) through scipy."""
    identity = Rotation.identity()
    C_rel, w_b, wd_b = _wobbling_new(identity, axis_enu, theta, theta_dot, theta_ddot, wobble_rad,
                                     phase_rad, harmonic)
    return C_bn0 * C_rel, C_bn0.apply(w_b), C_bn0.apply(wd_b)


def _samples(scheme, truth, seed):
    capture = dryrun.simulate_capture(scheme, truth, seed)
    return {s.name: s.data for s in capture.segments}


@pytest.mark.parametrize("wobble_arcsec", [0.0, 40.0])
def test_quaternion_arrays_give_the_scipy_compositions_samples(monkeypatch, wobble_arcsec):
    scheme = load_scheme("optimal9")
    truth = dryrun.load_truth(None, 0)
    truth.bench.wobble_arcsec = wobble_arcsec
    new = _samples(scheme, truth, 7)
    monkeypatch.setattr(world, "table_attitude", _table_attitude_scipy)
    monkeypatch.setattr(world, "wobbling_table", _wobbling_table_scipy)
    old = _samples(scheme, truth, 7)
    assert new.keys() == old.keys()
    rotations = 0
    for name in new:
        a, b = new[name], old[name]
        np.testing.assert_array_equal(a.t, b.t)
        for field in ("accel", "gyro"):
            x, y = getattr(a, field), getattr(b, field)
            scale = np.max(np.abs(y))
            assert np.max(np.abs(x - y)) <= 1e-12 * scale, (name, field, np.max(np.abs(x - y)), scale)
        rotations += name.startswith("rot")
    assert rotations >= 6          # the composition under test ran


def test_quat_product_is_scipys_composition():
    rng = np.random.default_rng(3)
    p = Rotation.random(50, random_state=rng)
    q = Rotation.random(50, random_state=rng)
    got = Rotation.from_quat(world.quat_product(p.as_quat(), q.as_quat()))
    want = p * q
    v = rng.standard_normal(3)
    np.testing.assert_allclose(got.apply(v), want.apply(v), rtol=0, atol=1e-14 * np.linalg.norm(v))
    one = world.quat_product(p[0].as_quat(), q.as_quat())               # one against a stack
    np.testing.assert_allclose(Rotation.from_quat(one).apply(v), (p[0] * q).apply(v), rtol=0, atol=1e-14 * np.linalg.norm(v))
