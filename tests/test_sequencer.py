"""station run end to end through the serial drivers against the device twins (real
pseudo-terminals, --speed 100; settles are kept in device time by ImuStream.sync): the
estimate against the twins' truth, compared with the in-process dry run; no sample of a move in the data; a run killed with
SIGKILL and resumed; Ctrl-C pausing at a safe point.

Errors are judged against the 1-sigma the least-squares estimator reports (z = error / sigma):
with 21 parameters, max |z| < 4.5 fails by chance with probability ~1e-4, and the rms of z
(about 1) exceeds 1.6 with probability < 1e-3.
"""
import hashlib
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from sim_devices.truth import default_truth
from sim_devices.twins.serve import BenchOptions, BenchServer
from station.simulate import dryrun
from station.io.calfile import read_calfile
from station.model.calibration import parameter_errors
from station.io.capture import read_capture
from station.estimate import estimate_with
from station.io.scheme import load_scheme

SPEED = 100.0
SEED = 11
# 1 revolution at 60 deg/s, 5 s per attitude (the run and its killed-and-resumed twin record the
# scheme twice: its device time, read frame by frame at --speed 100, is most of this file's wall
# time; 10 s and 30 deg/s before: the z-scores below are in the estimator's own sigmas, which grow
# as the data shrink, so the tolerances hold as derived)
DWELL_S, RATE_DPS, ROTATION_S = 5, 60, 6
SHORT = ["--dwell-s", str(DWELL_S), "--rate-dps", str(RATE_DPS), "--rotation-s", str(ROTATION_S)]
CONFIG = """\
version: 1
# replies waited for 10 s, not a real device's 1 s (as tests/test_multi_imu.py): the twins answer
# from threads of this test process among the frames they stream at 100 x a sensor's rate, and a
# whole suite with three workers on two cores at a load of ~15 once saw "no reply to $VNWRG,75,...
# within 1 s" at the start of a run (twentieth session)
imu:
  serial: {timeout_s: 10}
  # and frames waited for 10 s, not 2 (the twins' stream is a thread of this test process: two CIs
  # of the twenty-first session saw "no valid frame for 2 s" mid-run with the other worker busy)
  frame_timeout_s: 10
table:
  serial: {timeout_s: 10}
  # the driver's waits read the table every 10 ms of a real table's time: the twins' 0.1 ms of wall
  # at --speed 100 (its arrival rule, 5 reads in a row, unchanged in device time; docs/sequencer.md)
  poll_interval_s: 0.001      # the least the configuration takes (starving the IMU reader below)
  axes: 3
  limits: [{max_rate_dps: 300, max_accel_dps2: 300, move_rate_dps: 60, move_accel_dps2: 60, rate_accel_dps2: 100}]
run:
  operator: false
  settle_s: 3
  # the twins' clock waits for a reader that falls behind (no frame is lost); should one be
  # lost all the same, a recording that lost more than this is recorded again (up to 5 times)
  max_missing_fraction: 0.02
  max_gap_s: 2.0
  rerecord_attempts: 5
"""
Z_MAX, Z_RMS = 4.5, 1.6


@pytest.fixture(scope="module")
def bench():
    with BenchServer(default_truth(SEED), BenchOptions(speed=SPEED, seed=SEED, axes=3, lossless=True)) as b:
        yield b


@pytest.fixture(scope="module")
def config(tmp_path_factory):
    path = tmp_path_factory.mktemp("cfg") / "station.yaml"
    path.write_text(CONFIG)
    return path


def station(bench, config, *args, **popen):
    cmd = [sys.executable, "-m", "station.cli", "run", "--config", str(config),
           "--port", bench.imu_path, "--table-port", bench.table_path, *args]
    return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            cwd=Path(__file__).parent, **popen)


def run_to_end(bench, config, *args, timeout=120):
    proc = station(bench, config, *args)
    out, err = proc.communicate(timeout=timeout)
    assert proc.returncode == 0, err[-3000:]
    return out, err


def z_scores(cal, truth):
    return np.array([(value - true) / cal.sigma[name]
                     for name, value, true, _, _ in parameter_errors(cal, dryrun.truth_calibration(truth))])


def calibration(capture_dir):
    """{name: (value, sigma)} from the calibration file station run wrote."""
    doc = read_calfile(Path(capture_dir) / "calibration.yaml")
    return {name: (p["value"], p["sigma"]) for name, p in doc["parameters"].items()}


def file_z_scores(capture_dir, truth):
    cal = calibration(capture_dir)
    return np.array([(cal[name][0] - true) / cal[name][1]
                     for name, true, _ in dryrun.truth_calibration(truth).parameters()])


