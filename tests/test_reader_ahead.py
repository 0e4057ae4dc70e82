"""Reading the next segment while the current one is worked on (station/io/capture.py,
ReaderAhead): the same samples as reading in turn, errors at their segment's turn and in the
segments' order, no reading thread left behind."""
import os
import threading
import time

import numpy as np
import pytest

from station.core.errors import CaptureError, UserError
from station.estimate import summaries
from station.io.capture import read_capture
from test_capture import base_manifest, csv_text, make_bundle

BROKEN = csv_text().replace("\n0.02,", "\n0.02,x", 1)      # line 4: column 'ax' is not a number


def reading_threads():
    return [t for t in threading.enumerate() if t.name == "capture-read-ahead"]


def test_the_samples_taken_are_those_read_in_turn(tmp_path):
    capture = read_capture(make_bundle(tmp_path), load_data=False)
    with capture.reader_ahead(capture.segments) as reader:
        taken = []
        for seg in capture.segments:
            taken.append(reader.take(seg))
            reader.ahead()
    for seg, data in zip(capture.segments, taken):
        expected = capture.read_samples(seg)
        np.testing.assert_array_equal(np.column_stack([data.t, data.accel, data.gyro]),
                                      np.column_stack([expected.t, expected.accel, expected.gyro]))
    assert all(seg.data is None for seg in capture.segments)
    with capture.reader_ahead(capture.segments) as reader, pytest.raises(ValueError, match="next one"):
        reader.take(capture.segments[1])


def test_a_read_that_fails_ahead_raises_at_its_segments_turn(tmp_path):
    capture = read_capture(make_bundle(tmp_path, files={"rot1p.csv": BROKEN}), load_data=False)
    with capture.reader_ahead(capture.segments) as reader:
        reader.take(capture.segments[0])
        reader.ahead()                      # rot1p is read (and fails) on the other thread
        with pytest.raises(CaptureError) as info:
            reader.take(capture.segments[1])
    assert str(info.value).startswith(f"{capture.path / 'rot1p.csv'}: segments[1] (rot1p): line 4: "
                                      "column 'ax': not a number")
    assert not reading_threads()


def test_summaries_raise_the_first_segments_error_first(tmp_path):
    """The check of the first segment refuses: its error is raised, not the broken second one's
    (whose file may be read ahead meanwhile: its error is kept for its turn); when the first
    passes, the second one's error is raised at its turn.  No reading thread is left either way."""
    manifest = base_manifest()
    manifest["segments"].insert(1, {"name": "pos02", "kind": "static", "file": "pos02.csv",
                                    "status": "complete", "up_body": [0, 0, -1]})
    directory = make_bundle(tmp_path, manifest, files={"pos02.csv": BROKEN})
    checked = []

    def check(seg):
        checked.append((seg.name, seg.data is not None))
        if seg.name == "pos01":
            raise UserError("pos01 refused by the check")

    with pytest.raises(UserError, match="pos01 refused"):
        summaries.summarise(read_capture(directory, load_data=False), check_segment=check)
    assert checked == [("pos01", True)] and not reading_threads()
    checked.clear()
    with pytest.raises(CaptureError, match=r"pos02.csv: segments\[1\] \(pos02\): line 4: "):
        summaries.summarise(read_capture(directory, load_data=False), check_segment=lambda seg: checked.append(seg.name))
    assert checked == ["pos01"] and not reading_threads()


def test_summarise_runs_on_a_thread_that_is_not_the_main_one(optimal9_run):
    """The estimate command may read and summarise the capture on a second thread while the main
    one imports the fit: the same summaries there."""
    here = summaries.summarise(read_capture(optimal9_run, load_data=False))
    result = {}
    worker = threading.Thread(target=lambda: result.update(
        s=summaries.summarise(read_capture(optimal9_run, load_data=False))))
    worker.start()
    worker.join()
    there = result["s"]
    for a, b in zip(here.statics + here.rotations, there.statics + there.rotations):
        for name, value in vars(a).items():
            if isinstance(value, np.ndarray):
                np.testing.assert_array_equal(value, getattr(b, name))
    np.testing.assert_array_equal(here.gyro_sigma, there.gyro_sigma)
    assert len(here.rotations) == len(there.rotations) > 0


