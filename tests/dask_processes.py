"""A real Dask cluster for the tests: a `dask scheduler` and `dask worker` processes (each with
its nanny) on loopback, each in a session of its own, each guarded (tests/server_guard.py): a
pytest killed before its finalizers run leaves none of them running."""
from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from server_guard import guard, session_members


def kill_session(sid: int) -> None:
    for pid in session_members(sid):
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass


@contextlib.contextmanager
def cluster(directory: Path, env: dict, workers: int = 2, on_started=None):
    """``with cluster(d, env) as (address, worker_pids, procs)``: the scheduler (port chosen by it,
    its address read from the scheduler file in ``d``) and ``workers`` one-thread workers, all
    connected; ended (their sessions killed) when the block ends.  ``on_started(procs)`` is
    called once the processes are started and guarded (before the workers are connected)."""
    dask = [sys.executable, "-m", "distributed.cli.dask_scheduler"]
    sched_file = directory / "scheduler.json"
    procs, guards, logs = [], [], []

    def spawn(cmd, name):
        log = open(directory / f"{name}.log", "w")
        logs.append(log)
        p = subprocess.Popen(cmd, cwd=directory, env=env, stdout=log, stderr=subprocess.STDOUT,
                             stdin=subprocess.DEVNULL, start_new_session=True)
        procs.append(p)
        # killed outright (the session: a nanny's worker process too): with the tests gone nobody
        # waits for a graceful close, which takes a loaded machine seconds
        guards.append(guard(sessions=[p.pid], sig=signal.SIGKILL, grace_s=0.0))
        return p

    try:
        spawn(dask + ["--host", "127.0.0.1", "--port", "0", "--no-dashboard", "--scheduler-file", sched_file],
              "scheduler")
        # the workers started at once: each waits for the scheduler file (distributed's
        # json_load_robust), their imports overlapping the scheduler's
        for k in range(workers):
            spawn([sys.executable, "-m", "distributed.cli.dask_worker", "--scheduler-file", sched_file,
                   "--host", "127.0.0.1", "--nthreads", "1", "--nworkers", "1", "--no-dashboard",
                   "--name", f"w{k}"], f"worker{k}")
        if on_started is not None:
            on_started(procs)
        # the file appears before its JSON is written whole (seen in CI: read empty): read until it
        # parses, as distributed's own json_load_robust does
        deadline, address = time.monotonic() + 60, None
        while address is None and time.monotonic() < deadline:
            try:
                address = json.loads(sched_file.read_text())["address"]
            except (FileNotFoundError, ValueError, KeyError):
                time.sleep(0.05)
        assert address is not None, (directory / "scheduler.log").read_text()
        from distributed import Client

        with Client(address, timeout=60) as client:
            client.wait_for_workers(workers, timeout=120)
            worker_pids = set(client.run(os.getpid).values())
        yield address, worker_pids, procs
    finally:
        for p in reversed(procs):
            kill_session(p.pid)
            p.wait(timeout=30)
        for g in guards:
            g.release()
        for log in logs:
            log.close()
