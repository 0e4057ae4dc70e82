"""Several IMUs in one run (issue 29), end to end over real pseudo-terminals: one table twin and
three IMU twins (``BenchServer(imus=N)``, as ``station sim serve --imus N``: each its own truth,
noise seed and serial number), ``station run`` with station.yaml ``imus:``.  Two runs, each
checked for several properties (a ``station run`` and its resume cost a process start-up, the
twins' frames and the fits: the file's time is theirs):

- three IMUs, one mute from power-up (the twins' per-IMU faults: no reply to its start-up) and one
  whose line hangs up mid-run: the run says both, marks the first's bundle and the second's
  segment being recorded, the third completes, estimates and passes against its own truth, exit
  status 4; the line plugged in again and the sensor speaking, ``--resume`` records only what
  each lacks (the complete IMU's bundle untouched): all three estimate and pass against their own
  truths, at the same table angles, no frame lost;
- two IMUs and a third whose port does not exist, killed (SIGKILL) mid-way, then ``--resume``: the
  two complete with what was complete before kept byte for byte; the third lost at the start of
  both (exit status 4).

The scheme is a small one written here (six attitudes, three +/- rotations about the case axes,
2 s each: every parameter of the model determined, as with optimal9, with larger sigmas which the
z-scores take into account), at 50 frames/s.  Errors are judged against the 1-sigma the estimator
reports (z = error / sigma): with 21 parameters per IMU, max |z| < 4.5 fails by chance with
probability ~1e-4 per IMU (two-sided normal tail 6.8e-6 x 21 parameters) and the rms of z
exceeds 1.6 with probability < 1e-3 (chi-square with 21 degrees of freedom above 21 x 1.6^2 =
53.8).
"""
import hashlib
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from sim_devices.truth import default_truth
from sim_devices.twins.faults import ImuFaults
from sim_devices.twins.serve import BenchOptions, BenchServer
from station.io.calfile import read_calfile
from station.io.capture import read_capture
from station.simulate import dryrun

pytestmark = pytest.mark.skipif(not hasattr(signal, "SIGKILL"), reason="needs SIGKILL and pseudo-terminals")

SPEED = 400.0
SEED = 29
RATE_HZ = 50
TINY = """\
name: tiny12
title: six attitudes and three +/- rotations about the case axes (tests/test_multi_imu.py)
defaults: {dwell_s: 2.0, rate_dps: 180.0, rotation_s: 2.0}
segments:
  - {static: pos01, up_body: [1, 0, 0]}
  - {static: pos02, up_body: [-1, 0, 0]}
  - {static: pos03, up_body: [0, 1, 0]}
  - {static: pos04, up_body: [0, -1, 0]}
  - {static: pos05, up_body: [0, 0, 1]}
  - {static: pos06, up_body: [0, 0, -1]}
  - {rotation: rotx, axis_body: [1, 0, 0]}
  - {rotation: roty, axis_body: [0, 1, 0]}
  - {rotation: rotz, axis_body: [0, 0, 1]}
"""
SEGMENTS = 12                 # six statics, three rotations each way
# Each statistical check below fails an honest calibration with probability TEST_ALPHA at most: the
# product's verdict fails an honest fit at 1e-3 by design, which five fits per run made a failure
# of these tests about once in 220 runs (seventeenth session: 158 fits on the twins at reduced
# chi2 1.00 +- 0.14, the one failure seen at 1.504, p = 8.9e-4; docs/fleet.md)
TEST_ALPHA = 1e-6
LIMITS = "[{max_rate_dps: 300, max_accel_dps2: 300, move_rate_dps: 90, move_accel_dps2: 180, rate_accel_dps2: 150}]"


