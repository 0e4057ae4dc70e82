"""station.core.forked (one function in a forked child) and `estimate`'s reader in a child:
results, errors raised as in process, a lost child, a child ended when its parent stops."""
import os
import time

import pytest

from processes import interrupt, start_script, still_running
from station.core import forked
from station.core.errors import CaptureError
from station.estimate import estimate_capture, summaries

pytestmark = pytest.mark.skipif(not forked.available(), reason="fork is used on Linux only")


def test_the_result_of_the_function_comes_back():
    with forked.Forked(lambda: (os.getpid(), [1.5, "x"])) as child:
        pid, value = child.result()
    assert pid != os.getpid() and value == [1.5, "x"]


def test_an_error_in_the_child_is_raised_here_with_its_fields():
    def fail():
        raise CaptureError("cap/pos01.csv", "not a number: 'abc'", line=12, field="gx", segment="segments[0] (pos01)")

    with pytest.raises(CaptureError) as e, forked.Forked(fail) as child:
        child.result()
    assert str(e.value) == "cap/pos01.csv: segments[0] (pos01): line 12: field 'gx': not a number: 'abc'"
    assert (e.value.line, e.value.field) == (12, "gx")


def test_a_child_that_dies_is_lost_not_waited_for():
    with pytest.raises(forked.ChildLost), forked.Forked(lambda: os._exit(3)) as child:
        child.result()


def test_closing_ends_a_child_that_still_runs():
    child = forked.Forked(lambda: time.sleep(60))
    pid = child.pid
    child.close()
    with pytest.raises(ChildProcessError):
        os.waitpid(pid, os.WNOHANG)          # ended and reaped: no such child any more


def _waits_for_the_last(item):
    """Item 0 waits (up to 30 s) for the last item's file: only if the others were started while
    it still ran, i.e. if a slow child does not hold the rest back."""
    x, flag = item
    if x == 0:
        deadline = time.monotonic() + 30
        while not flag.exists() and time.monotonic() < deadline:
            time.sleep(0.01)
        return os.getpid(), flag.exists()
    if x == 6:
        flag.touch()
    return os.getpid(), x * x


@pytest.mark.skipif(forked.usable_cores() < 2, reason="one core: one child at a time")
def test_map_in_children_keeps_the_order_and_starts_the_next_when_any_ends(tmp_path):
    parent = os.getpid()
    out = forked.map_in_children(_waits_for_the_last, [(x, tmp_path / "last") for x in range(7)])
    assert out[0][1] is True                               # the last one ran while the first waited
    assert [value for _, value in out[1:]] == [x * x for x in range(1, 7)]
    pids = {pid for pid, _ in out}
    assert parent not in pids and len(pids) == 7           # one child each


def test_map_in_children_raises_the_first_error_in_order_and_recovers_lost_children(monkeypatch):
    parent = os.getpid()

    def f(x):
        if x in (2, 4):
            raise ValueError(f"item {x}")
        if x == 1 and os.getpid() != parent:
            os._exit(9)                               # lost in its child: computed here instead
        return x

    with pytest.raises(ValueError, match="item 2"):
        forked.map_in_children(f, range(6))
    assert forked.map_in_children(f, [0, 1, 3]) == [0, 1, 3]
    monkeypatch.setattr(forked, "available", lambda: False)
    assert forked.map_in_children(lambda x: (os.getpid(), x), [5, 6]) == [(parent, 5), (parent, 6)]


def test_estimate_reads_in_process_when_its_reader_is_lost(optimal9_run, monkeypatch):
    """A reader killed (out of memory, a signal) costs only time: the capture is read here."""
    parent = os.getpid()
    real = summaries.summarise

    def dies_in_the_child(*args, **kwargs):
        if os.getpid() != parent:
            os._exit(9)
        return real(*args, **kwargs)

    monkeypatch.setattr(summaries, "summarise", dies_in_the_child)
    cal, capture, provenance = estimate_capture(optimal9_run)
    monkeypatch.setenv("STATION_READ_IN_PROCESS", "1")
    cal_here, _, provenance_here = estimate_capture(optimal9_run)
    assert provenance["capture_sha256"] == provenance_here["capture_sha256"]
    assert cal.fit["chi2"] == cal_here.fit["chi2"]


