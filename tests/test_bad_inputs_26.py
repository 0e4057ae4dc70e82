"""Issue 26, item 5: bad inputs that were tracebacks, hangs or a way to run code.  Every one is
one line naming the file, line, field or option and exit status 2 (docs/reliability.md)."""
import os
import sys
from pathlib import Path

import pytest
import yaml

from station.cli import main
from test_bad_inputs import capture_dir, one_line_exit_2, run_child  # noqa: F401 - fixtures

DEEP = "a: " + "[" * 3000 + "]" * 3000 + "\n"
DEEP_BLOCK = "a:\n" + "".join(" " * i + "-\n" for i in range(1, 400))


# ------------------------------------------------------------------ deeply nested YAML

@pytest.mark.parametrize("text", [DEEP, DEEP_BLOCK], ids=["flow", "block"])
@pytest.mark.parametrize("argv", [
    ["plan", "--scheme", "{f}"],
    ["plan", "--config", "{f}"],
    ["plan", "--reveals", "--sim-truth", "{f}"],
    ["sim", "serve", "--faults", "{f}"],
    ["export", "{cal}", "--to", "kalibr", "--noise", "{f}", "-o", "{out}"],
], ids=["scheme", "station.yaml", "sim-truth", "faults", "noise"])
def test_deeply_nested_yaml_is_one_line_naming_the_file(capture_dir, tmp_path, capsys, argv, text):
    deep = tmp_path / "deep.yaml"
    deep.write_text(text)
    argv = [a.format(f=deep, cal=capture_dir / "calibration.yaml", out=tmp_path / "k.yaml") for a in argv]
    one_line_exit_2(argv, capsys, str(deep), "deeper than")


# ------------------------------------------------------------------ schemes

@pytest.mark.parametrize("defaults", ["[1, 2]", "5", "abc"])
def test_scheme_defaults_not_a_mapping(tmp_path, capsys, defaults):
    scheme = tmp_path / "s.yaml"
    scheme.write_text(f"name: s\ndefaults: {defaults}\nsegments:\n  - static: a\n    up_body: [0, 0, 1]\n"
                      "    dwell_s: 1\n")
    one_line_exit_2(["plan", "--scheme", scheme], capsys, str(scheme), "defaults", "mapping")


@pytest.mark.parametrize("entry, key", [("{static: a, up_body: [0, 0, 1], duration_s: 31}", "duration_s"),
                                        ("{rotation: r, axis_body: [0, 0, 1], rate_dps: 10, rotation_s: 36, dwell_s: 5}",
                                         "dwell_s"),
                                        ("{static: a, up_body: [0, 0, 1], dwell_s: 5, heading: 90}", "heading")])
def test_a_segment_field_the_scheme_does_not_know_is_refused(tmp_path, capsys, entry, key):
    """Found by the thirteenth session: a key a segment does not have (``duration_s`` on a
    static: the dwell is ``dwell_s``) was ignored without a word, and the run was not the one
    asked for."""
    scheme = tmp_path / "s.yaml"
    scheme.write_text(f"name: s\ndefaults: {{dwell_s: 20}}\nsegments:\n  - {entry}\n")
    one_line_exit_2(["plan", "--scheme", scheme], capsys, str(scheme), "segments[0]", f"unknown field '{key}'")


# ------------------------------------------------------------------ import csv / rosbag

@pytest.fixture(scope="module")
def hand_log(tmp_path_factory):
    """A short hand session: (the log as t,ax..gz in s, m/s^2, deg/s; its samples)."""
    from test_import_recordings import session, write_csv
    _, hs = session(poses=4, dwell_s=(2.5, 3.0))
    path = tmp_path_factory.mktemp("log") / "log.csv"
    return write_csv(path, hs), hs


