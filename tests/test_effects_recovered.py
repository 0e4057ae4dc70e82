"""Library effects hidden in a simulated capture (issue 25): the simulated truth (sim_devices,
written from the physics without station.model) carries the effect at a typical size; the fit
with the effect added must recover it within 4 sigma with a 1-sigma small enough that the check
can fail (below a fifth of the size), the calibration's error on held-out samples of the same
IMU must fall to that of a capture without the effect (the noise floor), and diagnose's score
test must name it (or, where the capture cannot tell it from another effect, say which: the
effect's ``signature`` says so too).

Held-out error: noise-free raw outputs that the truth gives at random attitudes, rates up to
150 deg/s, temperatures and times over the training capture's (tests/effect_recovery.py),
compensated with the fitted calibration and its effects, against the true specific force and
rate in frame p.  The floor is the same error of a fit to a capture of the same IMU, seed and
scheme without the hidden effect.
"""
from __future__ import annotations

import functools

import numpy as np
import pytest

from effect_recovery import estimates, fit, held_out_error, mems, scheme, simulate
import simhelpers
from simhelpers import NINE_STATICS
from station.diagnose.core import diagnose
from station.io.scheme import load_scheme, parse_scheme

K = 4.0                       # recovered within K sigma (a 4-sigma miss: 6e-5 per parameter)
FLOOR_FACTOR = 1.6            # the held-out error with the effect: within this of the floor

OPTIMAL9_FAST = load_scheme("optimal9", {"rate_dps": 100.0, "rotation_s": 7.2, "dwell_s": 20.0})
ROTATIONS_XYZ = """\
  - {{rotation: rotx{k}, axis_body: [1, 0, 0]}}
  - {{rotation: roty{k}, axis_body: [0, 1, 0]}}
  - {{rotation: rotz{k}, axis_body: [0, 0, 1]}}
"""
# nine statics and three rotation pairs, three times over a warm-up (10 s dwells, 2 turns at
# 100 deg/s): every attitude and every rotation axis at three temperatures
WARM3 = scheme("name: warm3\ndefaults: {dwell_s: 10.0, rate_dps: 100.0, rotation_s: 7.2}\nsegments:\n"
               + "".join(NINE_STATICS.replace("pos0", f"p{k}_") + ROTATIONS_XYZ.format(k=k) for k in range(3)))
WARM = {"temperature__warmup_delta_c": 12.0, "temperature__warmup_time_constant_s": 400.0}
WARM_RANGE_C = (25.0, 36.0)     # the temperature over WARM3 with WARM: 25.4 to 35.7 deg C


@functools.lru_cache(maxsize=None)
def mems_floor_optimal9_fast():
    """The floor of the MEMS IMU (no hidden effect) on OPTIMAL9_FAST: the held-out error of the
    base fit to its capture (seed 3).  Computed once for the module: the K3 and cross-axis tests
    both compare with it (a HeldOut of floats: the tests only read it)."""
    clean = mems()
    return held_out_error(fit(simulate(clean, OPTIMAL9_FAST)), clean)


def check_recovered(result, truth: dict):
    est = estimates(result)
    for name, true in truth.items():
        value, sigma = est[name]
        assert abs(value - true) < K * sigma, (name, value, sigma, true)
        assert sigma < abs(true) / 5, (name, value, sigma, true)
    return est


def first_significant(result):
    d = diagnose(result)
    sig = [c.effect for c in d.candidates if c.significant]
    return sig, d


def test_accel_cubic_is_recovered_and_named():
    """K3 = 800, -600, 1000 ug/g^3 (MEMS), optimal9 with 20 s dwells: 4-5 sigma each.  The ±1 g
    statics and the rotations' first harmonic cannot tell K3 from the scale factor; the three 45°
    attitudes do (sigma 90 ug/g^3).  Held-out: 172 ug before, 39 after (floor 32)."""
    k3 = [800.0, -600.0, 1000.0]
    hidden = mems(accel__cubic_ug_per_g3=k3)
    floor = mems_floor_optimal9_fast()
    capture = simulate(hidden, OPTIMAL9_FAST)
    base, with_effect = fit(capture), fit(capture, "accel_cubic")
    check_recovered(with_effect, {f"accel_k3_{a}": v for a, v in zip("xyz", k3)})
    before, after = held_out_error(base, hidden), held_out_error(with_effect, hidden)
    assert after.accel_ug < FLOOR_FACTOR * floor.accel_ug, (before, after, floor)
    assert before.accel_ug > 3 * after.accel_ug, (before, after, floor)
    sig, _ = first_significant(base)
    # scale_temperature is significant too (its accelerometer part, over the default 2 degC
    # warm-up, can bend ±1 g statics recorded at different temperatures), but second
    assert sig[0] == "accel_cubic", sig