def test_estimate_reads_in_process_when_no_process_can_be_forked(optimal9_run, monkeypatch):
    def no_fork():
        raise BlockingIOError(11, "Resource temporarily unavailable")

    monkeypatch.setattr(os, "fork", no_fork)
    cal, capture, provenance = estimate_capture(optimal9_run)
    assert cal.fit["chi2"] > 0 and all(seg.content_sha256 for seg in capture.complete())


def test_estimate_raises_the_readers_error_as_reading_here_does(optimal9_run, tmp_path):
    """A bad line in a segment: the same message (file, segment, line, column) from the child."""
    import hashlib
    import shutil

    import yaml

    bad = tmp_path / "cap"
    shutil.copytree(optimal9_run, bad)
    csv = bad / "pos03.csv"
    lines = csv.read_text().splitlines(keepends=True)
    lines[40] = lines[40].replace(",", ",abc", 1)
    csv.write_text("".join(lines))
    manifest = yaml.safe_load((bad / "manifest.yaml").read_text())
    for seg in manifest["segments"]:
        if seg["file"] == "pos03.csv":
            seg["sha256"] = hashlib.sha256(csv.read_bytes()).hexdigest()
    (bad / "manifest.yaml").write_text(yaml.safe_dump(manifest, sort_keys=False))
    messages = []
    for env in ({}, {"STATION_READ_IN_PROCESS": "1"}):
        os.environ.update(env)
        try:
            with pytest.raises(CaptureError) as e:
                estimate_capture(bad)
            messages.append(str(e.value))
        finally:
            os.environ.pop("STATION_READ_IN_PROCESS", None)
    assert messages[0] == messages[1] and "pos03.csv" in messages[0] and "line 41" in messages[0]


CTRL_C = """
import os, sys, time
from station.estimate import summaries
real = summaries.summarise
parent = os.getpid()
def slow(*args, **kwargs):
    if os.getpid() != parent:            # the forked reader: a long read
        print(os.getpid(), flush=True)
        time.sleep(60)
    return real(*args, **kwargs)
summaries.summarise = slow
from station.cli import main
sys.exit(main(["diagnose", sys.argv[1], "-o", sys.argv[2]]))
"""


def test_ctrl_c_while_the_child_reads_ends_both(optimal9_run, tmp_path):
    """Ctrl-C (SIGINT to the process group, as a terminal sends it) while the forked reader
    reads (diagnose's, which imports the diagnosis meanwhile): exit status 130, "interrupted",
    and no reader left running."""
    p = start_script(CTRL_C, optimal9_run, tmp_path / "cal.yaml")
    try:
        reader = int(p.stdout.readline())        # the child says it is reading
    finally:
        out, err = interrupt(p)
    assert p.returncode == 130 and err.strip().splitlines()[-1] == "interrupted"
    assert still_running([reader]) == []
    assert not (tmp_path / "cal.yaml").exists()


CTRL_C_READING_HERE = """
import sys, threading, time
import station.io.capture as capture_io
real = capture_io.read_csv_pieces
def slow(*args, **kwargs):
    if threading.current_thread() is not threading.main_thread():    # the reading thread
        print("reading", flush=True)
        time.sleep(60)
    return real(*args, **kwargs)
capture_io.read_csv_pieces = slow
from station.cli import main
sys.exit(main(["estimate", sys.argv[1], "-o", sys.argv[2]]))
"""


def test_ctrl_c_while_estimate_reads_ends_it_at_once(optimal9_run, tmp_path):
    """`station estimate` reads in its own process, the next segment on a reading thread: Ctrl-C
    while that thread reads ends the command at once (exit status 130, "interrupted", no file),
    not after the file being read (here a read that would take a minute)."""
    p = start_script(CTRL_C_READING_HERE, optimal9_run, tmp_path / "cal.yaml")
    try:
        assert p.stdout.readline().strip() == "reading"
        started = time.monotonic()
    finally:
        out, err = interrupt(p)
    assert p.returncode == 130 and err.strip().splitlines()[-1] == "interrupted"
    assert time.monotonic() - started < 30       # the read would have taken 60 s
    assert not (tmp_path / "cal.yaml").exists()
