"""Servers a test starts never outlive the test process (issue 29, test infrastructure).

A fixture's finalizer stops its server, but a pytest killed with SIGKILL (or by the OOM killer,
or SIGTERM, which Python does not turn into an exception) runs no finalizer: a PostgreSQL server
started by tests/pg_server.py stayed up for hours after a helper's pytest was killed, and the
Dask scheduler and workers of tests/test_batch.py run in sessions of their own, which no signal
to pytest's process group reaches.

``guard(...)`` starts one small guard process per server (this file run as a script: the
standard library only, ``python -I -S``, ~20 ms) in a session of its own, so that a Ctrl-C or a
kill of pytest's process group does not take it down first.  It waits, with no polling, on
pidfds (Linux >= 5.3; elsewhere it looks every 0.1 s) for the test process (and, under
pytest-xdist, the controlling pytest whose worker it is) to end.  When one ends it stops the
server: ``signal`` (SIGQUIT for PostgreSQL: an immediate shutdown, as ``pg_ctl stop -m
immediate``; SIGTERM for Dask) to each target -- a pid, the pid in a pid file (PostgreSQL's
``postmaster.pid``: guarded before ``pg_ctl start`` is run, so that no moment of the start is
unguarded), or every process of a session (a command started with ``start_new_session``, and
all it started) -- then SIGKILL to whatever is left after ``grace_s``, and the folders in
``remove`` deleted.  The fixture that stops its server itself calls ``Guard.release()``
afterwards: the guard ends and does nothing.

A pid is signalled through its pidfd (never a recycled pid); the watched test processes are
identified by pid and start time, so a pid reused before the guard opened it is seen as ended.
"""
from __future__ import annotations

import os
import select
import shutil
import signal
import subprocess
import sys
import time

HERE = os.path.abspath(__file__)


# ----------------------------------------------------------------------------- /proc helpers


def _stat(pid: int) -> list[str] | None:
    """/proc/PID/stat's fields after the command name (state first), None if there is no such process."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()
    except (OSError, IndexError):
        return None


def start_time(pid: int) -> str | None:
    """The process' start time (clock ticks after boot): with the pid, who it is."""
    fields = _stat(pid)
    return fields[19] if fields else None


def alive(pid: int, started: str | None = None) -> bool:
    """Running (not a zombie) and, given ``started``, the same process that started then."""
    fields = _stat(pid)
    return bool(fields) and fields[0] != "Z" and (started is None or fields[19] == started)


def session_members(sid: int) -> list[int]:
    """Every live process of session ``sid``."""
    found = []
    for name in os.listdir("/proc"):
        if name.isdigit():
            fields = _stat(int(name))
            if fields and fields[0] != "Z" and int(fields[3]) == sid:
                found.append(int(name))
    return found


# ----------------------------------------------------------------------------- the guard process


def _open(pid: int, started: str | None) -> int | None:
    """A pidfd of the process (None: it has ended, or the pid is another process' now)."""
    try:
        fd = os.pidfd_open(pid)
    except ProcessLookupError:
        return None
    if not alive(pid, started):              # ended (or the pid reused) before it was opened
        os.close(fd)
        return None
    return fd


def _wait(watched: list[tuple[int, str]], targets: list[int]) -> bool:
    """Wait until one of the watched (pid, start time) has ended (True: stop the server), or
    every one of ``targets`` (pids, when given) has (False: the server ended on its own, nothing
    to do); at once if that is so already."""
    if not hasattr(os, "pidfd_open"):        # no pidfds here: look every 0.1 s
        while all(alive(pid, started) for pid, started in watched):
            if targets and not any(alive(pid) for pid in targets):
                return False
            time.sleep(0.1)
        return True
    fds, kinds = [], {}
    try:
        for pid, started in watched:
            fd = _open(pid, started)
            if fd is None:
                return True
            fds.append(fd)
            kinds[fd] = "watched"
        for pid in targets:
            fd = _open(pid, None)
            if fd is not None:
                fds.append(fd)
                kinds[fd] = "target"
        if targets and "target" not in kinds.values():
            return False
        poller = select.poll()
        for fd in fds:
            poller.register(fd, select.POLLIN)
        left = sum(k == "target" for k in kinds.values())
        while True:
            for fd, _ in poller.poll():
                if kinds[fd] == "watched":
                    return True
                poller.unregister(fd)
                left -= 1
                if targets and left == 0:
                    return False
    finally:
        for fd in fds:
            os.close(fd)


def _targets(pids, pidfiles, sessions) -> tuple[list[int], list[int]]:
    """(pids to signal, sessions to signal) as they are now."""
    found = list(pids)
    for path in pidfiles:
        try:
            with open(path) as f:
                found.append(int(f.readline().strip()))
        except (OSError, ValueError):
            pass                                     # not started yet, or already gone
    return found, list(sessions)