def test_scale_temperature_is_recovered_and_named():
    """Scale factors 100, -80, 60 ppm/degC (accelerometers) and 300, -200, 250 ppm/degC (gyros,
    MEMS) over a 10 degC warm-up: sigma 4-5 ppm/degC; the base model leaves 1230 ppm of the rate
    on held-out samples (the issue's 610 ppm), the effect brings it to the floor (69 against 66
    ppm); accelerometers 190 -> 36 ug (floor 32)."""
    sa, sg = [100.0, -80.0, 60.0], [300.0, -200.0, 250.0]
    clean = mems(**WARM)
    hidden = mems(accel__scale_tempco_ppm_per_c=sa, gyro__scale_tempco_ppm_per_c=sg, **WARM)
    floor = held_out_error(fit(simulate(clean, WARM3)), clean, temp_c=WARM_RANGE_C)
    capture = simulate(hidden, WARM3)
    base, with_effect = fit(capture), fit(capture, "scale_temperature")
    truth = {f"accel_scale_tempco_{a}": v for a, v in zip("xyz", sa)}
    truth.update({f"gyro_scale_tempco_{a}": v for a, v in zip("xyz", sg)})
    check_recovered(with_effect, truth)
    before = held_out_error(base, hidden, temp_c=WARM_RANGE_C)
    after = held_out_error(with_effect, hidden, temp_c=WARM_RANGE_C)
    for q in ("accel_ug", "gyro_ppm"):
        assert getattr(after, q) < FLOOR_FACTOR * getattr(floor, q), (q, before, after, floor)
        assert getattr(before, q) > 3 * getattr(after, q), (q, before, after, floor)
    sig, _ = first_significant(base)
    assert sig[0] == "scale_temperature", sig


def test_quadratic_temperature_bias_is_recovered_with_the_linear_one():
    """Bias curvature 20, -15, 12 ug/degC^2 and 3, -2, 2.5 deg/h/degC^2 (MEMS) over a 10 degC
    warm-up, fitted with temperature_bias + temperature_bias_quadratic: sigma 1.1-2.1 ug/degC^2
    and 0.11-0.14 deg/h/degC^2; held-out 226 -> 48 ug (floor 30) and 174 -> 69 ppm (floor 66).
    Over a warm-up, bias_drift is significant too on the linear model (a curve in temperature is
    partly a line in time), but second.  The truth's curve is
    about its own reference (25 degC); the estimator's is about the statics' mean temperature
    T_m, so the linear coefficients it finds are the truth's slope there, 2 c2 (T_m - 25)."""
    ca, cg = [20.0, -15.0, 12.0], [3.0, -2.0, 2.5]
    clean = mems(**WARM)
    hidden = mems(accel__bias_tempco2=ca, gyro__bias_tempco2=cg, **WARM)
    floor = held_out_error(fit(simulate(clean, WARM3), "temperature_bias"), clean, temp_c=WARM_RANGE_C)
    capture = simulate(hidden, WARM3)
    with_effect = fit(capture, "temperature_bias", "temperature_bias_quadratic")
    t_m = with_effect.model.effects[0].reference_c
    truth = {f"accel_bias_tempco2_{a}": v for a, v in zip("xyz", ca)}
    truth.update({f"gyro_bias_tempco2_{a}": v for a, v in zip("xyz", cg)})
    truth.update({f"accel_bias_tempco_{a}": 2 * v * (t_m - 25.0) for a, v in zip("xyz", ca)})
    truth.update({f"gyro_bias_tempco_{a}": 2 * v * (t_m - 25.0) for a, v in zip("xyz", cg)})
    check_recovered(with_effect, truth)
    after = held_out_error(with_effect, hidden, temp_c=WARM_RANGE_C)
    # the accelerometers' curvature is known to ~1.5 ug/degC^2: at the ends of the range, 5.5 degC
    # from T_m, that is ~45 ug against the floor's 30
    assert after.accel_ug < 2.0 * floor.accel_ug and after.gyro_ppm < FLOOR_FACTOR * floor.gyro_ppm, (after, floor)
    # the linear model alone on the accelerometer part (a gyro bias misfit makes the base fit
    # wander in the statics' headings for 1000 evaluations: ~10 s, left to the report)
    accel_only = mems(accel__bias_tempco2=ca, **WARM)
    capture = simulate(accel_only, WARM3)
    linear, both = fit(capture, "temperature_bias"), fit(capture, "temperature_bias", "temperature_bias_quadratic")
    before = held_out_error(linear, accel_only, temp_c=WARM_RANGE_C)
    after = held_out_error(both, accel_only, temp_c=WARM_RANGE_C)
    assert before.accel_ug > 3 * after.accel_ug, (before, after, floor)
    sig, _ = first_significant(linear)
    assert sig[0] == "temperature_bias_quadratic", sig


