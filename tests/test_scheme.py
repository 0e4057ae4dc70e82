import math

import pytest

from station.core.errors import UserError
from station.io.scheme import RotationSpec, StaticSpec, builtin_names, load_scheme


def test_optimal9_is_the_papers_scheme():
    s = load_scheme("optimal9")
    statics = [x for x in s.segments if isinstance(x, StaticSpec)]
    rotations = [x for x in s.segments if isinstance(x, RotationSpec)]
    assert len(statics) == 9 and len(rotations) == 12
    ups = {tuple(round(c, 6) for c in x.up_body) for x in statics}
    h = round(1 / math.sqrt(2), 6)
    for axis in range(3):
        for sign in (1, -1):
            v = [0.0, 0.0, 0.0]
            v[axis] = float(sign)
            assert tuple(v) in ups
    assert {(h, h, 0.0), (h, 0.0, h), (0.0, h, h)} <= ups
    assert all(x.dwell_s == 100 for x in statics)
    assert all(abs(x.rate_dps) == 10 and x.duration_s == 180 and x.revolutions == 5 for x in rotations)
    # each axis as a +/- pair, plus first
    assert [x.rate_dps > 0 for x in rotations] == [True, False] * 6
    assert s.duration_s == 9 * 100 + 12 * 180
    assert "optimal9" in builtin_names()


def test_overrides_apply_to_every_segment():
    s = load_scheme("optimal9", {"dwell_s": 10, "rate_dps": 20, "rotation_s": 18})
    assert {x.duration_s for x in s.segments} == {10, 18}
    with pytest.raises(UserError, match="unknown default"):
        load_scheme("optimal9", {"dwell": 10})


@pytest.mark.parametrize("text, message", [
    ("- 1\n", "mapping"),
    ("name: x\n", "missing field 'segments'"),
    ("name: x\nsegments: [{static: a}]\n", "no dwell_s"),
    ("name: x\ndefaults: {dwell_s: 1}\nsegments: [{static: a, up_body: [0, 0]}]\n", r"segments\[0\].up_body"),
    ("name: x\ndefaults: {dwell_s: 1}\nsegments: [{static: a, up_body: [0, 0, 0]}]\n", "zero vector"),
    ("name: x\ndefaults: {dwell_s: -1}\nsegments: [{static: a, up_body: [0, 0, 1]}]\n", "must be > 0"),
    ("name: x\nsegments: [{rotation: r, axis_body: [1, 0, 0], rate_dps: .nan, rotation_s: 1}]\n", "finite"),
    ("name: x\nsegments: [{wobble: a}]\n", "'static' or a 'rotation'"),
    ("name: x\ndefaults: {dwell_s: 1}\nsegments: [{static: a, up_body: [0, 0, 1]}, {static: a, up_body: [0, 0, 1]}]\n",
     "duplicate"),
    ("name: [unclosed\n", "not valid YAML"),
])
def test_bad_scheme_files_are_refused_naming_the_field(tmp_path, text, message):
    path = tmp_path / "s.yaml"
    path.write_text(text)
    with pytest.raises(UserError, match=message) as e:
        load_scheme(str(path))
    assert str(path) in str(e.value)


def test_traditional24_is_the_papers_laboratory_method():
    s = load_scheme("traditional24")
    statics = [x for x in s.segments if isinstance(x, StaticSpec)]
    rotations = [x for x in s.segments if isinstance(x, RotationSpec)]
    assert len(statics) == 24 and len(rotations) == 6 and s.table
    # X, Y, Z up then down; the next axis (X->Y, Y->Z, Z->X) north, west, south, east in order
    for k, spec in enumerate(statics):
        axis, down = k // 8, (k // 4) % 2
        up = [0.0, 0.0, 0.0]
        up[axis] = -1.0 if down else 1.0
        heading = [0.0, 0.0, 0.0]
        heading[(axis + 1) % 3] = 1.0
        assert spec.up_body == tuple(up) and spec.heading_body == tuple(heading), spec.name
        assert spec.heading_deg == (0.0, 270.0, 180.0, 90.0)[k % 4] and spec.dwell_s == 100
    assert [r.axis_body for r in rotations[::2]] == [(1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)]
    assert [r.rate_dps for r in rotations] == [10.0, -10.0] * 3