def sha(path):
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def complete_segments(capture_dir):
    try:
        doc = yaml.safe_load((Path(capture_dir) / "manifest.yaml").read_text())
    except (OSError, yaml.YAMLError):
        return []
    return [s for s in (doc or {}).get("segments", []) if s.get("status") == "complete"]


def wait_for_recording(out, after: int, timeout_s: float = 120.0, proc=None) -> str:
    """The name of the segment being recorded once ``after`` segments are complete and it has
    rows on disk.  ``proc`` (the run): when it ends first, or the time runs out, the failure shows
    its exit status and stderr and the manifest's segments (a flake seen once in CI said only "no
    segment recording within 60 s")."""
    deadline = time.monotonic() + timeout_s
    segs = []
    while time.monotonic() < deadline:
        try:
            # libyaml's loader where there is one: polled every 20 ms while the twins share this
            # interpreter (a look at a 21-segment manifest: ~1 ms, ~9 ms with the Python loader)
            doc = yaml.load((Path(out) / "manifest.yaml").read_text(),
                            Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader)) or {}
        except (OSError, yaml.YAMLError):
            doc = {}
        segs = doc.get("segments", [])
        done = sum(s.get("status") == "complete" for s in segs)
        if done >= after and segs and segs[-1].get("status") == "incomplete":
            csv = Path(out) / segs[-1]["file"]
            if csv.exists() and csv.stat().st_size > 2000:
                return segs[-1]["name"]
        if proc is not None and proc.poll() is not None:
            break
        time.sleep(0.02)           # gently: the twins run in this process
    state = [(s.get("name"), s.get("status")) for s in segs]
    if proc is not None and proc.poll() is None:
        proc.terminate()
    err = ""
    if proc is not None:
        try:
            _, err = proc.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()
            _, err = proc.communicate()
    raise AssertionError(f"no segment recording after {after} complete ones within {timeout_s} s; segments "
                         f"{state}; the run's exit status {None if proc is None else proc.returncode}, "
                         f"stderr: {(err or '')[-3000:]}")


@pytest.fixture(scope="module")
def full_run(bench, config, tmp_path_factory):
    out = tmp_path_factory.mktemp("full") / "cap"
    t0 = time.monotonic()
    stdout, _ = run_to_end(bench, config, "--scheme", "optimal9", "--out", str(out), *SHORT)
    return out, stdout, time.monotonic() - t0, [list(ax.motion.history) for ax in bench.table.axes]


def test_optimal9_through_the_drivers_matches_the_truth_like_the_dry_run(full_run):
    out, stdout, wall_s, history = full_run
    capture = read_capture(out)
    names = [s.name for s in load_scheme("optimal9").segments]
    assert [s.name for s in capture.complete()] == names
    # every sample measured at least settle_s (3 s) after the table twin's axes reached their
    # final state (at the goal, at the demanded rate; its own motion history): none of a move
    for seg in capture.complete():
        t0 = float(seg.data.t[0])
        steady = max(max(st for tc, st in h if tc <= t0) for h in history)
        assert t0 - steady >= 3.0 - 0.01, seg.name
    assert (out / "calibration.yaml").exists() and "calibration file" in stdout
    for seg in capture.complete("static"):
        assert len(seg.data.t) == DWELL_S * 100 and seg.data.gaps == 0
    for seg in capture.complete("rotation"):
        # one revolution at the table's measured rate; the twin holds exactly RATE_DPS
        assert len(seg.data.t) == ROTATION_S * 100
        assert seg.angle_deg == pytest.approx(np.sign(seg.rate_dps) * 360.0, abs=1e-6)
        assert seg.extra["revolutions"] == 1
    truth = default_truth(SEED)
    assert read_calfile(out / "calibration.yaml")["provenance"]["method"] == "lsq"
    z_twin = file_z_scores(out, truth)
    assert len(z_twin) == 21
    scheme = load_scheme("optimal9", {"dwell_s": DWELL_S, "rate_dps": RATE_DPS, "rotation_s": ROTATION_S})
    dry, _ = estimate_with(dryrun.simulate_capture(scheme, truth, SEED), "lsq")
    z_dry = z_scores(dry, truth)
    print(f"\ntwins ({wall_s:.1f} s wall): max |z| {np.abs(z_twin).max():.2f}, rms z "
          f"{np.sqrt(np.mean(z_twin**2)):.2f}; in-process dry run: max |z| {np.abs(z_dry).max():.2f}, "
          f"rms z {np.sqrt(np.mean(z_dry**2)):.2f}")
    for z in (z_twin, z_dry):
        assert np.abs(z).max() < Z_MAX
        assert np.sqrt(np.mean(z**2)) < Z_RMS


