"""The term search finds the physics outside the library (issue 25 items 3-4): hidden effects
whose library effect is taken out of the registry (tests/terms_cases.py), the dictionary's
terms chosen on the right sensor and named in natural units, --auto carrying them into the
model, and the emitted plugin used unchanged by `estimate --add` and `apply --plugin` on a
held-out capture, whose error falls to the clean floor and never grows."""
from pathlib import Path

import numpy as np
import pytest

import simhelpers
import terms_cases as tc
from station.diagnose import auto, terms
from station.diagnose.core import ALPHA, diagnose
from station.estimate import lsq

G0 = terms.G0


def _discovered(steps, final):
    got = terms.in_model(final.result)
    assert got is not None, [s.added for s in steps]
    effect, values, sigmas = got
    return effect.terms, values, sigmas


# the truth per case: (sensor, axis, regressor key) -> value in the term's natural unit
TRUTH = {
    "accel_cubic": {("accel", i, f"f{'xyz'[i]}3"): v for i, v in enumerate([3000.0, -2500.0, 3500.0])},
    "gyro_scale_temperature": {("gyro", i, f"w{'xyz'[i]}T"): v for i, v in enumerate([300.0, -200.0, 250.0])},
    "gyro_rate_odd_squared": {("gyro", i, f"w{'xyz'[i]}absw{'xyz'[i]}"): v for i, v in enumerate([4.0, -3.0, 5.0])},
    "accel_cross_axis": {("accel", 0, "fxfy"): 2000.0, ("accel", 0, "fxfz"): -1500.0, ("accel", 1, "fxfy"): 1800.0,
                         ("accel", 1, "fyfz"): 1200.0, ("accel", 2, "fxfz"): -1600.0, ("accel", 2, "fyfz"): 1400.0},
}


@pytest.fixture(scope="module")
def searched(tmp_path_factory):
    """name -> tc.run of that case (seed 3): --auto on its training capture, done once per case
    for the module (the accel_cubic and gyro_scale_temperature runs serve two tests each; the
    tests only read the steps)."""
    done = {}

    def run(name):
        if name not in done:
            done[name] = tc.run(tc.BY_NAME[name], tmp=tmp_path_factory.mktemp(name))
        return done[name]
    return run


@pytest.mark.parametrize("name", sorted(TRUTH))
def test_the_search_finds_the_physical_term_on_the_right_sensor(name, searched):
    """Every hidden term is found on its own sensor and axis, in its physical regressor, within
    4 sigma (the fit's, from the noise) of the truth; nothing else is added; the fit then passes."""
    steps, final, _ = searched(name)
    assert [s.added for s in steps] == [auto.DISCOVERED] and steps[0].discovered
    found, values, sigmas = _discovered(steps, final)
    got = {(t.sensor, t.axis, t.regressor.key): (t.natural(v), abs(t.natural(s)))
           for t, v, s in zip(found, values, sigmas)}
    assert set(got) == set(TRUTH[name]), sorted(got)
    for key, true in TRUTH[name].items():
        value, sigma = got[key]
        assert abs(value - true) < 4 * sigma, (key, value, sigma, true)
    assert final.p_value > ALPHA / 10, final.reduced_chi2
    # held out by the leave-one-segment-out rule: the step predicts the left-out segments better
    assert steps[0].holdout_after < steps[0].holdout_before
    if name == "gyro_rate_odd_squared":     # at 25, 60 and 100 deg/s w·|w| and w³ are alike
        said = " ".join(steps[0].caveats)
        assert "cannot be told here from w_" in said and "rotations at three or more rates" in said, said


def test_an_accelerometer_misfit_gives_no_gyro_term(searched, tmp_path):
    """The issue's K3 came out as gyro w·|w| terms.  A K3 of 3000 ug/g^3 leaks into the gyro rows
    through the shared attitudes (they fail too), but the accelerometer terms explain both and no
    gyro term is taken; a K3 of 1000 ug/g^3 leaves the gyro rows at the noise, and the gyro
    terms are not searched at all."""
    steps, final, _ = searched("accel_cubic")
    assert all(t.sensor == "accel" for t in _discovered(steps, final)[0])
    small = tc.Case("k3_small", {"accel__cubic_ug_per_g3": [1000.0, -800.0, 1200.0]}, ("accel_cubic",), "accel", ())
    _, capture = tc.training(small, 3, tmp_path)
    fails = terms.failing_sensors(lsq.fit(lsq.summarise(capture)))
    assert fails["accel"][0] and not fails["gyro"][0], fails


def test_a_scale_that_follows_temperature_beats_the_rate_term_that_also_fits(searched):
    """gyro_rate_nonlinearity (w|w|) fits this capture too (the issue's 610 ppm on the test set);
    the w·T terms predict the left-out segments better and replace it, and the step says so."""
    steps, final, _ = searched("gyro_scale_temperature")
    assert steps[0].instead_of == "gyro_rate_nonlinearity", [(s.added, s.instead_of) for s in steps]
    assert "gyro_rate_nonlinearity" not in final.effects
    assert "predicts the left-out segments worse" in steps[0].caveats[0]
    assert "scale factor changes with temperature" in final.verdict and "ppm/degC" in final.verdict


