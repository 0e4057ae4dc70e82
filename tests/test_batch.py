"""station batch on real Dask clusters (issue 29 items 2 and 5): a `dask scheduler` and two
`dask worker` processes started here on loopback; the local-cluster default; a bad capture is
one line and the others complete; a batch killed (SIGKILL) or interrupted (Ctrl-C) leaves no
process behind, and the next batch resumes where it stopped.  `station montecarlo --scheduler`
on the same cluster.  Every process started here is ended in a finalizer."""
from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

import dask_processes
from dask_processes import kill_session
from processes import running
from server_guard import guard, session_members
from station import api
from station.batch.cluster import CLOCKWORK

ROOT = Path(__file__).resolve().parents[1]
GOOD = 3
SHORT = {"dwell_s": 5.0, "rotation_s": 5.0}      # 21 segments, ~0.65 MB, ~0.25 s of CPU to estimate


def _env(tmp_path) -> dict:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    env["STATION_HISTORY_DIR"] = str(tmp_path / "store")
    return env


@pytest.fixture(scope="module")
def captures(tmp_path_factory):
    """GOOD simulated captures (seeds 1..GOOD) and one whose manifest is not a capture's."""
    root = tmp_path_factory.mktemp("batch-captures")
    for i in range(GOOD):
        api.simulate("optimal9", root / f"cap{i}", seed=1 + i, **SHORT)
    (root / "bad").mkdir()
    (root / "bad" / "manifest.yaml").write_text("format: not-a-capture\n")
    return root


def _copy(captures, tmp_path, names=None) -> Path:
    dest = tmp_path / "caps"
    for p in sorted(captures.iterdir()):
        if names is None or p.name in names:
            shutil.copytree(p, dest / p.name)
    return dest


def _wait_session_empty(sid: int, seconds: float = 30.0) -> list[int]:
    deadline = time.monotonic() + seconds
    while session_members(sid) and time.monotonic() < deadline:
        time.sleep(0.1)
    return session_members(sid)


def _start(args, tmp_path, cwd=None) -> subprocess.Popen:
    """A command in its own session (as a terminal starts it), Ctrl-C at its default action."""
    return subprocess.Popen([sys.executable, "-m", "station.cli", *map(str, args)], cwd=cwd or tmp_path,
                            env=_env(tmp_path), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: (signal.signal(signal.SIGINT, signal.SIG_DFL), os.setsid()))


@pytest.fixture
def started(request):
    """start(popen) registers a process session to be killed at the end of the test (and by a
    guard, tests/server_guard.py, if pytest is killed first: a batch's local cluster with it)."""
    sessions, guards = [], []

    def start(p):
        sessions.append(p)
        guards.append(guard(sessions=[p.pid], sig=signal.SIGKILL, grace_s=0.0))

    yield start
    for p in sessions:
        kill_session(p.pid)
        if p.poll() is None:
            p.kill()
        p.wait(timeout=30)
        for f in (p.stdout, p.stderr):
            if f:
                f.close()
    for g in guards:
        g.release()


def _records(state: Path) -> list[dict]:
    if not state.exists():
        return []
    out = []
    for line in state.read_text().splitlines():
        try:
            out.append(json.loads(line))
        except ValueError:
            pass
    return out


def _failed_lines(stderr: str) -> list[str]:
    return [line for line in stderr.splitlines() if line.startswith("failed: ")]


def _check_outcome(caps: Path, r_stdout: str, stderr: str) -> None:
    """The three good captures calibrated, the bad one said in one line (naming it and the
    manifest's field), no traceback."""
    for i in range(GOOD):
        doc = api.load_calibration(caps / f"cap{i}" / "calibration.yaml")
        assert doc["verdict"]["result"] in ("passes", "noise overestimated"), doc["verdict"]
    failed = _failed_lines(stderr)
    assert len(failed) == 1, stderr
    assert f"{caps / 'bad'}" in failed[0] and "manifest.yaml" in failed[0] and "'format'" in failed[0]
    assert "Traceback" not in stderr
    assert not (caps / "bad" / "calibration.yaml").exists()


