"""Backward elimination: an effect --auto added early is dropped when a later effect (or the
terms found outside the library) explains the same thing, and kept when it is still needed.

The simulated gyro has a term in the square of the rate, q_i r_i^2 (sim_devices: the same sign in
both directions, like a scale asymmetry A_i |r_i|); with rotations at 25, 60 and 100 deg/s the two
are told apart, but a scale asymmetry fitted first takes up part of the r^2 term."""
import pytest

from station.diagnose import auto
from station.diagnose.core import diagnose
from station.diagnose.holdout import leave_one_segment_out
from station.estimate import lsq
from station.io.scheme import parse_scheme
from station.model.effect import Effect, Param
from station.model.registry import EffectRegistry
from station.simulate import dryrun
import simhelpers

Q = [4.0, -3.0, 5.0]                    # ppm/(deg/s): 4e-6 deg/s per (deg/s)^2
UPS = [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1], [1, 1, 0], [1, 0, 1], [0, 1, 1]]


class GyroRateSquaredEven(Effect):
    """The physics the simulated gyro has: q_i 1e-6 w_i^2 (ppm per deg/s), the same sign both ways."""
    id = "gyro_rate_squared_even"
    title = "gyro output term in the square of the rate"

    @property
    def params(self):
        return tuple(Param(f"gyro_rate2_even_{a}", "ppm/(deg/s)", 1.0, 5.0, 1000.0) for a in "xyz")

    def gyro(self, x, ctx):
        w = ctx.w_p @ ctx.gyro_matrix.T
        return 1e-6 * x * w**2


def multirate_summaries(seed, **hidden):
    """optimal9's attitudes (5 s dwells) and one revolution each way about x, y and z at 30 and
    100 deg/s: the smallest capture that separates |r| from r^2 (two rates)."""
    from sim_devices.truth import mems_truth

    segments = [{"static": f"pos{i}", "up_body": u} for i, u in enumerate(UPS)]
    for name, axis in (("rotx", [1, 0, 0]), ("roty", [0, 1, 0]), ("rotz", [0, 0, 1])):
        for rate in (30.0, 100.0):
            segments.append({"rotation": f"{name}{int(rate)}", "axis_body": axis, "rate_dps": rate,
                             "rotation_s": 360.0 / rate})
    scheme = parse_scheme({"name": "multirate", "defaults": {"dwell_s": 5.0}, "segments": segments}, "test", {})
    truth = simhelpers.hide(mems_truth(0), **hidden)
    return lsq.summarise(dryrun.simulate_capture(scheme, truth, seed))


@pytest.fixture(scope="module")
def rate_squared():
    return multirate_summaries(3, gyro__rate_squared_ppm_per_dps=Q)


def _fit(s, *effects):
    return diagnose(lsq.fit(s, list(effects)), exclude=EffectRegistry().ids() + [GyroRateSquaredEven.id])


def _step_then_eliminate(s):
    """The loop's state after it added the r^2 effect to a model holding a scale asymmetry."""
    current = _fit(s, EffectRegistry().create("gyro_scale_asymmetry"), GyroRateSquaredEven())
    step = auto.Step(GyroRateSquaredEven.id, current, current, 0.0, 0.0, [])
    reg = EffectRegistry()
    reg._register(GyroRateSquaredEven, "test")
    refused = set()
    final, _ = auto.eliminate(s, step, ["gyro_scale_asymmetry"], current, leave_one_segment_out(current.result),
                              "auto", reg, refused)
    return step, final, refused


def test_an_earlier_effect_explained_by_a_later_one_is_dropped_and_the_step_says_so(rate_squared):
    step, final, refused = _step_then_eliminate(rate_squared)
    assert [e.id for e in final.result.model.effects] == [GyroRateSquaredEven.id]
    assert [e for e, _ in step.removed] == ["gyro_scale_asymmetry"]
    assert "no longer needed with gyro_rate_squared_even in the model" in step.removed[0][1]
    assert "gyro_scale_asymmetry" in refused          # not tried again by the loop
    # the refit r^2 coefficients, now alone, are the truth within 4 sigma
    assert len(step.estimate) == 3
    for name, value, sigma, unit in step.estimate:
        assert abs(value - Q["xyz".index(name[-1])]) < 4 * sigma, (name, value, sigma)


def test_an_earlier_effect_still_needed_is_kept():
    s = multirate_summaries(3, gyro__rate_squared_ppm_per_dps=Q, gyro__scale_asymmetry_ppm=[400.0, -300.0, 500.0])
    step, final, _ = _step_then_eliminate(s)
    assert step.removed == []
    assert {e.id for e in final.result.model.effects} == {"gyro_scale_asymmetry", GyroRateSquaredEven.id}


def test_terms_found_later_make_an_earlier_effect_redundant_in_the_verdict(rate_squared):
    """What conclude() does with the terms found outside the library (any extra effect: here the
    r^2 term itself): the scale asymmetry added first is named as no longer needed."""
    d = _fit(rate_squared, EffectRegistry().create("gyro_scale_asymmetry"))
    redundant = auto.redundant_with(d, GyroRateSquaredEven(), {"gyro_scale_asymmetry"}, rate_squared)
    assert [e for e, _ in redundant] == ["gyro_scale_asymmetry"]
    assert "removing it raises chi2 by only" in redundant[0][1]

