import math

import pytest

from station.errors import UserError
from station.scheme import RotationSpec, StaticSpec, builtin_names, load_scheme


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