def _gappy(t0):
    """Five rows at 100 Hz with a jump of 0.5 s after the second: one gap in time."""
    text = csv_text(5, t0=t0).splitlines()
    header, body = text[0], text[1:]
    shifted = [line if k < 2 else ",".join([f"{float(line.split(',')[0]) + 0.5:.10g}"] + line.split(",")[1:])
               for k, line in enumerate(body)]
    return "\n".join([header] + shifted) + "\n"


def test_warnings_come_in_the_segments_order_whichever_file_is_read_first(tmp_path, monkeypatch):
    """Two files are read at once: the first segment's read is made slow, so the second one's
    ends first; its warning (a gap in time) still comes after the first one's, when it is taken."""
    from station.io import capture as capture_module

    manifest = base_manifest()
    manifest["segments"] = [{"name": f"pos0{k}", "kind": "static", "file": f"pos0{k}.csv", "status": "complete",
                             "up_body": [0, 0, 1]} for k in range(1, 5)]
    directory = make_bundle(tmp_path, manifest, files={f"pos0{k}.csv": _gappy(k) for k in range(1, 5)})
    monkeypatch.setattr(capture_module, "read_ahead_threads", lambda: 2)
    real = capture_module._read_segment_data
    finished = []

    def slow_first(capture, segment, label, *args, **kwargs):
        if segment.name == "pos01":
            time.sleep(0.3)
        data = real(capture, segment, label, *args, **kwargs)
        finished.append(segment.name)
        return data

    monkeypatch.setattr(capture_module, "_read_segment_data", slow_first)
    capture = read_capture(directory, load_data=False)
    with capture.reader_ahead(capture.segments) as reader:
        for seg in capture.segments:
            reader.take(seg)
            reader.ahead()
    assert finished[0] != "pos01"           # the second file's read did end first
    gaps = [w.split(":")[0] for w in capture.warnings if "gaps in time" in w]
    assert gaps == [f"segments[{k}] (pos0{k + 1})" for k in range(4)]
    assert not reading_threads()


def test_files_are_read_ahead_within_the_byte_limit(tmp_path, monkeypatch):
    """With a limit of no bytes only the next file is read ahead; with room for them, every file
    of the list is handed to the reading threads at the first take."""
    from station.io import capture as capture_module

    manifest = base_manifest()
    manifest["segments"] = [{"name": f"pos0{k}", "kind": "static", "file": f"pos0{k}.csv", "status": "complete",
                             "up_body": [0, 0, 1]} for k in range(1, 6)]
    directory = make_bundle(tmp_path, manifest, files={f"pos0{k}.csv": csv_text(t0=k) for k in range(1, 6)})
    real = capture_module._read_segment_data
    for limit, most in ((0, 1), (10**6, 5)):
        begun = []
        monkeypatch.setattr(capture_module, "READ_AHEAD_BYTES", limit)
        monkeypatch.setattr(capture_module, "_read_segment_data",
                            lambda capture, segment, *a, **k: begun.append(segment.name) or real(capture, segment, *a, **k))
        capture = read_capture(directory, load_data=False)
        with capture.reader_ahead(capture.segments) as reader:
            reader.take(capture.segments[0])
            # the files handed out by the first take: read, or being read, by now
            time.sleep(0.2)
            assert len(begun) == most, (limit, begun)
            for seg in capture.segments[1:]:
                reader.ahead()
                reader.take(seg)
        assert sorted(begun) == [f"pos0{k}" for k in range(1, 6)]


def test_ctrl_c_before_the_summaries_take_the_early_reader_leaves_its_reads_at_once(optimal9_run, monkeypatch):
    """estimate_capture starts reading the files before it imports the summaries: Ctrl-C there
    (before the summaries take the reader over) ends it at once, the reads under way left to
    their threads, not waited for."""
    import station.estimate as estimate
    from station.io import capture as capture_module

    release = threading.Event()
    real = capture_module.read_csv_pieces

    def held(*args, **kwargs):
        if threading.current_thread() is not threading.main_thread():
            release.wait(60)
        return real(*args, **kwargs)

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(capture_module, "read_csv_pieces", held)
    monkeypatch.setattr(estimate, "summarise_while_importing", interrupted)
    started = time.monotonic()
    try:
        with pytest.raises(KeyboardInterrupt):
            estimate.estimate_capture(optimal9_run)
        assert time.monotonic() - started < 20
    finally:
        release.set()
    for thread in reading_threads():
        thread.join(30)
    assert not reading_threads()


