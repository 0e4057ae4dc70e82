"""Servers a test starts never outlive a killed pytest (issue 29, test infrastructure;
tests/server_guard.py).  A pytest (with one xdist worker, as the suite runs: `-n`) runs a test
that starts the long-lived servers the suite starts -- a PostgreSQL server through
tests/pg_server.py, a `dask scheduler` and a `dask worker` (nanny and worker process) through
tests/dask_processes.py as tests/test_batch.py does, and `station sim serve` guarded as
tests/test_probe.py guards it -- writes their pids and hangs.  The controlling pytest is then
killed with SIGKILL (no finalizer runs): every server's process must end within a few seconds,
and the PostgreSQL folder must be gone."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

import pg_server
from server_guard import alive, session_members, start_time

ROOT = Path(__file__).resolve().parents[1]

INNER = '''
import json, os, signal, subprocess, sys, threading, time
from pathlib import Path

import dask_processes
import pg_server
from server_guard import guard, session_members

OUT = Path(os.environ["GUARD_TEST_PIDS"])


def children(pid):
    try:
        with open(f"/proc/{pid}/task/{pid}/children") as f:
            return [int(x) for x in f.read().split()]
    except OSError:
        return []


def test_servers_then_hang(tmp_path):
    pids = {}
    server = None
    if pg_server.unavailable() is None:       # initdb and its start while the others start
        server = pg_server.Server()
        starting = threading.Thread(target=server.start)
        starting.start()
    serve = subprocess.Popen([sys.executable, "-m", "station.cli", "sim", "serve", "--speed", "50"],
                             stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    guarded = guard(pids=[serve.pid], sig=signal.SIGTERM, grace_s=3.0)
    pids["station sim serve"] = [serve.pid]

    def hang(procs):
        assert serve.stdout.readline().startswith("table: ")      # serving (started beside the others)
        # the scheduler, and the worker's nanny once it has started its worker process (not yet
        # connected: what is guarded is the same from then on, and connecting costs seconds)
        deadline = time.monotonic() + 120
        while len(session_members(procs[1].pid)) < 2 and time.monotonic() < deadline:
            time.sleep(0.02)
        pids["dask scheduler and worker"] = sorted(m for p in procs for m in session_members(p.pid))
        if server is not None:
            starting.join()
            post = int((server.dir / "data" / "postmaster.pid").read_text().split()[0])
            pids["postgres"] = [post, *children(post)]
            pids["postgres folder"] = str(server.dir)
        tmp = OUT.with_suffix(".tmp")
        tmp.write_text(json.dumps(pids))
        tmp.rename(OUT)
        time.sleep(600)           # killed here: no finalizer runs

    with dask_processes.cluster(tmp_path, dict(os.environ), workers=1, on_started=hang):
        pass
'''


def test_a_killed_pytest_leaves_no_server_running(tmp_path):
    why = pg_server.unavailable()
    if why and os.environ.get("STATION_REQUIRE_POSTGRES") == "1":
        pytest.fail(f"STATION_REQUIRE_POSTGRES=1 but {why}")
    (tmp_path / "test_inner.py").write_text(INNER)
    (tmp_path / "pytest.ini").write_text("[pytest]\n")
    record = tmp_path / "pids.json"
    env = dict(os.environ, GUARD_TEST_PIDS=str(record),
               PYTHONPATH=os.pathsep.join([str(ROOT), str(ROOT / "tests")]))
    inner = subprocess.Popen([sys.executable, "-m", "pytest", "-q", "-n", "1", "-p", "no:cacheprovider",
                              "-c", str(tmp_path / "pytest.ini"), "--rootdir", str(tmp_path),
                              str(tmp_path / "test_inner.py")],
                             cwd=tmp_path, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                             stdin=subprocess.DEVNULL, start_new_session=True)
    pids, started = {}, {}
    try:
        deadline = time.monotonic() + 180
        while not record.exists() and inner.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        assert record.exists(), f"the inner pytest started no server: {inner.communicate(timeout=60)[0][-3000:]}"
        pids = json.loads(record.read_text())
        folder = pids.pop("postgres folder", None)
        assert pids["station sim serve"] and len(pids["dask scheduler and worker"]) >= 3   # scheduler, nanny, worker
        if why is None:
            assert pids["postgres"] and Path(folder).is_dir()
        # who each pid is (its start time): a pid the system gives to another process after the
        # server's ends is neither counted as the server nor killed below
        started.update({pid: start_time(pid) for group in pids.values() for pid in group})
        assert all(alive(pid, started[pid]) for group in pids.values() for pid in group)

        inner.kill()                          # SIGKILL to the controlling pytest alone, as it happened
        killed = time.monotonic()
        inner.wait(timeout=30)
        # the guards stop each server (SIGQUIT / SIGTERM, SIGKILL after 3-5 s): well within 20 s
        deadline = killed + 20
        left = {name: [p for p in group if alive(p, started[p])] for name, group in pids.items()}
        while any(left.values()) and time.monotonic() < deadline:
            time.sleep(0.05)
            left = {name: [p for p in group if alive(p, started[p])] for name, group in left.items()}
        took = time.monotonic() - killed
        assert not any(left.values()), f"still running {took:.1f} s after pytest was killed: {left}"
        if folder:
            while Path(folder).exists() and time.monotonic() < deadline:
                time.sleep(0.05)
            assert not Path(folder).exists(), f"the PostgreSQL folder {folder} is left"
    finally:
        # what the inner pytest left of its own (its xdist worker, asleep) and, if the check
        # failed, the servers: the test's processes only (the inner session and the pids it wrote)
        for pid in session_members(inner.pid):
            os.kill(pid, signal.SIGKILL)
        for pid in (p for group in pids.values() for p in group):
            if pid in started and alive(pid, started[pid]):
                os.kill(pid, signal.SIGKILL)
        if inner.poll() is None:
            inner.kill()
        inner.wait(timeout=30)
        inner.stdout.close()
