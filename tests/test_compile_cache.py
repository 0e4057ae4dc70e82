"""Compiled plans kept in the user's cache folder (station/bench/compile_cache.py, issue 26):
`station schemes` and `station plan` print exactly what they print without the cache, for every
built-in scheme and a user's scheme; a scheme, configuration or compiler changed misses; a
damaged or foreign cache file is a miss and never runs code."""
import os
import pickle

import pytest

from station.bench import compile as compile_module
from station.bench import compile_cache
from station.cli import main

USER_SCHEME = """\
name: my5
title: five statics and one rotation of a user's own
defaults:
  dwell_s: 30.0
  rotation_s: 36.0
segments:
  - {static: zup, up_body: [0, 0, 1]}
  - {static: zdown, up_body: [0, 0, -1]}
  - {static: xup, up_body: [1, 0, 0]}
  - {static: yup, up_body: [0, 1, 0]}
  - {static: tilt, up_body: [1, 1, 1]}
  - {rotation: rz, axis_body: [0, 0, 1], rate_dps: 20}
"""


def _out(capsys, argv):
    assert main(argv) == 0
    c = capsys.readouterr()
    return c.out, c.err


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("STATION_CACHE_DIR", str(tmp_path / "cache"))
    return tmp_path / "cache" / "plans"


def _no_compiling(monkeypatch):
    def refuse(*a, **k):
        raise AssertionError("compiled although cached")
    monkeypatch.setattr(compile_module, "compile_scheme", refuse)


def test_schemes_prints_the_same_without_cache_cold_and_warm(cache, capsys, monkeypatch):
    monkeypatch.setenv("STATION_CACHE_DIR", "off")
    without = _out(capsys, ["schemes"])
    monkeypatch.setenv("STATION_CACHE_DIR", str(cache.parent))
    cold = _out(capsys, ["schemes"])
    assert len(list(cache.glob("*.plan"))) == 7          # one per built-in scheme, screwdriver's refusal too
    with monkeypatch.context() as m:
        _no_compiling(m)
        warm = _out(capsys, ["schemes"])
    assert cold == without and warm == without
    assert "screwdriver" in without[1]                  # the refusal's note, from the cache too


def test_plan_of_a_user_scheme_is_the_same_and_an_edit_misses(cache, capsys, monkeypatch, tmp_path):
    path = tmp_path / "my5.yaml"
    path.write_text(USER_SCHEME)
    monkeypatch.setenv("STATION_CACHE_DIR", "off")
    without = _out(capsys, ["plan", "--scheme", str(path), "--all"])
    monkeypatch.setenv("STATION_CACHE_DIR", str(cache.parent))
    assert _out(capsys, ["plan", "--scheme", str(path), "--all"]) == without
    with monkeypatch.context() as m:
        _no_compiling(m)
        assert _out(capsys, ["plan", "--scheme", str(path), "--all"]) == without
    # an edited scheme (one dwell longer) is another key: compiled again, not the old plan
    path.write_text(USER_SCHEME.replace("{static: zup, up_body: [0, 0, 1]}",
                                        "{static: zup, up_body: [0, 0, 1], dwell_s: 31}"))
    edited = _out(capsys, ["plan", "--scheme", str(path), "--all"])
    assert edited != without and len(list(cache.glob("*.plan"))) == 2
    # so is an override on the command line
    with monkeypatch.context() as m:
        _no_compiling(m)
        with pytest.raises(AssertionError, match="compiled although cached"):
            main(["plan", "--scheme", str(path), "--dwell-s", "40"])


def test_a_changed_compiler_misses(cache, monkeypatch):
    from station.bench.config import load_config
    from station.io.scheme import load_scheme

    sch, cfg = load_scheme("sizeeffect"), load_config(None)
    k = compile_cache.key(sch, cfg)
    monkeypatch.setattr(compile_cache, "_code_digest", b"another compiler")
    assert compile_cache.key(sch, cfg) != k


def test_a_damaged_or_foreign_cache_file_is_a_miss_and_runs_nothing(cache, capsys, monkeypatch, tmp_path):
    from station.bench.config import load_config
    from station.io.scheme import load_scheme

    monkeypatch.setenv("STATION_CACHE_DIR", "off")
    without = _out(capsys, ["plan", "--scheme", "sizeeffect"])
    monkeypatch.setenv("STATION_CACHE_DIR", str(cache.parent))
    _out(capsys, ["plan", "--scheme", "sizeeffect"])
    (entry,) = cache.glob("*.plan")
    assert entry.name == f"{compile_cache.key(load_scheme('sizeeffect'), load_config(None))}.plan"
    marker = tmp_path / "ran"

    class Evil:
        def __reduce__(self):
            return (os.system, (f"touch {marker}",))

    for damaged in (b"", b"station-plan/1\n" + b"\x80\x05garbage", entry.read_bytes()[:200],
                    b"station-plan/1\n" + pickle.dumps(("plan", Evil())), pickle.dumps(("plan", Evil()))):
        entry.write_bytes(damaged)
        assert _out(capsys, ["plan", "--scheme", "sizeeffect"]) == without
        assert not marker.exists()
        assert entry.read_bytes().startswith(b"station-plan/1\n") and entry.read_bytes() != damaged   # rewritten


def test_an_unwritable_cache_folder_is_no_error(tmp_path, capsys, monkeypatch):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    monkeypatch.setenv("STATION_CACHE_DIR", str(blocker))        # plans/ cannot be made under a file
    out, err = _out(capsys, ["plan", "--scheme", "sizeeffect"])
    assert "total:" in out and err == ""


def test_the_cache_keeps_the_newest_entries(cache, monkeypatch):
    from station.bench.config import load_config
    from station.io.scheme import load_scheme

    monkeypatch.setattr(compile_cache, "KEEP", 2)
    cfg = load_config(None)
    for dwell in (20, 21, 22, 23):
        compile_cache.compile_cached(load_scheme("sizeeffect", {"dwell_s": dwell}), cfg)
    assert len(list(cache.glob("*.plan"))) == 2
    assert not list(cache.glob(".*.tmp"))
