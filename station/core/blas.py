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
import sys

# BLAS libraries read their thread count when they are loaded: numpy's and scipy's OpenBLAS (MKL
# in some distributions).  Not OMP_NUM_THREADS: pyarrow's CSV engine sizes its pool by it.
THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")

# the thread count every BLAS library of this process starts with, while a command runs that set
# it before any was loaded (whole_process); None otherwise
_whole_process: int | None = None


def blas_threads() -> int:
    """STATION_BLAS_THREADS, default 1 (a value that is not a positive integer counts as 1)."""
    try:
        return max(1, int(os.environ.get("STATION_BLAS_THREADS", "1")))
    except ValueError:
        return 1


@contextlib.contextmanager
def whole_process(threads: int):
    """A command's whole run with ``threads`` BLAS threads (the command line, station/cli/app.py).
    The commands import numpy and scipy only when they need them, and threadpoolctl limits only
    the libraries already loaded: the limit is given to those not loaded yet through the
    variables they read when they load (left alone when the user set them).  When no BLAS library
    is loaded yet and those variables say ``threads``, every library loaded in the block starts
    with that many threads, so threadpoolctl is neither imported nor asked (issue 27: ~5 ms of a
    small estimate, once here and once per limited call); else the loaded ones are limited by it.
    Without the limit a 200 x 100 SVD in the fit spanned two OpenBLAS threads on a busy machine:
    6 s of CPU for one `station estimate` instead of 0.8 s."""
    global _whole_process
    for name in THREAD_VARIABLES:
        os.environ.setdefault(name, str(threads))
    loaded = "numpy" in sys.modules or "scipy" in sys.modules
    if not loaded and all(os.environ.get(name) == str(threads) for name in THREAD_VARIABLES):
        previous, _whole_process = _whole_process, threads
        try:
            yield
        finally:
            _whole_process = previous
        return
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=threads, user_api="blas"):
        yield


@contextlib.contextmanager
def limited_blas(threads: int | None = None):
    """BLAS libraries already loaded run with ``threads`` (default :func:`blas_threads`) threads
    inside the block (threadpoolctl; about 5 ms to enter), unless every one of them was loaded
    with that many inside :func:`whole_process`."""
    threads = blas_threads() if threads is None else threads
    if _whole_process == threads:
        yield
        return
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=threads, user_api="blas"):
        yield


def limited(function):
    """``function`` run inside :func:`limited_blas`."""
    @functools.wraps(function)
    def wrapper(*args, **kwargs):
        with limited_blas():
            return function(*args, **kwargs)
    return wrapper