def anisoelastic_in_frame_p(truth) -> dict:
    """The simulated N (case axes, sum over j <= k of N_jk F_j F_k per gyro) as the effect's
    parameters: the quadratic form turned into frame p (F_b = C_pb^T F_p), F_z^2 taken out as a
    bias (F_x^2 + F_y^2 + F_z^2 is constant at rest)."""
    C = truth.paper_parameters()["C_pb"]
    out = {}
    for i, n in enumerate(truth.gyro.anisoelastic_dph_per_g2):
        Q = np.diag(n[:3])
        for c, (j, k) in zip(n[3:], ((0, 1), (0, 2), (1, 2))):
            Q[j, k] = Q[k, j] = c / 2
        Q = C @ Q @ C.T
        values = (Q[0, 0] - Q[2, 2], Q[1, 1] - Q[2, 2], 2 * Q[0, 1], 2 * Q[0, 2], 2 * Q[1, 2])
        out.update({f"gyro_aniso_{'xyz'[i]}_{name}": v for name, v in zip(("xx", "yy", "xy", "xz", "yz"), values)})
    return out


def test_gyro_anisoelastic_is_recovered_and_named():
    """N = 0.2-1.2 deg/h/g^2 (FOG-like) on a tactical IMU (0.03 deg/h/sqrt(Hz), default_truth):
    sigma 0.01-0.03 deg/h/g^2; held-out gyro error falls to the floor (29 ppm of the rate).
    gyro_g_sensitivity is significant too (the squares at ±1 g look like per-attitude biases
    and 45° products partly like a force-proportional rate), but second.  (On a MEMS gyro, 5-20
    deg/h/sqrt(Hz), 20 s dwells give a 1-sigma of ~4 deg/h/g^2, above the typical size: held at
    0 by the prior.  On the tactical gyro, terms of ~5 deg/h/g^2, a third of the Earth rate, send
    the fit of statics' headings to another basin: reduced chi2 ~6000 even with the effect.)"""
    from sim_devices.truth import default_truth

    n = 2 * np.array([[0.3, -0.4, 0.1, 0.5, 0.0, -0.3], [0.0, 0.2, -0.15, 0.0, 0.6, 0.25],
                      [-0.5, 0.0, 0.3, -0.2, 0.0, 0.45]])
    clean = default_truth(0)
    hidden = simhelpers.hide(default_truth(0), gyro__anisoelastic_dph_per_g2=n)
    floor = held_out_error(fit(simulate(clean, OPTIMAL9_FAST)), clean)
    capture = simulate(hidden, OPTIMAL9_FAST)
    base, with_effect = fit(capture), fit(capture, "gyro_anisoelastic")
    truth = anisoelastic_in_frame_p(hidden)
    est = estimates(with_effect)
    for name, true in truth.items():
        value, sigma = est[name]
        assert abs(value - true) < K * sigma, (name, value, sigma, true)
        assert sigma < max(abs(true), 0.2) / 5, (name, value, sigma, true)   # 0.2: the smallest non-zero
    before, after = held_out_error(base, hidden), held_out_error(with_effect, hidden)
    assert after.gyro_ppm < FLOOR_FACTOR * floor.gyro_ppm, (before, after, floor)
    assert before.gyro_ppm > 2 * after.gyro_ppm, (before, after, floor)
    sig, _ = first_significant(base)
    assert sig[0] == "gyro_anisoelastic", sig