def _signal_all(pidfds: dict, sessions, sig) -> None:
    for pid, fd in pidfds.items():
        try:
            if fd is None:                         # no pidfds here: by pid
                os.kill(pid, sig)
            else:
                signal.pidfd_send_signal(fd, sig)
        except (ProcessLookupError, OSError):
            pass
    for sid in sessions:
        for pid in session_members(sid):
            try:
                os.kill(pid, sig)
            except (ProcessLookupError, PermissionError):
                pass


def _stop(pids, pidfiles, sessions, sig, grace_s) -> None:
    pids, sessions = _targets(pids, pidfiles, sessions)
    pidfds = {}
    for pid in pids:
        try:
            pidfds[pid] = os.pidfd_open(pid) if hasattr(os, "pidfd_open") else (None if alive(pid) else 0)
        except OSError:
            pass
    pidfds = {pid: fd for pid, fd in pidfds.items() if fd != 0}
    try:
        _signal_all(pidfds, sessions, sig)
        deadline = time.monotonic() + grace_s
        while time.monotonic() < deadline and (any(alive(p) for p in pidfds)
                                               or any(session_members(s) for s in sessions)):
            time.sleep(0.05)
        _signal_all({p: fd for p, fd in pidfds.items() if alive(p)}, sessions, signal.SIGKILL)
    finally:
        for fd in pidfds.values():
            if fd is not None:
                os.close(fd)


def _main(argv: list[str]) -> int:
    import argparse

    p = argparse.ArgumentParser(description="stop a test's server when the test process ends")
    p.add_argument("--watch", action="append", default=[], metavar="PID:START", required=True)
    p.add_argument("--pid", action="append", type=int, default=[])
    p.add_argument("--pidfile", action="append", default=[])
    p.add_argument("--session", action="append", type=int, default=[])
    p.add_argument("--signal", default="SIGTERM")
    p.add_argument("--grace-s", type=float, default=3.0)
    p.add_argument("--remove", action="append", default=[])
    a = p.parse_args(argv)
    signal.signal(signal.SIGINT, signal.SIG_IGN)              # a terminal's Ctrl-C is for pytest
    signal.signal(signal.SIGHUP, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, lambda *_: os._exit(0))      # released: the fixture stopped it
    watched = [(int(w.split(":", 1)[0]), w.split(":", 1)[1]) for w in a.watch]
    sys.stdout.write("armed\n")
    sys.stdout.flush()
    os.close(1)
    # with pids only (no pid file, no session), the guard also ends when they all have
    if not _wait(watched, a.pid if not (a.pidfile or a.session) else []):
        return 0
    signal.signal(signal.SIGTERM, signal.SIG_IGN)              # from here on, finish the job
    _stop(a.pid, a.pidfile, a.session, getattr(signal, a.signal), a.grace_s)
    for path in a.remove:
        shutil.rmtree(path, ignore_errors=True)
    return 0


# ----------------------------------------------------------------------------- the tests' side


def watched_processes() -> list[int]:
    """The processes whose end means the tests are over: this one, and the controlling pytest
    when this is a pytest-xdist worker (its parent)."""
    pids = [os.getpid()]
    if os.environ.get("PYTEST_XDIST_WORKER"):
        pids.append(os.getppid())
    return pids


class Guard:
    def __init__(self, proc: subprocess.Popen | None):
        self.proc = proc                  # None: nothing guards (no /proc here)

    def release(self) -> None:
        """The server was stopped by its fixture: the guard ends without doing anything."""
        if self.proc is None:
            return
        if self.proc.poll() is None:
            self.proc.terminate()
        self.proc.wait(timeout=30)


def guard(*, pids=(), pidfiles=(), sessions=(), sig: signal.Signals = signal.SIGTERM, grace_s: float = 3.0,
          remove=()) -> Guard:
    """Start a guard that stops the targets (``pids``; the pid in each of ``pidfiles`` when the
    test process ends; every process of each of ``sessions``) with ``sig``, then SIGKILL after
    ``grace_s``, and removes the folders ``remove``, if the test process ends first.  Returns
    once the guard is watching.  Linux only (it reads /proc): elsewhere nothing is guarded."""
    if not os.path.exists(f"/proc/{os.getpid()}/stat"):
        return Guard(None)
    argv = [sys.executable, "-I", "-S", HERE]
    for pid in watched_processes():
        argv += ["--watch", f"{pid}:{start_time(pid)}"]
    argv += [x for pid in pids for x in ("--pid", str(pid))]
    argv += [x for path in pidfiles for x in ("--pidfile", str(path))]
    argv += [x for sid in sessions for x in ("--session", str(sid))]
    argv += [x for path in remove for x in ("--remove", str(path))]
    argv += ["--signal", signal.Signals(sig).name, "--grace-s", str(grace_s)]
    proc = subprocess.Popen(argv, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                            start_new_session=True, text=True)
    line = proc.stdout.readline()
    proc.stdout.close()
    if line.strip() != "armed":
        proc.kill()
        proc.wait()
        raise RuntimeError(f"the server guard did not start (exit status {proc.poll()})")
    return Guard(proc)


if __name__ == "__main__":
    sys.exit(_main(sys.argv[1:]))
