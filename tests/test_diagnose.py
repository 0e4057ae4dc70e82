"""Diagnostics: find a hidden effect, add it, watch the error fall; say when nothing fits."""
import json
import math

import numpy as np
import pytest
from scipy import stats

import simhelpers
from station.simulate import dryrun
from station.cli import main
from station.diagnose import auto
from station.diagnose.core import ALPHA, diagnose
from station.estimate import lsq
from station.io.scheme import load_scheme

FAST = {"rate_dps": 100.0, "rotation_s": 36.0}     # optimal9 with rotations fast enough to excite


def capture_with(seed=3, **hidden):
    truth = simhelpers.hide(dryrun.load_truth(None, 0), **hidden)
    return truth, dryrun.simulate_capture(load_scheme("optimal9", FAST), truth, seed)


def chi2_band(dof):
    return stats.chi2.ppf(0.0005, dof) / dof, stats.chi2.ppf(0.9995, dof) / dof


def test_clean_capture_has_no_significant_candidate():
    _, capture = capture_with()
    d = diagnose(lsq.fit(lsq.summarise(capture)))
    assert not any(c.significant for c in d.candidates), [(c.effect, c.p_value_corrected) for c in d.candidates]
    assert d.p_value > ALPHA / 10 and "explains the data" in d.verdict
    assert not d.failures


def test_hidden_lever_arm_is_found_added_and_estimated():
    positions = np.array([[0.012, 0.004, -0.006], [-0.005, 0.009, 0.007], [0.006, -0.008, -0.014]])
    truth, capture = capture_with(accel__position_m=positions)
    steps, final = auto.run(lsq.summarise(capture))
    first = steps[0].before
    assert first.candidates[0].effect == "accel_lever_arm" and first.candidates[0].significant
    assert any("rotation segments only" in f and "accelerometer" in f for f in first.failures)
    assert [s.added for s in steps] == ["accel_lever_arm"]
    lo, hi = chi2_band(final.dof)
    assert lo < final.reduced_chi2 < hi
    # the mounting offset is unknown: the reference point is fixed by each element's own-axis
    # coordinate, so compare with the truth moved to that point, in frame p
    C_pb = truth.paper_parameters()["C_pb"]
    p_true = positions @ C_pb.T
    p_gauge = p_true - np.diag(p_true)[None, :]
    for name, value, sigma, unit in steps[0].estimate:
        i, c = "xyz".index(name[-3]), "xyz".index(name[-1])
        assert abs(value - p_gauge[i, c] * 1e3) < 3 * sigma, (name, value, sigma, p_gauge[i, c] * 1e3)
    # the predicted chi2 drop is the actual one to first order
    assert steps[0].actual_drop == pytest.approx(steps[0].predicted_drop, rel=0.2)


def test_hidden_temperature_coefficients_are_found():
    tempco_ug = np.array([60.0, -40.0, 50.0])
    truth, capture = capture_with(accel__bias_tempco=tempco_ug, temperature__warmup_delta_c=6.0)
    d = diagnose(lsq.fit(lsq.summarise(capture)))
    assert d.candidates[0].effect == "temperature_bias" and d.candidates[0].significant
    steps, final = auto.run(lsq.summarise(capture))
    assert steps[0].added == "temperature_bias"
    lo, hi = chi2_band(final.dof)
    assert lo < final.reduced_chi2 < hi
    for (name, value, sigma, unit), true in zip(steps[0].estimate[:3], tempco_ug):
        assert abs(value - true) < 3 * sigma, (name, value, sigma, true)


