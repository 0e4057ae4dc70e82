"""Hypothesis fuzz of the other YAML files the commands read, structure-aware (issue 26 goal):
a simulated truth (``run --sim --sim-truth``, ``plan --reveals --sim-truth``), a noise file
(``export --noise``: station-noise/1, written by ``station noise``) and a twin faults file
(``sim serve --faults``).  Each starts from a valid document that station itself writes or
documents; every field found by walking it is set to another type or an absurd value or
deleted, up to three at a time (tests/test_fuzz_configs.py's mutation).  The command's code —
api.simulate on a two-segment scheme, api.export to Kalibr, load_faults — answers or raises
UserError in one line; never another exception, never a hang (an alarm of HANG_S)."""
import os

import pytest
import yaml
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from station import api
from station.core.errors import UserError
from test_fuzz_bags import time_limit
from test_fuzz_configs import mutated, paths
from test_fuzz_readers import VALID_CAL, values

EXAMPLES = int(os.environ.get("STATION_FUZZ_EXAMPLES", "5"))
FUZZ = settings(max_examples=EXAMPLES, deadline=None, suppress_health_check=list(HealthCheck))
# each call here is ~10-100 ms of CPU; 30 s is a hang on a machine loaded 10x
HANG_S = 30.0

TINY_SCHEME = """name: tiny
title: one pose and one turn (the truth fuzz's scheme)
segments:
  - {static: pos01, up_body: [0, 0, 1], dwell_s: 1.0}
  - {rotation: rotz, axis_body: [0, 0, 1], rate_dps: 90, rotation_s: 4.0, pair: false}
"""
FAULTS = {"version": 1,
          "imu": {"garbage": {"every_s": 1.0, "bytes": 32}, "corrupt": {"probability": 0.01},
                  "drop": {"probability": 0.01}, "stall": {"at_s": 20.0, "duration_s": 5.0},
                  "disconnect": {"at_s": 30.0}},
          "table": {"interlock_trip": {"axis": 1, "at_s": 10.0}, "stuck_axis": {"axis": 2, "shortfall_deg": 0.5},
                    "stall": {"at_s": 20.0, "duration_s": 5.0}, "disconnect": {"at_s": 30.0}}}


def _axis(white, upper):
    return {"white_noise_ug_rthz": white, "white_noise_sigma_ug_rthz": white / 115, "white_noise_tau_s": 0.01,
            "bias_instability_ug": None, "bias_instability_tau_s": None, "bias_instability_upper_ug": upper,
            "random_walk_ug_rth": None, "random_walk_sigma_ug_rth": None, "random_walk_tau_s": None,
            "random_walk_upper_ug_rth": upper * 15}


# what `station noise still.csv` writes for 30 s of white noise at 100 Hz (its numbers, rounded;
# written here so that the suite does not characterise and plot a recording for the fuzz)
NOISE = {"format": "station-noise/1", "imu": {"model": None, "serial": None},
         "noise": {"method": "overlapping Allan deviation", "source": "still.csv (3000 samples)",
                   "sample_rate_hz": 100.0, "duration_s": 30.0,
                   "accel": {a: _axis(98.0, 75.5) for a in "xyz"}, "gyro": {a: _axis(0.0206, 0.017) for a in "xyz"},
                   "kalibr": {"accelerometer_noise_density": 0.00101, "accelerometer_random_walk": 0.000475,
                              "accelerometer_random_walk_is_upper_bound": True,
                              "gyroscope_noise_density": 1.77e-05, "gyroscope_random_walk": 7.89e-06,
                              "gyroscope_random_walk_is_upper_bound": True, "update_rate": 100.0}}}


def answers_or_refuses(call, count=True):
    try:
        with time_limit(HANG_S):
            call()
        outcome = "answered"
    except UserError as e:
        assert "\n" not in str(e).strip() and len(str(e)) < 2000, str(e)
        outcome = "refused"
    if count:
        event(outcome)
    return outcome


def changes_of(doc, depth=4):
    return st.lists(st.tuples(st.sampled_from(paths(doc, depth=depth)), values, st.booleans()), min_size=1, max_size=3)


@pytest.fixture(scope="module")
def side_files(tmp_path_factory):
    """The valid documents: a truth (station's default, as sim_truth.yaml holds it), a noise
    file as `station noise` writes one, the documented faults file; the tiny scheme and an
    accelerometer-only calibration to export."""
    from sim_devices.truth import default_truth
    d = tmp_path_factory.mktemp("side")
    (d / "tiny.yaml").write_text(TINY_SCHEME)
    (d / "cal.yaml").write_text(yaml.safe_dump(VALID_CAL))
    (d / "still-noise.yaml").write_text(yaml.safe_dump(NOISE))
    return {"dir": d, "truth": yaml.safe_load(yaml.safe_dump(default_truth(1).to_yaml_dict())),
            "noise": NOISE, "faults": FAULTS}


