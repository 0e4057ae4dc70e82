"""The command line, end to end on files: run --sim, estimate, show, apply, and user errors."""
import math
import subprocess
import sys

import numpy as np
import pytest
import yaml

from station.io.calfile import read_calfile
from station.io.capture import read_capture, read_segment_csv
from station.cli import main

SHORT = ["--dwell-s", "20", "--rotation-s", "36"]   # one revolution at 10 deg/s: a quick run


@pytest.fixture(scope="module")
def dry_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("run") / "cap"
    assert main(["run", "--scheme", "optimal9", "--sim", "--seed", "7", "--out", str(out), *SHORT]) == 0
    return out


def test_dry_run_writes_capture_truth_and_calibration(dry_run):
    capture = read_capture(dry_run)
    assert [s.status for s in capture.segments] == ["complete"] * 21
    assert capture.complete("static")[0].data.t.size == 20 * 100
    assert (dry_run / "sim_truth.yaml").exists()
    doc = read_calfile(dry_run / "calibration.yaml")
    assert doc["effects"] == ["base_triads", "inter_triad"]
    assert doc["provenance"]["imu_serial"] == "SIM-7"
    assert len(doc["provenance"]["capture_sha256"]) == 64
    for name, p in doc["parameters"].items():
        assert p["unit"], name


def test_estimate_from_files_matches_the_run(dry_run, tmp_path):
    target = tmp_path / "again.yaml"
    assert main(["estimate", str(dry_run), "-o", str(target)]) == 0
    a = read_calfile(dry_run / "calibration.yaml")["compensation"]
    b = read_calfile(target)["compensation"]
    for key in ("accel_matrix", "accel_bias", "gyro_matrix", "gyro_bias"):
        np.testing.assert_allclose(a[key], b[key], rtol=0, atol=1e-12)


def test_apply_compensates_a_static_segment_to_gravity_and_earth_rate(dry_run, tmp_path):
    capture = read_capture(dry_run)
    seg = capture.complete("static")[6]
    out = tmp_path / "out.csv"
    assert main(["apply", str(dry_run / "calibration.yaml"), str(dry_run / seg.file), "-o", str(out)]) == 0
    header = out.read_text().splitlines()[0]
    assert header == "t,ax,ay,az,gx,gy,gz"
    data = read_segment_csv(out)
    n = len(data.t)
    truth = yaml.safe_load((dry_run / "sim_truth.yaml").read_text())
    # noise of a mean over the dwell, from the densities (µg/√Hz, °/h/√Hz), plus the
    # calibration's own error of the same size: 2 sigma_m, checked at 5 sigma
    sigma_f = truth["accelerometer"]["noise_density_ug_rthz"] * 9.80665e-6 / math.sqrt(20.0)
    f = data.accel.mean(axis=0)
    assert abs(np.linalg.norm(f) - capture.site.gravity_mps2) < 5 * 2 * sigma_f
    np.testing.assert_allclose(f / np.linalg.norm(f), seg.up_body, atol=1e-3)  # within the p/case frame tilt
    sigma_w = truth["gyroscope"]["noise_density_dph_rthz"] / math.sqrt(20.0) / 3600
    earth = 360.0 / 86164.0905
    assert abs(np.linalg.norm(data.gyro.mean(axis=0)) - earth) < 5 * 2 * sigma_w
    assert n == 2000


def test_show_prints_parameters(dry_run, capsys):
    assert main(["show", str(dry_run / "calibration.yaml")]) == 0
    text = capsys.readouterr().out
    assert "accel_misalignment_yz" in text and "arcsec" in text and "inter_triad_z" in text


