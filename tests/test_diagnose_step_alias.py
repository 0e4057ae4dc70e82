"""diagnose --auto on a capture with a bias step it cannot size (issue 28 item 3, "every alias
diagnose names comes with segments that separate it"; "a calibration never lies"; twenty-first
session).

The capture: long statics, each attitude visited once, then turns (tests/test_design_from_timeline's
scheme and bench); the simulated accelerometer biases step by (300, -200, 250) ug between the
statics xy and yz.  Before the change --auto kept accel_cross_axis (the first IMU effect that
passed: the step is ranked after the IMU's effects), replaced it by a discovered x accelerometer
term in f_z^3 of -2,713 +/- 290 ug/g^3 and declared the model explains the data, without a word
that the capture cannot tell the step from it, nor a command (bias_step was in suggest.NOT_DESIGNED).
Now the step is put against the IMU effect (it predicts the left-out segments better: 241.3
against 315.6), the terms do not displace it (chi2 94.2 against 97.2: not clearly better), the
step's caveats say the capture cannot tell it from them, and diagnose prints the station design
--from command that separates the step from accel_cross_axis.  The command is run as printed, its
extension recorded into a copy of the capture (the dry run's --append), and --auto on it finds
the step at the true time with the true sizes (within 3 of their 1-sigma, a reference sharing no
code with the estimator: the simulator's truth)."""
import contextlib
import io
import json
import shlex
import shutil

import numpy as np
import pytest

from station.bench.config import load_config
from station.cli import main
from station.cli.run import table_geometry
from station.io.scheme import load_scheme, scheme_from_text
from station.simulate import dryrun

from test_design_from_timeline import CONFIG, SCHEME, STEP_TIME_S, STEP_UG


def _diagnosed(cap, capsys) -> dict:
    capsys.readouterr()
    status = main(["diagnose", str(cap), "--auto", "--json"])
    said = capsys.readouterr()
    assert status in (0, 1), said.err
    return json.loads(said.out)


def _recorded(root, accel_ug=None, gyro_dph=None):
    (root / "station.yaml").write_text(CONFIG)
    config = load_config(str(root / "station.yaml"))
    truth = dryrun.load_truth(None, 1)
    for triad, step in ((truth.accel, accel_ug), (truth.gyro, gyro_dph)):
        if step is not None:
            triad.bias_step = np.array(step)
            triad.bias_step_time_s = STEP_TIME_S
    dryrun.record_scheme(scheme_from_text(SCHEME, "s.yaml"), truth, 1, root / "cap",
                         geometry=table_geometry(config.table), ramp_accel_dps2=dryrun.table_ramp_accel(config.table),
                         warmup=config.warmup)
    return root


@pytest.fixture(scope="module")
def step_capture(tmp_path_factory):
    return _recorded(tmp_path_factory.mktemp("step-alias"), accel_ug=STEP_UG)


@pytest.fixture(scope="module")
def step_report(step_capture):
    """diagnose --auto --json of the step capture, once for the tests that read it."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        status = main(["diagnose", str(step_capture / "cap"), "--auto", "--json"])
    assert status in (0, 1), err.getvalue()
    return json.loads(out.getvalue())


def test_auto_keeps_the_step_says_what_it_cannot_tell_and_prints_the_command(step_capture, step_report, tmp_path,
                                                                            capsys, monkeypatch):
    """The first --auto: the step is added (not terms of an implausible size), its caveats say the
    capture cannot tell it from the terms, and the printed command works as printed; its
    extension, recorded, lets --auto find the step (the truth within 3 sigma).  Before the change:
    discovered_terms added, no command (fails at the first assert)."""
    steps = step_report["steps"]
    assert steps and steps[0]["added"] == "bias_step" and not steps[0]["discovered"], [s["added"] for s in steps]
    assert all(not s["discovered"] for s in steps)
    words = " ".join(steps[0]["caveats"])
    assert "cannot tell bias_step from terms found outside the library" in words, words
    commands = steps[0]["separate_commands"]
    assert any("--separate bias_step,accel_cross_axis" in c for c in commands), commands

    # the command as printed (its -o relative to the working directory)
    cmd = next(c for c in commands if "--separate bias_step,accel_cross_axis" in c)
    words = shlex.split(cmd)
    assert words[:2] == ["station", "design"]
    monkeypatch.chdir(tmp_path)
    capsys.readouterr()
    status = main(words[1:])
    said = capsys.readouterr()
    assert status == 0, said.err
    ext = tmp_path / words[words.index("-o") + 1]

    # recorded into a copy of the capture, as station run --sim --append does
    cap = tmp_path / "cap"
    shutil.copytree(step_capture / "cap", cap)
    table = load_config(str(step_capture / "station.yaml"))
    dryrun.append_scheme(load_scheme(str(ext)), ext.read_text(), cap,
                         ramp_accel_dps2=dryrun.table_ramp_accel(table.table), warmup=table.warmup)
    after = _diagnosed(cap, capsys)
    assert after["steps"] and after["steps"][0]["added"] == "bias_step", [s["added"] for s in after["steps"]]
    assert all(not s["discovered"] for s in after["steps"])
    est = {e["name"]: e for e in after["steps"][0]["estimate"]}
    for axis, truth in zip("xyz", STEP_UG):
        e = est[f"accel_bias_step_{axis}"]
        assert not e["not_revealed"], e
        assert abs(e["value"] - truth) < 3.0 * e["sigma"], (axis, e, truth)


GYRO_STEP_DPH = [0.3, -0.2, 0.25]


def test_a_gyro_step_is_not_taken_for_g_dependent_gyro_terms(tmp_path, capsys):
    """A case the change was not designed for: the gyro biases step by (0.3, -0.2, 0.25) deg/h
    at the same time, the accelerometers do not.  Before the change --auto added
    gyro_anisoelastic and then gyro_g_sensitivity (0.70 and 0.82 deg/h/g: terms the IMU does
    not have, written into the calibration); now the step is put against the first IMU effect
    that passes, predicts the left-out segments far better (215.8 against 7,894.6) and is kept,
    each gyro step within 3 of its 1-sigma of the truth (measured pulls -0.6, +2.3, -0.6)."""
    root = _recorded(tmp_path, gyro_dph=GYRO_STEP_DPH)
    report = _diagnosed(root / "cap", capsys)
    added = [s["added"] for s in report["steps"]]
    assert added and added[0] == "bias_step", added
    assert not {"gyro_anisoelastic", "gyro_g_sensitivity", "discovered_terms"} & set(added), added
    est = {e["name"]: e for e in report["steps"][0]["estimate"]}
    for axis, truth in zip("xyz", GYRO_STEP_DPH):
        e = est[f"gyro_bias_step_{axis}"]
        assert abs(e["value"] - truth) < 3.0 * e["sigma"], (axis, e, truth)


def test_a_steps_rivals_get_the_command_or_the_words_why_not(monkeypatch):
    """suggest_steps (no fit: < 0.1 s): a rival the designer separates from the step gets its
    `station design --from --separate` command; one that, like the step, follows the capture's
    clock or temperature (the designer refuses the pair: 3.1 x the target) gets the words why.
    Before the change the step's rivals were ignored (no command, no words)."""
    from types import SimpleNamespace as NS

    from station.diagnose import suggest, words

    monkeypatch.setattr(words, "aliases", lambda summaries, effect_id: [])    # no alias of the words' own
    st = NS(discovered=False, added="bias_step", after=NS(effects=["base_triads", "inter_triad", "bias_step"]),
            rivals=["accel_cross_axis", "temperature_bias"], caveats=[], separations=[])
    suggest.suggest_steps([st], "/x/cap", NS(rotations=[]), None)
    assert st.separations == ["station design --from /x/cap --add bias_step --separate bias_step,accel_cross_axis "
                              "-o extension.yaml"]
    why = [c for c in st.caveats if "separate bias_step from temperature_bias" in c]
    assert len(why) == 1 and "clock or its temperature" in why[0], st.caveats
    assert suggest.step_lines(st) == [f"caveat: the fewest segments that separate bias_step from accel_cross_axis: "
                                      f"{st.separations[0]}"]