def config_text(bench, n, missing: int = 0, mute: int | None = None) -> str:
    # replies waited for 10 s, not a real sensor's 1 s: the twins stream at 400 times a sensor's
    # rate from this process, and on a loaded machine a reply at the start of a resume came later
    # than 1 s among those frames ("no reply to $VNASY,0 within 1 s": once in CI, once in 4 loaded
    # runs); the IMU ``mute`` (which never replies) for a real sensor's 1 s
    entries = [f"  - {{port: {line.port.path}, rate_hz: {RATE_HZ}, serial: {{timeout_s: {1 if k == mute else 10}}}}}"
               for k, line in enumerate(bench.lines[:n])]
    entries += [f"  - {{port: /nonexistent/imu{k}, name: gone{k}, rate_hz: {RATE_HZ}}}" for k in range(missing)]
    imus = "\n".join(entries)
    return f"""\
version: 1
imus:
{imus}
table:
  port: {bench.table_path}
  serial: {{timeout_s: 10}}       # as the IMUs': a resume at a load of 32 on 2 cores waited 1 s once
  poll_interval_s: {max(0.01 / SPEED, 0.001):g}    # a real table's 10 ms at the twins' speed, at least the 1 ms the configuration takes
  axes: 3
  limits: {LIMITS}
run:
  operator: false
  settle_s: 1
  # the twins' clock waits for a reader that falls behind (no frame is lost); should one be lost
  # all the same, a recording that lost more than this is recorded again
  max_missing_fraction: 0.02
  max_gap_s: 2.0
  rerecord_attempts: 3
"""


def steady_truth(seed):
    """default_truth at one temperature.  While a killed run is away the twins' device time runs
    on at SPEED: through a warm-up the resumed segments would sit at another temperature, and the
    truth's bias temperature coefficients, which the base model has not, would fail its fit
    (seen in CI: reduced chi2 1.51, 1.3 degC across a resumed capture).  These tests are about
    the run's mechanics: the temperature is held."""
    truth = default_truth(seed)
    truth.temperature.warmup_delta_c = 0.0
    truth.temperature.drift_c_per_h = 0.0
    return truth


def make_bench(n, imu_faults=()):
    return BenchServer([steady_truth(SEED + k) for k in range(n)],
                       BenchOptions(speed=SPEED, seed=SEED, axes=3, lossless=True, imus=n,
                                    imu_faults=tuple(imu_faults)))


def station(config: Path, *args):
    return subprocess.Popen([sys.executable, "-m", "station.cli", "run", "--config", str(config), *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=config.parent)


def finish(proc, timeout=240):
    try:
        return proc.communicate(timeout=timeout)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()


def write_config(tmp_path, bench, n, missing: int = 0, mute: int | None = None) -> Path:
    path = tmp_path / "station.yaml"
    path.write_text(config_text(bench, n, missing, mute))
    (tmp_path / "tiny.yaml").write_text(TINY)
    return path


SCHEME = ["--scheme", "tiny.yaml"]


def z_scores(bundle: Path, truth) -> np.ndarray:
    doc = read_calfile(bundle / "calibration.yaml")
    cal = {name: (p["value"], p["sigma"]) for name, p in doc["parameters"].items()}
    return np.array([(cal[name][0] - true) / cal[name][1]
                     for name, true, _ in dryrun.truth_calibration(truth).parameters()])


def calibrated(bundle: Path) -> bool:
    """The fit passes (or its noise is overestimated), or it fails on its chi2 only as an honest
    fit does by chance at TEST_ALPHA (the verdict's own threshold is 1e-3)."""
    v = read_calfile(bundle / "calibration.yaml")["fit"]["verdict"]
    if v["result"] in ("passes", "noise overestimated"):
        return True
    return (v["result"] == "fails" and str(v.get("reason", "")).startswith("reduced chi2")
            and float(v.get("p_value", 0.0)) > TEST_ALPHA)


def accurate(z: np.ndarray) -> bool:
    """The errors against the twin's truth, in their own 1-sigma, as honest ones are but with
    probability TEST_ALPHA: the largest |z| (Bonferroni over the parameters) and their sum of
    squares (chi2 with as many degrees of freedom)."""
    from scipy.stats import chi2, norm

    return bool(np.abs(z).max() < norm.isf(TEST_ALPHA / (2 * len(z)))
                and np.sum(z ** 2) < chi2.isf(TEST_ALPHA, len(z)))


_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


def segments(bundle: Path) -> list:
    # libyaml's loader where there is one: polled every 20 ms while the twins run in this
    # process, the pure-Python one took ~9 ms of their interpreter per look at a 5 kB manifest
    try:
        doc = yaml.load((bundle / "manifest.yaml").read_text(), Loader=_LOADER) or {}
    except (OSError, yaml.YAMLError):
        return []
    return doc.get("segments", [])


def wait_for(condition, what: str, timeout_s: float = 120.0):
    """Poll ``condition()`` (gently: the twins run in this process) until it is true."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        value = condition()
        if value:
            return value
        time.sleep(0.02)
    raise AssertionError(f"not within {timeout_s} s: {what}")


def recording_after(bundle: Path, after: int):
    """The segment being recorded into ``bundle`` once ``after`` are complete and it has rows."""
    segs = segments(bundle)
    done = sum(s.get("status") == "complete" for s in segs)
    if done >= after and segs and segs[-1].get("status") == "incomplete" and "note" not in segs[-1]:
        csv = bundle / segs[-1]["file"]
        if csv.exists() and csv.stat().st_size > 1000:
            return segs[-1]["name"]
    return None


def sha(path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def check_estimates(run: Path, bench, n, folders: dict | None = None):
    """Every IMU's bundle: named by its serial number (or as ``folders`` says: an IMU lost at the
    start of the run, which said no serial then), complete, estimated, passes, within its own
    twin's truth, no frame lost; every bundle recorded at the same table angles."""
    angles = None
    for k, line in enumerate(bench.lines[:n]):
        bundle = run / (folders or {}).get(k, line.serial_number)
        capture = read_capture(bundle)
        assert str(capture.imu.serial) == line.serial_number
        assert len(capture.complete()) == SEGMENTS
        assert sum(seg.data.gaps for seg in capture.complete()) == 0          # lossless twins: none lost
        # a usable calibration: 12 short segments at 50 Hz whose timing follows the wall clock (a
        # kill, a resume); in CI one resumed capture came out "noise overestimated" (chi2 below
        # its 0.1 % point: the 1-sigma conservative) -- the errors against the truth, below, are
        # the accuracy check
        assert calibrated(bundle), (bundle, read_calfile(bundle / "calibration.yaml")["fit"]["verdict"])
        z = z_scores(bundle, line.truth)
        print(f"IMU {line.serial_number}: max |z| {np.abs(z).max():.2f}, rms z {np.sqrt(np.mean(z**2)):.2f}")
        assert accurate(z), z
        table = {s.name: s.extra.get("table_deg") for s in capture.complete()}
        angles = table if angles is None else angles
        assert table == angles           # the table moved once for all: the same angles for every IMU


