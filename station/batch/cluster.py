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
                            silence_logs=logging.ERROR)
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None,
                               silence_logs=logging.ERROR)
    finally:
        signal.signal(signal.SIGINT, previous)
    return cluster


def worker_count(client) -> int:
    """The threads the cluster computes with (a task per thread at a time)."""
    return max(1, sum(client.nthreads().values()))