@pytest.mark.parametrize("options, words", [
    (["--time-unit", "ns"], ["--time-unit", "samples per second"]),
    (["--rate-hz", "1e300", "--columns", "ax=1,ay=2,az=3,gx=4,gy=5,gz=6"], ["--rate-hz", "samples per second"]),
    (["--rate-hz", "1e-300", "--columns", "ax=1,ay=2,az=3,gx=4,gy=5,gz=6"], ["--rate-hz", "samples per second"]),
    (["--window-s", "1e300"], ["--window-s"]),
    (["--init-rest-s", "1e300"], ["--init-rest-s"]),
])
def test_import_csv_time_base_far_off_is_refused_before_allocating(hand_log, tmp_path, capsys, options, words):
    log, _ = hand_log
    one_line_exit_2(["import", "csv", log, "-o", tmp_path / "cap", *options], capsys, str(log), *words)
    assert not (tmp_path / "cap").exists()


@pytest.mark.parametrize("kind", ["csv", "rosbag"])
def test_import_of_a_fifo_does_not_hang(tmp_path, capsys, kind):
    """import csv in a real process (a hang is the child's, ended by the timeout); import rosbag
    in this one, under an alarm that interrupts a blocked open() (as the YAML inputs' test)."""
    fifo = tmp_path / "log.bag"
    os.mkfifo(fifo)
    argv = ["import", kind, fifo, "-o", tmp_path / "cap"]
    if kind == "csv":
        done = run_child(argv, timeout=60)
        assert done.returncode == 2 and "not a regular file" in done.stderr and str(fifo) in done.stderr, done.stderr
        assert done.stderr.count("\n") == 1
        return
    from processes import time_limit
    with time_limit(30):            # (the refusal takes milliseconds; 30 s is a hang on a machine loaded 10x)
        one_line_exit_2(argv, capsys, "not a regular file", str(fifo))


@pytest.mark.parametrize("kind", ["fifo", "device"])
@pytest.mark.parametrize("argv, what", [
    (["plan", "--scheme", "{f}"], "scheme file"),
    (["plan", "--config", "{f}"], "the configuration"),
    (["export", "{cal}", "--to", "kalibr", "--noise", "{f}", "-o", "{out}"], "noise file"),
    (["run", "--sim", "--scheme", "{scheme}", "--sim-truth", "{f}", "--out", "{out}"], "truth file"),
    (["sim", "serve", "--faults", "{f}"], "faults file"),
], ids=["scheme", "station.yaml", "noise", "sim-truth", "faults"])
def test_a_fifo_or_device_given_as_a_yaml_input_is_refused_not_read(capture_dir, tmp_path, capsys, argv, what, kind):
    """Found in the thirteenth session's walk (benchmarks/walk_issue26.py): these five hung on a
    FIFO (open() waits for a writer) after the imports had been guarded.  In this process, an
    alarm as the guard (it interrupts a blocked open(): the old code fails with Hang)."""
    from processes import time_limit
    from test_bad_inputs import SCHEME
    scheme = tmp_path / "small.yaml"
    scheme.write_text(SCHEME)
    f = tmp_path / "input.yaml"
    if kind == "fifo":
        os.mkfifo(f)
    else:
        f = Path("/dev/zero")
    argv = [a.format(f=f, cal=capture_dir / "calibration.yaml", out=tmp_path / "out", scheme=scheme) for a in argv]
    with time_limit(30):            # (the refusal takes milliseconds; 30 s is a hang on a machine loaded 10x)
        one_line_exit_2(argv, capsys, "not a regular file", str(f), what)


def test_a_fifo_in_a_run_capture_is_refused_by_resume(capture_dir, tmp_path):
    import shutil
    cap = Path(shutil.copytree(capture_dir, tmp_path / "cap"))
    os.mkfifo(cap / "run.yaml")
    done = run_child(["run", "--resume", cap, "--port", "/dev/null", "--table-port", "/dev/null"], timeout=60)
    assert done.returncode == 2 and "not a regular file" in done.stderr and "run.yaml" in done.stderr, done.stderr


