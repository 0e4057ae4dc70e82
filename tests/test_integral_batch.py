"""An effect's batch form of its rotation-integral term (Effect.integral_batch, optional) is used by
the fit only where it is the batch of the integral in force: TimeOffset's equals its integral term
for term, and a subclass that overrides integral alone (a plugin's clock model) has that integral
called, not its parent's batch (review of the nineteenth session's branch arcs)."""
from types import SimpleNamespace

import numpy as np

from station.estimate import lsq
from station.model.time_offset import TimeOffset


class Doubled(TimeOffset):
    id = "doubled_offset"

    def integral(self, x, rotation):
        return 2.0 * super().integral(x, rotation)


def _rotations(rng, n):
    return [SimpleNamespace(gyro_start=rng.normal(size=3) * 50, gyro_end=rng.normal(size=3) * 50) for _ in range(n)]


def test_time_offsets_batch_equals_its_integral_term_for_term():
    rng = np.random.default_rng(4)
    rotations, X = _rotations(rng, 5), rng.normal(size=(7, 1)) * 1e-3
    effect = TimeOffset()
    batch = lsq._own_batch(effect)(X, rotations)
    each = np.array([[effect.integral(x, r) for r in rotations] for x in X])
    assert batch.shape == (7, 5, 3)
    np.testing.assert_array_equal(batch, each)


def test_a_subclass_overriding_integral_alone_is_not_given_its_parents_batch():
    assert lsq._own_batch(Doubled()) is None            # the fit calls Doubled.integral row by row
    assert lsq._own_batch(TimeOffset()) is not None