def test_accel_cross_axis_is_recovered_and_named():
    """C_ij = 1200-2000 ug/g^2 (MEMS) in the simulator's a_i F_j (F in case axes): in frame p the
    truth is c_i = C_pb C[i] (the IMU's 0.1-1 deg misalignments move ~40 ug/g^2 into a_i f_i, a
    K2-like term the effect does not have: it stays in the held-out error, 46 ug against the
    floor's 32; 691 ug without the effect).  sigma 70 ug/g^2."""
    c = [[0.0, 2000.0, -1500.0], [1800.0, 0.0, 1200.0], [-1600.0, 1400.0, 0.0]]
    hidden = mems(accel__cross_coupling_ug_per_g2=c)
    floor = mems_floor_optimal9_fast()
    capture = simulate(hidden, OPTIMAL9_FAST)
    base, with_effect = fit(capture), fit(capture, "accel_cross_axis")
    C_pb = hidden.paper_parameters()["C_pb"]
    truth = {f"accel_cross_{'xyz'[i]}{'xyz'[j]}": (C_pb @ np.array(c[i]))[j]
             for i in range(3) for j in range(3) if i != j}
    check_recovered(with_effect, truth)
    before, after = held_out_error(base, hidden), held_out_error(with_effect, hidden)
    assert after.accel_ug < FLOOR_FACTOR * floor.accel_ug, (before, after, floor)
    assert before.accel_ug > 5 * after.accel_ug, (before, after, floor)
    sig, _ = first_significant(base)
    assert sig[0] == "accel_cross_axis", sig      # accel_nonlinearity is significant too, second


UPS9 = [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1], [1, 1, 0], [1, 0, 1], [0, 1, 1]]
# optimal9's attitudes (10 s) and two turns each way about x, y and z at 30, 100 and 200 deg/s
MULTIRATE = parse_scheme({"name": "multirate", "defaults": {"dwell_s": 10.0}, "segments": (
    [{"static": f"pos{i}", "up_body": u} for i, u in enumerate(UPS9)]
    + [{"rotation": f"rot{a}{int(rate)}", "axis_body": axis, "rate_dps": rate, "rotation_s": 720.0 / rate}
       for a, axis in zip("xyz", np.eye(3).tolist()) for rate in (30.0, 100.0, 200.0)])}, "test", {})


def test_gyro_rate_nonlinearity_is_recovered_and_named():
    """Even q = 4, -3, 5 and odd p = 3, -4, 2 ppm/(deg/s) (MEMS) at 30, 100 and 200 deg/s: sigma
    0.05 (even) and 0.12 (odd); the simulator's terms are k_i q_i (u.w)^2, the effect's q r^2
    with r = k_i u.w, so its truth is q / k_i.  Held-out gyro error 445 -> 77 ppm (floor 76).
    gyro_scale_asymmetry is significant too (the even part at each rate), but second."""
    q, p = [4.0, -3.0, 5.0], [3.0, -4.0, 2.0]
    clean = mems()
    hidden = mems(gyro__rate_squared_ppm_per_dps=q, gyro__rate_odd_squared_ppm_per_dps=p)
    floor = held_out_error(fit(simulate(clean, MULTIRATE)), clean)
    capture = simulate(hidden, MULTIRATE)
    base, with_effect = fit(capture), fit(capture, "gyro_rate_nonlinearity")
    k = hidden.gyro.scale
    truth = {f"gyro_rate_sq_even_{a}": q[i] / k[i] for i, a in enumerate("xyz")}
    truth.update({f"gyro_rate_sq_odd_{a}": p[i] / k[i] for i, a in enumerate("xyz")})
    check_recovered(with_effect, truth)
    before, after = held_out_error(base, hidden), held_out_error(with_effect, hidden)
    assert after.gyro_ppm < FLOOR_FACTOR * floor.gyro_ppm, (before, after, floor)
    assert before.gyro_ppm > 3 * after.gyro_ppm, (before, after, floor)
    sig, _ = first_significant(base)
    assert sig[0] == "gyro_rate_nonlinearity", sig


