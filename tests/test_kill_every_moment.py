"""SIGKILL at every moment of a capture writer's life: before every rename (manifest
replacements, files kept aside), every file creation (segment CSVs, temporaries) and every
fsync (each block of samples): the bundle is always readable and always resumable to the same
complete capture.  The moments are counted, not timed: independent of the machine's load."""
import os
import signal
import sys

import numpy as np
import pytest

from station.io.capture import CaptureWriter, ImuInfo, Site, read_capture

pytestmark = pytest.mark.skipif(not hasattr(os, "fork") or not hasattr(signal, "SIGKILL"),
                                reason="needs fork and SIGKILL")

RATE = 100.0
SEGMENTS = [("pos01", "static", {"up_body": [0, 0, 1]}),
            ("rot1p", "rotation", {"axis_body": [0, 0, 1], "rate_dps": 10.0}),
            ("rot1m", "rotation", {"axis_body": [0, 0, 1], "rate_dps": -10.0})]
BLOCKS, BLOCK = 2, 20
EVENTS = ("replace", "open", "fsync")


def rows(index, first, n):
    k = np.arange(first, first + n, dtype=float)
    return k / RATE, np.column_stack([k, -k, 9.8 + index + 0 * k]), np.column_stack([0 * k, k, index + 0 * k])


def record(directory, done=()):
    """Record every segment not in ``done``: a new bundle, or the rest of a reopened one."""
    if (directory / "manifest.yaml").exists():
        writer = CaptureWriter.reopen(directory)
    else:
        writer = CaptureWriter(directory, ImuInfo(RATE, "m/s^2", "deg/s", serial="K-1"), Site(9.80665))
        writer.write_file("notes.txt", "kill test\n")
    for index, (name, kind, meta) in enumerate(SEGMENTS):
        if name in done:
            continue
        with writer.begin_segment(name, kind, **meta) as seg:
            for b in range(BLOCKS):
                seg.write(*rows(index, b * BLOCK, BLOCK))
            seg.close(**({"angle_deg": 6.0 * np.sign(meta["rate_dps"])} if kind == "rotation" else {}))


def child(directory, kill_at):
    """In a forked child: count the file-system events; SIGKILL before event ``kill_at``."""
    count = [0]

    def counted(name, real):
        def wrapper(*args, **kwargs):
            if count[0] == kill_at:
                os.kill(os.getpid(), signal.SIGKILL)
            count[0] += 1
            return real(*args, **kwargs)
        return wrapper
    for name in EVENTS:
        setattr(os, name, counted(name, getattr(os, name)))
    record(directory)
    return count[0]


def run_child(directory, kill_at):
    """(exit signal or status, events counted) of a forked child killed at ``kill_at``."""
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:                                    # the child: never returns into pytest
        try:
            os.close(r)
            n = child(directory, kill_at)
            os.write(w, str(n).encode())
            os._exit(0)
        except BaseException:
            os._exit(3)
    os.close(w)
    with os.fdopen(r) as f:
        text = f.read()
    _, status = os.waitpid(pid, 0)
    return status, int(text) if text else None


def moments(tmp_path_factory):
    status, n = run_child(tmp_path_factory.mktemp("count") / "cap", kill_at=-1)
    assert os.WIFEXITED(status) and os.WEXITSTATUS(status) == 0 and n
    return n


def test_killed_at_every_moment_the_capture_is_readable_and_resumes_to_the_same_data(tmp_path_factory):
    n = moments(tmp_path_factory)
    assert n >= 20                         # every rename, creation and fsync of the run
    reference = tmp_path_factory.mktemp("ref") / "cap"
    record(reference)
    expected = {s.name: s.data for s in read_capture(reference).segments}
    sys.stdout.write(f"\n{n} moments killed\n")
    for k in range(n):
        directory = tmp_path_factory.mktemp(f"kill{k}") / "cap"
        status, _ = run_child(directory, kill_at=k)
        assert os.WIFSIGNALED(status) and os.WTERMSIG(status) == signal.SIGKILL, k
        done = ()
        if (directory / "manifest.yaml").exists():
            capture = read_capture(directory)            # readable whenever it was killed
            for seg in capture.complete():
                np.testing.assert_array_equal(seg.data.t, expected[seg.name].t)
            done = {s.name for s in capture.complete()}
        record(directory, done)                          # resume
        capture = read_capture(directory)
        assert [(s.name, s.status) for s in capture.segments] == [(n_, "complete") for n_, _, _ in SEGMENTS], k
        for seg in capture.segments:
            np.testing.assert_array_equal(seg.data.accel, expected[seg.name].accel)
        assert not [p.name for p in directory.iterdir() if p.name.endswith(".tmp")], k