# --------------------------------------------------------------------------- a real cluster


@pytest.fixture(scope="module")
def dask_cluster(tmp_path_factory):
    """`dask scheduler` and two `dask worker` processes on loopback (ports chosen by the
    scheduler, its address read from the scheduler file), each guarded against a killed pytest
    (tests/dask_processes.py); ended in the finalizer."""
    d = tmp_path_factory.mktemp("dask")
    with dask_processes.cluster(d, _env(d), workers=2) as (address, worker_pids, _):
        yield address, worker_pids


def test_batch_on_a_scheduler_and_two_worker_processes(dask_cluster, captures, tmp_path, started):
    address, worker_pids = dask_cluster
    caps = _copy(captures, tmp_path)
    p = _start(["batch", "estimate", caps / "cap*", caps / "bad", "--scheduler", address], tmp_path)
    started(p)
    stdout, stderr = p.communicate(timeout=240)
    assert p.returncode == 2, stderr            # one capture was bad input
    _check_outcome(caps, stdout, stderr)
    assert f"on {address}" in stdout and "2 worker thread(s)" in stdout
    records = _records(tmp_path / ".station-batch-estimate.jsonl")
    assert len(records) == GOOD + 1
    # computed by the worker processes, not by the command
    assert {int(r["worker"].rsplit(":", 1)[1]) for r in records} <= worker_pids
    # the cluster is the user's: still there, its two workers too
    assert all(running(pid) for pid in worker_pids)


