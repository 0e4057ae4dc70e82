"""Issue 28 item 3: an offset per axis group (rotation_axis_offsets) and a table vibrating once per
revolution.  Fifteenth session: named with the `station design --from ... --separate` command, the
designed vertical turns separated them, because no vibration was modelled about a vertical axis;
turns appended about the capture's own axes share its offsets (station.model.axis_offsets.
offset_groups: the IMU's distance from the line the table turns it about is the table's and the
mounting's, not the run's).  Sixteenth session: the vibration is modelled about a vertical axis too,
and then no segment separates the pair (station/model/table_vibration.py, the derivation): it is
named without a command, and the designer asked by hand refuses it."""

import numpy as np
import yaml

from sim_devices.truth import mems_truth
from station.cli import main
from station.diagnose import suggest, words
from station.estimate.summaries import summarise
from station.io.capture import read_capture
from station.model.axis_offsets import offset_groups
from test_alias_bench import _scheme as alias_bench_scheme

# the simulated table's axis that turns the IMU about case axis y runs 20 mm from it along z, the
# one about z 15 mm along x (sim_devices/truth.py axis_offsets_m): w^2 d at 100 deg/s = 3.0 mm/s^2
# per mm, 4.6-6.1 mg across the axis
OFFSETS_M = [[0.0, 0.0, 0.0], [0.0, 0.0, 0.02], [0.015, 0.0, 0.0]]


def _scheme() -> str:
    """test_alias_bench's capture that cannot tell the two apart, two revolutions a turn."""
    return alias_bench_scheme(revolutions=2)


def test_appended_turns_share_the_capture_offsets_about_the_same_axis_line():
    """offset_groups: a group of a later session about the same body axis (and table axis) has
    the first group's offset; a new axis, or the same axis on another table axis, its own."""
    class R:
        def __init__(self, index, group, axis, table_axis=None):
            self.index, self.group, self.axis_body, self.table_axis = index, group, np.array(axis, float), table_axis

    rots = [R(0, 0, [1, 0, 0]), R(1, 1, [0, 1, 0]), R(2, 2, [2, 0, 0]), R(3, 3, [0, 1, 0], 2), R(4, 4, [0, 0, 1])]
    assert offset_groups(rots) == {0: 0, 1: 1, 2: 0, 3: 3, 4: 4}


def test_the_pair_is_named_without_a_command_vertical_turns_or_not():
    """Since the sixteenth session the vibration is modelled about a vertical axis too (its part
    across the axis per rotation group), so a vertical turn no longer resolves the pair: it is named
    whatever turns the capture has, and no `--separate` command is printed (suggest.NOT_SEPARABLE)."""
    from types import SimpleNamespace as NS

    g = 9.80665
    level = NS(index=0, group=0, steady=True, axis_body=np.array([1.0, 0, 0]), table_axis=1, rate_dps=100.0,
               name="l", accel_cos=np.array([0, g, 0.0]), accel_sin=np.array([0, 0, g]), accel_dc=np.zeros(3))
    vertical = NS(index=1, group=1, steady=True, axis_body=np.array([1.0, 0, 0]), table_axis=1, rate_dps=200.0,
                  name="v", accel_cos=np.zeros(3), accel_sin=np.zeros(3), accel_dc=np.array([g, 0, 0]))
    for rotations in ([level], [level, vertical]):
        s = NS(rotations=rotations, mounting_offset_m=None)
        said = words.aliases(s, "rotation_axis_offsets")
        assert [r for r, _ in said] == ["table_vibration_once_per_rev"] and "no segment" in said[0][1], said
        assert suggest.separations("cap", [], "rotation_axis_offsets", s) == []
        said = suggest.separations("cap", ["rotation_axis_offsets"], "table_vibration_once_per_rev", s)
        assert not [c for c in said if "rotation_axis_offsets," in c or ",rotation_axis_offsets" in c], said


def test_axis_offsets_and_the_vibration_are_named_and_the_designer_refuses_them(tmp_path, capsys, monkeypatch):
    """The physics (station/model/table_vibration.py): a vibration's part turning with the platter is
    a constant across the axis in the case's frame, as an offset's w^2 d is; with a vibration of its
    own at every rate and, about a vertical axis, for every rotation group, no segment separates them:
    the designer, asked by hand for the fifteenth session's vertical turns, finds none (exit 2, its
    one line naming the pair and what stays furthest)."""
    doc = mems_truth(0).to_yaml_dict()
    doc["bench"]["axis_offsets_m"] = OFFSETS_M
    (tmp_path / "truth.yaml").write_text(yaml.safe_dump(doc))
    (tmp_path / "s.yaml").write_text(_scheme())
    monkeypatch.chdir(tmp_path)
    assert main(["run", "--scheme", "s.yaml", "--sim", "--sim-truth", "truth.yaml", "--seed", "4", "--out", "cap",
                 "--no-history"]) in (0, 3)
    capsys.readouterr()
    s = summarise(read_capture("cap"))
    assert [r for r, _ in words.aliases(s, "rotation_axis_offsets")] == ["table_vibration_once_per_rev"]
    assert suggest.separations("cap", [], "rotation_axis_offsets", s) == []
    assert main(["design", "--from", "cap", "--add", "rotation_axis_offsets", "--separate",
                 "rotation_axis_offsets,table_vibration_once_per_rev", "--rates", "200", "--revolutions", "1",
                 "--dwells", "10", "-o", "extension.yaml"]) == 2
    err = capsys.readouterr().err
    assert "separate rotation_axis_offsets from table_vibration_once_per_rev" in err, err
    assert not (tmp_path / "extension.yaml").exists()
