"""The verdict's rules on small calibrations made by hand (issue 30 item 6: survivors of mutation
testing in station/estimate/verdict.py killed here, fast enough for the mutation run to afford):
a stopped fit judged on the parameters written, the words for rotations and axes, the verdicts
that exit 3."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from sim_devices.truth import default_truth
from station.estimate.verdict import (ACCEL_BLOCK, GYRO_BLOCK, INTER_TRIAD, fit_fails, judge, not_determined)
from station.simulate import dryrun

DOF = 400


def calibration(*, chi2=1.0 * DOF, converged=True, steps=None, rotations=6, R_po=None, scale_sign=1.0):
    """The truth's calibration with a 1-sigma for every base parameter (well determined), a fit
    of DOF degrees of freedom, ``rotations`` rotation segments and, for a stopped fit, the step
    the solver would still take per parameter in 1-sigma (``steps``)."""
    cal = dryrun.truth_calibration(default_truth(1))
    if R_po is not None:
        cal.R_po = R_po
    cal.gyro_scale = cal.gyro_scale * np.array([1.0, scale_sign, 1.0])
    cal.sigma = {n: 1e-6 if "_scale_" in n else 1.0 for n in ACCEL_BLOCK + GYRO_BLOCK + INTER_TRIAD}
    cal.fit = {"method": "lsq", "chi2": chi2, "dof": DOF, "converged": converged, "rotation_segments": rotations}
    if steps is not None:
        cal.fit["remaining_step_sigma"] = steps
    return cal


def test_a_stopped_fit_is_judged_on_what_is_written():
    """Statics only (the gyro block not determined, not written): the solver stopped with a large
    step left in the gyro block and in a nuisance that is no parameter (a pose's heading), and
    0.005 sigma in the accelerometers: at the minimum for everything written.  Judged "not
    converged" before the dropping, then again after it: passes, with the note."""
    steps = {**{n: 0.005 for n in ACCEL_BLOCK}, **{n: 7.0 for n in GYRO_BLOCK + INTER_TRIAD},
             "pose_heading_3": 5.0}
    cal = judge(calibration(converged=False, steps=steps, rotations=0))
    v = cal.fit["verdict"]
    assert v["result"] == "passes" and "agree with the noise" in v["reason"]
    assert cal.fit["converged"] is False                      # said, not rewritten
    assert set(not_determined(cal)) == set(GYRO_BLOCK + INTER_TRIAD)
    assert any("every parameter written is at the minimum: the step it would still take is at most 0.005 "
               "of a 1-sigma" in n for n in cal.fit["notes"])
    assert not fit_fails(cal)


def test_a_failing_stopped_fit_says_its_minimum_rests_on_the_linear_model():
    """A failing fit (reduced chi2 3) stopped with its written parameters' step below 0.01 sigma:
    the note says so by the linear model, which a failing fit's residuals can mislead (the
    eighteenth session's settled fits were 1.0-5.8 chi2 units above a minimum dogbox from the start
    reached: nineteenth session); a passing one's note does not."""
    steps = {**{n: 0.005 for n in ACCEL_BLOCK}, **{n: 7.0 for n in GYRO_BLOCK + INTER_TRIAD}}
    failing = judge(calibration(chi2=3.0 * DOF, converged=False, steps=steps, rotations=0))
    assert failing.fit["verdict"]["result"] == "fails"
    note = [n for n in failing.fit["notes"] if "every parameter written is at the minimum" in n]
    assert note and "by the linear model, which a failing fit's residuals can mislead" in note[0], failing.fit["notes"]
    passing = judge(calibration(converged=False, steps=steps, rotations=0))
    assert not any("linear model" in n for n in passing.fit["notes"])


@pytest.mark.parametrize("moving", ["accel_scale_x", "accel_bias_z"])
def test_a_written_parameter_still_moving_is_not_converged(moving):
    steps = {**{n: 0.005 for n in ACCEL_BLOCK}, **{n: 7.0 for n in GYRO_BLOCK + INTER_TRIAD}}
    steps[moving] = 0.0101
    cal = judge(calibration(converged=False, steps=steps, rotations=0))
    assert cal.fit["verdict"]["result"] == "not converged"
    assert fit_fails(cal)
    assert not any("every parameter written is at the minimum" in n for n in cal.fit["notes"])


def test_a_stopped_fit_without_steps_is_not_converged():
    cal = judge(calibration(converged=False, steps=None))
    assert cal.fit["verdict"]["result"] == "not converged" and fit_fails(cal)


def test_a_converged_fit_gets_no_convergence_note():
    cal = judge(calibration(steps={n: 5.0 for n in ACCEL_BLOCK}))
    assert cal.fit["verdict"]["result"] == "passes"
    assert not any("evaluation limit" in n for n in cal.fit["notes"])


def test_not_determined_lists_what_is_left_out():
    cal = judge(calibration(rotations=0))
    assert not_determined(cal) == GYRO_BLOCK + INTER_TRIAD
    assert cal.fit["gyro_calibrated"] is False
    assert not_determined(judge(calibration())) == []


@pytest.mark.parametrize("result, unusable", [("passes", False), ("fails", True), ("not converged", True),
                                              ("noise overestimated", False), ("untested", False)])
def test_the_verdicts_that_exit_3(result, unusable):
    cal = calibration()
    cal.fit["verdict"] = {"result": result}
    assert fit_fails(cal) is unusable


def test_a_large_inter_triad_rotation_is_named_with_its_axis():
    R = Rotation.from_rotvec(math.radians(2.0) * np.array([0.0, 0.6, 0.8])).as_matrix()
    cal = judge(calibration(R_po=R))
    assert ("warning: a large rotation between the triads: 2.00 deg about [+0.000, +0.600, +0.800] (a mounting "
            "or axis-order problem; the usual size is arcseconds to arcminutes)") in cal.fit["notes"]


def test_inverted_gyro_axes_are_named():
    R = Rotation.from_rotvec(math.radians(180.0) * np.array([0.0, 0.0, 1.0])).as_matrix()
    cal = judge(calibration(R_po=R))
    note = next(n for n in cal.fit["notes"] if "inverted against" in n)
    assert note.startswith("warning: the gyro axes are inverted against the accelerometers': a rotation of 180.0 deg "
                           "about [+0.000, +0.000, +1.000] between the triads (gyro x, y pointing opposite")


def test_a_negative_scale_factor_is_named():
    cal = judge(calibration(scale_sign=-1.0))
    assert any(n.startswith("warning: the gyro y axis is inverted (scale factor -") for n in cal.fit["notes"])
    assert not any("accelerometer" in n and "inverted" in n for n in cal.fit["notes"])


# ------------------------------------------------------------------------ identifiability bounds
# The bounds as documented (docs/calibration-file.md), not read from verdict.BOUNDS: scale factor
# 1 % of its value, misalignment and inter-triad angle 3600 arcsec, accelerometer bias 10,000 ug,
# gyro bias 360 deg/h; raw units converted through the scale factor.  Each checked 1 % inside and
# 1 % outside.

def values_of(cal):
    return {n: v for n, v, _ in cal.parameters()}


def raw(cal, factor=1000.0):
    """The same calibration in raw counts: factor counts per m/s^2 and per deg/s."""
    cal.accel_unit = cal.gyro_unit = "raw"
    cal.accel_scale = cal.accel_scale * factor
    cal.gyro_scale = cal.gyro_scale * factor
    cal.accel_bias = cal.accel_bias * factor
    cal.gyro_bias = cal.gyro_bias * factor
    return cal


@pytest.mark.parametrize("units", ["physical", "raw"])
@pytest.mark.parametrize("name, bound", [("gyro_scale_y", 0.01), ("gyro_misalignment_zx", 3600.0),
                                         ("gyro_bias_z", 360.0)])
def test_the_gyro_block_is_written_inside_its_bounds_only(units, name, bound):
    for inside in (True, False):
        cal = calibration()
        if units == "raw":
            cal = raw(cal)
        value = values_of(cal)[name]
        s = bound * (0.99 if inside else 1.01)
        if "_scale_" in name:
            s *= abs(value)                     # relative: raw/(deg/s) when raw
        elif "_bias_" in name and units == "raw":
            s *= abs(values_of(cal)["gyro_scale_z"]) / 3600.0      # deg/h -> deg/s -> counts
        cal.sigma[name] = s
        judge(cal)
        assert (not_determined(cal) == []) is inside, (units, name, inside)
        if not inside:
            assert set(not_determined(cal)) == set(GYRO_BLOCK + INTER_TRIAD) and name not in cal.sigma
            assert any(f"{name}: 1-sigma infinite or above its bound" in n for n in cal.fit["notes"])


def test_the_inter_triad_rotation_alone_is_left_out_above_its_bound():
    for inside in (True, False):
        cal = calibration()
        cal.sigma["inter_triad_y"] = 3600.0 * (0.99 if inside else 1.01)
        judge(cal)
        assert not_determined(cal) == ([] if inside else INTER_TRIAD)
        assert ("inter_triad" in cal.effects) is inside
        if not inside:
            np.testing.assert_array_equal(cal.R_po, np.eye(3))
            assert "gyro_bias_x" in cal.sigma


@pytest.mark.parametrize("units", ["physical", "raw"])
def test_accelerometers_above_their_bound_are_refused(units):
    from station.core.errors import UserError

    for inside in (True, False):
        cal = calibration()
        if units == "raw":
            cal = raw(cal)
        s = 1e4 * (0.99 if inside else 1.01)                        # ug
        if units == "raw":
            s *= 9.80665e-6 * abs(values_of(cal)["accel_scale_y"])  # ug -> m/s^2 -> counts
        cal.sigma["accel_bias_y"] = s
        if inside:
            judge(cal)
            assert not_determined(cal) == []
        else:
            with pytest.raises(UserError, match="does not determine the accelerometers \\(accel_bias_y"):
                judge(cal)


@pytest.mark.parametrize("sigma", [None, math.nan, math.inf])
def test_a_sigma_that_is_no_number_is_not_determined(sigma):
    cal = calibration()
    if sigma is None:
        del cal.sigma["gyro_misalignment_yz"]
    else:
        cal.sigma["gyro_misalignment_yz"] = sigma
    judge(cal)
    assert set(not_determined(cal)) == set(GYRO_BLOCK + INTER_TRIAD)


def test_a_zero_scale_factor_is_not_determined():
    cal = calibration()
    cal.gyro_scale = cal.gyro_scale * np.array([1.0, 0.0, 1.0])
    judge(cal)
    assert set(not_determined(cal)) == set(GYRO_BLOCK + INTER_TRIAD)


# ------------------------------------------------------------------------ the verdict's branches

def judged(**fit):
    cal = calibration()
    cal.fit.update(fit)
    return judge(cal)


@pytest.mark.parametrize("fit, words", [
    ({"dof": 0}, "no redundant data (0 degrees of freedom for method lsq): the model cannot be checked against "
                 "the measurements"),
    ({"dof": None}, "no redundant data (no degrees of freedom for method lsq)"),
    ({"chi2": math.nan}, "no redundant data (400 degrees of freedom"),
    ({"data_redundancy": 0.49}, "the data have no redundancy of their own (0.49; the 400 degrees of freedom counted "
                                "are the priors'): the model cannot be checked against the measurements"),
    ({"noise_model": {"tested": {"chi2": 0.3, "redundancy": 0.49, "left_out": ["hand turns", "static gyro means"]}}},
     "no redundancy is left to test the model (0.49) once the noise of hand turns, static gyro means is estimated "
     "from its own scatter"),
    ({"noise_model": {"tested": {"chi2": 0.3, "redundancy": 0.49}}},
     "once the noise of the data is estimated from its own scatter"),
])
def test_untested_fits_say_why(fit, words):
    v = judged(**fit).fit["verdict"]
    assert v["result"] == "untested" and words in v["reason"], v


def test_a_redundancy_just_enough_is_tested():
    v = judged(data_redundancy=0.51).fit["verdict"]
    assert v["result"] == "passes" and v["dof"] == DOF and isinstance(v["dof"], int)


def test_the_tested_part_of_a_noise_model_decides():
    """The data's own chi2 on their redundancy, the estimated groups named."""
    tested = {"chi2": 150.0, "redundancy": 123.456, "left_out": ["hand turns"]}
    cal = judged(chi2=10 * DOF, noise_model={"tested": tested, "terms": ["white", "quantisation"]})
    v = cal.fit["verdict"]
    assert v["result"] == "passes" and v["dof"] == 123.46
    assert v["reduced_chi2"] == pytest.approx(150.0 / 123.456, rel=1e-12)
    assert v["left_out"] == ["hand turns"] and v["noise_model"] == "white, quantisation"
    assert v["reason"].endswith("the residuals agree with the noise model (white, quantisation); hand turns not "
                                "tested (their noise estimated from their scatter)")
    white = judged(noise_model={"terms": ["white"]}).fit["verdict"]
    assert white["reason"].endswith("the residuals agree with the noise") and "left_out" not in white


def test_a_failing_fit_widens_every_sigma_but_a_pose_only_accelerometer_block():
    reduced = 4.0
    for pose_only in (False, True):
        cal = calibration(chi2=reduced * DOF)
        before = dict(cal.sigma)
        if pose_only:
            cal.fit["pose_check"] = {"written": "pose-only accelerometers", "sigma_scale": 1.25}
        judge(cal)
        v = cal.fit["verdict"]
        assert v["result"] == "fails" and cal.fit["sigma_scale"] == pytest.approx(2.0)
        assert v["reason"].startswith("reduced chi2 4 (p = ") and "station diagnose shows where" in v["reason"]
        for name, s in cal.sigma.items():
            own = pose_only and name in ACCEL_BLOCK
            assert s == pytest.approx(before[name] * (1.0 if own else 2.0), rel=1e-12), name
        note = next(n for n in cal.fit["notes"] if n.startswith("the fit fails"))
        assert note.startswith("the fit fails (reduced chi2 4): every 1-sigma is multiplied by sqrt(reduced chi2) = 2")
        assert note.endswith(", except the accelerometers', which are the poses' own fit's (scaled by its own "
                             "sqrt(reduced chi2) = 1.25)") if pose_only else note.endswith("= 2")


def test_noise_overestimated_says_by_how_much():
    cal = judged(chi2=0.25 * DOF)
    v = cal.fit["verdict"]
    assert v["result"] == "noise overestimated" and 0 < v["p_below"] < 1e-3
    assert "every 1-sigma is too large, by up to 2 times (kept as they are: conservative)" in v["reason"]
    assert "a noise figure from a datasheet, or samples averaged before recording" in v["reason"]


def test_a_pass_near_the_threshold_is_said_to_be_at_the_edge_not_to_agree():
    """A fit passes unless p < P_FAIL (0.1 %); one whose chi2 comes by chance in 0.1-1 % of fits of a
    right model passes, but its reason must not say the residuals agree with the noise (imucal's
    real session through import imucal: reduced chi2 4.86 on 3, p = 0.0022, was said to "agree").
    Both sides: p = 0.0022 at the edge, p = 0.02 agrees."""
    from scipy.stats import chi2
    edge = judged(chi2=14.6, noise_model={"tested": {"chi2": 14.6, "redundancy": 3.0}, "terms": ["white", "quantisation"]})
    v = edge.fit["verdict"]
    assert v["result"] == "passes" and 1e-3 < v["p_value"] < 1e-2, v
    assert "agree" not in v["reason"] and "at the edge of what the noise model (white, quantisation) explains" in v["reason"], v
    assert v["p_value"] == pytest.approx(chi2.sf(14.6, 3), rel=1e-9)
    fine = judged(chi2=9.8, noise_model={"tested": {"chi2": 9.8, "redundancy": 3.0}, "terms": ["white", "quantisation"]})
    w = fine.fit["verdict"]
    assert w["result"] == "passes" and w["p_value"] > 1e-2 and "agree with the noise model" in w["reason"], w
