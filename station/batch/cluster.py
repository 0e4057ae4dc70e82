"""The Dask client a batch runs on: a local cluster (every usable core, one worker process per
core, one thread each) started and stopped by the batch, or an existing scheduler.

Dask is imported here, inside the functions, never at import time: ``station --help`` and
``import station`` do not pay for it (tests/test_cli_startup.py).

A local cluster is closed on every way out of the ``with`` block -- the batch done, a failure,
Ctrl-C (KeyboardInterrupt) -- so that no worker process outlives the command.  A scheduler
given by address is the user's: the batch only disconnects from it (its workers go on)."""
from __future__ import annotations

import contextlib
import logging
import os

from station.core.errors import UserError


#: the environment variable (Dask's configuration) that turns the workers' profiler off
PROFILE_ENV = "DASK_DISTRIBUTED__WORKER__PROFILE__ENABLED"


def _quiet() -> None:
    """Distributed logs every worker start and stop at INFO: the batch says what matters."""
    for name in ("distributed", "distributed.nanny", "distributed.scheduler", "distributed.worker",
                 "distributed.core", "distributed.http.proxy", "tornado", "bokeh"):
        logging.getLogger(name).setLevel(logging.ERROR)


def _users_profile_setting(dask) -> bool | None:
    """distributed.worker.profile.enabled as the user's Dask configuration sets it (its YAML files:
    ~/.config/dask, $DASK_CONFIG, ...; or $DASK_DISTRIBUTED__WORKER__PROFILE__ENABLED), None when
    it does not (Dask's own default is not the user's)."""
    user = dask.config.collect(paths=dask.config.paths, env=os.environ)
    value = user.get("distributed", {}).get("worker", {}).get("profile", {}).get("enabled")
    if value is None:
        return None
    if isinstance(value, str):
        return value.strip().lower() not in ("false", "0", "no", "off", "")
    return bool(value)


def _check_address(scheduler: str) -> str:
    if "://" not in scheduler:
        scheduler = f"tcp://{scheduler}"
    scheme = scheduler.split("://", 1)[0]
    if scheme not in ("tcp", "tls", "inproc", "ws", "wss", "ucx"):
        raise UserError(f"--scheduler {scheduler}: not a Dask scheduler address (tcp://HOST:8786)")
    return scheduler


#: the cluster's clockwork, slowed where a batch does not need Dask's defaults: the event loop's
#: tick monitor (20 ms: it only warns of a blocked loop), the workers' memory monitor (100 ms: 1 s
#: still pauses a worker over its memory limit within a second; a capture takes ~1 MB) and the
#: system monitor (500 ms: the dashboard's CPU and memory plots, which a batch does not serve).
#: An idle local cluster of two workers: 0.016 s of CPU per wall second in each worker and 0.035 s
#: in the command (scheduler, nannies) with Dask's defaults, 0.0027 s and 0.007 s with these; a
#: task's process CPU (Outcome.cpu_s) carries its worker's share: 0.49 s against 0.08 s over a
#: task that sleeps 30 s (27 Nov 2026, load 15; docs/fleet.md, Fourteenth session).  Each is kept
#: as the user's own Dask configuration sets it (YAML or environment), and local workers inherit
#: these through the environment.
CLOCKWORK = (("distributed.admin.tick.interval", "DASK_DISTRIBUTED__ADMIN__TICK__INTERVAL", "1s"),
             ("distributed.worker.memory.monitor-interval", "DASK_DISTRIBUTED__WORKER__MEMORY__MONITOR_INTERVAL", "1s"),
             ("distributed.admin.system-monitor.interval", "DASK_DISTRIBUTED__ADMIN__SYSTEM_MONITOR__INTERVAL", "2s"))


def _users_setting(dask, key: str):
    """``key`` (dotted) as the user's own Dask configuration sets it, None when it does not."""
    node = dask.config.collect(paths=dask.config.paths, env=os.environ)
    for part in key.split("."):
        if not isinstance(node, dict):
            return None
        node = node.get(part, node.get(part.replace("-", "_")))
    return node


def _slower_clockwork(dask) -> None:
    for key, env, value in CLOCKWORK:
        if _users_setting(dask, key) is None:
            os.environ.setdefault(env, value)
            dask.config.set({key: value})


@contextlib.contextmanager
def open_client(scheduler: str | None = None, workers: int | None = None):
    """``with open_client(...) as client``: a distributed.Client on the scheduler at ``scheduler``
    (an address such as tcp://HOST:8786), or on a LocalCluster of ``workers`` processes (default:
    every usable core) with one thread each, closed when the block ends however it ends."""
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")      # inherited by local workers' processes
    os.environ.setdefault("MKL_NUM_THREADS", "1")
    # a worker's statistical profiler walks the running task's stack every 10 ms: 7 % of a
    # capture's CPU in the workers (0.554 s against 0.513 s per capture, two 40-capture batches
    # side by side; docs/fleet.md, Throughput); its profiles are only seen on a dashboard, which
    # a batch does not serve.  Off unless the user's own Dask configuration (its YAML files or
    # the environment) says otherwise; local workers inherit it; remote ones are started by the user
    _quiet()
    import dask
    from distributed import Client, LocalCluster

    enabled = _users_profile_setting(dask)
    if enabled is None:
        enabled = False
        os.environ.setdefault(PROFILE_ENV, "False")
    dask.config.set({"distributed.worker.profile.enabled": enabled})
    _slower_clockwork(dask)

    if scheduler:
        address = _check_address(scheduler)
        try:
            # how long it tries: Dask's distributed.comm.timeouts.connect (30 s unless configured)
            client = Client(address)
        except (OSError, TimeoutError) as e:
            raise UserError(f"--scheduler {address}: cannot connect to the Dask scheduler "
                            f"({' '.join(str(e).split())[:160]})") from None
        try:
            yield client
        finally:
            client.close()
        return
    from station.core.forked import usable_cores

    n = max(1, workers or usable_cores())
    cluster = _start_local(LocalCluster, n)
    try:
        client = Client(cluster)
        try:
            yield client
        finally:
            client.close()
    finally:
        cluster.close()


# what the local cluster's worker processes log: only CRITICAL.  At ERROR a worker whose heartbeat
# was in flight while the cluster closed logged "Failed to communicate with scheduler during
# heartbeat" with its traceback on the batch's stderr (CI, at load ~10: test_batch's
# nothing-left-running test); what fails in a task reaches the batch through its future and is
# said in one line per capture, and a worker lost is the client's KilledWorker
WORKER_LOG_LEVEL = logging.CRITICAL


def _start_local(LocalCluster, n: int):
    """A LocalCluster whose worker processes ignore Ctrl-C: a terminal sends it to the whole
    foreground process group, and each worker would print its own traceback; this process gets
    it too, and ends them by closing the cluster.  (SIGINT ignored while the workers are spawned:
    a disposition a child keeps through exec, and Python then installs no handler of its own.
    A Ctrl-C in the second or two the cluster takes to start is not seen: press it again.)"""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        return LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None,
                            silence_logs=WORKER_LOG_LEVEL)
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None,
                               silence_logs=WORKER_LOG_LEVEL)
    finally:
        signal.signal(signal.SIGINT, previous)
    return cluster


def worker_count(client) -> int:
    """The threads the cluster computes with (a task per thread at a time)."""
    return max(1, sum(client.nthreads().values()))