def test_a_reader_started_early_is_taken_over_by_the_same_list_and_closed_by_another(tmp_path, monkeypatch):
    from station.io import capture as capture_module

    real = capture_module._read_segment_data
    begun = []
    monkeypatch.setattr(capture_module, "_read_segment_data",
                        lambda capture, segment, *a, **k: begun.append(segment.name) or real(capture, segment, *a, **k))
    capture = read_capture(make_bundle(tmp_path), load_data=False)
    capture.read_ahead(capture.summary_order())
    with capture.reader_ahead(capture.summary_order()) as reader:
        taken = [reader.take(seg) for seg in capture.summary_order()]
    assert begun == ["pos01", "rot1p"] and all(d is not None for d in taken)     # each file read once
    capture.read_ahead(capture.summary_order())
    with capture.reader_ahead(capture.summary_order()[1:]) as reader:      # another list: read anew
        assert reader.take(capture.segments[1]) is not None
    # the early reader's reads begun before it was closed (none, one or both), then rot1p anew
    assert begun[-1] == "rot1p" and sorted(begun[2:-1]) in ([], ["pos01"], ["rot1p"], ["pos01", "rot1p"])
    capture.read_ahead(capture.summary_order())
    capture.stop_reading_ahead()
    assert not reading_threads()


def test_no_reading_thread_to_be_had_reads_on_the_callers_thread(tmp_path, monkeypatch):
    """Where no thread can be started (a limit on a process's threads, no memory for a thread's
    stack: RuntimeError "can't start new thread"), the files are read on the caller's thread, as
    where no child can be forked: the same summaries, not a wait for a read no thread will do."""
    real_start = threading.Thread.start

    def refused(thread):
        if thread.name == "capture-read-ahead":
            raise RuntimeError("can't start new thread")
        return real_start(thread)

    directory = make_bundle(tmp_path, files={"pos01.csv": csv_text(40), "rot1p.csv": csv_text(40)})
    expected = summaries.summarise(read_capture(directory, load_data=False), check_segment=lambda seg: None)
    monkeypatch.setattr(threading.Thread, "start", refused)
    result = {}

    def summarise():
        try:
            result["s"] = summaries.summarise(read_capture(directory, load_data=False),
                                              check_segment=lambda seg: None)
        except BaseException as e:  # noqa: BLE001 - said by the assertion below
            result["error"] = e

    worker = threading.Thread(target=summarise, daemon=True)
    worker.start()
    worker.join(30)
    assert not worker.is_alive(), "summarise waits for a read no thread will do"
    assert "error" not in result, result
    assert [s.name for s in result["s"].statics + result["s"].rotations] == \
        [s.name for s in expected.statics + expected.rotations]
    np.testing.assert_array_equal(result["s"].statics[0].accel, expected.statics[0].accel)


def test_ctrl_c_while_the_early_reader_hands_out_its_files_leaves_no_reading_thread(optimal9_run, monkeypatch):
    """Ctrl-C while estimate_capture's early reader is handing out the files (a reading thread
    started for the first one, the next ones' sizes being looked up): its threads end after the
    reads begun, none is left waiting for files forever (a long-lived process: a notebook's
    interrupted estimate)."""
    import station.estimate as estimate
    from station.io import capture as capture_module

    calls = []

    def interrupted_at_the_second_file():
        calls.append(1)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return 2

    monkeypatch.setattr(capture_module, "read_ahead_threads", interrupted_at_the_second_file)
    with pytest.raises(KeyboardInterrupt):
        estimate.estimate_capture(optimal9_run)
    assert len(calls) == 2
    for thread in reading_threads():
        thread.join(30)
    assert not reading_threads()


@pytest.mark.skipif(not hasattr(os, "sched_setaffinity") or (os.cpu_count() or 1) < 2,
                    reason="needs CPU affinity and two cores")
def test_one_reading_thread_where_the_process_may_run_on_one_core():
    """Under taskset, a container's cpuset or a pinned worker the process runs on the cores it is
    given, not the machine's: on one core, one file read at a time (a second thread there gains no
    core, and its malloc arena costs memory)."""
    import subprocess
    import sys

    code = ("import os; os.sched_setaffinity(0, {min(os.sched_getaffinity(0))}); "
            "from station.io.capture import read_ahead_threads; print(read_ahead_threads())")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "1"


