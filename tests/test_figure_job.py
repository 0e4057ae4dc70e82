"""The report's figures drawn in a forked worker (station/diagnose/figure_job.py) and its noise
computed where the capture is read (station.estimate.noise.LongestStatic): the same bytes and the
same numbers as in this process; a worker or a drawing process that fails or dies costs only
time (the figures are drawn here), never a hang or a missing figure."""
from __future__ import annotations

import os

import numpy as np
import pytest

from processes import interrupt, start_script, still_running
from station.core import forked
from station.diagnose import auto, figure_job
from station.diagnose.figure_job import FigureJob
from station.diagnose.figures import draw
from station.diagnose.report import diagnosis_figure_specs, noise_of
from station.estimate import READ_IN_PROCESS, lsq, noise, summarise_while_importing
from station.io.capture import read_capture


@pytest.fixture(scope="module")
def specs(optimal9_run):
    capture = read_capture(optimal9_run)
    steps, final = auto.run(lsq.summarise(capture), [])
    result, note = noise_of(capture)
    assert note is None
    return {"allan.svg": result}, diagnosis_figure_specs(steps[0].before if steps else final, steps)


def _drawn_by_job(specs) -> dict:
    allan, diagnosis = specs
    with FigureJob() as job:
        assert job._pool is not None            # Linux: forked, beside this process
        job.draw(allan)
        job.draw(diagnosis)
        pngs = job.result()
    assert job._pool is None                     # ended on leaving the block
    return pngs


def test_the_worker_draws_the_bytes_drawn_here(specs):
    here = draw({**specs[0], **specs[1]})
    there = _drawn_by_job(specs)
    assert list(there) == list(here) and len(here) >= 3
    for name in here:
        assert there[name] == here[name], name
        assert here[name].startswith(b"<?xml") and b"</svg>" in here[name][-100:]      # SVG by the name


# module-level: the task is sent to the worker by name (a local function could not be, and would
# fail in this process instead of in the worker)
def _fail_in_the_worker(_specs):
    raise RuntimeError("the worker failed")


def _die_in_the_worker(_specs):
    os._exit(9)


@pytest.mark.parametrize("task", [_fail_in_the_worker, _die_in_the_worker])
def test_a_worker_that_fails_or_dies_costs_only_time(specs, monkeypatch, task):
    calls = []
    real = figure_job._draw_here

    def drawn_here(s):
        calls.append(os.getpid())
        return real(s)

    monkeypatch.setattr(figure_job, "_draw_task", task)
    monkeypatch.setattr(figure_job, "_draw_here", drawn_here)
    assert _drawn_by_job(specs) == draw({**specs[0], **specs[1]})
    assert calls == [os.getpid()] * 2          # both tasks failed there and were drawn here


@pytest.mark.skipif(forked.usable_cores() < 2, reason="one core: the worker forks no drawing process")
def test_a_drawing_process_that_dies_is_replaced_by_the_worker(specs, monkeypatch, tmp_path):
    """The worker draws what its dying process did not: every figure is drawn in the worker, none
    here (where each drawing happened is written down by the drawing processes themselves)."""
    class Dying(forked.Forked):
        def __init__(self, fn):
            super().__init__(lambda: os._exit(9))

    real = figure_job._draw_here
    log = tmp_path / "drawn-by"

    def drawn_here(s):
        with open(log, "a") as f:
            f.write(f"{os.getpid()} {len(s)}\n")
        return real(s)

    monkeypatch.setattr(forked, "Forked", Dying)
    monkeypatch.setattr(figure_job, "_draw_here", drawn_here)
    assert _drawn_by_job(specs) == draw({**specs[0], **specs[1]})
    calls = [line.split() for line in log.read_text().splitlines()]
    assert calls and all(int(pid) != os.getpid() for pid, _ in calls)
    assert sum(int(n) for _, n in calls) == len(specs[0]) + len(specs[1])


@pytest.mark.parametrize("in_process", [False, True])
def test_the_noise_computed_where_the_capture_is_read_is_from_capture(optimal9_run, monkeypatch, in_process):
    if in_process:
        monkeypatch.setenv(READ_IN_PROCESS, "1")
    capture = read_capture(optimal9_run, load_data=False)
    longest = noise.LongestStatic(capture)
    value = summarise_while_importing(capture, longest.check, then=longest.curves)
    got, note = longest.noise(value)
    want = noise.from_capture(read_capture(optimal9_run))
    assert note is None and got.source == want.source
    for a, b in zip(got.axes, want.axes):
        np.testing.assert_array_equal(a.adev, b.adev)
        assert a.report() == b.report()


