"""Test helpers for commands that fork: start a script in its own process group (as a terminal
starts a command), and wait until given processes have ended."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from contextlib import contextmanager


def start_script(script: str, *args) -> subprocess.Popen:
    """``python -c script args`` in a new session (its own process group), with Ctrl-C's
    default action (a test runner may have it ignored), stdout and stderr as text pipes."""
    return subprocess.Popen([sys.executable, "-c", script, *map(str, args)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: (signal.signal(signal.SIGINT, signal.SIG_DFL), os.setsid()))


def running(pid: int) -> bool:
    """The process exists and has not ended (a zombie nobody reaped yet has ended)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except (FileNotFoundError, ProcessLookupError, IndexError):
        return False


def still_running(pids, seconds: float = 10.0) -> list:
    """The processes among ``pids`` still running after waiting up to ``seconds`` for them."""
    deadline = time.monotonic() + seconds
    while any(running(pid) for pid in pids) and time.monotonic() < deadline:
        time.sleep(0.05)
    return [pid for pid in pids if running(pid)]


def interrupt(p: subprocess.Popen, how=signal.SIGINT, group: bool = True) -> tuple:
    """Send ``how`` to ``p``'s process group (as a terminal's Ctrl-C does) or to ``p`` alone, and
    (stdout, stderr) once it has ended (killed after 60 s)."""
    try:
        if group:
            os.killpg(p.pid, how)
        else:
            p.send_signal(how)
        return p.communicate(timeout=60)
    finally:
        if p.poll() is None:
            p.kill()


def read_until(port, done, seconds: float = 10.0) -> bytes:
    """Bytes read from ``port`` until ``done(bytes so far)`` (or ``seconds`` pass: the caller's
    assertion then fails on what came): a wait on the condition, not a sleep that a loaded
    machine can outlast."""
    buf, deadline = bytearray(), time.monotonic() + seconds
    while not done(bytes(buf)) and time.monotonic() < deadline:
        buf += port.read(max(1, port.in_waiting))
    return bytes(buf)


def quiet_after(port, unwanted, quiet_s: float, seconds: float = 10.0) -> bool:
    """Whether ``port`` went ``quiet_s`` seconds without ``unwanted(chunk)`` within ``seconds``:
    what was already under way when a stream was stopped may still arrive (at any delay on a
    loaded machine); the stream has stopped when nothing of it comes for a while after."""
    deadline = time.monotonic() + seconds
    since = time.monotonic()
    while time.monotonic() < deadline:
        if unwanted(port.read(max(1, port.in_waiting))):
            since = time.monotonic()
        elif time.monotonic() - since >= quiet_s:
            return True
    return False


class Hang(BaseException):      # not an Exception: a reader's "except Exception" cannot swallow it
    pass


@contextmanager
def time_limit(seconds):
    """Raise Hang in this (main) thread if the block takes longer than ``seconds`` (SIGALRM):
    the fuzz tests' guard against an input that makes a reader hang."""
    def alarm(signum, frame):
        raise Hang(f"no answer in {seconds} s: a hang")
    old = signal.signal(signal.SIGALRM, alarm)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)