def test_a_run_killed_mid_way_resumes_without_rewriting_what_was_complete(bench, config, full_run, tmp_path):
    out = tmp_path / "cap"
    proc = station(bench, config, "--scheme", "optimal9", "--out", str(out), *SHORT)
    try:
        recording = wait_for_recording(out, after=11, proc=proc)          # into the rotations
        assert proc.poll() is None, proc.communicate()[1][-2000:]
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(10)
    finally:
        if proc.poll() is None:
            proc.kill()
    before = {s["name"]: (s["sha256"], sha(out / s["file"])) for s in complete_segments(out)}
    assert 11 <= len(before) < 21
    assert all(recorded == actual for recorded, actual in before.values())

    run_to_end(bench, config, "--resume", str(out))
    capture = read_capture(out)
    assert [s.name for s in capture.complete()] == [s.name for s in load_scheme("optimal9").segments]
    after = {s.name: s.extra["sha256"] for s in capture.complete()}
    for name, (recorded, _) in before.items():
        assert after[name] == recorded == sha(out / f"{name}.csv"), name
    assert (out / f"{recording}.csv.incomplete").stat().st_size > 0       # the one being recorded

    resumed, whole = calibration(out), calibration(full_run[0])      # as station run wrote them
    assert len(resumed) == 21
    d = {name: (value - whole[name][0]) / np.hypot(sigma, whole[name][1]) for name, (value, sigma) in resumed.items()}
    print(f"\nkilled during {recording} after {len(before)} complete segments (kept byte for byte); "
          f"resumed vs uninterrupted: max |difference| {max(map(abs, d.values())):.2f} combined sigma, rms "
          f"{np.sqrt(np.mean(np.square(list(d.values())))):.2f}")
    for name, value in d.items():
        assert abs(value) < Z_MAX, name


def test_ctrl_c_pauses_at_a_safe_point_with_the_table_at_rest(bench, config, tmp_path):
    scheme = tmp_path / "small.yaml"
    scheme.write_text("name: small\ndefaults: {dwell_s: 20, rate_dps: 10, rotation_s: 36}\nsegments:\n"
                      "  - {static: zup, up_body: [0, 0, 1]}\n  - {rotation: rotx, axis_body: [1, 0, 0]}\n")
    out = tmp_path / "cap"
    proc = station(bench, config, "--scheme", str(scheme), "--out", str(out))
    try:
        assert wait_for_recording(out, after=1, proc=proc) == "rotx_p"
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, err[-2000:]
    assert "paused" in err and f"--resume {out}" in err
    capture = read_capture(out)
    seg = capture.segment("rotx_p")
    assert seg.status == "incomplete" and len(seg.data.t) > 0          # kept, marked incomplete
    assert capture.segment("zup").status == "complete"
    assert _comes_to_rest(bench)                                       # brought to rest
    assert all(ax.mode == "position" for ax in bench.table.axes)


def _comes_to_rest(bench, wall_s=10.0):
    """Every axis of the twin reads a rate of exactly 0 within ``wall_s`` (the hold at the rest
    position may still correct by a fraction of an encoder count for a moment after the stop
    returned: waited for, not slept over)."""
    deadline = time.monotonic() + wall_s
    while time.monotonic() < deadline:
        if all(bench.table.read_rate(axis) == 0.0 for axis in (1, 2, 3)):
            return True
        time.sleep(0.01)
    return False


def _small_scheme(tmp_path):
    scheme = tmp_path / "small.yaml"
    scheme.write_text("name: small\ndefaults: {dwell_s: 20, rate_dps: 10, rotation_s: 36}\nsegments:\n"
                      "  - {static: zup, up_body: [0, 0, 1]}\n  - {rotation: rotx, axis_body: [1, 0, 0]}\n")
    return scheme


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP], ids=["SIGTERM", "SIGHUP"])
def test_sigterm_and_sighup_abort_with_the_table_at_rest(bench, config, tmp_path, sig):
    """The terminal or SSH session closed (SIGHUP), or a service manager's stop (SIGTERM), during
    a rotation: like a second Ctrl-C, the table is braked to rest and what was recorded is kept."""
    out = tmp_path / "cap"
    proc = station(bench, config, "--scheme", str(_small_scheme(tmp_path)), "--out", str(out))
    try:
        assert wait_for_recording(out, after=1, proc=proc) == "rotx_p"
        assert any(abs(bench.table.read_rate(axis)) > 1.0 for axis in (1, 2, 3))     # turning
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, err[-2000:]
    assert "aborted" in err and f"--resume {out}" in err and "Traceback" not in err
    assert _comes_to_rest(bench)
    assert all(ax.mode == "position" for ax in bench.table.axes)
    capture = read_capture(out)
    assert capture.segment("zup").status == "complete"
    assert capture.segment("rotx_p").status == "incomplete"