CUBIC_UG_PER_G3 = [200.0, -150.0, 180.0]


def test_a_real_cubic_accelerometer_is_not_displaced_by_a_step_that_is_not_there(tmp_path, capsys):
    """Review of the twenty-first session: the same capture with no step at all and a real
    accelerometer cubic K3 = (200, -150, 180) ug/g^3 (the twin's truth).  The step's time is
    located on every segment, the left-out one too, so its leave-one-segment-out score is
    optimistic; held-out alone (237.4 against 249.4) kept a step that is not there (chi2 85.9
    against 93.5: not clearly better for its extra parameters and its time) with a gyro y step of
    +0.030 +/- 0.0078 deg/h (3.8 sigma from the truth 0) and dropped the real K3.  Now the real
    term is kept (each K3 within 3 of its 1-sigma of the truth) and the step is named as what the
    capture cannot tell it from."""
    root = tmp_path
    (root / "station.yaml").write_text(CONFIG)
    config = load_config(str(root / "station.yaml"))
    truth = dryrun.load_truth(None, 1)
    truth.accel.cubic_ug_per_g3 = np.array(CUBIC_UG_PER_G3)
    dryrun.record_scheme(scheme_from_text(SCHEME, "s.yaml"), truth, 1, root / "cap",
                         geometry=table_geometry(config.table), ramp_accel_dps2=dryrun.table_ramp_accel(config.table),
                         warmup=config.warmup)
    report = _diagnosed(root / "cap", capsys)
    added = [s["added"] for s in report["steps"]]
    assert added and added[0] == "accel_cubic" and "bias_step" not in added, added
    est = {e["name"]: e for e in report["steps"][0]["estimate"]}
    for axis, k3 in zip("xyz", CUBIC_UG_PER_G3):
        e = est[f"accel_k3_{axis}"]
        assert abs(e["value"] - k3) < 3.0 * e["sigma"], (axis, e, k3)
    said = report["steps"][0]["caveats"]
    assert any("cannot tell accel_cubic from bias_step" in c for c in said), said
    assert not any("accel_cubic predicts the left-out segments better" in c for c in said), said    # it does not


def test_the_steps_words_size_no_part_the_capture_does_not_reveal(step_report):
    """Review of the twenty-first session: before the extension the step's accelerometer parts are
    "not revealed: held by its prior, not written", yet its caveats said "accelerometer z bias
    steps by +237 +/- 74 ug" (the prior-held posterior, sized as a finding; station estimate's
    notes give a held parameter no size).  Every sized part the words name is revealed."""
    step = step_report["steps"][0]
    assert step["added"] == "bias_step", step["added"]
    held = {e["name"] for e in step["estimate"] if e["not_revealed"]}
    assert held, step["estimate"]          # the case: parts held by their prior
    sized = {f"{'accel' if c.startswith('accelerometer') else 'gyro'}_bias_step_{c.split()[1]}"
             for c in step["caveats"] if c.startswith(("accelerometer ", "gyro ")) and " bias steps by " in c}
    assert not sized & held, (sized & held, step["caveats"])