def test_ros1_bag_with_flipped_bytes_is_one_line(hand_log, tmp_path, capsys):
    import numpy as np
    from station.io.importers.rosbag import write_imu_bag
    _, hs = hand_log
    bag = write_imu_bag(tmp_path / "good.bag", hs.t, hs.accel, np.radians(hs.gyro), fmt="rosbag1")
    data = bytearray(bag.read_bytes())
    rng = np.random.default_rng(3)
    failures = 0
    for trial in range(60):       # (before the guard, some of these were tracebacks: AssertionError, UnicodeDecodeError, KeyError)
        bad = bytearray(data)
        for i in rng.integers(0, len(bad), int(rng.integers(1, 4))):
            bad[i] ^= int(rng.integers(1, 256))
        path = tmp_path / f"bad{trial}.bag"
        path.write_bytes(bad)
        capsys.readouterr()
        code = main(["import", "rosbag", str(path), "-o", str(tmp_path / f"cap{trial}")])
        err = capsys.readouterr().err
        assert code in (0, 2) and "Traceback" not in err, err
        if code == 2:
            assert err.count("\n") == 1 and str(path) in err, err
            failures += 1
    assert failures


@pytest.mark.parametrize("columns", ["t=0,ax=1,ay=1,az=1,gx=4,gy=5,gz=6", "t=t,ax=ax,ay=1,az=3,gx=4,gy=5,gz=6",
                                     "t=0,ax=0,ay=2,az=3,gx=4,gy=5,gz=6"])
def test_import_csv_one_column_for_two_roles_is_refused(hand_log, tmp_path, capsys, columns):
    log, _ = hand_log
    one_line_exit_2(["import", "csv", log, "-o", tmp_path / "cap", "--columns", columns], capsys,
                    "--columns", str(log), "own column")


# ------------------------------------------------------------------ files written

@pytest.mark.parametrize("command", ["run", "import"])
@pytest.mark.parametrize("target", ["dangling", "file"])
def test_output_directory_on_a_dangling_symlink_or_a_file(tmp_path, capsys, target, command):
    from test_bad_inputs import SCHEME
    out = tmp_path / "out"
    if target == "dangling":
        out.symlink_to(tmp_path / "nowhere" / "x")
    else:
        out.write_text("precious\n")
    if command == "run":
        scheme = tmp_path / "small.yaml"
        scheme.write_text(SCHEME)
        argv = ["run", "--sim", "--scheme", scheme, "--out", out]
    else:
        from test_import_recordings import session, write_csv
        _, hs = session(poses=12)
        argv = ["import", "csv", write_csv(tmp_path / "log.csv", hs), "-o", out]
    one_line_exit_2(argv, capsys, str(out), "capture directory")
    assert not (tmp_path / "nowhere").exists()
    assert out.is_symlink() if target == "dangling" else out.read_text() == "precious\n"


@pytest.mark.parametrize("command", ["apply", "report"])
@pytest.mark.parametrize("link", ["dangling", "folder", "loop"])
def test_output_file_on_a_symbolic_link_that_cannot_be_written_says_what_the_link_is(
        capture_dir, tmp_path, capsys, command, link):
    """apply -o and report -o write through a symbolic link as the shell's > does; one that
    cannot be written through is named with where it points and why (it was "cannot write: No
    such file or directory" about a path that ls shows)."""
    out = tmp_path / "out"
    if link == "dangling":
        out.symlink_to(tmp_path / "nowhere" / "x.csv")
        why = f"whose folder {tmp_path / 'nowhere'} does not exist"
    elif link == "folder":
        out.symlink_to(tmp_path)
        why = "which is a folder"
    else:
        out.symlink_to(tmp_path / "other")
        (tmp_path / "other").symlink_to(out)
        why = "loop of symbolic links"
    argv = (["apply", capture_dir / "calibration.yaml", capture_dir / "pos01.csv", "-o", out] if command == "apply"
            else ["report", capture_dir, "--no-auto", "-o", out])
    one_line_exit_2(argv, capsys, f"{out}: cannot write", "symbolic link to", why)
    assert out.is_symlink() and not (tmp_path / "nowhere").exists()