def _guardians(run_pid):
    """pids of the table guardians started by the run ``run_pid`` (station.bench.guardian)."""
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                cmd = (entry / "cmdline").read_bytes().split(b"\0")
            except OSError:
                continue
            if b"station.bench.guardian" in cmd and f'"run_pid": {run_pid}'.encode() in b" ".join(cmd):
                found.append(int(entry.name))
    return found


def test_a_run_killed_during_a_rotation_has_its_table_stopped_by_its_guardian(bench, config, tmp_path):
    """SIGKILL cannot be caught and the run's finally never runs: its guardian (a process of its
    own session, station/bench/guardian.py) sees the run gone, opens the table port, brakes the
    turning axis without resuming an old demand, holds it, writes what it did and exits."""
    from processes import running, still_running

    out = tmp_path / "cap"
    proc = station(bench, config, "--scheme", str(_small_scheme(tmp_path)), "--out", str(out))
    try:
        assert wait_for_recording(out, after=1, proc=proc) == "rotx_p"
        guardians = _guardians(proc.pid)
        assert len(guardians) == 1 and running(guardians[0])
        rates = [bench.table.read_rate(axis) for axis in (1, 2, 3)]
        turning = [axis for axis, r in zip((1, 2, 3), rates) if abs(r) > 1.0]
        assert turning, rates
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(10)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert still_running(guardians, 30.0) == []            # it did its work and ended
    assert _comes_to_rest(bench)
    assert all(bench.table.axes[axis - 1].mode == "position" for axis in turning)
    log = (out / "guardian.log").read_text()
    assert f"(pid {proc.pid}) ended without stopping the table" in log
    found = {int(a): float(r) for a, r in re.findall(r"axis (\d) was turning at (\S+) deg/s", log)}
    assert set(found) == set(turning), log
    assert "braked to rest and held" in log


def test_a_run_that_ends_leaves_no_guardian_and_the_table_untouched(bench, config, tmp_path):
    out = tmp_path / "cap"
    proc = station(bench, config, "--scheme", str(_small_scheme(tmp_path)), "--out", str(out))
    try:
        assert wait_for_recording(out, after=1, proc=proc) == "rotx_p"
        guardians = _guardians(proc.pid)
        assert len(guardians) == 1
        proc.send_signal(signal.SIGTERM)                    # aborted in its own hands
        proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    from processes import still_running

    assert still_running(guardians, 10.0) == []
    assert not (out / "guardian.log").exists()              # it never opened the port


def test_probe_finds_a_table_left_turning_and_stops_it(bench):
    """An axis left turning (a killed program without a guardian, another tool): `station probe
    --table-port` finds it moving, says so, brakes it without resuming any old demand and holds it."""
    from drivers.registry import open_table

    with open_table(bench.table_path) as table:
        table.close_interlocks()
        table.set_rate(2, -25.0)
        table._exchange(("demand_position", 2, 200.0))     # a stale demand, as another tool leaves
    probe = subprocess.run([sys.executable, "-m", "station.cli", "probe", "--table-port", bench.table_path],
                           capture_output=True, text=True, timeout=60)
    assert probe.returncode == 0, probe.stderr
    found = {int(a): float(r) for a, r in re.findall(r"axis (\d) was turning at (\S+) deg/s", probe.stdout)}
    assert found == {2: pytest.approx(-25.0, abs=0.01)}, probe.stdout
    rest = float(re.search(r"held \(axis 2 at (\S+) deg\)", probe.stdout).group(1))
    # at rest as the driver judges it (its rate tolerance): a position loop holding the axis reads
    # a few resolution steps (1e-5 deg/s) while it settles, an exact 0 only by timing
    from drivers.table import TableSettings

    assert abs(bench.table.read_rate(2)) <= TableSettings().rate_tolerance_dps
    assert bench.table.axes[1].mode == "position"
    assert abs((bench.table.read_position(2) - rest + 180) % 360 - 180) < 0.002
    assert all(ax.interlock_closed for ax in bench.table.axes)


@pytest.mark.parametrize("argv, expected", [
    (["run", "--scheme", "manual6"], "no IMU port"),
    (["run", "--scheme", "optimal9", "--port", "/dev/nonexistent-imu"], "needs a rate table: give --table-port"),
    (["run", "--scheme", "optimal9", "--unattended", "--port", "/dev/nonexistent-imu", "--table-port",
      "/dev/nonexistent-table"], "cannot open /dev/nonexistent-table"),
    (["run", "--resume", "{tmp}"], "not a capture of station run"),
])
def test_run_errors_are_one_line(argv, expected, tmp_path, capsys, monkeypatch):
    from station.cli import main

    monkeypatch.chdir(tmp_path)                      # no ./station.yaml
    monkeypatch.delenv("STATION_CONFIG", raising=False)
    assert main([a.replace("{tmp}", str(tmp_path)) for a in argv]) == 2
    err = capsys.readouterr().err
    assert expected in err and err.count("\n") == 1
