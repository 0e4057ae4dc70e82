"""Review of issue 28's twenty-first session (branch vibphys28): what the review found."""
import pytest

from sim_devices.truth import mems_truth

import independent_crb


def test_the_independent_bound_refuses_an_imbalance_it_does_not_model():
    """tests/independent_crb.py computes its bound from world.body_kinematics alone and refuses a
    truth with a bench effect it does not model (the vibration among them); an imbalance of the
    platter (bench.imbalance_g_mm, new this session) shakes the IMU as the vibration does and must
    be refused too, not bound silently as if absent."""
    truth = mems_truth(0)
    truth.bench.imbalance_g_mm = 2000.0
    with pytest.raises(ValueError, match="imbalance"):
        independent_crb._check_supported(truth)
    truth.bench.imbalance_g_mm = 0.0
    independent_crb._check_supported(truth)         # the same truth without it is bound


# The review's second test (a recorded ramp's vibration harmonics against table_vibration's (4) on
# the fit's rows: off by 5-7 % of the vibration) fails on this merge: kept on branch
# wip/vibphys-review (docs/design.md, twenty-first session).
