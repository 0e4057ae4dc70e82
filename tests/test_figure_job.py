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
        job.draw(allan)
        assert job._worker is not None           # Linux: forked, beside this process
        job.draw(diagnosis)
        figures = job.result()
        directory = job._dir
    assert job._worker is None and not os.path.exists(directory)      # ended on leaving the block
    return figures


def test_the_worker_draws_the_bytes_drawn_here(specs):
    here = draw({**specs[0], **specs[1]})
    there = _drawn_by_job(specs)
    assert list(there) == list(here) and len(here) >= 3
    for name in here:
        assert there[name] == here[name], name
        assert here[name].startswith(b"<?xml") and b"</svg>" in here[name][-100:]      # SVG by the name


def _logged(log, real):
    """``real`` (figure_job._draw_here or _draw_one), each call written down in ``log`` by the
    process that makes it (pid and how many figures)."""
    def logged(*args):
        with open(log, "a") as f:
            f.write(f"{os.getpid()} {len(args[0]) if isinstance(args[0], dict) else 1}\n")
        return real(*args)
    return logged


def _calls(log) -> list:
    return [tuple(map(int, line.split())) for line in log.read_text().splitlines()] if log.exists() else []


def _fail(name, spec):
    raise RuntimeError("drawing failed there")


def _die(name, spec):
    os._exit(9)


@pytest.mark.parametrize("how", [_fail, _die])
def test_figures_that_fail_or_whose_processes_die_are_drawn_here(specs, monkeypatch, tmp_path, how):
    """Every drawing process fails (or dies at its first figure): every figure is drawn here,
    once, with the same bytes; nothing hangs."""
    log = tmp_path / "drawn-here"
    monkeypatch.setattr(figure_job, "_draw_one", how)        # before the fork: theirs too
    monkeypatch.setattr(figure_job, "_draw_here", _logged(log, figure_job._draw_here))
    assert _drawn_by_job(specs) == draw({**specs[0], **specs[1]})
    calls = _calls(log)
    assert {pid for pid, _ in calls} == {os.getpid()}
    assert sum(n for _, n in calls) == len(specs[0]) + len(specs[1])


@pytest.mark.skipif(forked.usable_cores() < 2, reason="one core: the worker forks no drawing process")
def test_a_drawing_process_that_dies_leaves_its_figure_to_the_others(specs, monkeypatch, tmp_path):
    """The process the worker forked dies at the first figure it takes: the worker draws it and
    every other figure, none is drawn here (each drawing process writes down what it drew)."""
    me = os.getpid()
    log = tmp_path / "drawn-by"
    real = _logged(log, figure_job._draw_one)

    def worker_only(name, spec):
        if os.getppid() != me:        # not the worker (forked by this process): its drawing process
            os._exit(9)
        return real(name, spec)

    monkeypatch.setattr(figure_job, "_draw_one", worker_only)
    assert _drawn_by_job(specs) == draw({**specs[0], **specs[1]})
    calls = _calls(log)
    assert len({pid for pid, _ in calls}) == 1 and me not in {pid for pid, _ in calls}
    assert len(calls) == len(specs[0]) + len(specs[1])        # each figure once


@pytest.mark.skipif(forked.usable_cores() < 2, reason="one core: the worker forks no drawing process")
def test_a_drawing_process_that_dies_while_taking_a_figure_loses_none(specs, monkeypatch, tmp_path):
    """It dies after saying it takes a figure and before saying which (killed at that instant):
    every figure no living process holds is given again; all are drawn there, none here."""
    me = os.getpid()
    log = tmp_path / "drawn-by"
    real_read = figure_job._read_whole

    def dying_read(fd, size):
        if size == figure_job.TASK.size and os.getppid() != me:
            os._exit(9)
        return real_read(fd, size)

    monkeypatch.setattr(figure_job, "_read_whole", dying_read)
    monkeypatch.setattr(figure_job, "_draw_one", _logged(log, figure_job._draw_one))
    monkeypatch.setattr(figure_job, "_draw_here", _logged(tmp_path / "here", figure_job._draw_here))
    assert _drawn_by_job(specs) == draw({**specs[0], **specs[1]})
    assert me not in {pid for pid, _ in _calls(tmp_path / "here")}       # (_draw_one draws through it)
    assert len(_calls(log)) >= len(specs[0]) + len(specs[1]) and me not in {pid for pid, _ in _calls(log)}