def test_an_imu_mute_at_start_and_one_lost_mid_run_do_not_stop_the_third_and_resume_records_both(tmp_path):
    # IMU 3 mute from power-up: the twins' per-IMU faults (station sim serve --imus 3 --faults
    # none.yaml --faults none.yaml --faults mute.yaml gives the same)
    with make_bench(3, imu_faults=[ImuFaults(), ImuFaults(), ImuFaults(mute_at_s=0.0)]) as bench:
        config = write_config(tmp_path, bench, 3, mute=2)
        run = tmp_path / "run"
        serial1, serial2, serial3 = (line.serial_number for line in bench.lines)
        first, second, third = run / serial1, run / serial2, run / "imu3"     # IMU 3 said no serial
        proc = station(config, *SCHEME, "--out", "run")
        try:
            # the world slowed down to 2 x wall time once IMU 2 has three segments: its fourth (2 s
            # of device time) lasts 1 s of wall time, for the unplug to land in it
            wait_for(lambda: sum(s.get("status") == "complete" for s in segments(second)) >= 3,
                     "IMU 2 with three segments")
            bench.clock.set_speed(2.0)
            wait_for(lambda: recording_after(second, 3), "IMU 2 recording its fourth segment")
            bench.unplug_imu(1)                                       # its USB adapter pulled out
            bench.clock.set_speed(SPEED)
            out, err = finish(proc)
        finally:
            if proc.poll() is None:
                proc.kill()
        assert proc.returncode == 4, err[-3000:]
        assert "Traceback" not in err
        # IMU 3 did not answer its start-up: said, its bundle marked, nothing recorded
        assert f"IMU imu3 (imus[2], {bench.lines[2].port.path}) lost at the start (DeviceTimeout" in err
        mark = yaml.safe_load((third / "manifest.yaml").read_text())
        assert "DeviceTimeout" in mark["lost_at_start"]["why"] and mark["segments"] == []
        assert "IMU imu3: lost: at the start" in err
        # IMU 2 lost mid-run: said while running, the segment it was recording marked
        assert f"IMU {serial2} lost" in out
        assert f"IMU {serial2}: lost" in err and f"--resume {Path('run')}" in err
        segs = segments(second)
        marked = [s for s in segs if s.get("status") == "incomplete" and "IMU lost" in s.get("note", "")]
        assert len(marked) == 1
        done_before = {s["name"]: s["sha256"] for s in segs if s.get("status") == "complete"}
        assert 3 <= len(done_before) < SEGMENTS
        # IMU 1 went on to the end and estimated; the others did not
        assert len(read_capture(first, load_data=False).complete()) == SEGMENTS
        assert calibrated(first)
        assert not (second / "calibration.yaml").exists() and not (third / "calibration.yaml").exists()
        kept1 = {s["name"]: s["sha256"] for s in segments(first)}

        # IMU 2 plugged in again (a new device path), IMU 3 speaking: resume records what each lacks
        bench.replug_imu(1)
        bench._between_steps(lambda: setattr(bench.lines[2].faults, "mute_at_s", None))
        config.write_text(config_text(bench, 3))
        moves_before = len(bench.table.axes[0].motion.history)
        resume = station(config, "--resume", "run")
        out, err = finish(resume)
    assert resume.returncode == 0, err[-3000:]
    assert "Traceback" not in err
    assert len(bench.table.axes[0].motion.history) > moves_before       # the table moved for IMUs 2, 3
    check_estimates(run, bench, 3, folders={2: "imu3"})       # its bundle now says its serial
    capture = read_capture(second, load_data=False)
    assert {s.name: s.extra["sha256"] for s in capture.complete() if s.name in done_before} == done_before
    assert {s["name"]: s["sha256"] for s in segments(first)} == kept1    # IMU 1 had everything: untouched
    assert "lost_at_start" not in yaml.safe_load((third / "manifest.yaml").read_text())
    truths = [line.truth.accel.bias for line in bench.lines]
    assert not np.allclose(truths[0], truths[1])                           # different sensors


