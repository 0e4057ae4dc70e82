"""Closing the loop honestly: the bench terms of slow and rippling rotations, the stop rule of
--auto, terms found outside the library and written as a plugin, words when the fit fails."""
import json
from dataclasses import replace

import numpy as np
import pytest
from scipy import stats

from station.cli import main
from station.diagnose import auto, terms
from station.diagnose.core import ALPHA, diagnose
from station.diagnose.holdout import leave_one_segment_out
from station.estimate import lsq
from station.model.registry import EffectRegistry
import simhelpers

C_UG = [[0.0, 2000.0, -1500.0], [1800.0, 0.0, 1200.0], [-1600.0, 1400.0, 0.0]]


def mems(seed=3, rate=100.0, out=None, **hidden):
    overrides = {"rate_dps": rate, "rotation_s": max(36.0, 360.0 / rate)}
    return simhelpers.mems_capture(seed, overrides=overrides, out=out, **hidden)


def band(dof):
    """Reduced chi2 within which 99.9 % of fits of a right model fall."""
    return stats.chi2.ppf(0.0005, dof) / dof, stats.chi2.ppf(0.9995, dof) / dof


@pytest.mark.parametrize("rate", [10.0, 25.0])
def test_clean_slow_rotations_fit(rate):
    """A MEMS gyro's noise integrated into the phase used to wander over one revolution and
    leave a misfit at 10 °/s (reduced chi2 ~2-4): the phase is now uniform where the rate is
    steady within that noise."""
    for seed in (3, 4):
        _, capture = mems(seed=seed, rate=rate)
        d = diagnose(lsq.fit(lsq.summarise(capture)))
        lo, hi = band(d.dof)
        assert lo < d.reduced_chi2 < hi, (rate, seed, d.reduced_chi2)


def test_a_rippling_rate_off_the_axis_is_bench_physics_not_an_imu_effect():
    """20 % rate ripple with the IMU 5 cm off the axis: the tangential acceleration dw/dt x d and
    the varying centripetal force are in the model, so nothing is missing and nothing is added."""
    _, capture = mems(bench__rate_ripple_fraction=0.2, bench__rate_ripple_hz=0.9,
                      bench__lever_arm_m=[0.03, -0.04, 0.0])
    steps, final = auto.run(lsq.summarise(capture))
    assert not steps, [s.added for s in steps]
    lo, hi = band(final.dof)
    assert lo < final.reduced_chi2 < hi and "explains the data" in final.verdict


def test_holdout_falls_for_the_true_effect_and_the_stop_rule_reports_a_partial_one():
    _, capture = mems(accel__nonlinearity_ug_per_g2=[300.0, -200.0, 400.0])
    s = lsq.summarise(capture)
    reg = EffectRegistry()
    base = lsq.fit(s)
    with_k2 = lsq.fit(s, [reg.create("accel_nonlinearity")])
    b, a = leave_one_segment_out(base).common_score(leave_one_segment_out(with_k2))
    assert a < 0.5 * b
    # cross-coupling (outside the library once accel_cross_axis is taken out of it): nonlinearity
    # lowers chi2 but explains little of the excess: not kept, said so, and the terms outside the
    # library are found instead
    _, capture = mems(accel__cross_coupling_ug_per_g2=C_UG)
    steps, final = auto.run(lsq.summarise(capture), registry=simhelpers.registry_without(simhelpers.CROSS_AXIS))
    assert "accel_nonlinearity" not in [st.added for st in steps]
    assert any(r.effect == "accel_nonlinearity" and "does not explain the failure" in r.reason
               for r in final.rejected)
    # the terms found outside the library are carried into the model (--auto, discovered)
    assert steps and steps[-1].discovered
    effect, values, _ = terms.in_model(final.result)
    found = {(t.sensor, t.axis, t.regressor.key): v for t, v in zip(effect.terms, values)}
    # each true pair appears with its coefficient: C_ij µg/g^2 = C_ij * 1e-6 / g0 (m/s^2 per (m/s^2)^2)
    g0 = 9.80665
    expected = {("accel", 0, "fxfy"): C_UG[0][1], ("accel", 0, "fxfz"): C_UG[0][2],
                ("accel", 2, "fxfz"): C_UG[2][0], ("accel", 2, "fyfz"): C_UG[2][1]}
    for key, c_ug in expected.items():
        assert key in found, (key, sorted(found))
        assert found[key] == pytest.approx(c_ug * 1e-6 / g0, rel=0.15), key
    assert "terms found outside the library (discovered, in the model)" in final.verdict
    assert "--emit-effect" in final.verdict


