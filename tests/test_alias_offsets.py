"""Issue 28 item 3, the last alias without segments (fifteenth session): an offset per axis group
(rotation_axis_offsets) and a table vibrating once per revolution at one rate are named with the
`station design --from ... --separate` command; turns appended about the capture's own axes share
its offsets (station.model.axis_offsets.offset_groups: the IMU's distance from the line the table
turns it about is the table's and the mounting's, not the run's), and about a vertical axis no
vibration is modelled, so the designed vertical turns, appended to the dry run's capture,
separate the two."""
import json
import shlex

import numpy as np
import pytest
import yaml

from sim_devices.truth import mems_truth
from station.cli import main
from station.diagnose import suggest, words
from station.estimate.summaries import summarise
from station.io.capture import read_capture
from station.estimate import lsq
from station.model.axis_offsets import offset_groups
from station.model.registry import EffectRegistry

RATE = 100.0
# the simulated table's axis that turns the IMU about case axis y runs 20 mm from it along z, the
# one about z 15 mm along x (sim_devices/truth.py axis_offsets_m): w^2 d at 100 deg/s = 3.0 mm/s^2
# per mm, 4.6-6.1 mg across the axis
OFFSETS_M = [[0.0, 0.0, 0.0], [0.0, 0.0, 0.02], [0.015, 0.0, 0.0]]


