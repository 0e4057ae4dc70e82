"""station.model.compensate on hand-made calibrations (issue 30 item 6: the survivors of mutation
testing): raw samples are made here from a known specific force and rate by the forward model
written out in numpy (not by station.model), and compensation must give them back.

Tolerances: the compensation is exact algebra (matrix inverse, a fixed-point iteration stopped
when the relative change is below 1e-13, whose terms here are at most 1e-3 of the values, so
the error left is below 1e-13 / (1 - 1e-3)); the matrices' condition numbers are below 10, so
float64 rounding stays near 1e-14 relative: 1e-10 relative is 4 orders above what a correct
compensation leaves and far below what any changed term (>= 1e-6 of the values) gives.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from station.model import compensate as C

G = 9.80665
RTOL = 1e-10


def _matrices(rng):
    """A forward matrix near the identity (scale factors 1 +/- 2 %, misalignments ~1e-2)."""
    return np.eye(3) + 0.02 * rng.standard_normal((3, 3))


def _samples(n=50, seed=1):
    rng = np.random.default_rng(seed)
    t = 100.0 + np.arange(n) * 0.01                          # a run that does not start at 0 s
    f = np.array([1.0, -2.0, 9.0]) + 0.5 * rng.standard_normal((n, 3))          # m/s^2
    w = np.array([5.0, -20.0, 90.0]) + np.outer(t - t[0], [3.0, 1.0, -2.0])     # deg/s, linear in t
    temp = 20.0 + 3.0 * (t - t[0]) ** 2                       # deg C, its rate changes
    return rng, t, f, w, temp


def test_factors_are_the_raw_units():
    assert C.factors({"raw_units": {"accel": "g", "gyro": "rad/s"}}) == (G, 180.0 / math.pi)
    assert C.factors({"raw_units": {"accel": "raw", "gyro": "raw"}}) == (1.0, 1.0)
    assert C.factors({"raw_units": {"accel": "m/s^2"}}) == (1.0, 1.0)
    assert C.factors({"raw_units": {"gyro": "rad/s"}}) == (1.0, 180.0 / math.pi)
    assert C.factors({"raw_units": None}) == (1.0, 1.0)
    assert C.factors({}) == (1.0, 1.0)


def _comp(rng, Ma, Mg, accel="g", gyro="rad/s"):
    fa, fg = C.factors({"raw_units": {"accel": accel, "gyro": gyro}})
    return {"raw_units": {"accel": accel, "gyro": gyro},
            "accel_matrix": fa * np.linalg.inv(Ma), "gyro_matrix": fg * np.linalg.inv(Mg),
            "accel_bias": np.array([0.01, -0.02, 0.03]), "gyro_bias": np.array([0.001, 0.002, -0.003])}, fa, fg


def _raw(comp, fa, fg, Ma, Mg, f, w, da=0.0, dw=0.0):
    """The forward model: a_si = Ma f + da, raw = a_si / fa + bias (the same for the gyro)."""
    a_si = f @ Ma.T + da
    w_si = w @ Mg.T + dw
    return a_si / fa + comp["accel_bias"], w_si / fg + comp["gyro_bias"]


def test_without_effects_the_forward_model_is_inverted_in_any_raw_units():
    rng, t, f, w, _ = _samples()
    Ma, Mg = _matrices(rng), _matrices(rng)
    for accel, gyro in (("g", "rad/s"), ("m/s^2", "deg/s")):
        comp, fa, fg = _comp(rng, Ma, Mg, accel, gyro)
        ar, gr = _raw(comp, fa, fg, Ma, Mg, f, w)
        t2, f2, w2 = C.compensate_with_effects(comp, [], t, ar, gr)
        np.testing.assert_array_equal(t2, t)
        np.testing.assert_allclose(f2, f, rtol=RTOL, atol=RTOL * 10)
        np.testing.assert_allclose(w2, w, rtol=RTOL, atol=RTOL * 100)


class _AllInputs:
    """An effect whose terms use every field of the sample context (small: <= 1e-3 of the
    values), and that shifts the time stamps; calls counted."""
    def __init__(self):
        self.calls = 0

    def compensate_time(self, x, t):
        return np.asarray(t) - x[0]

    @staticmethod
    def terms(x, f, w_dps, w_rad, wdot, temp, temp_rate, t_s, Ma, Mg):
        da = (x[1] * f ** 2 / G + x[2] * w_rad + x[3] * wdot + x[4] * (temp[:, None] - 20.0)
              + x[5] * t_s[:, None] + x[6] * temp_rate[:, None] + x[7] * f @ (Ma - np.eye(3)).T)
        dw = x[1] * w_dps ** 2 / 100.0 + x[3] * wdot + x[7] * w_dps @ (Mg - np.eye(3)).T + x[8] * f
        return da, dw

    def accel(self, x, ctx):
        self.calls += 1
        return self.terms(x, ctx.f_p, ctx.w_p, ctx.w_table, ctx.wdot_table, ctx.temp_c,
                          ctx.temp_rate_c_per_s, ctx.t_s, ctx.accel_matrix, ctx.gyro_matrix)[0]

    def gyro(self, x, ctx):
        return self.terms(x, ctx.f_p, ctx.w_p, ctx.w_table, ctx.wdot_table, ctx.temp_c,
                          ctx.temp_rate_c_per_s, ctx.t_s, ctx.accel_matrix, ctx.gyro_matrix)[1]


def test_every_effect_input_is_the_compensated_value_and_the_time_corrected_first():
    rng, t, f, w, temp = _samples()
    Ma, Mg = _matrices(rng), _matrices(rng)
    comp, fa, fg = _comp(rng, Ma, Mg)
    x = np.array([0.25, 1e-4, 1e-3, 1e-3, 1e-4, 1e-4, 1e-4, 1e-3, 1e-4])
    t_true = t - x[0]               # the effect's clock offset: the samples' true time
    w_rad = np.radians(w)
    da, dw = _AllInputs.terms(x, f, w, w_rad, np.gradient(w_rad, t_true, axis=0), temp,
                              np.gradient(temp, t_true), t_true - t_true[0], Ma, Mg)
    ar, gr = _raw(comp, fa, fg, Ma, Mg, f, w, da, dw)
    effect = _AllInputs()
    t2, f2, w2 = C.compensate_with_effects(comp, [(effect, x)], t, ar, gr, temp=temp)
    np.testing.assert_allclose(t2, t_true, rtol=0, atol=1e-12)
    np.testing.assert_allclose(f2, f, rtol=RTOL, atol=RTOL * 10)
    np.testing.assert_allclose(w2, w, rtol=RTOL, atol=RTOL * 100)
    assert effect.calls < 10            # a contraction of 1e-3 a step: a few steps to 1e-13


class _Constant:
    """A constant term: exact after one step, so the iteration ends on the second (no change)."""
    def __init__(self):
        self.calls = 0

    def compensate_time(self, x, t):
        return t

    def accel(self, x, ctx):
        self.calls += 1
        return np.broadcast_to(x, ctx.f_p.shape)

    def gyro(self, x, ctx):
        return None


def test_the_iteration_stops_once_nothing_changes():
    rng, t, f, w, _ = _samples()
    Ma, Mg = _matrices(rng), _matrices(rng)
    comp, fa, fg = _comp(rng, Ma, Mg)
    x = np.array([0.01, 0.02, -0.03])
    ar, gr = _raw(comp, fa, fg, Ma, Mg, f, w, da=x)
    effect = _Constant()
    _, f2, w2 = C.compensate_with_effects(comp, [(effect, x)], t, ar, gr)
    np.testing.assert_allclose(f2, f, rtol=RTOL, atol=RTOL * 10)
    np.testing.assert_allclose(w2, w, rtol=RTOL, atol=RTOL * 100)
    assert effect.calls == 2
    # small values (|f| < 1): the change is relative to the values, not to 1
    f_small = f * 1e-3
    ar, gr = _raw(comp, fa, fg, Ma, Mg, f_small, w, da=x * 1e-3)
    effect = _Constant()
    _, f2, _ = C.compensate_with_effects(comp, [(effect, x * 1e-3)], t, ar, gr)
    np.testing.assert_allclose(f2, f_small, rtol=RTOL, atol=RTOL * 1e-2)
    assert effect.calls == 2


def test_a_term_that_never_settles_stops_at_the_iteration_limit():
    class Flip(_Constant):
        def accel(self, x, ctx):            # a term that changes sign every step: no fixed point
            self.calls += 1
            return np.full(ctx.f_p.shape, 1e-3 * (-1) ** self.calls)
    rng, t, f, w, _ = _samples()
    comp, fa, fg = _comp(rng, np.eye(3), np.eye(3))
    effect = Flip()
    C.compensate_with_effects(comp, [(effect, None)], t, *_raw(comp, fa, fg, np.eye(3), np.eye(3), f, w))
    assert effect.calls == C.MAX_ITERATIONS == 20


def test_one_sample_has_no_derivatives():
    seen = {}

    class Probe(_Constant):
        def accel(self, x, ctx):
            seen.update(wdot=ctx.wdot_table.copy(), rate=ctx.temp_rate_c_per_s, temp=ctx.temp_c.copy(),
                        t_s=ctx.t_s.copy())
            return None
    rng, t, f, w, temp = _samples(n=1)
    comp, fa, fg = _comp(rng, np.eye(3), np.eye(3))
    ar, gr = _raw(comp, fa, fg, np.eye(3), np.eye(3), f, w)
    _, f2, w2 = C.compensate_with_effects(comp, [(Probe(), None)], t, ar, gr, temp=temp)
    assert seen["wdot"].shape == (1, 3) and seen["wdot"].dtype == np.float64 and not seen["wdot"].any()
    assert seen["rate"] is None and seen["temp"].tolist() == [20.0] and seen["t_s"].tolist() == [0.0]
    np.testing.assert_allclose(f2, f, rtol=RTOL)
    # and no temperature column: NaN, no rate
    seen.clear()
    rng, t, f, w, _ = _samples(n=5)
    C.compensate_with_effects(comp, [(Probe(), None)], t, *_raw(comp, fa, fg, np.eye(3), np.eye(3), f, w))
    assert seen["rate"] is None and np.isnan(seen["temp"]).all() and seen["temp"].shape == (5,)


# ------------------------------------------------------------------ the legacy keys (compensate)

def _legacy(rng, Ma, Mg):
    return {"accel_matrix": np.linalg.inv(Ma), "gyro_matrix": np.linalg.inv(Mg),
            "accel_bias": np.array([0.01, -0.02, 0.03]), "gyro_bias": np.array([0.001, 0.002, -0.003])}


def test_legacy_compensation_inverts_the_matrices_and_biases():
    rng, t, f, w, _ = _samples()
    Ma, Mg = _matrices(rng), _matrices(rng)
    comp = _legacy(rng, Ma, Mg)
    ar, gr = f @ Ma.T + comp["accel_bias"], w @ Mg.T + comp["gyro_bias"]
    f2, w2 = C.compensate(comp, t, ar, gr)
    np.testing.assert_allclose(f2, f, rtol=RTOL, atol=RTOL * 10)
    np.testing.assert_allclose(w2, w, rtol=RTOL, atol=RTOL * 100)


def test_legacy_biases_follow_the_temperature():
    rng, t, f, w, temp = _samples()
    Ma, Mg = _matrices(rng), _matrices(rng)
    comp = _legacy(rng, Ma, Mg)
    comp.update(temperature_reference_c=25.0, accel_bias_tempco_raw_per_c=[1e-3, -2e-3, 3e-3],
                gyro_bias_tempco_raw_per_c=[-1e-4, 2e-4, 3e-4])
    dT = (temp - 25.0)[:, None]
    ar = f @ Ma.T + comp["accel_bias"] + dT * np.array(comp["accel_bias_tempco_raw_per_c"])
    gr = w @ Mg.T + comp["gyro_bias"] + dT * np.array(comp["gyro_bias_tempco_raw_per_c"])
    f2, w2 = C.compensate(comp, t, ar, gr, temp=temp)
    np.testing.assert_allclose(f2, f, rtol=RTOL, atol=RTOL * 10)
    np.testing.assert_allclose(w2, w, rtol=RTOL, atol=RTOL * 100)
    # without a temperature column the coefficients are not applied
    f3, _ = C.compensate(comp, t, ar, gr)
    assert np.max(np.abs(f3 - f)) > 1e-3


def test_legacy_lever_arm_moves_each_accelerometer_to_the_reference_point():
    """f_i = f + wdot x p_i + w x (w x p_i) at accelerometer i (rate linear in time, so the
    compensation's finite-difference derivative is exact)."""
    rng, t, f, w, _ = _samples()
    Ma, Mg = _matrices(rng), _matrices(rng)
    comp = _legacy(rng, Ma, Mg)
    positions = np.array([[0.05, 0.01, -0.02], [-0.03, 0.04, 0.01], [0.02, -0.01, 0.06]])
    comp["accel_lever_arm_m"] = positions
    w_rad = np.radians(w)
    wdot = np.gradient(w_rad, t, axis=0)
    ar = np.empty_like(f)
    for i in range(3):
        fi = f + np.cross(wdot, positions[i]) + np.cross(w_rad, np.cross(w_rad, positions[i]))
        ar[:, i] = (fi @ Ma.T)[:, i] + comp["accel_bias"][i]
    gr = w @ Mg.T + comp["gyro_bias"]
    f2, w2 = C.compensate(comp, t, ar, gr)
    np.testing.assert_allclose(f2, f, rtol=RTOL, atol=RTOL * 10)
    np.testing.assert_allclose(w2, w, rtol=RTOL, atol=RTOL * 100)
    # one sample: no derivative, the lever arm is left out (not a crash)
    f1, _ = C.compensate(comp, t[:1], ar[:1], gr[:1])
    assert f1.shape == (1, 3)
    np.testing.assert_allclose(f1, (ar[:1] - comp["accel_bias"]) @ comp["accel_matrix"].T, rtol=RTOL)


# ------------------------------------------------------------------ survivors of the mutation run

def test_time_comes_back_as_float_whatever_it_was_given_as():
    rng, t, f, w, _ = _samples(n=5)
    comp, fa, fg = _comp(rng, np.eye(3), np.eye(3))
    ar, gr = _raw(comp, fa, fg, np.eye(3), np.eye(3), f, w)
    t2, _, _ = C.compensate_with_effects(comp, [], [0, 1, 2, 3, 4], ar, gr)
    assert t2.dtype == np.float64 and t2.tolist() == [0.0, 1.0, 2.0, 3.0, 4.0]


def test_two_samples_have_derivatives():
    """The derivatives (rate, temperature) and the lever arm are taken from two samples on."""
    seen = {}

    class Probe(_Constant):
        def accel(self, x, ctx):
            seen.update(wdot=ctx.wdot_table.copy(), rate=ctx.temp_rate_c_per_s)
            return None
    rng, t, f, w, temp = _samples(n=2)
    comp, fa, fg = _comp(rng, np.eye(3), np.eye(3))
    ar, gr = _raw(comp, fa, fg, np.eye(3), np.eye(3), f, w)
    C.compensate_with_effects(comp, [(Probe(), None)], t, ar, gr, temp=temp)
    np.testing.assert_allclose(seen["wdot"], np.radians(np.gradient(w, t, axis=0)), rtol=RTOL)
    np.testing.assert_allclose(seen["rate"], np.gradient(temp, t), rtol=RTOL)
    legacy = _legacy(rng, np.eye(3), np.eye(3))
    legacy["accel_lever_arm_m"] = np.full((3, 3), 0.1)
    f_with, _ = C.compensate(legacy, t, f, w)
    del legacy["accel_lever_arm_m"]
    f_without, _ = C.compensate(legacy, t, f, w)
    assert np.max(np.abs(f_with - f_without)) > 1e-3        # (w ~ 90 deg/s: w^2 r ~ 0.25 m/s^2)


class _Contraction(_Constant):
    """A term of 1e-3 of the compensated value, on one sensor (the other's change is then 0 from
    the first step, so the stop is decided by this one's): each step shrinks the change 1000 times."""
    def __init__(self, sensor):
        super().__init__()
        self.sensor = sensor

    def accel(self, x, ctx):
        self.calls += 1
        return 1e-3 * ctx.f_p if self.sensor == "accel" else None

    def gyro(self, x, ctx):
        return 1e-3 * ctx.w_p if self.sensor == "gyro" else None


@pytest.mark.parametrize("sensor", ["accel", "gyro"])
@pytest.mark.parametrize("size", [1e-6, 1e6])
def test_the_iteration_stops_on_the_relative_change_at_any_size(size, sensor):
    """The same number of steps for values a million times smaller or larger: the change that
    ends it is relative to the values (not absolute, not multiplied by them)."""
    rng, t, f, w, _ = _samples()
    comp, fa, fg = _comp(rng, np.eye(3), np.eye(3))
    counts = []
    for s in (1.0, size):
        fs, ws = f * s, w * s
        comp_s = dict(comp, accel_bias=comp["accel_bias"] * s, gyro_bias=comp["gyro_bias"] * s)
        da, dw = (1e-3 * fs, 0.0) if sensor == "accel" else (0.0, 1e-3 * ws)
        ar, gr = _raw(comp_s, fa, fg, np.eye(3), np.eye(3), fs, ws, da=da, dw=dw)
        effect = _Contraction(sensor)
        _, f2, w2 = C.compensate_with_effects(comp_s, [(effect, None)], t, ar, gr)
        np.testing.assert_allclose(f2, fs, rtol=1e-12)
        np.testing.assert_allclose(w2, ws, rtol=1e-12)
        counts.append(effect.calls)
    assert counts[0] == counts[1] and 3 <= counts[0] <= 8, counts
