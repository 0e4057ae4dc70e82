"""Every bad input of issue 11 gives one line naming the file or field and exit status 2, never a
traceback, a hang or a write outside the capture.  One regression test per case; the table of
cases and counts is in docs/reliability.md."""
import hashlib
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from station.cli import main
from station.io.capture import CaptureWriter, read_capture
from station.io.scheme import scheme_from_text
from station.simulate import dryrun
from simhelpers import scheme_yaml

HERE = Path(__file__).resolve().parent
SCHEME = scheme_yaml("small", 5.0)


@pytest.fixture(scope="module")
def capture_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("bad") / "cap"
    dryrun.record_scheme(scheme_from_text(SCHEME, "test"), dryrun.load_truth(None, 5), 5, out)
    assert main(["estimate", str(out)]) == 0
    return out


@pytest.fixture
def cap(capture_dir, tmp_path):
    return Path(shutil.copytree(capture_dir, tmp_path / "cap"))


def one_line_exit_2(argv, capsys, *words):
    capsys.readouterr()
    assert main([str(a) for a in argv]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    for w in words:
        assert w in err, err
    return err


def edit_manifest(cap, change):
    path = cap / "manifest.yaml"
    doc = yaml.safe_load(path.read_text())
    change(doc)
    path.write_text(yaml.safe_dump(doc, sort_keys=False))


def rewrite_csv(cap, name, change):
    doc = yaml.safe_load((cap / "manifest.yaml").read_text())
    entry = next(e for e in doc["segments"] if e["name"] == name)
    path = cap / entry["file"]
    lines = path.read_text().splitlines()
    text = "\n".join(change(lines)) + "\n"
    path.write_text(text)
    entry["sha256"] = hashlib.sha256(text.encode()).hexdigest()
    (cap / "manifest.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))


def run_child(argv, timeout=120):
    """station in a child process (for inputs that used to hang; the timeout only guards)."""
    return subprocess.run([sys.executable, "-m", "station.cli", *map(str, argv)], capture_output=True,
                          text=True, timeout=timeout, cwd=HERE)


# ------------------------------------------------------------------ estimation that broke down

def test_coarse_quantisation_is_refused_naming_file_and_column(cap, capsys):
    def quantise(lines):       # 0.05 m/s^2 steps: far above the accelerometer noise
        out = [lines[0]]
        for line in lines[1:]:
            v = line.split(",")
            v[1:4] = [f"{round(float(x) / 0.05) * 0.05:.6g}" for x in v[1:4]]
            out.append(",".join(v))
        return out
    rewrite_csv(cap, "pos01", quantise)
    one_line_exit_2(["estimate", cap], capsys, "pos01.csv", "column 'ax'", "quantised")


@pytest.mark.parametrize("where, value, words", [
    ("csv", "1e300", ["pos02.csv", "line 2", "column 'ax'", "out of range"]),
    ("gravity", 1e300, ["site.gravity_mps2"]),
    ("gravity", 1.0, ["site.gravity_mps2"]),
    ("rate", 1e300, ["imu.sample_rate_hz"]),
    ("rotation_rate", 1e300, ["rate_dps"]),
    ("axis", [1e300, 0, 0], ["axis_body"]),
    ("angle", -1e300, ["angle_deg"]),
])
def test_huge_finite_numbers_are_refused(cap, capsys, where, value, words):
    if where == "csv":
        rewrite_csv(cap, "pos02", lambda lines: [lines[0], ",".join([lines[1].split(",")[0], value]
                                                                    + lines[1].split(",")[2:])] + lines[2:])
    else:
        def change(doc):
            rot = next(s for s in doc["segments"] if s["kind"] == "rotation")
            if where == "gravity":
                doc["site"]["gravity_mps2"] = value
            elif where == "rate":
                doc["imu"]["sample_rate_hz"] = value
            elif where == "rotation_rate":
                rot["rate_dps"] = value
            elif where == "axis":
                rot["axis_body"] = value
            else:
                rot["angle_deg"] = value
        edit_manifest(cap, change)
    one_line_exit_2(["estimate", cap], capsys, *words)


def test_effects_on_a_raw_capture_are_scaled_to_counts_not_refused(cap, capsys):
    """(tests/test_effects_raw_counts.py checks the values on a capture in counts)"""
    edit_manifest(cap, lambda d: d["imu"].update(accel_unit="raw", gyro_unit="raw"))
    assert main(["estimate", str(cap), "--add", "accel_nonlinearity", "--accept-poor-fit"]) == 0
    assert "Traceback" not in capsys.readouterr().err


def test_statics_only_with_add_and_diagnose_auto_are_not_tracebacks(cap, capsys):
    def statics_only(doc):
        doc["segments"] = [s for s in doc["segments"] if s["kind"] == "static"]
        doc["site"].pop("latitude_deg")
    edit_manifest(cap, statics_only)
    assert main(["estimate", str(cap), "--add", "accel_nonlinearity"]) == 0
    assert main(["diagnose", str(cap), "--auto"]) in (0, 2)
    assert "Traceback" not in capsys.readouterr().err


# ------------------------------------------------------------------ calibration files

@pytest.mark.parametrize("content, words", [
    (b"format: station-calibration/1\nnote: \xff\xfe\n", ["not UTF-8"]),
    ("effects: 5", ["field 'effects'"]),
    ("parameters: [1, 2]", ["field 'parameters'"]),
    ("parameters: {a: {value: 1e300e, unit: x}}", ["parameters.a"]),
    ('parameters: {"a\\nb": 5}', ["parameters.a\\nb"]),       # a name with a line end: shown escaped
    ("compensation: {accel_matrix: 5}", ["compensation.accel_matrix"]),
    ("compensation: {accel_matrix: [[1e300, 0, 0], [0, 1, 0], [0, 0, 1]]}", ["compensation.accel_matrix"]),
    ("provenance: {imu_serial: [1, 2]}", ["field 'provenance'"]),
    ("imu: {accel_unit: furlongs}", ["imu.accel_unit"]),
    ("verdict: 7", ["field 'verdict'"]),
    ('x: &a ["lol", "lol"]\ny: &b [*a, *a]\nprovenance: {imu_serial: *b}', ["aliases"]),
])
def test_bad_calibration_files_are_one_line(capture_dir, tmp_path, capsys, content, words):
    good = yaml.safe_load((capture_dir / "calibration.yaml").read_text())
    bad = tmp_path / "bad.yaml"
    if isinstance(content, bytes):
        bad.write_bytes(content)
    else:
        patch = yaml.safe_load(content.replace("&a", "").replace("&b", "").replace("*a", "1").replace("*b", "1"))
        doc = {**good, **{k: ({**good[k], **v} if isinstance(v, dict) and isinstance(good.get(k), dict)
                              else v) for k, v in patch.items()}}
        text = yaml.safe_dump(doc, sort_keys=False)
        if "&a" in content:      # keep the aliases as written
            text = content + "\n" + yaml.safe_dump({k: v for k, v in good.items() if k != "provenance"},
                                                   sort_keys=False)
        bad.write_text(text)
    for argv in (["show", bad], ["apply", bad, capture_dir / "pos01.csv", "-o", tmp_path / "o.csv"]):
        one_line_exit_2(argv, capsys, str(bad), *words)


def test_a_fifo_as_calibration_or_input_file_does_not_hang(capture_dir, tmp_path):
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    for argv in (["show", fifo], ["apply", capture_dir / "calibration.yaml", fifo, "-o", tmp_path / "o.csv"]):
        done = run_child(argv)
        assert done.returncode == 2 and "not a regular file" in done.stderr, done.stderr


# ------------------------------------------------------------------ capture manifests and files

def test_yaml_aliases_expanding_in_a_text_field_do_not_hang(cap):
    text = (cap / "manifest.yaml").read_text()
    laughs = "".join(f"l{i}: &l{i} [{', '.join([f'*l{i - 1}'] * 9)}]\n" for i in range(1, 10))
    text = "l0: &l0 lol\n" + laughs + text.replace("serial: SIM-5", "serial: *l9")
    (cap / "manifest.yaml").write_text(text)
    done = run_child(["estimate", cap])
    assert done.returncode == 2 and "imu.serial" in done.stderr and "must be text" in done.stderr, done.stderr
    assert done.stderr.count("\n") == 1 and len(done.stderr) < 400


def test_a_fifo_in_place_of_an_incomplete_segment_file(cap):
    def incomplete(doc):
        doc["segments"][-1]["status"] = "incomplete"
    edit_manifest(cap, incomplete)
    last = yaml.safe_load((cap / "manifest.yaml").read_text())["segments"][-1]["file"]
    (cap / last).unlink()
    os.mkfifo(cap / last)
    capture = read_capture(cap)          # does not block on the FIFO
    assert "not a regular file" in capture.segments[-1].problem
    writer = CaptureWriter.reopen(cap)     # moves it aside, so the segment can be recorded again
    assert not (cap / last).exists() and (cap / f"{last}.incomplete").is_fifo()
    with writer.begin_segment("again", "static", file=last) as seg:
        seg.write([0.0, 0.01], np.zeros((2, 3)) + 9.8, np.zeros((2, 3)))
    # and a FIFO as a *complete* segment's file is refused, not read
    (cap / "pos01.csv").unlink()
    os.mkfifo(cap / "pos01.csv")
    done = run_child(["estimate", cap])
    assert done.returncode == 2 and "pos01" in done.stderr, done.stderr


def test_run_resume_with_sim_is_refused(cap, capsys):
    one_line_exit_2(["run", "--resume", cap, "--sim"], capsys, "--resume", "--sim")


# ------------------------------------------------------------------ files written

def test_a_symlinked_temporary_or_target_file_is_never_followed(cap, tmp_path):
    outside = tmp_path / "outside.txt"
    outside.write_text("precious\n")
    for name in ("calibration.yaml.tmp", ".calibration.yaml.tmp"):
        (cap / name).symlink_to(outside)
    (cap / "calibration.yaml").unlink()
    (cap / "calibration.yaml").symlink_to(outside)
    assert main(["estimate", str(cap)]) == 0
    assert outside.read_text() == "precious\n"
    assert (cap / "calibration.yaml").is_file() and not (cap / "calibration.yaml").is_symlink()
    assert not [p for p in cap.iterdir() if p.name.endswith(".tmp") and not p.is_symlink()]


def test_stray_temporaries_are_removed_and_unlisted_files_kept_aside_on_resume(cap):
    (cap / ".manifest.yaml.k2j4h5.tmp").write_text("half a manifest")
    (cap / "rot_new.csv").write_text("t,ax\n1,2\n")       # a killed writer's file, never listed
    writer = CaptureWriter.reopen(cap)
    assert not (cap / ".manifest.yaml.k2j4h5.tmp").exists()
    with writer.begin_segment("rot_new", "static") as seg:
        seg.write([0.0, 0.01], np.zeros((2, 3)) + 9.8, np.zeros((2, 3)))
    assert (cap / "rot_new.csv.unlisted").read_text() == "t,ax\n1,2\n"
    assert read_capture(cap).segment("rot_new").status == "complete"


# ------------------------------------------------------------------ interrupts

@pytest.mark.parametrize("where", ["import", "parse", "command"])
def test_ctrl_c_at_start_up_is_clean(monkeypatch, capsys, where):
    import station.cli.app as app

    def interrupt(*a, **k):
        raise KeyboardInterrupt
    if where == "import":                  # while the command's modules are imported
        monkeypatch.setitem(sys.modules, "station.cli.app", None)
        monkeypatch.setattr("builtins.__import__", _interrupting_import(__import__, "station.cli.app"))
    elif where == "parse":
        monkeypatch.setattr(app, "build_parser", interrupt)
    else:
        monkeypatch.setattr("station.cli.run.cmd_run", interrupt)
        monkeypatch.setattr(app, "build_parser", _parser_with(app.build_parser, interrupt))
    assert main(["run", "--sim"]) == 130
    err = capsys.readouterr().err
    assert "interrupted" in err and "Traceback" not in err


def _interrupting_import(real, name):
    def fake(module, *args, **kwargs):
        if module == name:
            raise KeyboardInterrupt
        return real(module, *args, **kwargs)
    return fake


def _parser_with(build, func):
    def build_and_patch(*args):
        parser = build(*args)
        parser.set_defaults(func=func)
        for action in parser._subparsers._group_actions:
            for sub in action.choices.values():
                sub.set_defaults(func=func)
        return parser
    return build_and_patch


def test_a_dead_axis_is_refused_by_diagnose_and_report_as_by_estimate(capture_dir, tmp_path, capsys):
    """A gyro axis that reads 0 in every sample: the fit's start has no rotation to align
    (scipy's SVD did not converge: a traceback in diagnose and report); refused in one line, as
    estimate refuses it (quantised coarser than its noise)."""
    import hashlib
    import shutil

    cap = tmp_path / "cap"
    shutil.copytree(capture_dir, cap)
    manifest = yaml.safe_load((cap / "manifest.yaml").read_text())
    for seg in manifest["segments"]:
        lines = (cap / seg["file"]).read_text().splitlines()
        k = lines[0].split(",").index("gx")
        lines = lines[:1] + [",".join("0" if i == k else v for i, v in enumerate(line.split(",")))
                             for line in lines[1:]]
        (cap / seg["file"]).write_text("\n".join(lines) + "\n")
        seg["sha256"] = hashlib.sha256((cap / seg["file"]).read_bytes()).hexdigest()
    (cap / "manifest.yaml").write_text(yaml.safe_dump(manifest, sort_keys=False))
    for argv in (["diagnose", cap], ["report", cap, "-o", tmp_path / "page.html"]):
        one_line_exit_2(argv, capsys, "column 'gx': quantised coarser than its noise")