@pytest.mark.parametrize("command", ["apply", "report"])
def test_output_file_on_a_symbolic_link_is_written_through_it(capture_dir, tmp_path, capsys, command):
    out, target = tmp_path / "out", tmp_path / "kept" / "result"
    target.parent.mkdir()
    out.symlink_to(target)
    argv = (["apply", capture_dir / "calibration.yaml", capture_dir / "pos01.csv", "-o", out] if command == "apply"
            else ["report", capture_dir, "--no-auto", "-o", out])
    assert main([str(a) for a in argv]) == 0
    assert out.is_symlink() and target.stat().st_size > 0


# ------------------------------------------------------------------ the calibration history

@pytest.fixture
def filed(capture_dir, tmp_path):
    """A store with the capture's calibration filed as #1 and a later one (of another capture:
    a re-estimate of the same capture and model is not filed twice) as #2."""
    import sqlite3
    store = tmp_path / "store"
    cal = capture_dir / "calibration.yaml"
    other = tmp_path / "other.yaml"
    doc = yaml.safe_load(cal.read_text())
    doc["provenance"]["date_utc"] = "2030-01-01T00:00:00Z"
    doc["provenance"]["capture_sha256"] = "d" * 64
    other.write_text(yaml.safe_dump(doc, sort_keys=False))
    assert main(["history", "--store", str(store), "--add", str(cal), "--add", str(other)]) == 0
    serial = sqlite3.connect(store / "index.sqlite").execute("SELECT serial FROM calibrations").fetchone()[0]
    return store, serial


def _commands(store, serial, cal):
    s = ["--store", store]
    return [["history", *s], ["history", serial, *s], ["diff", "#1", "#2", *s], ["history", *s, "--add", cal]]


@pytest.mark.parametrize("damage", ["garbage", "truncated", "foreign", "types"])
def test_damaged_or_foreign_history_index_is_one_line(filed, capture_dir, tmp_path, capsys, damage):
    import sqlite3
    store, serial = filed
    index = store / "index.sqlite"
    if damage == "garbage":
        index.write_bytes(os.urandom(8192))
    elif damage == "truncated":
        index.write_bytes(index.read_bytes()[:1500])
    elif damage == "foreign":
        index.unlink()
        db = sqlite3.connect(index)
        db.execute("CREATE TABLE calibrations (id INTEGER PRIMARY KEY, name TEXT)")
        db.execute("INSERT INTO calibrations (name) VALUES ('x')")
        db.commit()
        db.close()
    else:
        db = sqlite3.connect(index)
        db.execute("UPDATE calibrations SET file = 7, date_utc = x'00ff'")
        db.commit()
        db.close()
    capsys.readouterr()
    for argv in _commands(store, serial, capture_dir / "calibration.yaml"):
        code = main([str(a) for a in argv])
        err = capsys.readouterr().err
        assert "Traceback" not in err and err.count("\n") <= 1, err
        if code != 0:
            assert code == 2 and str(index) in err, (argv, err)
    # estimate files quietly: a warning, never a failure
    assert main(["estimate", str(capture_dir), "-o", str(tmp_path / "again.yaml")]) == 0


@pytest.mark.parametrize("file", ["/etc/passwd", "../outside.yaml", "{outside}", "link/out.yaml"])
def test_a_tampered_history_row_cannot_open_a_file_outside_the_store(filed, tmp_path, capsys, file):
    import sqlite3
    store, serial = filed
    outside = tmp_path / "outside.yaml"
    outside.write_text((store.parent / "other.yaml").read_text())
    (store / "link").symlink_to(tmp_path)
    db = sqlite3.connect(store / "index.sqlite")
    db.execute("UPDATE calibrations SET file = ? WHERE id = 2", (file.format(outside=outside),))
    db.commit()
    db.close()
    for argv in (["diff", "#1", "#2", "--store", store], ["history", serial, "--store", store, "--drift", tmp_path / "d.png"]):
        one_line_exit_2(argv, capsys, str(store / "index.sqlite"), "row #2", "field 'file'", "inside the store")