def test_a_run_killed_mid_way_resumes_every_imu_and_a_missing_port_is_lost_at_both_starts(tmp_path):
    with make_bench(2) as bench:
        config = write_config(tmp_path, bench, 2, missing=1)
        run = tmp_path / "run"
        proc = station(config, *SCHEME, "--out", "run")
        try:
            first = run / bench.lines[0].serial_number
            recording = wait_for(lambda: recording_after(first, 5), "IMU 1 recording its sixth segment")
            assert proc.poll() is None
            os.kill(proc.pid, signal.SIGKILL)                 # no finally, no flush: the guardian stops the table
            proc.wait(10)
        finally:
            if proc.poll() is None:
                proc.kill()
        before = {}
        for line in bench.lines:
            bundle = run / line.serial_number
            kept = {s["name"]: s["sha256"] for s in segments(bundle) if s.get("status") == "complete"}
            assert 4 <= len(kept) < SEGMENTS, (line.serial_number, len(kept))
            before[line.serial_number] = kept
        assert "DeviceError" in yaml.safe_load((run / "gone0" / "manifest.yaml").read_text())["lost_at_start"]["why"]
        resume = station(config, "--resume", "run")
        out, err = finish(resume)
        # the first resume completed every IMU but the missing one (checked before the second:
        # CI once saw the second drive the table, which it does only when an IMU still lacks
        # segments -- this says which and why, from the first resume's own words)
        for line in bench.lines:
            done = [s["name"] for s in segments(run / line.serial_number) if s.get("status") == "complete"]
            assert len(done) == SEGMENTS, (line.serial_number, done, resume.returncode, err[-3000:])
        # resumed again with the port still missing: only that IMU lacks segments, nobody would
        # record, and the table is not driven through the scheme
        moves = [len(ax.motion.history) for ax in bench.table.axes]
        again = station(config, "--resume", "run")
        _, err_again = finish(again)
        assert [len(ax.motion.history) for ax in bench.table.axes] == moves, err_again[-2000:]
    assert again.returncode == 4, err_again[-3000:]
    assert "nothing to record: every IMU that lacks segments is lost again at the start (gone0)" in err_again
    assert "Traceback" not in err
    assert resume.returncode == 4, err[-3000:]                # the missing port: lost again, the others done
    assert "IMU gone0 (imus[2], /nonexistent/imu0) lost at the start (DeviceError" in err
    assert "IMU gone0: lost: at the start" in err
    try:
        check_estimates(run, bench, 2)
    except AssertionError as e:      # what the resume said, with the failure
        raise AssertionError(f"{e}; resume exit {resume.returncode}: {err[-3000:]}") from None
    for serial, kept in before.items():
        capture = read_capture(run / serial, load_data=False)
        after = {s.name: s.extra["sha256"] for s in capture.complete()}
        for name, digest in kept.items():
            assert after[name] == digest == sha(run / serial / f"{name}.csv"), (serial, name)
    print(f"killed while recording {recording}; resumed: {out.count('--- IMU')} IMUs estimated")