def test_without_a_worker_the_figures_are_drawn_here(specs, monkeypatch):
    monkeypatch.setattr(forked, "available", lambda: False)
    with FigureJob() as job:
        job.draw(specs[0])
        assert job._worker is None
        assert job.result() == draw(specs[0])


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


def test_ctrl_c_while_the_figures_are_drawn_leaves_no_process(optimal9_run, tmp_path, monkeypatch):
    """Ctrl-C (SIGINT to the process group, as a terminal sends it) while the worker and the
    process it forked draw: exit status 130, "interrupted", no page, and neither left running
    (the worker is killed on leaving the job; the process it forked dies with it)."""
    temporary = tmp_path / "tmp"
    temporary.mkdir()
    monkeypatch.setenv("TMPDIR", str(temporary))          # where the job keeps its figures
    p = start_script(CTRL_C, optimal9_run, tmp_path / "report", tmp_path / "drawing")
    try:
        drawers = drawing(p, tmp_path / "drawing")
    finally:
        out, err = interrupt(p)
    # (what the command said, on failure: CI once saw exit status 1 here, cause not yet known)
    assert p.returncode == 130 and err.strip().splitlines()[-1] == "interrupted", (p.returncode, err[-3000:])
    assert still_running(drawers) == []
    assert not (tmp_path / "report" / "index.html").exists()
    assert list(temporary.iterdir()) == []


@pytest.mark.parametrize("how", ["SIGKILL", "SIGTERM"])
def test_a_killed_diagnose_leaves_no_figure_process(optimal9_run, tmp_path, how, monkeypatch):
    """The parent killed while its worker and the process the worker forked draw (the out-of-memory
    killer, a closed terminal, `timeout`): both end with it, nothing is left running, and the
    worker removes the figures' temporary directory, which the parent could not."""
    import signal

    temporary = tmp_path / "tmp"
    temporary.mkdir()
    monkeypatch.setenv("TMPDIR", str(temporary))
    p = start_script(CTRL_C, optimal9_run, tmp_path / "report", tmp_path / "drawing")
    try:
        drawers = drawing(p, tmp_path / "drawing")
    finally:
        interrupt(p, getattr(signal, how), group=False)     # the parent alone, not its group
    left = still_running(drawers)
    for pid in left:                                 # not to leave them to the next tests
        os.kill(pid, signal.SIGKILL)
    assert not left
    assert list(temporary.iterdir()) == []


def test_directories_a_killed_process_group_left_are_removed(tmp_path):
    """A process group killed at once (SIGKILL) leaves the figures' temporary directory: the
    next worker removes those of this user's processes that are gone, and nothing else."""
    import subprocess
    import sys

    gone = subprocess.Popen([sys.executable, "-c", "pass"])
    gone.wait()                                   # a process number no process has now
    prefix = figure_job.DIRECTORY_PREFIX
    orphan = tmp_path / f"{prefix}{gone.pid}-abc123"
    (orphan / "sub").mkdir(parents=True)
    (orphan / "sub" / "0.figure").write_bytes(b"x")
    living = tmp_path / f"{prefix}{os.getpid()}-def456"
    living.mkdir()
    not_a_directory = tmp_path / f"{prefix}{gone.pid}-ghi789"
    not_a_directory.write_bytes(b"")
    link = tmp_path / f"{prefix}{gone.pid}-jkl012"
    link.symlink_to(living)
    other = tmp_path / f"other-{gone.pid}-abc123"
    other.mkdir()
    assert figure_job.remove_orphaned_directories(str(tmp_path)) == [orphan.name]
    assert not orphan.exists()
    assert living.is_dir() and not_a_directory.exists() and link.is_symlink() and other.is_dir()