def test_history_drift_without_a_serial_says_what_it_needs(filed, tmp_path, capsys):
    """Found by the thirteenth session's walk: `history --drift PNG` without SERIAL exited 0 and
    drew nothing."""
    store, serial = filed
    one_line_exit_2(["history", "--store", store, "--drift", tmp_path / "d.png"], capsys, "--drift", "SERIAL")
    assert not (tmp_path / "d.png").exists()


# ------------------------------------------------------------------ calibration files

def _edited_calibration(capture_dir, tmp_path, change):
    doc = yaml.safe_load((capture_dir / "calibration.yaml").read_text())
    change(doc)
    path = tmp_path / "edited.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def _without_gyro_parameters(doc):
    doc["parameters"] = {k: v for k, v in doc["parameters"].items() if not k.startswith("gyro_")}


@pytest.mark.parametrize("change, words", [
    (lambda d: d["compensation"].update(accel_matrix=[[0, 0, 0] for _ in range(3)]), ["compensation.accel_matrix", "singular"]),
    (lambda d: d["compensation"].update(gyro_matrix=[[1, 2, 3], [2, 4, 6], [0, 0, 1]]),
     ["compensation.gyro_matrix", "singular"]),
    (lambda d: d["parameters"]["accel_bias_x"].update(sigma=float("nan")), ["parameters.accel_bias_x", "sigma"]),
    (lambda d: d["parameters"]["accel_bias_x"].update(sigma=-1.0), ["parameters.accel_bias_x", "sigma"]),
    (lambda d: d["parameters"]["gyro_scale_x"].update(sigma=float("inf")), ["parameters.gyro_scale_x", "sigma"]),
    (_without_gyro_parameters, ["field 'parameters'", "gyro_scale_x", "compensation.gyro_matrix"]),
    # found by tests/test_fuzz_consumers.py (thirteenth session): show divided by it (ZeroDivisionError)
    (lambda d: d["parameters"]["gyro_scale_y"].update(value=0.0), ["parameters.gyro_scale_y.value", "scale factor of 0"]),
    (lambda d: d["parameters"]["accel_scale_x"].update(value=0), ["parameters.accel_scale_x.value", "scale factor of 0"]),
    # the walk (benchmarks/walk_issue26.py): a matrix of 1e-308s (well conditioned, compensating
    # into nothing) beside scale factors near 1, and a scale factor edited beside its matrix
    (lambda d: d["compensation"].update(accel_matrix=[[1e-308, 0, 0], [0, 1e-308, 0], [0, 0, 1e-308]]),
     ["parameters.accel_scale_x.value", "disagrees with 'compensation.accel_matrix'"]),
    (lambda d: d["parameters"]["gyro_scale_z"].update(value=d["parameters"]["gyro_scale_z"]["value"] * 1.0001),
     ["parameters.gyro_scale_z.value", "disagrees with 'compensation.gyro_matrix'"]),
], ids=["zero-accel-matrix", "singular-gyro-matrix", "nan-sigma", "negative-sigma", "inf-sigma", "gyro-params-removed",
        "zero-gyro-scale", "zero-accel-scale", "tiny-accel-matrix", "gyro-scale-edited"])
def test_calibration_file_inconsistent_is_refused_by_every_reader(capture_dir, tmp_path, capsys, change, words):
    import warnings
    warnings.simplefilter("error", RuntimeWarning)      # (numpy's overflow warning was a second line)
    cal = _edited_calibration(capture_dir, tmp_path, change)
    for argv in (["show", cal], ["apply", cal, capture_dir / "pos01.csv", "-o", tmp_path / "o.csv"],
                 ["export", cal, "--to", "imu_tk", "-o", tmp_path / "x"], ["diff", cal, capture_dir / "calibration.yaml"]):
        one_line_exit_2(argv, capsys, str(cal), *words)
    assert not list(tmp_path.glob("o.csv*")) and not list(tmp_path.glob("x*"))


