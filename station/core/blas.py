"""How many BLAS threads the estimation runs with (one, unless STATION_BLAS_THREADS says more).

The fits' matrices are small (a few hundred rows): more threads only contend, badly so on a
loaded machine (`diagnose --auto`: 4.8 s of CPU with one thread, 14.8 s with two on two busy
cores; tests/test_effects_recovered.py in one process: 12.5 s against 41-50 s at a load of 12).
The command line limits the whole process (station/cli/app.py); the Python API limits each call
and restores the caller's setting after it (:func:`limited`)."""
from __future__ import annotations

import contextlib
import functools
import os


def blas_threads() -> int:
    """STATION_BLAS_THREADS, default 1 (a value that is not a positive integer counts as 1)."""
    try:
        return max(1, int(os.environ.get("STATION_BLAS_THREADS", "1")))
    except ValueError:
        return 1


@contextlib.contextmanager
def limited_blas():
    """BLAS libraries already loaded run with :func:`blas_threads` threads inside the block
    (threadpoolctl; about 5 ms to enter)."""
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=blas_threads(), user_api="blas"):
        yield


def limited(function):
    """``function`` run inside :func:`limited_blas`."""
    @functools.wraps(function)
    def wrapper(*args, **kwargs):
        with limited_blas():
            return function(*args, **kwargs)
    return wrapper