def test_emitted_plugin_is_added_and_the_error_falls(tmp_path, capsys, monkeypatch):
    simhelpers.library_without(monkeypatch, simhelpers.CROSS_AXIS)      # the cross-coupling: outside it
    _, cap = mems(out=tmp_path / "cap", accel__cross_coupling_ug_per_g2=C_UG)
    plugin = tmp_path / "found.py"
    assert main(["diagnose", str(cap), "--auto", "--json", "--emit-effect", str(plugin)]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["steps"][-1]["added"] == "discovered_terms" and doc["steps"][-1]["discovered"]
    assert len(doc["steps"][-1]["estimate"]) >= 4
    assert "accelerometer: cross-axis coupling" in doc["verdict"]
    before = doc["steps"][0]["chi2_before"] / (doc["dof"] + len(doc["steps"][-1]["estimate"]))
    spec = f"{plugin}:DiscoveredTerms"
    assert main(["diagnose", str(cap), "--add", spec, "--json"]) == 0
    after = json.loads(capsys.readouterr().out)
    assert after["reduced_chi2"] < 0.2 * before
    cal = tmp_path / "cal.yaml"
    assert main(["estimate", str(cap), "--add", spec, "-o", str(cal), "--accept-poor-fit"]) == 0
    seg = tmp_path / "cap" / "pos07.csv"
    assert main(["apply", str(cal), str(seg), "-o", str(tmp_path / "o.csv"), "--plugin", spec]) == 0
    assert "compensated: discovered_terms" in capsys.readouterr().err


def test_over_dispersion_and_words_when_everything_is_a_little_off():
    """Noise 1.6x what the statics' first differences say, everywhere: the verdict fails, the
    words say it is spread over every kind, and the candidates are not called significant by
    chi2 drops that are large only against the nominal noise."""
    _, capture = mems()
    s = lsq.summarise(capture)
    s = replace(s, accel_sigma=s.accel_sigma / 1.6, gyro_sigma=s.gyro_sigma / 1.6)
    steps, final = auto.run(s)
    assert final.p_value < ALPHA / 10
    assert final.failures, final.verdict
    assert any("no single segment kind stands out" in f for f in final.failures)
    assert not steps, [st.added for st in steps]
    assert final.notes and "over-dispersion" in final.notes[0]


def test_a_once_per_revolution_vibration_is_not_taken_for_the_size_effect():
    """At one rate a vibration fixed to the table's turn is fitted in part by the size effect,
    whose rate² extrapolation is wrong elsewhere: it is not kept.  The words name a vibration along
    the axis, so the library's table_vibration_once_per_rev is tried first and the fit then passes
    (without it in the library the verdict said the model still fails)."""
    _, capture = mems(bench__vibration_mg=[1.0, 0.0, 1.0], bench__vibration_phase_deg=30.0)
    steps, final = auto.run(lsq.summarise(capture))
    assert "accel_lever_arm" not in [st.added for st in steps], [st.added for st in steps]
    assert [st.added for st in steps][:1] == ["table_vibration_once_per_rev"], [st.added for st in steps]
    assert final.p_value > ALPHA / 10, final.verdict


def test_a_bias_step_is_named_as_a_step_in_time():
    """A bias step during a warm-up: a bias linear in the (monotonic) temperature is a likely
    candidate too, but the words name the step and the failing verdict points to it first."""
    _, capture = mems(accel__bias_step=[1000.0, -500.0, 0.0], accel__bias_step_time_s=300.0,
                      gyro__bias_step=[0.0, 0.0, 100.0], gyro__bias_step_time_s=300.0)
    s = lsq.summarise(capture)
    first = auto.conclude(diagnose(lsq.fit(s)), s)
    assert "a step in time" in first.failures[0], first.failures[:2]
    assert first.p_value < ALPHA / 10
    assert "first look at this" in first.verdict and "a step in time" in first.verdict


def test_a_remount_between_the_two_directions_is_named():
    _, capture = mems(bench__remount_error_arcsec=3600.0, bench__remount_rotations=True)
    d = diagnose(lsq.fit(lsq.summarise(capture)))
    assert any("was moved or remounted between the two directions" in f for f in d.failures[:3]), d.failures[:3]