BIG = 10 ** 400         # an integer no float holds (YAML reads 400 digits as a Python int)


@pytest.mark.parametrize("where", ["parameters.inter_triad_y.sigma", "parameters.accel_bias_x.value",
                                   "compensation.accel_bias.0"])
def test_an_integer_beyond_every_float_in_a_calibration_is_one_line(capture_dir, tmp_path, capsys, where):
    """Found by tests/test_fuzz_consumers.py (thirteenth session): ``OverflowError: int too large
    to convert to float`` from the readers' finite checks."""
    def change(doc):
        *path, last = where.split(".")
        target = doc
        for key in path:
            target = target[key]
        target[int(last) if last.isdigit() else last] = BIG
    cal = _edited_calibration(capture_dir, tmp_path, change)
    for argv in (["show", cal], ["export", cal, "--to", "json", "-o", tmp_path / "x.json"]):
        one_line_exit_2(argv, capsys, str(cal))


@pytest.mark.parametrize("field", ["gravity_mps2", "latitude_deg"])
def test_an_integer_beyond_every_float_in_a_manifest_is_one_line(capture_dir, tmp_path, capsys, field):
    import shutil
    from test_bad_inputs import edit_manifest
    cap = Path(shutil.copytree(capture_dir, tmp_path / "cap"))
    edit_manifest(cap, lambda d: d["site"].update({field: -BIG}))
    one_line_exit_2(["estimate", cap, "-o", tmp_path / "c.yaml"], capsys, "manifest.yaml", field)


# ------------------------------------------------------------------ plugins only from where the user named them

EVIL = """import pathlib
pathlib.Path({marker!r}).write_text("ran")
from station.model.effect import Effect
"""


def _bundle_with_station_yaml(capture_dir, tmp_path):
    """A downloaded capture bundle that ships a station.yaml listing a plugin of its own."""
    import shutil
    cap = Path(shutil.copytree(capture_dir, tmp_path / "download"))
    marker = tmp_path / "ran.txt"
    (cap / "evil.py").write_text(EVIL.format(marker=str(marker)))
    (cap / "station.yaml").write_text("effects:\n  plugins: [evil.py]\n")
    return cap, marker


@pytest.mark.parametrize("command", ["estimate", "diagnose", "apply", "effects"])
def test_a_station_yaml_in_the_working_directory_runs_no_code(capture_dir, tmp_path, monkeypatch, capsys, command):
    cap, marker = _bundle_with_station_yaml(capture_dir, tmp_path)
    monkeypatch.chdir(cap)
    argv = {"estimate": ["estimate", ".", "-o", str(tmp_path / "c.yaml")], "diagnose": ["diagnose", "."],
            "apply": ["apply", "calibration.yaml", "pos01.csv", "-o", str(tmp_path / "o.csv")],
            "effects": ["effects"]}[command]
    capsys.readouterr()
    assert main(argv) == 0
    assert not marker.exists()
    assert "./station.yaml names effect plugins: not loaded" in capsys.readouterr().err
    # named, it is the user's choice: loaded (this one defines no effect: exit 2 after running it)
    assert main(argv + ["--config", "station.yaml"]) == 2 and marker.exists()


@pytest.mark.parametrize("how", ["env", "user-config-dir"])
def test_plugins_of_a_configuration_the_user_named_or_owns_are_loaded(capture_dir, tmp_path, monkeypatch, capsys, how):
    cap, marker = _bundle_with_station_yaml(capture_dir, tmp_path)
    if how == "env":
        monkeypatch.setenv("STATION_CONFIG", str(cap / "station.yaml"))
    else:
        monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "config"))
        (tmp_path / "config" / "station").mkdir(parents=True)
        (tmp_path / "config" / "station" / "station.yaml").write_text(f"effects:\n  plugins: [{cap / 'evil.py'}]\n")
    monkeypatch.chdir(tmp_path)
    one_line_exit_2(["effects"], capsys, "evil.py", "no subclass")
    assert marker.exists()