@pytest.mark.parametrize("argv, expected", [
    (["estimate", "/nonexistent/cap"], "/nonexistent/cap: no such directory"),
    (["estimate", __file__], "a file, not a capture bundle"),
    (["show", "/nonexistent.yaml"], "/nonexistent.yaml"),
    (["run", "--scheme", "nope", "--sim"], "unknown scheme 'nope'"),
    (["run", "--scheme", "optimal9"], "add --sim"),
    (["run", "--sim", "--sim-truth", "/nonexistent-truth.yaml"], "nonexistent-truth.yaml"),
])
def test_user_errors_are_one_line_with_status_2(argv, expected, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert expected in err and err.count("\n") == 1 and "Traceback" not in err


def test_bad_calibration_file_and_bad_input_csv(dry_run, tmp_path, capsys):
    bad = tmp_path / "bad.yaml"
    bad.write_text("format: station-calibration/1\ncompensation: {accel_matrix: [1, 2]}\n")
    assert main(["show", str(bad)]) == 2
    assert "accel_matrix" in capsys.readouterr().err
    csv = tmp_path / "in.csv"
    csv.write_text("t,ax,ay,az,gx,gy,gz\n0,1,2,3,4,5,6\n0.01,1,2,x,4,5,6\n")
    assert main(["apply", str(dry_run / "calibration.yaml"), str(csv), "-o", str(tmp_path / "o.csv")]) == 2
    assert "line 3" in capsys.readouterr().err


def test_console_script_exit_status():
    done = subprocess.run([sys.executable, "-m", "station.cli", "estimate", "/nonexistent/cap"],
                          capture_output=True, text=True)
    assert done.returncode == 2 and done.stderr.count("\n") == 1


def exit_status(argv) -> int:
    """main()'s status; argparse's refusals exit (SystemExit) instead of returning."""
    try:
        return main(argv)
    except SystemExit as e:
        return e.code


@pytest.mark.parametrize("argv, words", [
    (["run", "--scheme", "optimal9", "--sim", "--seed", "-1"], "argument --seed: must be at least 0"),
    (["run", "--scheme", "optimal9", "--sim", "--dwell-s", "0.001"], "gives fewer than 2 samples"),
    (["run", "--scheme", "optimal9", "--sim", "--dwell-s", "1e7"], "more than the simulator holds at once"),
    (["run", "--scheme", "optimal9", "--sim", "--rate-dps", "1e9"], "argument --rate-dps: must be from"),
    (["run", "--scheme", "optimal9", "--sim", "--rate-dps", "-0"], "argument --rate-dps: must be from"),
    (["montecarlo", "--runs", "2", "--table-angle-arcsec", "1e9"], "argument --table-angle-arcsec"),
    (["montecarlo", "--runs", "2", "--gyro-noise-dph", "nan"], "must be finite"),
    (["montecarlo", "--runs", "2", "--accel-noise-ug", "-1"], "argument --accel-noise-ug"),
    (["sim", "serve", "--speed", "0"], "argument --speed: must be a positive number"),
])
def test_options_out_of_range_are_refused_before_anything_runs(tmp_path, capsys, argv, words):
    """Options a simulation or a Monte Carlo could not use (they ended in a traceback, a
    worker's traceback, or the out-of-memory killer): exit 2, one line, nothing written."""
    out = tmp_path / "cap"
    assert exit_status(argv + (["--out", str(out)] if argv[0] == "run" else [])) == 2
    err = capsys.readouterr().err.strip()
    assert words in err and len(err.splitlines()) == 1 and "Traceback" not in err, err
    assert not out.exists()


def test_the_rate_option_allows_what_a_capture_may_record(capsys):
    """--rate-dps's bound is the capture format's (written twice: the parser must not import the
    reader, for --help's speed)."""
    from station.io.capture import MAX_RATE_DPS

    assert exit_status(["plan", "--scheme", "optimal9", "--rate-dps", f"{MAX_RATE_DPS * 1.01:g}"]) == 2
    assert f"must be from 0.001 to {MAX_RATE_DPS:g}" in capsys.readouterr().err


def test_output_to_a_reader_that_went_away_ends_quietly(optimal9_run, tmp_path):
    """`station diagnose CAPTURE --json | head -0`: the pipe closed before the output is written
    (print(), not rich's console, which handles it itself): no traceback, status 1."""
    import os

    read, write = os.pipe()
    os.close(read)                     # nobody reads: the first write fails with EPIPE
    try:
        r = subprocess.run([sys.executable, "-m", "station.cli", "diagnose", str(optimal9_run), "--json"],
                           stdout=write, stderr=subprocess.PIPE, text=True, timeout=300,
                           env={**os.environ, "STATION_HISTORY_DIR": str(tmp_path / "history")})
    finally:
        os.close(write)
    assert r.returncode == 1 and "Traceback" not in r.stderr and "BrokenPipe" not in r.stderr, r.stderr


def test_estimate_of_a_single_static_recording_is_one_line(tmp_path, capsys):
    """A noise recording (one attitude) given to estimate: the one-line refusal, without scipy's
    two-line warning about a rotation not uniquely defined before it."""
    cap = tmp_path / "noise"
    assert main(["run", "--scheme", "noise", "--sim", "--dwell-s", "30", "--out", str(cap)]) == 0
    r = subprocess.run([sys.executable, "-m", "station.cli", "estimate", str(cap), "-o", str(tmp_path / "cal.yaml")],
                       capture_output=True, text=True, timeout=300)      # a process: its own warnings
    err = r.stderr.strip()
    assert r.returncode == 2 and len(err.splitlines()) == 1 and "cannot determine" in err, err


def test_plan_says_a_shaft_scheme_is_not_a_table_scheme(capsys):
    """`plan --scheme screwdriver` on the default table: its 720 deg/s shaft turns exceed the table;
    the one line says what the scheme is and that run --sim simulates it (issue 26)."""
    from station.cli import main as station_main

    assert station_main(["plan", "--scheme", "screwdriver"]) == 2
    line = " ".join(capsys.readouterr().err.split())
    assert "scheme screwdriver is not a table scheme: its rotations have no encoder" in line
    assert "station run --scheme screwdriver --sim" in line and "max_rate_dps (300)" in line
