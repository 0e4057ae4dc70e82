"""The capture writer's crash-safety helpers (issue 30 item 6: survivors of mutation testing of
station/io/capture.py's writer): where a segment's file is put aside, the temporary files an
atomic write makes (in the same folder, named so that a later writer finds and removes them if
this one is killed), and what happens to them when the write fails.  Milliseconds each."""
from __future__ import annotations

import os

import pytest

from station.io import capture as C


def test_a_file_put_aside_never_overwrites_an_earlier_one(tmp_path):
    p = tmp_path / "rot1p.csv"
    assert C._aside_name(p) == tmp_path / "rot1p.csv.incomplete"
    (tmp_path / "rot1p.csv.incomplete").write_text("1")
    assert C._aside_name(p) == tmp_path / "rot1p.csv.incomplete2"
    (tmp_path / "rot1p.csv.incomplete2").write_text("2")
    assert C._aside_name(p) == tmp_path / "rot1p.csv.incomplete3"
    (tmp_path / "rot1p.csv.incomplete3").write_text("3")
    assert C._aside_name(p) == tmp_path / "rot1p.csv.incomplete4"
    assert C._aside_name(p, ".unlisted") == tmp_path / "rot1p.csv.unlisted"


def test_stray_temporaries_are_removed_and_named(tmp_path):
    stray = f".manifest.yaml.ab12CD_x{C.TEMP_SUFFIX}"
    (tmp_path / stray).write_text("half a manifest")
    (tmp_path / "keep.csv").write_text("t\n")
    (tmp_path / f".short.ab{C.TEMP_SUFFIX}").write_text("random part too short: not ours")
    assert C.remove_stray_temporaries(tmp_path) == [stray]
    assert sorted(os.listdir(tmp_path)) == sorted(["keep.csv", f".short.ab{C.TEMP_SUFFIX}"])
    assert C.remove_stray_temporaries(tmp_path / "missing") == []


def test_an_atomic_write_goes_through_a_temporary_a_later_writer_would_remove(tmp_path, monkeypatch):
    path = tmp_path / "manifest.yaml"
    path.write_text("old")
    seen = []
    real = os.replace

    def replace(src, dst):
        seen.append(os.fspath(src))
        assert open(src, "rb").read() == b"new"
        return real(src, dst)
    monkeypatch.setattr(C.os, "replace", replace)
    C._atomic_write(path, b"new")
    assert path.read_bytes() == b"new"
    tmp = seen[0]
    assert os.path.dirname(tmp) == str(tmp_path)                 # the same folder: a rename, not a copy
    name = os.path.basename(tmp)
    assert name.startswith(".manifest.yaml.") and C._TEMP_NAME.fullmatch(name)
    assert sorted(os.listdir(tmp_path)) == ["manifest.yaml"]


def test_a_failed_atomic_write_leaves_the_old_file_and_no_temporary(tmp_path, monkeypatch):
    path = tmp_path / "manifest.yaml"
    path.write_text("old")

    def fail(src, dst):
        raise OSError("replace failed")
    monkeypatch.setattr(C.os, "replace", fail)
    with pytest.raises(OSError, match="^replace failed$"):
        C._atomic_write(path, b"new")
    assert path.read_text() == "old" and os.listdir(tmp_path) == ["manifest.yaml"]

    def fail_after_removing(src, dst):          # the temporary already gone: the first error stands
        os.unlink(src)
        raise OSError("replace failed")
    monkeypatch.setattr(C.os, "replace", fail_after_removing)
    with pytest.raises(OSError, match="^replace failed$"):
        C._atomic_write(path, b"new")
    assert os.listdir(tmp_path) == ["manifest.yaml"]
