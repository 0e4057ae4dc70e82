"""The report's noise section computed in a second (forked) process while the diagnosis runs:
the same numbers and the same figure as computed in this process; a child that fails changes
nothing but the time (the work is done here, and says why if it fails here too)."""
from __future__ import annotations

import numpy as np

from station.diagnose import noise_job
from station.diagnose.noise_job import NoiseJob, noise_section
from station.io.capture import read_capture


def _same(a, b) -> None:
    (ra, note_a, png_a), (rb, note_b, png_b) = a, b
    assert note_a == note_b is None
    assert [x.sensor + x.axis for x in ra.axes] == [x.sensor + x.axis for x in rb.axes]
    for x, y in zip(ra.axes, rb.axes):
        np.testing.assert_array_equal(x.adev, y.adev)            # the same samples, the same code
        assert x.report() == y.report()
    assert png_a[:8] == png_b[:8] == b"\x89PNG\r\n\x1a\n" and abs(len(png_a) - len(png_b)) < 0.02 * len(png_a)


def test_the_second_process_gives_the_noise_section_computed_here(optimal9_run):
    capture = read_capture(optimal9_run)
    here = noise_section(capture)
    with NoiseJob(capture) as job:
        assert job._pending is not None          # Linux: forked, running beside this process
        there = job.result()
    assert job._pool is None                     # ended on leaving the block
    _same(here, there)


def test_a_failing_child_falls_back_to_the_work_done_here(optimal9_run, monkeypatch):
    def broken():
        raise RuntimeError("the child failed")

    monkeypatch.setattr(noise_job, "_child", broken)      # the forked child inherits it
    capture = read_capture(optimal9_run)
    with NoiseJob(capture) as job:
        result = job.result()
    _same(noise_section(capture), result)


def test_no_static_segment_is_a_note_not_a_failure(optimal9_run):
    capture = read_capture(optimal9_run)
    capture.segments = [s for s in capture.segments if s.kind != "static"]
    with NoiseJob(capture) as job:
        result, note, png = job.result()
    assert result is None and png is None and note.startswith("Not characterised:")