def test_a_segment_taken_and_let_go_is_not_held_by_the_thread_that_read_it(tmp_path, monkeypatch):
    """Once taken and let go by the caller, a segment's samples are freed: the reading thread that
    read them, idle until its next file, holds nothing (else each idle thread kept one segment's
    samples beyond READ_AHEAD_BYTES)."""
    import gc
    import weakref

    from station.io import capture as capture_module

    real = capture_module._read_segment_data

    def slow(capture, segment, *args, **kwargs):
        # the first file's thread busy long enough for the second thread to take the second file
        time.sleep(0.3 if segment.name == "pos01" else 0.6)
        return real(capture, segment, *args, **kwargs)

    monkeypatch.setattr(capture_module, "read_ahead_threads", lambda: 2)
    monkeypatch.setattr(capture_module, "_read_segment_data", slow)
    capture = read_capture(make_bundle(tmp_path), load_data=False)
    with capture.reader_ahead(capture.segments) as reader:
        first = reader.take(capture.segments[0])     # both files handed out: one thread each
        assert len(reading_threads()) == 2
        freed = weakref.ref(first)
        del first
        gc.collect()
        assert freed() is None
        assert reader.take(capture.segments[1]) is not None
    assert not reading_threads()


SPY = """
import sys, threading
seen = []

class Spy:
    def find_spec(self, name, path=None, target=None):
        seen.append((threading.current_thread().name, name))
        return None

sys.meta_path.insert(0, Spy())
import station
assert station.__file__.startswith(sys.argv[2]), station.__file__
import station.estimate
station.estimate.estimate_capture(sys.argv[1])
print(sorted({name for thread, name in seen if thread == "capture-read-ahead"}))
"""


def test_the_reading_threads_import_nothing(optimal9_run):
    """The reading threads import no module (the CSV engine is imported by the thread that starts
    them): the main thread imports the fit's modules meanwhile, and a Ctrl-C that lands while it
    waits for the import lock a reading thread holds is raised inside importlib's own lock
    handling (``_get_module_lock``'s callback: "Exception ignored"), the Ctrl-C lost and the lock
    never given back: the reading thread waits for it for ever, the estimate for the reading
    thread (seen: `station estimate` of a 1 kHz capture hung after ~1 Ctrl-C in 20 within its
    first 0.7 s)."""
    import subprocess
    import sys
    from pathlib import Path

    root = str(Path(__file__).resolve().parents[1])
    done = subprocess.run([sys.executable, "-c", SPY, str(optimal9_run), root], capture_output=True, text=True,
                          timeout=120, cwd=root, env=dict(os.environ, PYTHONPATH=root))
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.strip().splitlines()[-1] == "[]"


LEFT = """
import sys, threading, time
from pathlib import Path
import station
assert station.__file__.startswith(sys.argv[2]), station.__file__
from station.io import capture as capture_module
from station.io.capture import read_capture

real = capture_module._read_segment_data
begun = threading.Event()

def slow(capture, segment, *args, **kwargs):
    begun.set()
    time.sleep(1.0)
    data = real(capture, segment, *args, **kwargs)
    with open(sys.argv[3], "a") as f:
        f.write(segment.name + " ")
    return data

capture_module._read_segment_data = slow
capture = read_capture(sys.argv[1], load_data=False)
reader = capture.reader_ahead(capture.segments)
reader.ahead()
begun.wait(30)
reader.close(wait=False)        # Ctrl-C: the read under way left to its thread
print("closed")
"""


def test_a_read_left_by_ctrl_c_ends_before_the_process(tmp_path):
    """close(wait=False) (Ctrl-C) leaves the read under way to its thread and returns at once; the
    process then ends after that read (up to LEFT_READS_WAIT_S: here 1 s), not during it: a reading
    thread still in the CSV engine while the interpreter ended crashed the process (`station
    estimate` of a 1 kHz capture interrupted while reading: exit status -11 instead of 130, ~1
    Ctrl-C in 6).  (tests/test_forked.py: a read of a minute does not hold the process.)"""
    import subprocess
    import sys
    from pathlib import Path

    root = str(Path(__file__).resolve().parents[1])
    marker = tmp_path / "read"
    done = subprocess.run([sys.executable, "-c", LEFT, str(make_bundle(tmp_path)), root, str(marker)],
                          capture_output=True, text=True, timeout=120, cwd=root, env=dict(os.environ, PYTHONPATH=root))
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.strip() == "closed"
    assert marker.exists(), "the process ended during the read"
    assert "pos01" in marker.read_text().split()