# two blocks of nine statics (30 s) and three rotation pairs, 15 minutes apart: every attitude at
# the start and at the end of a ~30 minute run
DRIFT2 = scheme("name: drift2\ndefaults: {dwell_s: 30.0, rate_dps: 100.0, rotation_s: 7.2}\nsegments:\n"
                + NINE_STATICS.replace("pos0", "a_") + ROTATIONS_XYZ.format(k="a")
                + "  - {static: wait, up_body: [0, 0, 1], dwell_s: 900.0}\n"
                + NINE_STATICS.replace("pos0", "b_") + ROTATIONS_XYZ.format(k="b"))


def test_bias_drift_is_recovered_and_named():
    """Biases drifting by 500, -400, 300 ug/h and 50, -40, 30 deg/h per hour (MEMS in its first
    hour) at a constant temperature: sigma 50 ug/h and 4 deg/h/h over the 30 minutes; held-out
    accelerometer error 77 -> 29 ug (floor 28) over the same span.  (Over a warm-up that follows
    the time, temperature_bias scores nearly as high: the effect's signature says so.)"""
    da, dg = [500.0, -400.0, 300.0], [50.0, -40.0, 30.0]
    flat = {"temperature__warmup_delta_c": 0.0}
    clean = mems(**flat)
    hidden = mems(accel__bias_drift_per_h=da, gyro__bias_drift_per_h=dg, **flat)
    capture = simulate(hidden, DRIFT2)
    span = capture.segments[-1].data.t[-1]
    floor = held_out_error(fit(simulate(clean, DRIFT2)), clean, t_s=span)
    base, with_effect = fit(capture), fit(capture, "bias_drift")
    truth = {f"accel_bias_drift_{a}": v for a, v in zip("xyz", da)}
    truth.update({f"gyro_bias_drift_{a}": v for a, v in zip("xyz", dg)})
    check_recovered(with_effect, truth)
    before, after = held_out_error(base, hidden, t_s=span), held_out_error(with_effect, hidden, t_s=span)
    assert after.accel_ug < FLOOR_FACTOR * floor.accel_ug, (before, after, floor)
    assert before.accel_ug > 2 * after.accel_ug, (before, after, floor)
    sig, _ = first_significant(base)
    assert sig[0] == "bias_drift", sig


ISSUE_25_FAILURES = {
    # what the user's captures had: (hidden, scheme, what --auto must add)
    "accel_k3_taken_for_gyro_w_abs_w": ({"accel__cubic_ug_per_g3": [800.0, -600.0, 1000.0]}, "OPTIMAL9_FAST",
                                     ["accel_cubic"]),
    "gyro_scale_tempco_taken_for_w_abs_w": ({"accel__scale_tempco_ppm_per_c": [100.0, -80.0, 60.0],
                                          "gyro__scale_tempco_ppm_per_c": [300.0, -200.0, 250.0], **WARM},
                                         "WARM3", ["scale_temperature"]),
    "quadratic_temperature_bias_taken_for_segment_index": ({"accel__bias_tempco2": [20.0, -15.0, 12.0], **WARM},
                                                           "WARM3", ["temperature_bias", "temperature_bias_quadratic"]),
}


@pytest.mark.parametrize("case", sorted(ISSUE_25_FAILURES))
def test_diagnose_auto_adds_the_library_effect_instead_of_terms_outside_it(case):
    """Issue 25's failures: diagnose --auto on each capture adds the library's effect(s), the model
    then explains the data and no term outside the library is proposed."""
    from station.diagnose import auto
    from station.estimate import lsq

    hidden, scheme_name, added = ISSUE_25_FAILURES[case]
    steps, final = auto.run(lsq.summarise(simulate(mems(**hidden), globals()[scheme_name])))
    assert [s.added for s in steps] == added
    assert "explains the data" in final.verdict, final.verdict
    assert final.proposal is None or not final.proposal.kept