def test_the_quadratic_temperature_bias_is_found_in_temperature_terms(tmp_path):
    """The issue's quadratic temperature bias came out as segment-index terms.  Searched with the
    library's linear temperature_bias in the model (where --auto ends; the linear part that
    T_ref != the simulator's reference makes is its): every gyro gets its (T - T_ref)² term
    within 4 sigma of the truth where it is significant (x and y here; z's 2.5 deg/h/degC² is
    not, nor the accelerometers' 6-10 ug/degC²), and no step, time or other term is taken."""
    case = tc.BY_NAME["temperature_bias_quadratic"]
    _, capture = tc.training(case, 3, tmp_path)
    s = lsq.summarise(capture)
    reg = simhelpers.registry_without(*case.library)
    d = diagnose(lsq.fit(s, [reg.create("temperature_bias")]), registry=reg)
    prop = terms.propose(d, s)
    assert prop is not None and prop.kept, prop and prop.reason
    found = {(t.sensor, t.axis, t.regressor.family): (t.natural(v), abs(t.natural(sg)))
             for t, v, sg in zip(prop.effect.terms, prop.values, prop.sigmas)}
    assert all(f == "T2" for _, _, f in found), sorted(found)
    assert sum(sensor == "gyro" for sensor, _, _ in found) >= 2, sorted(found)
    for (sensor, axis, _), (value, sigma) in found.items():
        true = case.hidden[f"{sensor}__bias_tempco2"][axis]
        assert abs(value - true) < 4 * sigma, (sensor, axis, value, sigma, true)


def test_words_and_units():
    t = terms.Term("gyro", 0, terms.regressor("wxT"))
    assert t.words(120e-6, 8e-6) == ("x gyro: its scale factor changes with temperature: +120 ± 8 ppm/degC "
                                     "(in w_x·(T - T_ref))")
    k3 = terms.Term("accel", 2, terms.regressor("fz3"))
    assert k3.natural(1e-6 * G0 / G0**3) == pytest.approx(1.0)          # 1 ug/g^3
    assert "third-order nonlinearity (K3)" in k3.words(1e-9) and "ug/g^3" in k3.words(1e-9)
    q = terms.Term("gyro", 1, terms.regressor("T2"))
    assert q.words(1 / 3600).startswith("y gyro: its bias changes with the square of the temperature: +1 deg/h/degC^2")
    # the dictionary per sensor: no rate terms for an accelerometer
    assert not any(r.family.startswith("w") for r in terms.dictionary("accel", 20))
    assert {"f3", "fT", "T2", "step"} <= {r.family for r in terms.dictionary("accel", 20)}
    assert {"w3", "wT", "wabsw", "f", "ff", "T2", "wd"} <= {r.family for r in terms.dictionary("gyro", 20)}


@pytest.mark.parametrize("seed", [3, 4, 5, 6, 7, 8])
def test_no_false_alarm_on_clean_captures(seed, tmp_path):
    """A clean capture: nothing added, nothing proposed (the whole library in the registry)."""
    _, capture = tc.training(None, seed, tmp_path)
    steps, final = auto.run(lsq.summarise(capture))
    assert not steps and final.proposal is None, ([s.added for s in steps], final.verdict)
    assert final.p_value > ALPHA / 10


@pytest.fixture(scope="module")
def floor(tmp_path_factory):
    """The held-out error of a clean capture's calibration: estimation noise only."""
    with tc.without_library(()):
        return tc.heldout(None, tmp_path_factory.mktemp("clean"))


@pytest.mark.parametrize("name", ["accel_cubic", "gyro_scale_temperature"])
def test_the_emitted_plugin_is_used_unchanged_and_the_held_out_error_falls_to_the_floor(name, floor, tmp_path,
                                                                                          monkeypatch):
    simhelpers.library_without(monkeypatch, *tc.BY_NAME[name].library)
    r = tc.heldout(tc.BY_NAME[name], tmp_path)
    assert r["added"] == [auto.DISCOVERED] and r["plugin"], r["added"]
    before, after, clean = r["before"], r["after"], floor["before"]
    # never grows (per sensor), and falls to the clean floor within 2x
    assert after["accel_mg"] <= before["accel_mg"] and after["gyro_dph"] <= before["gyro_dph"], (before, after)
    assert after["accel_mg"] < 2 * clean["accel_mg"] and after["gyro_dph"] < 2 * clean["gyro_dph"], (after, clean)
    # the plugin's own self-test runs
    ns = {}
    exec(compile(r["plugin"], "found.py", "exec"), ns)
    ns["test_compensation_removes_the_terms"]()


def test_nothing_to_emit_is_one_line_and_exit_0(floor):
    """The floor's loop ran `diagnose CLEAN --auto --json --emit-effect found.py` (exit 0, or
    tc.heldout fails) on the clean training capture: one line on stderr, no file written."""
    err = floor["diagnose_stderr"].strip().splitlines()
    assert len(err) == 1 and "nothing to emit" in err[0], err
    assert floor["added"] == [] and floor["plugin"] is None