def _scheme() -> str:
    """Nine 3 s statics and one ± pair (two revolutions) about each of the six body and diagonal
    axes, all at 100 deg/s, the table axis level: the capture that cannot tell the two apart."""
    ups = [[0, 0, 1], [0, 0, -1], [1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [1, 1, 0], [0, 1, 1], [1, 0, 1]]
    axes = [[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 0], [0, 1, 1], [1, 0, 1]]
    segs = [{"static": f"s{i}", "up_body": u} for i, u in enumerate(ups)]
    segs += [{"rotation": f"r{i}", "axis_body": a} for i, a in enumerate(axes)]
    return yaml.safe_dump({"name": "onerate", "segments": segs,
                           "defaults": {"dwell_s": 3.0, "rate_dps": RATE, "rotation_s": 720.0 / RATE}})


def test_appended_turns_share_the_capture_offsets_about_the_same_axis_line():
    """offset_groups: a group of a later session about the same body axis (and table axis) has
    the first group's offset; a new axis, or the same axis on another table axis, its own."""
    class R:
        def __init__(self, index, group, axis, table_axis=None):
            self.index, self.group, self.axis_body, self.table_axis = index, group, np.array(axis, float), table_axis

    rots = [R(0, 0, [1, 0, 0]), R(1, 1, [0, 1, 0]), R(2, 2, [2, 0, 0]), R(3, 3, [0, 1, 0], 2), R(4, 4, [0, 0, 1])]
    assert offset_groups(rots) == {0: 0, 1: 1, 2: 0, 3: 3, 4: 4}


@pytest.mark.parametrize("vertical_table_axis, resolved", [(1, True), (2, False), (None, False)])
def test_diagnose_says_the_pair_resolved_only_where_the_model_shares_the_offset(vertical_table_axis, resolved):
    """words._vertical_on_own_axes follows offset_groups: an appended vertical turn about body x
    resolves the pair only when the level turn about x was turned by the same table axis (the
    review's case: the same body axis on another table axis has an offset of its own)."""
    from types import SimpleNamespace as NS

    from station.diagnose.words import _vertical_on_own_axes

    g = 9.80665
    level = NS(index=0, group=0, steady=True, axis_body=np.array([1.0, 0, 0]), table_axis=1,
               accel_cos=np.array([0, g, 0.0]), accel_sin=np.array([0, 0, g]), accel_dc=np.zeros(3))
    vertical = NS(index=1, group=1, steady=True, axis_body=np.array([1.0, 0, 0]), table_axis=vertical_table_axis,
                  accel_cos=np.zeros(3), accel_sin=np.zeros(3), accel_dc=np.array([g, 0, 0]))
    s = NS(rotations=[level, vertical])
    assert (offset_groups([level, vertical])[1] == 0) == resolved
    assert _vertical_on_own_axes(s) == resolved


def test_axis_offsets_and_the_vibration_are_named_with_a_command_and_separated_by_vertical_turns(
        tmp_path, capsys, monkeypatch):
    doc = mems_truth(0).to_yaml_dict()
    doc["bench"]["axis_offsets_m"] = OFFSETS_M
    (tmp_path / "truth.yaml").write_text(yaml.safe_dump(doc))
    (tmp_path / "s.yaml").write_text(_scheme())
    monkeypatch.chdir(tmp_path)
    assert main(["run", "--scheme", "s.yaml", "--sim", "--sim-truth", "truth.yaml", "--seed", "4", "--out", "cap",
                 "--no-history"]) in (0, 3)
    capsys.readouterr()
    s = summarise(read_capture("cap"))
    # named, with the command diagnose prints beside the offsets (suggest.separations)
    assert [r for r, _ in words.aliases(s, "rotation_axis_offsets")] == ["table_vibration_once_per_rev"]
    said = suggest.separations("cap", [], "rotation_axis_offsets", s)
    assert said == ["station design --from cap --add rotation_axis_offsets --separate "
                    "rotation_axis_offsets,table_vibration_once_per_rev -o extension.yaml"], said
    # the command as printed (a small candidate set: 200 deg/s, one revolution, 10 s dwells; at
    # 100 deg/s alone twelve vertical turns leave the vibration at 1.1 x its target, 0.05 mg)
    assert main([*shlex.split(said[0])[1:], "--json", "--rates", "200", "--revolutions", "1",
                 "--dwells", "10"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["segments"] and report["correlation_after"] < 0.95
    assert all(seg.get("axis_elevation_deg") == 90.0 for seg in report["segments"]), report["segments"]
    vib = [p for p in report["parameters"] if p["name"].startswith("table_vibration_")]
    assert vib and all(p["revealed_after"] for p in vib), vib
    assert main(["run", "--sim", "--append", "cap", "--scheme", "extension.yaml", "--no-history"]) in (0, 3)
    capsys.readouterr()
    s2 = summarise(read_capture("cap"))
    assert words.aliases(s2, "rotation_axis_offsets") == []
    assert suggest.separations("cap", [], "rotation_axis_offsets", s2) == []
    # separated: with both in the model, the vibration at zero and each offset's part that a turn
    # sees (across its axis and across the first group's, x: the rest trades with the common
    # offset, held by its prior) at the simulated truth, each within 4.5 sigma (two-sided, ~10
    # numbers: a false alarm once in 1e4); the vibration revealed (1-sigma under 0.1 mg, its
    # typical size)
    truth = np.array(OFFSETS_M) * 1e3        # mm, the offset of the line about case axis k
    reg = EffectRegistry()
    fit = lsq.fit(s2, [reg.create("rotation_axis_offsets"), reg.create("table_vibration_once_per_rev")])
    names, index, factors, _ = lsq._reported_index(fit, "m/s^2", "deg/s")
    where = {n: k for k, n in enumerate(names)}
    vib = [n for n in names if n.startswith("table_vibration_100dps_")]
    assert len(vib) == 6
    for n in vib:
        c, f = index[where[n]], factors[where[n]]
        value, sigma = fit.x[c] * f, float(np.sqrt(fit.covariance_of([c])[0, 0])) * abs(f)
        assert sigma < 0.1 and abs(value) < 4.5 * sigma, (n, value, sigma)
    axes = [[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 0], [0, 1, 1], [1, 0, 1]]
    for g in range(1, 6):
        k = [where[f"axis{g}_offset_{c}"] for c in "xyz"]
        cols, f = index[k], np.asarray(factors)[k]
        v = fit.x[cols] * f
        cov = fit.covariance_of(cols) * np.outer(f, f)
        a = np.array(axes[g], float) / np.linalg.norm(axes[g])
        n = np.cross(a, [1.0, 0.0, 0.0])
        n /= np.linalg.norm(n)
        d = truth[int(np.argmax(np.abs(axes[g])))] - truth[0]      # the simulator's nearest case axis
        sigma = float(np.sqrt(n @ cov @ n))
        assert sigma < 1.0 and abs(n @ v - n @ d) < 4.5 * sigma, (g, n @ v, n @ d, sigma)
