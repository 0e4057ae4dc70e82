"""A writer killed (SIGKILL) in the middle of a segment leaves a readable capture."""

import hashlib
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from station.io.capture import CaptureWriter, read_capture

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _kill_writer import BLOCK, samples  # noqa: E402

BLOCKS_BEFORE_KILL = 3

pytestmark = pytest.mark.skipif(not hasattr(signal, "SIGKILL"), reason="needs SIGKILL")


def assert_rows_are_the_written_ones(data):
    """Each row is the one the child wrote for its index (recovered from t)."""
    k = np.rint(data.t * 100.0).astype(int)
    np.testing.assert_array_equal(k, np.arange(len(k)))
    t, accel, gyro = samples(0, len(k))
    np.testing.assert_allclose(data.t, t, rtol=1e-12)
    np.testing.assert_allclose(data.accel, accel, rtol=1e-11)
    np.testing.assert_allclose(data.gyro, gyro, rtol=1e-11)


def run_and_kill(directory):
    """Run the writer until it has flushed BLOCKS_BEFORE_KILL blocks of the third segment,
    SIGKILL it, and return what it printed."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [str(HERE.parent)] + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]))
    child = subprocess.Popen([sys.executable, str(HERE / "_kill_writer.py"), str(directory)],
                             stdout=subprocess.PIPE, text=True, env=env)
    printed = []
    try:
        for line in child.stdout:
            printed.append(line.strip())
            if printed[-1] == f"block {BLOCKS_BEFORE_KILL - 1}":
                break
    finally:
        child.kill()  # SIGKILL, in the middle of the third segment (or if it went wrong)
        child.wait(timeout=30)
        child.stdout.close()
    assert printed[-1:] == [f"block {BLOCKS_BEFORE_KILL - 1}"], printed
    assert child.returncode == -signal.SIGKILL
    return printed


def test_killed_writer_leaves_complete_segments_intact_and_the_third_incomplete(tmp_path):
    directory = tmp_path / "cap"
    printed = run_and_kill(directory)
    assert printed[:2] == ["complete pos01", "complete rot1p"]

    capture = read_capture(directory)
    assert [(s.name, s.status) for s in capture.segments] == [
        ("pos01", "complete"), ("rot1p", "complete"), ("rot1m", "incomplete")]
    for segment in capture.complete():
        raw = (directory / segment.file).read_bytes()
        assert segment.extra["sha256"] == hashlib.sha256(raw).hexdigest()
        assert segment.extra["samples"] == len(segment.data.t) == 200
        assert_rows_are_the_written_ones(segment.data)
    third = capture.segment("rot1m")
    assert third.problem is None
    assert len(third.data.t) >= BLOCKS_BEFORE_KILL * BLOCK  # every flushed block, maybe more
    assert_rows_are_the_written_ones(third.data)
    assert "samples" not in third.extra and "sha256" not in third.extra
    assert [w for w in capture.warnings if w.startswith("segments[2] (rot1m): incomplete, ")]
    assert capture.rotation_pairs() == []  # rot1m is not usable

    # Resume: the complete segments stay as they were, rot1m is recorded again.
    before = {n: (directory / f"{n}.csv").read_bytes() for n in ("pos01", "rot1p")}
    writer = CaptureWriter.reopen(directory)
    with writer.begin_segment("rot1m", "rotation", axis_body=[0, 0, 1], rate_dps=-10.0) as seg:
        seg.write(*samples(0, 200))
        seg.close(angle_deg=-20.0)
    capture = read_capture(directory)
    assert [s.status for s in capture.segments] == ["complete"] * 3
    assert {n: (directory / f"{n}.csv").read_bytes() for n in ("pos01", "rot1p")} == before
    assert [(p.name, m.name) for p, m in capture.rotation_pairs()] == [("rot1p", "rot1m")]
    assert (directory / "rot1m.csv.incomplete").exists()