# nine 5 s statics and a turn about each body axis at 72 deg/s: all 21 base parameters determined; four
# dry runs and the bound 1.0 s of CPU against 1.9 s for optimal9 (the tasks' placement is checked)
SHORT_SCHEME = """\
name: short
defaults: {dwell_s: 5.0, rate_dps: 72.0, rotation_s: 5.0}
segments:
""" + "".join(f"  - {{static: s{i}, up_body: {u}}}\n" for i, u in enumerate(
    ([0, 0, 1], [0, 0, -1], [1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [1, 1, 0], [0, 1, 1], [1, 0, 1]))) + \
    "".join(f"  - {{rotation: r{a}, axis_body: {v}}}\n" for a, v in zip("xyz", ([1, 0, 0], [0, 1, 0], [0, 0, 1])))


def test_montecarlo_on_the_scheduler(dask_cluster, tmp_path):
    address, worker_pids = dask_cluster
    (tmp_path / "short.yaml").write_text(SHORT_SCHEME)
    r = subprocess.run([sys.executable, "-m", "station.cli", "montecarlo", "--scheme", "short.yaml", "--runs", "4",
                        "--scheduler", address, "--json"], cwd=tmp_path, env=_env(tmp_path), capture_output=True,
                       text=True, timeout=240)
    assert r.returncode == 0, r.stderr
    assert f"2 Dask worker thread(s) at {address}" in r.stderr
    doc = json.loads(r.stdout)
    assert doc["runs"] == 4 and len(doc["parameters"]) == 21
    assert all(row["crlb"] > 0 and row["std"] > 0 for row in doc["parameters"])


def test_design_on_the_scheduler(dask_cluster, tmp_path):
    """station design --scheduler: the predictions (the design's and a built-in scheme's) and the
    verification's noisy dry runs are Dask tasks on the workers; the scheme file written as ever.
    (A 450 s budget and one exchange pass: every parameter determined; the command 2.6 s of CPU
    on this machine's cores against 3.6 s at 700 s and three passes, 6.8 s at 1200 s: the tasks'
    placement is what is checked here, not the search, which tests/test_design.py checks.)"""
    address, worker_pids = dask_cluster
    r = subprocess.run([sys.executable, "-m", "station.cli", "design", "--duration", "450", "-o", "d.yaml",
                        "--rates", "30,100", "--revolutions", "1", "--dwells", "10,30", "--passes", "1",
                        "--compare", "optimal9", "--verify-runs", "2", "--statics", "unknown",
                        "--scheduler", address, "--json"],
                       cwd=tmp_path, env=_env(tmp_path), capture_output=True, text=True, timeout=240)
    assert r.returncode == 0, r.stderr[-3000:]
    assert f"design: on the Dask scheduler {address}" in r.stderr and "one Dask task per scheme" in r.stderr
    assert "2 noisy dry runs of the design" in r.stderr
    doc = json.loads(r.stdout)
    assert doc["designed"]["parameters"] and doc["builtins"][0]["scheme"] == "optimal9"
    assert (tmp_path / "d.yaml").exists()
    assert all(running(pid) for pid in worker_pids)        # the cluster is the test's: left running


def test_an_unreachable_scheduler_is_one_line(tmp_path, captures):
    import socket

    with socket.socket() as s:            # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    env = _env(tmp_path)
    # (how long distributed retries a refused connection: nobody listens, so every retry is
    # refused at once and the outcome is the same at any timeout; 0.3 s instead of 2 s waited out)
    env["DASK_DISTRIBUTED__COMM__TIMEOUTS__CONNECT"] = "0.3s"
    r = subprocess.run([sys.executable, "-m", "station.cli", "batch", "estimate", captures / "cap0",
                        "--scheduler", f"tcp://127.0.0.1:{port}"], cwd=tmp_path, env=env, capture_output=True,
                       text=True, timeout=120)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert "cannot connect to the Dask scheduler" in r.stderr and len(r.stderr.strip().splitlines()) == 1


# --------------------------------------------------------------------------- the local cluster


def test_local_cluster_by_default_nothing_left_running(captures, tmp_path, started):
    caps = _copy(captures, tmp_path)
    out = tmp_path / "out"
    p = _start(["batch", "estimate", caps, "-o", out], tmp_path)
    started(p)
    stdout, stderr = p.communicate(timeout=240)
    assert p.returncode == 2, stderr
    assert _wait_session_empty(p.pid) == []            # the local cluster's workers ended with it
    for i in range(GOOD):
        assert api.load_calibration(out / f"cap{i}.calibration.yaml")["verdict"]["result"] != "fails"
    assert len(_failed_lines(stderr)) == 1 and "Traceback" not in stderr
    assert "on a local cluster" in stdout
    # filed as the single commands file: the simulated IMUs into the simulations' own store
    sim_store = tmp_path / "store-simulations"
    assert len(list(sim_store.glob("SIM-*/*.yaml"))) == GOOD


def _run_until_records(args, tmp_path, state: Path, n: int, started) -> subprocess.Popen:
    p = _start(args, tmp_path)
    started(p)
    deadline = time.monotonic() + 180
    while len(_records(state)) < n and p.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
    assert p.poll() is None, f"the batch ended before it could be stopped: {p.communicate()}"
    assert len(_records(state)) >= n
    return p


def test_a_killed_batch_resumes_where_it_stopped(dask_cluster, captures, tmp_path, started):
    """Killed with SIGKILL after its first result, on the running cluster (whose workers are
    warm: no cluster to start twice), then run again."""
    address, _ = dask_cluster
    n = 8
    caps = _copy(captures, tmp_path, names={f"cap{i}" for i in range(GOOD)})
    for i in range(GOOD, n):                     # eight captures on two workers: killed midway
        shutil.copytree(caps / f"cap{i % GOOD}", caps / f"cap{i}")
    out = tmp_path / "out"
    state = out / ".station-batch-estimate.jsonl"
    args = ["batch", "estimate", caps, "-o", out, "--scheduler", address, "--no-history"]
    p = _run_until_records(args, tmp_path, state, 1, started)
    os.killpg(p.pid, signal.SIGKILL)
    p.wait(timeout=30)
    done_before = {r["source"] for r in _records(state) if r["status"] == "done"}
    assert 1 <= len(done_before) < n
    # one capture finished before the kill is changed since (a segment file touched): done again
    changed = sorted(done_before)[0]
    seg = Path(changed) / "pos01.csv"
    os.utime(seg, ns=(seg.stat().st_atime_ns, seg.stat().st_mtime_ns + 10**9))
    kept = {s: (out / f"{Path(s).name}.calibration.yaml").read_bytes() for s in done_before - {changed}}
    r = subprocess.run([sys.executable, "-m", "station.cli", *map(str, args)], cwd=tmp_path, env=_env(tmp_path),
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    last = {rec["source"]: rec["status"] for rec in _records(state)[-n:]}
    assert set(last) == {str(caps / f"cap{i}") for i in range(n)}
    assert {s for s, st in last.items() if st == "skipped"} == done_before - {changed}
    assert {s for s, st in last.items() if st == "done"} == set(last) - done_before | {changed}
    for s, data in kept.items():                  # not computed again: the same bytes
        assert (out / f"{Path(s).name}.calibration.yaml").read_bytes() == data
    assert "skipped (by an earlier batch)" in r.stdout


def test_ctrl_c_ends_the_batch_and_its_cluster(captures, tmp_path, started):
    caps = _copy(captures, tmp_path, names={f"cap{i}" for i in range(GOOD)})
    for i in range(GOOD, 8):
        shutil.copytree(caps / f"cap{i % GOOD}", caps / f"cap{i}")
    state = tmp_path / ".station-batch-diagnose.jsonl"
    p = _run_until_records(["batch", "diagnose", caps, "--workers", "1"], tmp_path, state, 1, started)
    os.killpg(p.pid, signal.SIGINT)              # as a terminal's Ctrl-C: the whole foreground group
    stdout, stderr = p.communicate(timeout=60)
    assert p.returncode == 130, stderr
    assert "interrupted" in stderr and "Traceback" not in stderr
    assert _wait_session_empty(p.pid) == []


# --------------------------------------------------------------------------- inputs and state (no cluster)


def test_inputs_globs_folders_and_names(captures, tmp_path):
    from station.batch import inputs
    from station.core.errors import UserError

    caps = _copy(captures, tmp_path)
    both = inputs.expand([str(caps / "cap*"), str(caps / "cap0"), str(caps)])
    assert both == [str(caps / f"cap{i}") for i in range(GOOD)] + [str(caps / "bad")]   # each once
    with pytest.raises(UserError, match="no capture matches"):
        inputs.expand([str(caps / "nothing*")])
    with pytest.raises(UserError, match="neither a capture"):
        inputs.expand([str(tmp_path)])
    (tmp_path / "other").mkdir()
    shutil.copytree(caps / "cap0", tmp_path / "other" / "cap0")
    items = inputs.plan("estimate", [str(caps / "cap0"), str(tmp_path / "other" / "cap0"), str(caps / "cap1")],
                        tmp_path / "o")
    names = [Path(i.output).name for i in items]
    assert len(set(names)) == 3 and names[2] == "cap1.calibration.yaml"       # same names told apart
    assert [Path(i.output).name for i in inputs.plan("diagnose", [str(caps / "cap1")])] == ["diagnosis.json"]
    exp = inputs.plan("export", [str(caps / "cap1")], tmp_path / "o", "imu_tk")[0]
    assert exp.calibrations == (str(tmp_path / "o" / "cap1.calibration.yaml"), str(caps / "cap1" / "calibration.yaml"))


def test_history_query_finds_the_captures_of_stored_calibrations(captures, tmp_path):
    from station.batch import inputs
    from station.core.errors import UserError
    from station.io.history import Store

    est = api.estimate(captures / "cap1")
    cal = est.save(tmp_path / "cal.yaml")
    Store(tmp_path / "store").file(cal)
    serial = est.provenance["imu_serial"]
    assert inputs.from_history([serial], tmp_path / "store") == [str((captures / "cap1").resolve())]
    assert inputs.from_history(["all"], tmp_path / "store") == [str((captures / "cap1").resolve())]
    with pytest.raises(UserError, match="no calibration of this IMU serial"):
        inputs.from_history(["NOPE"], tmp_path / "store")


def test_state_file_skips_only_what_is_done_and_survives_a_cut_line(tmp_path):
    from station.batch.state import State, item_key, options_key
    from station.batch.tasks import DONE, FAILED, Outcome

    path = tmp_path / "s.jsonl"
    k = options_key("estimate", {"method": "auto"})
    assert k != options_key("estimate", {"method": "lsq"})         # other options: other records
    with State(path) as st:
        st.record(item_key(k, "a", "a/out"), Outcome("a", DONE, outputs=["a/out"], output_sha256="x"))
        st.record(item_key(k, "b", "b/out"), Outcome("b", FAILED, "bad"))
    with open(path, "a") as f:
        f.write('{"key": "cut sh')                                  # a kill in the middle of a line
    st = State(path)
    assert st.previous(item_key(k, "a", "a/out"))["output_sha256"] == "x"
    assert st.previous(item_key(k, "b", "b/out")) is None           # failed: run again
    assert State(path, fresh=True).previous(item_key(k, "a", "a/out")) is None


def test_a_worker_task_never_raises(tmp_path, monkeypatch):
    """The task itself (as a worker runs it): a missing capture, a bad one and a good one.  Run
    here, its once-per-worker setup sets $STATION_READ_IN_PROCESS in this process: set through
    monkeypatch, so that it is undone for the tests after it (it made the forked reader's test,
    in the same pytest worker, read in process)."""
    from station.batch.tasks import FAILED, Job, run

    monkeypatch.setenv("STATION_READ_IN_PROCESS", "1")

    missing = run(Job("estimate", str(tmp_path / "none"), str(tmp_path / "o.yaml"), {}))
    assert missing.status == FAILED and "none" in missing.message and "\n" not in missing.message
    (tmp_path / "bad").mkdir()
    (tmp_path / "bad" / "manifest.yaml").write_text("[unclosed\n")
    bad = run(Job("diagnose", str(tmp_path / "bad"), str(tmp_path / "d.json"), {}))
    assert bad.status == FAILED and "manifest.yaml" in bad.message
    assert not (tmp_path / "d.json").exists()


_PROFILER_PROBE = '''
import os

def probe():
    import dask
    return (dask.config.get("distributed.worker.profile.enabled"),
            *(str(dask.config.get(k)) for k in ("distributed.admin.tick.interval",
                                                "distributed.worker.memory.monitor-interval",
                                                "distributed.admin.system-monitor.interval")))

if __name__ == "__main__":
    from station.batch.cluster import open_client
    with open_client(workers=1) as client:
        print(sorted(set(client.run(probe).values())))
'''


@pytest.mark.parametrize("user_yaml, expected", [
    (None, "[(False, '1s', '1s', '2s')]"),
    ("true", "[(True, '20ms', '1s', '2s')]")], ids=["off-by-default", "the-users-dask-yaml-wins"])
def test_the_workers_profiler_is_off_unless_the_users_dask_configuration_turns_it_on(tmp_path, user_yaml, expected):
    """The local cluster's workers run without Dask's statistical profiler (7 % of their CPU,
    docs/fleet.md) and with its clockwork slowed (the event loop's tick monitor 1 s, not 20 ms; the
    memory monitor 1 s, not 100 ms; the system monitor 2 s, not 500 ms: cluster.CLOCKWORK), unless
    the user's own Dask configuration says otherwise: a setting in their YAML (here $DASK_CONFIG:
    the profiler on and the tick at 20 ms) is theirs and is kept, in the workers too."""
    script = tmp_path / "probe.py"
    script.write_text(_PROFILER_PROBE)
    env = _env(tmp_path)
    env.pop("DASK_DISTRIBUTED__WORKER__PROFILE__ENABLED", None)
    for _, variable, _ in CLOCKWORK:       # set in this process by an earlier open_client: not the user's
        env.pop(variable, None)
    env["DASK_CONFIG"] = str(tmp_path / "dask")
    (tmp_path / "dask").mkdir()
    if user_yaml is not None:
        (tmp_path / "dask" / "mine.yaml").write_text(f"distributed:\n  worker:\n    profile:\n      enabled: {user_yaml}\n"
                                                     "  admin:\n    tick:\n      interval: 20ms\n")
    done = subprocess.run([sys.executable, str(script)], env=env, cwd=tmp_path, capture_output=True, text=True,
                          timeout=180)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.strip().splitlines()[-1] == expected, done.stdout + done.stderr[-2000:]