def test_station_run_still_reads_the_bench_from_an_implicit_station_yaml(tmp_path, monkeypatch):
    from station.bench.config import load_config
    monkeypatch.chdir(tmp_path)
    (tmp_path / "station.yaml").write_text("table:\n  axes: 2\neffects:\n  plugins: [evil.py]\n")
    assert load_config(None).table.axes == 2


# ------------------------------------------------------------------ temporaries left by a kill

def test_stale_temporary_calibration_files_are_removed_safely(capture_dir, tmp_path):
    import subprocess
    out = tmp_path / "out"
    out.mkdir()
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    hexes = iter(f"{i:016x}" for i in range(1, 100))
    stale = [f".cal.yaml.{dead.pid}_{next(hexes)}.tmp",            # its writer is gone
             f".cal.yaml.{os.getpid()}_{next(hexes)}.tmp",          # a live pid, but two hours old
             f".cal.yaml.{next(hexes)}.tmp"]                         # an older version's, two hours old
    kept = [f".cal.yaml.{os.getpid()}_{next(hexes)}.tmp",           # a live writer's, fresh
            f".cal.yaml.{next(hexes)}.tmp",                          # an older version's, fresh
            f".other.yaml.{dead.pid}_{next(hexes)}.tmp",            # another file's
            ".cal.yaml.notes.tmp", "cal.yaml.tmp"]                  # not our pattern
    for name in stale + kept:
        (out / name).write_text("half a calibration")
    for name in stale[1:]:
        os.utime(out / name, (os.path.getmtime(out / name) - 7200,) * 2)
    precious = tmp_path / "precious.txt"
    precious.write_text("precious\n")
    link = out / f".cal.yaml.{dead.pid}_{next(hexes)}.tmp"           # a link of our pattern: never followed
    link.symlink_to(precious)
    os.utime(link, (0, 0), follow_symlinks=False)
    assert main(["estimate", str(capture_dir), "-o", str(out / "cal.yaml")]) == 0
    left = sorted(p.name for p in out.iterdir())
    assert left == sorted(kept + [link.name, "cal.yaml"]), left
    assert precious.read_text() == "precious\n"


@pytest.mark.parametrize("what", ["deep", "fifo", "month-13"])
def test_import_sections_file_deep_fifo_or_bad_date(hand_log, tmp_path, capsys, what):
    """The FIFO in a real process (a hang there is the child's, ended by the timeout); the deep and
    the bad-date files in this one (nothing of them can hang or take the process down: one line,
    exit status 2, as test_deeply_nested_yaml_is_one_line_naming_the_file checks the others)."""
    log, _ = hand_log
    sections = tmp_path / "sections.yaml"
    argv = ["import", "csv", log, "--segments", sections, "-o", tmp_path / "cap"]
    if what == "fifo":
        os.mkfifo(sections)
        done = run_child(argv, timeout=60)
        assert done.returncode == 2 and str(sections) in done.stderr and done.stderr.count("\n") == 1, done.stderr
        return
    from processes import time_limit
    sections.write_text(DEEP if what == "deep" else "- {name: a, kind: static, start: 2026-13-01}\n")
    with time_limit(30):            # (the refusal takes milliseconds; 30 s is a hang on a machine loaded 10x)
        one_line_exit_2(argv, capsys, str(sections))


@pytest.mark.parametrize("argv", [["plan", "--scheme", "{f}"], ["plan", "--config", "{f}"],
                                  ["sim", "serve", "--faults", "{f}"]], ids=["scheme", "config", "faults"])
def test_a_timestamp_in_month_13_is_one_line(tmp_path, capsys, argv):
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: 2026-13-01\n")
    one_line_exit_2([a.format(f=bad) for a in argv], capsys, str(bad), "not valid YAML")
