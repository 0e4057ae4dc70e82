"""Issue 28 (twentieth session, review revvib): a capture with a level turn and a vertical turn
about the same body axis.  The estimator put both in one axis group (summaries: one group per body
axis and session), one gravity angle for two elevations: the fit of such a capture failed (reduced
chi2 2.2e6 on a simulator with no effect missing), and `station design --from` on it died with
KeyError (('capture', 0.0, 0.0, 1.0), 0.0) in search.State (design/information.py keyed the
group's prior by the first turn's (axis, elevation), the other turn's key had none).  A recorded
elevation is now part of the group (summaries), and the search keys each turn by its estimator
group (information._group_key: the group's axis nuisances and prior counted once)."""
import numpy as np
import yaml

from sim_devices.truth import mems_truth
from station.cli import main
from station.estimate import lsq
from station.estimate.summaries import summarise
from station.io.capture import read_capture
from station.io.scheme import scheme_from_text
from station.simulate import dryrun

# six 1 s statics, a level turn about z (a +/- pair, one revolution each) and a vertical one
SCHEME = """\
name: levelvertical
defaults: {dwell_s: 1.0, rate_dps: 100.0, rotation_s: 3.6}
segments:
""" + "".join(f"  - {{static: s{i}, up_body: {u}}}\n" for i, u in enumerate(
    [[0, 0, 1], [0, 0, -1], [1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0]])) + """\
  - {rotation: rx, axis_body: [1, 0, 0]}
  - {rotation: ry, axis_body: [0, 1, 0]}
  - {rotation: rz, axis_body: [0, 0, 1]}
  - {rotation: vz, axis_body: [0, 0, 1], axis_elevation_deg: 90}
"""


def _capture(path, seed=5):
    """The dry run's capture of SCHEME (no estimate): ~0.3 s."""
    scheme = scheme_from_text(SCHEME, "levelvertical.yaml")
    dryrun.record_scheme(scheme, mems_truth(0), seed, path)
    return path


def test_a_level_and_a_vertical_turn_about_one_axis_are_two_groups_and_the_fit_passes(tmp_path):
    """Two gravity angles, two groups; the fit's chi2 within the noise (it was 2.2e6 x its dof)."""
    s = summarise(read_capture(_capture(tmp_path / "cap")))
    group = {r.name: r.group for r in s.rotations}
    assert group["rz_p"] == group["rz_m"] != group["vz_p"] == group["vz_m"], group
    fit = lsq.fit(s, [])
    # chi2 on dof degrees of freedom: mean dof, spread sqrt(2 dof); 5 spreads over it fails
    assert fit.chi2 < fit.dof + 5 * np.sqrt(2 * fit.dof), (fit.chi2, fit.dof)


def test_design_from_a_capture_with_a_level_and_a_vertical_turn_answers(tmp_path, capsys, monkeypatch):
    """Run as diagnose would print it, the designer answers (a proposal, exit 0, or one line and
    exit 2: this pair no segment separates), not KeyError and exit 1."""
    monkeypatch.chdir(tmp_path)
    _capture(tmp_path / "cap")
    code = main(["design", "--from", "cap", "--add", "rotation_axis_offsets", "--separate",
                 "rotation_axis_offsets,table_vibration_once_per_rev", "--rates", "100", "--revolutions", "1",
                 "--dwells", "10", "-o", "extension.yaml"])
    err = capsys.readouterr().err
    assert code in (0, 2), (code, err)
    assert "Traceback" not in err, err
    if code == 2:          # (its progress lines start "design: ")
        said = [ln for ln in err.splitlines() if ln.startswith("station design:")]
        assert len(said) == 1 and "separate rotation_axis_offsets from table_vibration" in said[0], err


def test_the_capture_turns_about_one_axis_in_two_sessions_keep_two_groups_in_the_search(tmp_path, monkeypatch):
    """A capture extended by run --append with a turn about its own z again (same elevation): two
    estimator axis groups (one per session), which the search keyed alike ((capture z), 0.0): the
    second group's axis nuisances were laid over the first's and one prior was lost.  Each group
    has its own key now, one per estimator group of the capture (capture_groups)."""
    from station.design import search, sequential
    from station.model.registry import EffectRegistry

    made = []

    class Kept(search.Scorer):
        def __init__(self, *a, **k):
            super().__init__(*a, **k)
            made.append(self)

    monkeypatch.setattr(search, "Scorer", Kept)
    text = SCHEME.replace("  - {rotation: vz, axis_body: [0, 0, 1], axis_elevation_deg: 90}\n",
                          "  - {rotation: wz, axis_body: [0, 0, 1]}\n")
    dryrun.record_scheme(scheme_from_text(text, "twosessions.yaml"), mems_truth(0), 5, tmp_path / "cap")
    manifest = tmp_path / "cap" / "manifest.yaml"
    doc = yaml.safe_load(manifest.read_text())
    for seg in doc["segments"]:
        if seg["name"].startswith("wz"):
            seg["appended"] = 1                  # as run --append records it
    manifest.write_text(yaml.safe_dump(doc, sort_keys=False))
    capture = read_capture(tmp_path / "cap", load_data=False)
    sessions = sequential.capture_sessions(capture)
    groups = sequential.capture_groups(sequential.capture_scheme(capture), sessions)
    assert len(groups) == 4, groups             # x, y, z, and z of the extension
    ext = sequential.extend(tmp_path / "cap", [EffectRegistry().create("accel_lever_arm")],
                            reveal=["accel_position_*"], rates_dps=[100.0], revolutions=[1], dwells_s=[10.0])
    assert ext.entries
    sc = made[-1]
    own = [i for i, c in enumerate(sc.cands) if c.kind == "rotation" and c.key[0][0] == "capture"]
    keys = {sc.cands[i].key[2]: sc.info.rotation[sc.cands[i].key][0] for i in own}
    assert len(set(keys.values())) == len(groups), keys
    assert keys["rz_p"] == keys["rz_m"] != keys["wz_p"] == keys["wz_m"], keys
    assert all(k in sc.info.group_prior for k in keys.values())
    # and the search adds each turn's block to its group's by that key
    assert [sc.group[i] for i in own] == [keys[sc.cands[i].key[2]] for i in own]