def test_the_valid_side_files_are_accepted(side_files, tmp_path):
    """The fuzz starts from documents that work (else it would test refusals only)."""
    from sim_devices.twins.faults import load_faults
    d = side_files["dir"]
    (tmp_path / "t.yaml").write_text(yaml.safe_dump(side_files["truth"]))
    assert answers_or_refuses(lambda: api.simulate(d / "tiny.yaml", tmp_path / "c", truth=tmp_path / "t.yaml"),
                              count=False) == "answered"
    assert answers_or_refuses(lambda: api.export(d / "cal.yaml", "kalibr", tmp_path / "k.yaml",
                                                 noise=d / "still-noise.yaml", force=True), count=False) == "answered"
    (tmp_path / "f.yaml").write_text(yaml.safe_dump(FAULTS))
    assert answers_or_refuses(lambda: load_faults(tmp_path / "f.yaml"), count=False) == "answered"


@FUZZ
@given(data=st.data())
def test_fuzzed_sim_truth(side_files, tmp_path_factory, data):
    d = tmp_path_factory.mktemp("truth")
    doc = side_files["truth"]
    (d / "t.yaml").write_text(yaml.safe_dump(mutated(doc, data.draw(changes_of(doc)))))
    answers_or_refuses(lambda: api.simulate(side_files["dir"] / "tiny.yaml", d / "cap", truth=d / "t.yaml"))


@FUZZ
@given(data=st.data())
def test_fuzzed_noise_file(side_files, tmp_path_factory, data):
    d = tmp_path_factory.mktemp("noise")
    doc = side_files["noise"]
    (d / "n.yaml").write_text(yaml.safe_dump(mutated(doc, data.draw(changes_of(doc, depth=5)))))
    answers_or_refuses(lambda: api.export(side_files["dir"] / "cal.yaml", "kalibr", d / "k.yaml", noise=d / "n.yaml",
                                          force=True))


@FUZZ
@given(data=st.data(), axes=st.sampled_from([1, 2, 3]))
def test_fuzzed_faults_file(tmp_path_factory, data, axes):
    from sim_devices.twins.faults import load_faults
    d = tmp_path_factory.mktemp("faults")
    (d / "f.yaml").write_text(yaml.safe_dump(mutated(FAULTS, data.draw(changes_of(FAULTS)))))
    answers_or_refuses(lambda: load_faults(d / "f.yaml", axes))


# ------------------------------------------------------------------ found (by hand, beside the fuzz)

@pytest.mark.parametrize("where", ["noise file", "calibration"])
@pytest.mark.parametrize("key, value", [("accelerometer_noise_density", float("nan")),
                                        ("accelerometer_noise_density", -5.0), ("update_rate", 0.0),
                                        ("gyroscope_random_walk", float("inf")), ("gyroscope_noise_density", True)])
def test_kalibr_numbers_that_are_not_noise_are_one_line(side_files, tmp_path, capsys, where, key, value):
    """A noise figure NaN: ValueError "not finite" escaped `export --to kalibr`; -5 or a rate of 0
    was exported as it stood (another tool handed nonsense, exit 0).  From a noise file
    (`--noise`) or the calibration's own noise block: one line naming the file and the field."""
    from test_bad_inputs import one_line_exit_2
    doc = yaml.safe_load(yaml.safe_dump(side_files["noise"]))
    doc["noise"]["kalibr"][key] = value
    if where == "noise file":
        (tmp_path / "n.yaml").write_text(yaml.safe_dump(doc))
        cal, bad, extra = side_files["dir"] / "cal.yaml", tmp_path / "n.yaml", ["--noise", tmp_path / "n.yaml", "--force"]
    else:
        cal_doc = yaml.safe_load(yaml.safe_dump(VALID_CAL))
        cal_doc["noise"] = doc["noise"]
        (tmp_path / "cal.yaml").write_text(yaml.safe_dump(cal_doc))
        cal, bad, extra = tmp_path / "cal.yaml", tmp_path / "cal.yaml", []
    for to in ("kalibr", "json"):
        one_line_exit_2(["export", cal, "--to", to, "-o", tmp_path / f"out-{to}", *extra], capsys, str(bad),
                        f"noise.kalibr.{key}")