def test_a_run_whose_every_imu_fails_to_start_stops_saying_each(tmp_path):
    with make_bench(1) as bench:
        config = tmp_path / "station.yaml"
        config.write_text(config_text(bench, 0, missing=2))
        (tmp_path / "tiny.yaml").write_text(TINY)
        proc = subprocess.run([sys.executable, "-m", "station.cli", "run", "--config", str(config), *SCHEME,
                               "--out", "run"], capture_output=True, text=True, cwd=tmp_path, timeout=120)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "no IMU started" in lines[0], proc.stderr
    assert "imus[0] (/nonexistent/imu0)" in lines[0] and "imus[1] (/nonexistent/imu1)" in lines[0]
    assert not (tmp_path / "run").exists()


def test_faults_files_per_imu(tmp_path):
    from sim_devices.twins.faults import load_faults_per_imu
    from station.core.errors import UserError

    table = tmp_path / "table.yaml"
    table.write_text("version: 1\ntable: {stall: {at_s: 5}}\nimu: {drop: {probability: 0.1}}\n")
    mute = tmp_path / "mute.yaml"
    mute.write_text("version: 1\nimu: {mute: {at_s: 3, duration_s: 2}}\n")
    faults, per_imu = load_faults_per_imu([table, mute], 2)
    assert faults.table.stall_at_s == 5 and per_imu[0].drop_probability == 0.1
    m = per_imu[1]
    assert (m.muted(2.9), m.muted(3.0), m.muted(4.9), m.muted(5.0)) == (False, True, True, False)
    one, none = load_faults_per_imu([table], 3)                      # once: the table's and the first IMU's
    assert one.imu.drop_probability == 0.1 and none == ()
    for paths, field in (([mute, table], "table"), ([table, mute, mute], "--faults")):
        with pytest.raises(UserError) as e:
            load_faults_per_imu(paths, 2)
        assert field in str(e.value)


def test_sim_serve_takes_a_faults_file_per_imu(tmp_path, monkeypatch):
    """``station sim serve --imus 2 --faults A --faults B``: the twins get B's IMU faults for IMU 2
    (the server's construction intercepted: the command would serve until Ctrl-C)."""
    from station.cli import app, devices

    none = tmp_path / "none.yaml"
    none.write_text("version: 1\n")
    mute = tmp_path / "mute.yaml"
    mute.write_text("version: 1\nimu: {mute: {at_s: 0}}\n")
    seen = {}

    class Built(Exception):
        pass

    def server(truth, args, axes, faults, csv_format, imu_faults=()):
        seen["imu_faults"] = imu_faults
        raise Built()
    monkeypatch.setattr(devices, "_bench_server", server)
    with pytest.raises(Built):
        app.main(["sim", "serve", "--imus", "2", "--faults", str(none), "--faults", str(mute)])
    assert [f.muted(0.0) for f in seen["imu_faults"]] == [False, True]
    assert app.main(["sim", "serve", "--imus", "3", "--faults", str(none), "--faults", str(mute)]) == 2


# ------------------------------------------------------------------ the pieces, without devices

