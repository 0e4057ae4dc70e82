"""One function computed in a forked child process while this one goes on.

`station diagnose` spends about as long importing the diagnosis (~0.1 s) as reading a 100 Hz
capture; the two do not depend on each other (`station estimate`, whose fit imports ~7 ms since
it needs no scipy, reads in its own process: a child costs more than that).  Two threads of one
interpreter would take turns at the GIL (both are mostly Python: measured 4 % faster than one
after the other); a forked child has its own interpreter, so the child reads while the parent
imports, on two cores.

``Forked(fn)`` forks at once; the child calls ``fn()`` and sends back its result or the
exception it raised (pickled); ``result()`` waits for it and returns it or raises that
exception, in this process, as if ``fn()`` had run here.  The child inherits everything this
process holds at the fork (nothing is copied to it) and must only return what it computed; it
is killed when this process ends, whatever ends it (no child outlives its parent).
``ChildLost`` when the child ended without sending anything (killed, out of memory), and
OSError from ``Forked()`` when no process can be forked: the caller then does the work itself.

Fork is used on Linux only (``available()``): macOS's system libraries are not safe to use in
a forked child, and Windows has no fork.  The child ignores Ctrl-C: the parent is interrupted,
and the ``with`` block (or ``close()``) ends the child.  Only the standard library is imported.
"""
from __future__ import annotations

import gc
import os
import pickle
import signal
import sys


class ChildLost(Exception):
    """The child ended without a result (killed by a signal, out of memory, ...)."""


def available() -> bool:
    return sys.platform.startswith("linux") and hasattr(os, "fork")


def usable_cores() -> int:
    """The cores this process may run on (its CPU affinity, e.g. under taskset or a container's
    cpuset), not the machine's count."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return max(1, os.cpu_count() or 1)


def end_with_parent(parent: int, sig: int = signal.SIGKILL) -> None:
    """In a child: be sent ``sig`` (by default killed) when ``parent`` ends, however it ends
    (prctl PR_SET_PDEATHSIG), so that no child outlives a parent killed by a signal; a parent
    already gone sends it now.  (Linux sends the signal when the *thread* that forked ends: fork
    from the thread that waits.)"""
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, int(sig), 0, 0, 0)                # 1: PR_SET_PDEATHSIG (linux/prctl.h)
    except (OSError, AttributeError):                   # no prctl: the pipe's EPIPE ends it later
        return
    if os.getppid() != parent:
        signal.raise_signal(sig)
        os._exit(0)


class Forked:
    """``with Forked(fn) as child: ...; value = child.result()``"""

    def __init__(self, fn):
        readable, writable = os.pipe()
        parent = os.getpid()
        pid = os.fork()
        if pid == 0:                                    # the child
            try:
                signal.signal(signal.SIGINT, signal.SIG_IGN)
                gc.disable()        # it lives for one function: the cyclic collector only costs time
                end_with_parent(parent)
                os.close(readable)
                try:
                    reply = (True, fn())
                except BaseException as e:              # noqa: BLE001 - raised again in the parent
                    reply = (False, e)
                try:
                    data = pickle.dumps(reply, protocol=pickle.HIGHEST_PROTOCOL)
                except Exception as e:                  # noqa: BLE001 - what could not be sent
                    data = pickle.dumps((False, RuntimeError(f"the result cannot be sent back: {e}")))
                with os.fdopen(writable, "wb") as pipe:
                    pipe.write(data)
            finally:
                os._exit(0)                             # no atexit handlers, no buffers flushed twice
        os.close(writable)
        self.pid, self._pipe = pid, os.fdopen(readable, "rb")

    def fileno(self) -> int:
        """The pipe the result comes through (select: readable once the child sends or ends)."""
        return self._pipe.fileno()

    def result(self):
        """What fn() returned in the child, or the exception it raised, raised here."""
        try:
            data = self._pipe.read()
        finally:
            self.close()
        if not data:
            raise ChildLost(f"the child process {self.pid} ended without a result")
        ok, value = pickle.loads(data)
        if not ok:
            raise value
        return value

    def close(self) -> None:
        """End the child if it still runs, and reap it."""
        if self.pid is None:
            return
        self._pipe.close()
        try:
            if os.waitpid(self.pid, os.WNOHANG) == (0, 0):
                os.kill(self.pid, signal.SIGKILL)
                os.waitpid(self.pid, 0)
        except ChildProcessError:
            pass
        self.pid = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False


def map_in_children(fn, items) -> list:
    """[fn(item) for item in items], each computed in a forked child, as many at a time as this
    process has cores (the next one started when any ends), the results in order; in this
    process where fork is not used, when no child can be forked, or when one is lost.  If fn
    raises, the exception of the first such item is raised here once all have ended."""
    import select

    items = list(items)
    if not available():
        return [fn(item) for item in items]
    outcomes = [None] * len(items)      # (True, value) or (False, exception)

    def here(i):
        try:
            return True, fn(items[i])
        except Exception as e:          # noqa: BLE001 - raised below, in the items' order
            return False, e

    running, started = {}, 0
    try:
        while started < len(items) or running:
            while started < len(items) and len(running) < usable_cores():
                try:
                    running[started] = Forked(lambda item=items[started]: fn(item))
                except OSError:                       # no process to spare: computed here
                    outcomes[started] = here(started)
                started += 1
            if not running:
                continue
            ready, _, _ = select.select(list(running.values()), [], [])
            for i in [i for i, child in running.items() if child in ready]:
                child = running.pop(i)
                try:
                    outcomes[i] = (True, child.result())
                except ChildLost:
                    outcomes[i] = here(i)
                except Exception as e:                # noqa: BLE001 - fn raised it in the child
                    outcomes[i] = (False, e)
    finally:
        for child in running.values():
            child.close()
    for ok, value in outcomes:
        if not ok:
            raise value
    return [value for _, value in outcomes]
