"""Issue 28 (sixteenth session, review finding): `station design --from` on a capture that was
already extended (`run --append`).  The estimator gives an extension's rotations axis groups of
their own (summaries: one per body axis and session), and names the offsets per axis group
(rotation_axis_offsets) by those numbers; the designer modelled the capture as one session, so
on an extended capture its groups, names and offset rows were another numbering's: the
estimator's `axis4_offset_*` was refused ("no parameter matches"), its own `axis3_offset_*` ended
in a traceback (a level and a vertical turn about x merged into one group)."""
import json

import numpy as np
import pytest

from station.cli import main
from station.design.sequential import capture_groups, capture_scheme, capture_sessions
from station.estimate import lsq
from station.estimate.summaries import summarise
from station.io.capture import read_capture
from station.model.registry import EffectRegistry

BASE = """\
name: base3
defaults: {dwell_s: 3.0, rate_dps: 100.0, rotation_s: 3.6}
segments:
""" + "".join(f"  - {{static: s{i}, up_body: {u}}}\n" for i, u in enumerate(
    [[0, 0, 1], [0, 0, -1], [1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [1, 1, 0], [0, 1, 1], [1, 0, 1]])) + """\
  - {rotation: rx, axis_body: [1, 0, 0]}
  - {rotation: ry, axis_body: [0, 1, 0]}
  - {rotation: rz, axis_body: [0, 0, 1]}
"""
# the first extension: a vertical turn about the run's x (its offset the run's: no name of its
# own) and one about a new axis; the second: x again (a third session's group) and another axis
EXT1 = """\
name: e1
defaults: {rate_dps: 100.0, rotation_s: 3.6}
segments:
  - {rotation: vx, axis_body: [1, 0, 0], axis_elevation_deg: 90}
  - {rotation: vw, axis_body: [1, 1, 0], axis_elevation_deg: 90}
"""
EXT2 = EXT1.replace("name: e1", "name: e2").replace("vx", "ux").replace("vw, axis_body: [1, 1, 0]",
                                                                          "uv, axis_body: [0, 1, 1]")
SMALL = ["--rates", "200", "--revolutions", "1", "--dwells", "10"]


def _estimators_offset_names(cap) -> list:
    s = summarise(read_capture(cap))
    fit = lsq.fit(s, [EffectRegistry().create("rotation_axis_offsets")])
    names = lsq._reported_index(fit, "m/s^2", "deg/s")[0]
    return [n for n in names if n.startswith("axis") and "_offset_" in n]


@pytest.mark.parametrize("extensions", [1, 2])
def test_design_from_an_extended_capture_has_the_estimators_axis_groups(tmp_path, capsys, monkeypatch, extensions):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "s.yaml").write_text(BASE)
    assert main(["run", "--scheme", "s.yaml", "--sim", "--seed", "3", "--out", "cap", "--no-history"]) in (0, 3)
    for k, text in enumerate((EXT1, EXT2)[:extensions]):
        (tmp_path / f"e{k}.yaml").write_text(text)
        assert main(["run", "--sim", "--append", "cap", "--scheme", f"e{k}.yaml", "--no-history"]) in (0, 3)
    capsys.readouterr()
    capture = read_capture("cap", load_data=False)
    sessions = capture_sessions(capture)
    assert set(sessions.values()) == set(range(1, extensions + 1))
    # the groups as the estimator numbers them: x, y, z, then per extension its x and its new axis
    axes = capture_groups(capture_scheme(capture), sessions)
    expect = [[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 0, 0], [1, 1, 0], [1, 0, 0], [0, 1, 1]][:3 + 2 * extensions]
    assert np.allclose(axes, [np.array(a) / np.linalg.norm(a) for a in expect])
    named = _estimators_offset_names("cap")
    newest = sorted({n.split("_offset_")[0] for n in named}, key=lambda g: int(g[4:]))[-1]
    assert newest == f"axis{3 + 2 * extensions - 1}"       # the last extension's new axis
    # the designer takes the estimator's names (before: refused, "no parameter ... matches")
    rc = main(["design", "--from", "cap", "--add", "rotation_axis_offsets", "--reveal", f"{newest}_offset_*",
               "--json", "-o", "ext.yaml", *SMALL])
    out = capsys.readouterr()
    assert rc == 0, out.err
    report = json.loads(out.out)
    assert sorted(p["name"] for p in report["parameters"]) == sorted(n for n in named if n.startswith(newest + "_"))
    # a turn sees an offset only across its own axis and the first group's (x): the part across
    # both is the row designed for, revealed by the capture's own vertical turn about that axis
    # with the estimator's 1σ of it (the prediction's names are the estimator's; before, the
    # design's axis3 was this axis and the estimator's axis3 the run's x again)
    assert "Traceback" not in out.err