def test_imus_configuration_round_trips_and_bad_entries_name_their_field(tmp_path):
    from station.bench.config import from_dict, parse_config

    config = parse_config({"imus": [{"port": "/dev/a", "name": "left"},
                                    {"port": "/dev/b", "mounting": ["-x", "-y", "+z"], "offset_m": [0.1, 0, 0]}]},
                          "station.yaml")
    assert config.imu == config.imus[0] and len(config.imu_list) == 2
    assert from_dict(config.to_dict(), "run.yaml").imus == config.imus
    single = parse_config({"imu": {"port": "/dev/a"}}, "station.yaml")       # the one-IMU form unchanged
    assert single.imu_list == (single.imu,) and "imus" not in single.to_dict()
    assert "name" not in single.to_dict()["imu"]
    from station.core.errors import UserError

    for doc, field in (({"imus": []}, "'imus'"),
                       ({"imus": [{"port": "/dev/a"}, {"port": "/dev/a"}]}, "'imus[1].port'"),
                       ({"imu": {"port": "/dev/a"}, "imus": [{"port": "/dev/b"}]}, "'imus'"),
                       ({"imus": [{"port": "/dev/a", "name": "../up"}]}, "'imus[0].name'"),
                       ({"imus": [{"port": "/dev/a", "mounting": ["+x", "+x", "+z"]}]}, "'imus[0].mounting'"),
                       ({"imus": [{"port": "/dev/a", "baud": 9600}]}, "'imus[0].baud'")):
        with pytest.raises(UserError) as e:
            parse_config({"version": 1, **doc}, "bad.yaml")
        # one line: the command prints a UserError as one line with exit status 2 (through the
        # command in test_a_run_whose_every_imu_fails_to_start_stops_saying_each)
        assert field in str(e.value) and "\n" not in str(e.value)


def test_an_imu_mounted_otherwise_records_the_same_platform_directions_in_its_own_axes():
    from station.bench.channels import relative_mounting, segment_meta
    from station.bench.config import AXIS_NAMES

    def matrix(names):
        return np.column_stack([AXIS_NAMES[n] for n in names]).astype(float)
    m0, mk = matrix(("+x", "+y", "+z")), matrix(("+y", "+z", "+x"))        # IMU k: x along platform y ...
    r = relative_mounting(m0, mk)
    meta = {"up_body": [1, 0, 0], "axis_body": [0, 0, 1], "heading_body": [0, 1, 0], "rate_dps": 10.0,
            "mounting": ["+x", "+y", "+z"], "table_deg": [0, 90, 0]}
    out = segment_meta(meta, r)
    for key in ("up_body", "axis_body", "heading_body"):
        # the same platform direction: M_k v_k == M_0 v_0
        np.testing.assert_allclose(mk @ out[key], m0 @ np.array(meta[key], dtype=float))
    assert out["mounting"] == ["+y", "+z", "+x"] and out["table_deg"] == meta["table_deg"]
    assert segment_meta(meta, relative_mounting(m0, m0)) == meta


def test_bundles_are_named_by_serial_then_name_then_index_and_never_twice():
    from station.bench.multi import folder_names

    assert folder_names(["0100000029", None, None, "0100000029"], [None, "left", None, None]) == \
        ["0100000029", "left", "imu3", "0100000029-4"]
    assert folder_names(["a/../b"], [None]) == ["a_.._b"]


def test_the_live_display_shows_a_line_per_imu():
    from station.bench.live import imu_lines

    class Counters:
        frames, checksum_errors, resyncs, gaps = 100, 0, 0, 0
    lines = imu_lines({"imus": [{"label": "A", "lost": None, "f_mps2": 9.8, "w_dps": 0.01, "counters": Counters()},
                                {"label": "B", "lost": "OSError: hang-up"}]})
    assert lines[0].startswith("IMU A: |f| 9.80000 m/s^2") and "frames 100" in lines[0]
    assert lines[1] == "IMU B: LOST (OSError: hang-up)"
    assert imu_lines({"f_mps2": 9.8}) == []


def test_a_dry_run_of_several_imus_simulates_each_as_its_own_sensor(tmp_path, monkeypatch):
    config = tmp_path / "station.yaml"
    config.write_text("version: 1\nimus:\n  - {name: left}\n  - {}\n")
    (tmp_path / "tiny.yaml").write_text(TINY)
    from station.cli.app import main

    monkeypatch.chdir(tmp_path)              # in this process: no start-up of its own (the runs above have theirs)
    assert main(["run", "--sim", "--config", str(config), "--seed", "5", *SCHEME, "--out", "run"]) == 0
    truths = {}
    for folder, seed in (("left", 5), ("sim-6", 6)):
        bundle = tmp_path / "run" / folder
        assert calibrated(bundle)
        truths[folder] = yaml.safe_load((bundle / dryrun.TRUTH_FILE).read_text())
        z = z_scores(bundle, default_truth(seed))
        assert accurate(z), z
    assert truths["left"] != truths["sim-6"]