def test_no_static_segment_is_a_note_not_a_failure(optimal9_run):
    capture = read_capture(optimal9_run, load_data=False)
    capture.segments = [s for s in capture.segments if s.kind != "static"]
    longest = noise.LongestStatic(capture)
    for seg in capture.segments:          # (summarise refuses a capture without statics first)
        longest.check(seg)
    result, note = longest.noise(longest.curves())
    assert result is None and note.startswith("Not characterised:") and "no static segment" in note
    assert noise_of(capture) == (None, note)


PARENT = """
import sys
from station.cli import main
rc = main(["diagnose", sys.argv[1], "--auto", "--report", sys.argv[2]])
print(rc, "matplotlib" in sys.modules)
"""

READER = """
import sys
from station.estimate.noise import LongestStatic
from station.estimate.summaries import summarise
from station.io.capture import read_capture
capture = read_capture(sys.argv[1], load_data=False)
longest = LongestStatic(capture)
summarise(capture, check_segment=longest.check)
curves, note = longest.curves()
print(note is None and len(curves[0]) == 6, any(m.split(".")[0] == "scipy" for m in sys.modules))
"""


def test_diagnose_report_imports_matplotlib_only_in_its_worker_and_the_reader_no_scipy(optimal9_run, tmp_path):
    """The point of the two processes: the one that fits never pays for matplotlib (~0.25 s), and
    the one that reads the capture computes the Allan curves without importing scipy (~0.2 s)."""
    import subprocess
    import sys

    r = subprocess.run([sys.executable, "-c", PARENT, str(optimal9_run), str(tmp_path / "report")],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert r.stdout.split()[-2:] == ["0", "False"]
    assert (tmp_path / "report" / "allan.svg").stat().st_size > 0
    assert (tmp_path / "report" / "residuals_per_segment.svg").stat().st_size > 0
    r = subprocess.run([sys.executable, "-c", READER, str(optimal9_run)], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == ["True", "False"]


CTRL_C = """
import os, sys, time
from station.diagnose import figures
real = figures.draw
parent = os.getpid()
def slow(specs):
    if os.getpid() != parent and "allan.svg" not in specs:   # the diagnosis figures: a long draw
        with open(sys.argv[3], "a") as f:            # not stdout: the diagnosis is printed there
            f.write(f"{os.getpid()}\\n")
        time.sleep(60)
    return real(specs)
figures.draw = slow
from station.cli import main
sys.exit(main(["diagnose", sys.argv[1], "--auto", "--report", sys.argv[2]]))
"""


def drawing(p, pid_file) -> set:
    """The pids of the processes drawing, as CTRL_C's script writes them into ``pid_file`` (each
    line written whole by one process: on stdout they could land inside a line of the diagnosis,
    which is printed meanwhile), once every drawing process has begun."""
    import time

    pids = set()
    while len(pids) < min(2, forked.usable_cores()):
        assert p.poll() is None, "the command ended before its figures were drawn"
        time.sleep(0.02)
        if pid_file.exists():
            pids = {int(line) for line in pid_file.read_text().split("\n")[:-1]}   # whole lines only
    return pids


def test_ctrl_c_while_the_figures_are_drawn_leaves_no_process(optimal9_run, tmp_path):
    """Ctrl-C (SIGINT to the process group, as a terminal sends it) while the worker and the
    process it forked draw: exit status 130, "interrupted", no page, and neither left running
    (the worker is killed on leaving the job; the process it forked dies with it)."""
    p = start_script(CTRL_C, optimal9_run, tmp_path / "report", tmp_path / "drawing")
    try:
        drawers = drawing(p, tmp_path / "drawing")
    finally:
        out, err = interrupt(p)
    assert p.returncode == 130 and err.strip().splitlines()[-1] == "interrupted"
    assert still_running(drawers) == []
    assert not (tmp_path / "report" / "index.html").exists()


@pytest.mark.parametrize("how", ["SIGKILL", "SIGTERM"])
def test_a_killed_diagnose_leaves_no_figure_process(optimal9_run, tmp_path, how):
    """The parent killed while its worker and the process the worker forked draw (the out-of-memory
    killer, a closed terminal, `timeout`): both end with it, nothing is left running."""
    import signal

    p = start_script(CTRL_C, optimal9_run, tmp_path / "report", tmp_path / "drawing")
    try:
        drawers = drawing(p, tmp_path / "drawing")
    finally:
        interrupt(p, getattr(signal, how), group=False)     # the parent alone, not its group
    left = still_running(drawers)
    for pid in left:                                 # not to leave them to the next tests
        os.kill(pid, signal.SIGKILL)
    assert not left