def test_cli_json_and_report(tmp_path, capsys):
    cap = tmp_path / "cap"
    assert main(["run", "--sim", "--seed", "5", "--out", str(cap), "--dwell-s", "30",
                 "--rate-dps", "100", "--rotation-s", "36"]) == 0
    capsys.readouterr()
    assert main(["diagnose", str(cap), "--json", "--report", str(tmp_path / "rep")]) == 0
    doc = json.loads(capsys.readouterr().out)
    for key in ("chi2", "dof", "effects", "segments", "candidates"):
        assert key in doc
    assert {"name", "kind", "rms"} <= set(doc["segments"][0])
    assert {"effect", "significant", "predicted_chi2_drop", "estimate", "sigma"} <= set(doc["candidates"][0])
    drops = [c["predicted_chi2_drop"] for c in doc["candidates"] if not c["significant"]]
    assert drops == sorted(drops, reverse=True)
    assert (tmp_path / "rep" / "index.html").exists()
    assert (tmp_path / "rep" / "residuals_per_segment.svg").stat().st_size > 1000


def mems_capture(seed=3, **hidden):
    return simhelpers.mems_capture(seed, overrides=FAST, **hidden)


MEMS_EFFECTS = {
    # effect: (hidden truth at a MEMS-typical size, the truth in the estimator's parameters)
    "accel_nonlinearity": ({"accel__nonlinearity_ug_per_g2": [300.0, -200.0, 400.0]},
                           lambda t: t.accel.nonlinearity_ug_per_g2),
    "gyro_g_sensitivity": ({"gyro__g_sensitivity_dph_per_g": [[30.0, -20.0, 10.0], [15.0, 40.0, -25.0],
                                                             [-10.0, 20.0, 35.0]]},
                           lambda t: t.paper_parameters()["gyro_g_sensitivity_dph_per_g"].ravel()),
    "gyro_scale_asymmetry": ({"gyro__scale_asymmetry_ppm": [400.0, -300.0, 500.0]},
                             lambda t: t.gyro.scale_asymmetry_ppm),
    # a time offset shows only where the rate changes: a low-grade table's 20 % rate ripple; the
    # IMU centred on the axes (the model assumes a steady rate: with an offset from the axis the
    # ripple's tangential acceleration would be a second, unmodelled effect)
    "time_offset": ({"bench__time_offset_s": 0.005, "bench__rate_ripple_fraction": 0.2,
                     "bench__rate_ripple_hz": 0.9, "bench__lever_arm_m": [0.0, 0.0, 0.0]},
                    lambda t: [t.bench.time_offset_s * 1e3]),
}


@pytest.mark.parametrize("effect", sorted(MEMS_EFFECTS))
def test_each_hidden_mems_effect_is_the_first_significant_candidate(effect):
    hidden, truth_of = MEMS_EFFECTS[effect]
    truth, capture = mems_capture(**hidden)
    steps, final = auto.run(lsq.summarise(capture))
    first = steps[0].before
    assert first.candidates[0].effect == effect and first.candidates[0].significant, \
        [(c.effect, c.significant, c.predicted_chi2_drop) for c in first.candidates]
    assert steps[0].added == effect
    lo, hi = chi2_band(final.dof)
    assert lo < final.reduced_chi2 < hi, final.reduced_chi2
    for (name, value, sigma, unit), true in zip(steps[0].estimate, truth_of(truth)):
        assert abs(value - true) < 3 * sigma, (name, value, sigma, true)


def test_an_effect_outside_the_library_is_reported_as_a_failing_model():
    """The accelerometer cross-coupling, with the library's accel_cross_axis taken out of it: no
    library effect explains it (the base model fails, with words), the loop adds the terms it
    discovers outside the library, and says so."""
    truth, capture = mems_capture(accel__cross_coupling_ug_per_g2=[[0, 2000, -1500], [1800, 0, 1200],
                                                                   [-1600, 1400, 0]])
    steps, final = auto.run(lsq.summarise(capture), registry=simhelpers.registry_without(simhelpers.CROSS_AXIS))
    first = steps[0].before
    assert first.p_value < ALPHA / 10
    assert first.failures and "accelerometer" in " ".join(first.failures)
    assert [s.added for s in steps] == [auto.DISCOVERED] and steps[0].discovered
    assert "discovered" in final.verdict and "cross-axis coupling" in final.verdict