def test_manual6_is_done_by_hand():
    s = load_scheme("manual6")
    assert s.table is False
    statics = [x for x in s.segments if isinstance(x, StaticSpec)]
    turns = [x for x in s.segments if isinstance(x, RotationSpec)]
    assert sorted(x.up_body for x in statics) == sorted(
        tuple(float(sign) if i == axis else 0.0 for i in range(3)) for axis in range(3) for sign in (1, -1))
    assert [t.axis_body for t in turns] == [(1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)]
    assert all(t.turn_deg == 360 and not t.encoder and t.axis_elevation_deg == 90 for t in turns)
    assert all(load_scheme(n).table for n in builtin_names() if n != "manual6")


@pytest.mark.parametrize("text, message", [
    ("name: x\ndefaults: {dwell_s: 1}\nsegments: [{static: a, up_body: [0, 0, 1], heading_body: [1, 0, 0]}]\n",
     "heading_body and heading_deg go together"),
    ("name: x\ndefaults: {dwell_s: 1}\nsegments: [{static: a, up_body: [0, 0, 1], heading_body: [1, 0, 1], "
     "heading_deg: 0}]\n", r"segments\[0\].heading_body: must be perpendicular"),
    ("name: x\ndefaults: {dwell_s: 1}\nsegments: [{static: a, up_body: [0, 0, 1], heading_body: [1, 0, 0], "
     "heading_deg: 360}]\n", r"heading_deg: must be within \[0, 360\)"),
    ("name: x\ntable: maybe\ndefaults: {dwell_s: 1}\nsegments: [{static: a, up_body: [0, 0, 1]}]\n", "table: must be none"),
    ("name: x\ntable: none\nsegments: [{rotation: r, axis_body: [1, 0, 0], rate_dps: 9, rotation_s: 4}]\n",
     "without a table has no encoder"),
    ("name: x\nsegments: [{rotation: r, axis_body: [1, 0, 0], rate_dps: 9, rotation_s: 4, turn_deg: 360}]\n",
     "turn_deg: only for turns without an encoder"),
])
def test_the_extensions_are_checked(tmp_path, text, message):
    path = tmp_path / "s.yaml"
    path.write_text(text)
    with pytest.raises(UserError, match=message):
        load_scheme(str(path))


def test_station_schemes_lists_segments_and_durations(capsys):
    from station.cli import main

    assert main(["schemes"]) == 0
    out = capsys.readouterr().out
    for name in builtin_names():
        assert name in out
    row = next(line for line in out.splitlines() if "traditional24" in line)
    cells = [c.strip() for c in row.split("│")[1:-1]]
    assert cells[:4] == ["traditional24", "24", "6", "3480"]     # 24 x 100 s + 6 x 180 s of recording
    assert float(cells[4]) > 3480 and cells[5] == "1"            # moves, settling; the mounting check


def test_every_builtin_scheme_by_hand_runs_dry_and_writes_its_turns_as_the_bench_does(tmp_path, capsys):
    """manual6's dry run: its turns written with the protocol's angle and `motion: hand`, as the
    bench writes what a hand did (station/bench/manual.py), and estimated (it ended in exit 2:
    turns without any angle went to the Fourier method, which needs a horizontal shaft)."""
    import yaml

    from station.cli import main

    for name in (n for n in builtin_names() if not load_scheme(n).table):
        out = tmp_path / name
        assert main(["run", "--scheme", name, "--sim", "--out", str(out)]) == 0, capsys.readouterr().err
        turns = [s for s in yaml.safe_load((out / "manifest.yaml").read_text())["segments"] if s["kind"] == "rotation"]
        specs = {s.name: s for s in load_scheme(name).segments}
        assert turns and all(t["motion"] == "hand" and abs(t["angle_deg"]) == specs[t["name"]].turn_deg
                             for t in turns), turns
        assert (out / "calibration.yaml").exists()
