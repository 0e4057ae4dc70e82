"""The report's figures drawn in other processes while this one reads and fits.

A report's figures cost more CPU than its fit (docs/performance.md, "Diagnose and the report"):
importing matplotlib (~0.28 s) and drawing three to five figures (0.04-0.07 s each).  A FigureJob's
``start()`` (called where the capture is about to be read) forks a worker (Linux) that imports
matplotlib while this process reads the capture and fits, then forks a drawing process per
other core: every one of them takes the next figure given as soon as it may (one queue: no
figure waits behind another while a process is idle).  ``draw(specs)`` gives figures as plain numbers ({file name: SegmentsFigure,
CandidateFigure or NoiseResult}: the diagnosis objects stay here) as soon as each is known;
``result()`` waits for them and returns {file name: bytes} (the format of each name:
station.diagnose.figures.figure_format).  This process never imports matplotlib, and starts no
thread (a reader forked after the job is made forks a process with one thread).

How: each figure's numbers are pickled into a private temporary directory and its number
written to a pipe every drawing process reads (a record of a few bytes: written and read whole,
so each figure is taken by one process); the process writes the figure into the directory and
its number back through a second pipe.  Each drawing process holds a third pipe open, whose end
here reads end-of-file when it ends, however it ends: what it took and did not draw is given
again to the others, or drawn here when none is left.

While this process works, the drawing processes draw one figure at a time per core it leaves
free (a permit each, read from a fourth pipe); once it waits (``result()``), one more: figures
drawn on every core while it still fits would slow the fit the last figure waits for.

Where fork is not used (station.core.forked.available: Linux), or drawing fails there, the
figures are drawn here, with the same bytes.  The worker and the processes it forks end when
this process ends, however it ends (killed, the worker first removing the temporary directory),
and ignore Ctrl-C (this process is interrupted, ends them on leaving the ``with`` block and
exits 130 without a traceback from them).  Once every figure is here, the worker is asked to
end (SIGTERM: it kills its drawing processes and waits for them) so that it ends while the page
is written, and it is awaited before the ``with`` block is left: nothing of the job runs after
the command returns (tests/test_no_work_after_return.py).  A directory whose processes were all killed at once
(SIGKILL to the process group: nothing is left to remove it) is removed by the next worker
(``remove_orphaned_directories``: the directory's name holds its process's number).
"""
from __future__ import annotations

import gc
import os
import pickle
import select
import shutil
import signal
import struct
import tempfile

from station.core import forked

ALLAN_FIGURE = "allan.svg"                          # the report's figures, by file name
SEGMENTS_FIGURE = "residuals_per_segment.svg"
MOST_PROCESSES = 4          # drawing processes at most (a report has three to five figures)
TASK = struct.Struct("<i")                          # to the drawing processes: a figure's number
DONE = struct.Struct("<iii")                        # back: (number, TAKING/.../FAILED, process)
TAKING, TAKEN, DRAWN, FAILED = 0, 1, 2, 3          # TAKING: about to take one (its number: -1)
PERMIT = b"p"       # one byte per figure that may be drawn at once
DIRECTORY_PREFIX = "station-figures-"    # + the pid of the process that made it + "-" + random
# what matplotlib imports at the first figure drawn and saved as SVG (~10 ms), and what an Allan
# figure's numbers are (station.estimate.noise.NoiseResult, unpickled there)
WARM_MODULES = ("matplotlib.backends.backend_agg", "matplotlib.backends.backend_svg", "station.estimate.noise")


def remove_orphaned_directories(directory: str | None = None) -> list:
    """Remove the figures' temporary directories (in ``directory``, by default the system's
    temporary one) that this user's processes made and that outlived them: a process group
    killed at once (SIGKILL) leaves its directory, nothing being left to remove it.  One whose
    process lives, that another user owns, or that is not a plain directory is left.  The names
    of those removed."""
    import re
    import stat

    directory = directory or tempfile.gettempdir()
    removed = []
    try:
        names = os.listdir(directory)
    except OSError:
        return removed
    pattern = re.compile(re.escape(DIRECTORY_PREFIX) + r"(\d+)-[A-Za-z0-9_]+")
    for name in names:
        match = pattern.fullmatch(name)
        if not match:
            continue
        path = os.path.join(directory, name)
        try:
            info = os.lstat(path)
            if not stat.S_ISDIR(info.st_mode) or info.st_uid != os.getuid():
                continue
            os.kill(int(match.group(1)), 0)
            continue                      # its process lives (or another's has its number)
        except ProcessLookupError:
            shutil.rmtree(path, ignore_errors=True)
            removed.append(name)
        except (OSError, OverflowError, ValueError):
            continue
    return removed


def _draw_here(specs: dict) -> dict:
    from station.diagnose.figures import draw

    return draw(specs)


def _draw_one(name: str, spec) -> bytes:
    """In a drawing process: one figure's bytes."""
    return _draw_here({name: spec})[name]


def _read_whole(fd: int, size: int) -> bytes:
    """``size`` bytes from a pipe, or b"" at its end."""
    data = b""
    while len(data) < size:
        part = os.read(fd, size - len(data))
        if not part:
            return b""
        data += part
    return data


def _worker(parent: int, tasks: int, done: int, permits: tuple, alive: list, directory: str) -> None:
    """In the forked worker: matplotlib imported, a drawing process forked per other core (each
    holding its own end of ``alive``), then every one of them draws (_drawing)."""
    helpers = []

    def parent_gone(*_):
        """Sent by the parent's _stop, or by the kernel when the parent ended (killed): the
        drawing processes ended first (so that none writes into the directory after), then the
        directory removed, which a killed parent cannot do."""
        for pid in helpers:
            try:
                os.kill(pid, signal.SIGKILL)
                os.waitpid(pid, 0)
            except (ProcessLookupError, ChildProcessError):
                pass
        shutil.rmtree(directory, ignore_errors=True)
        os._exit(0)

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, parent_gone)
    forked.end_with_parent(parent, signal.SIGTERM)      # ended with this process, however it ends
    gc.disable()      # it lives for one command: the collector only costs time (7-10 % of drawing)
    try:
        import importlib

        from station.diagnose.figures import pyplot

        pyplot()
        for name in WARM_MODULES:         # imported here once, not in each process at its first figure
            importlib.import_module(name)
    except Exception:       # noqa: BLE001 -- each figure then fails there and is drawn here, which says why
        pass
    remove_orphaned_directories()       # here: not on the command's path
    me, index = os.getpid(), 0
    for k in range(1, len(alive)):
        try:
            pid = os.fork()
        except OSError:       # fewer processes: the others draw its share
            break
        if pid == 0:
            signal.signal(signal.SIGTERM, signal.SIG_DFL)
            forked.end_with_parent(me)
            index = k
            break
        helpers.append(pid)
    for k, fd in enumerate(alive):
        if k != index:
            os.close(fd)
    _drawing(index, tasks, done, permits, directory)


def _drawing(index: int, tasks: int, done: int, permits: tuple, directory: str) -> None:
    """With a permit, take a figure, draw it, say so, give the permit back; until the pipe of
    figures is closed."""
    while True:
        if not _read_whole(permits[0], 1):
            return
        os.write(done, DONE.pack(-1, TAKING, index))
        record = _read_whole(tasks, TASK.size)
        if not record:
            return
        (number,) = TASK.unpack(record)
        os.write(done, DONE.pack(number, TAKEN, index))
        try:
            with open(os.path.join(directory, f"{number}.spec"), "rb") as f:
                name, spec = pickle.load(f)
            data = _draw_one(name, spec)
            aside = os.path.join(directory, f"{number}.{index}.part")    # a figure drawn twice (given
            with open(aside, "wb") as f:                                  # again) is never read half
                f.write(data)                                             # written
            os.replace(aside, os.path.join(directory, f"{number}.figure"))
            status = DRAWN
        except Exception:   # noqa: BLE001 -- drawn here instead, which says why
            status = FAILED
        os.write(done, DONE.pack(number, status, index))
        os.write(permits[1], PERMIT)


def _end(worker: int, grace_s: float = 2.0, *, asked: bool = False) -> None:
    """End the worker: SIGTERM (it ends its drawing processes, waits for them and removes the
    directory, within the figure it may be drawing; unless ``asked`` already), SIGKILL if it has
    not ended within ``grace_s``; reaped.  When this returns, no process of the job is left to
    run (its drawing processes were awaited by the worker), but after a SIGKILL."""
    import time

    try:
        if not asked:
            os.kill(worker, signal.SIGTERM)
        deadline = time.monotonic() + grace_s
        try:
            pidfd = os.pidfd_open(worker)       # Linux 5.3: readable when the worker has ended
        except (AttributeError, OSError):
            pidfd = None
        try:
            while os.waitpid(worker, os.WNOHANG) == (0, 0):
                left = deadline - time.monotonic()
                if left <= 0:
                    os.kill(worker, signal.SIGKILL)
                    os.waitpid(worker, 0)
                    break
                if pidfd is not None:
                    select.select([pidfd], [], [], left)
                else:
                    time.sleep(0.002)
        finally:
            if pidfd is not None:
                os.close(pidfd)
    except (ProcessLookupError, ChildProcessError):
        pass


class FigureJob:
    """``with FigureJob() as job: job.start(); job.draw({name: spec}); ...; figures = job.result()``"""

    def __init__(self):
        self._names, self._specs = [], []
        self._drawn: dict = {}            # number -> bytes
        self._here: list = []             # numbers to draw here
        self._hand: dict = {}             # drawing process -> the number it holds, "taking" or None
        self._alive: dict = {}            # fd -> drawing process, while it lives
        self._worker = self._tasks = self._done = self._permits = self._dir = None
        self._started, self._waiting, self._killed = False, False, False
        self._buffer = b""

    def __enter__(self) -> "FigureJob":
        return self

    def start(self) -> None:
        """Fork the worker now (Linux; once): it imports matplotlib while this process goes on.
        (After the modules both need are imported here, so that it does not import them again;
        it starts no thread here.)  draw() starts it when not started."""
        if self._started:
            return
        self._started = True
        if forked.available():
            try:
                self._start()
            except OSError:           # no process or pipe to spare: drawn here, in result()
                self._stop()

    def _start(self) -> None:
        count = max(1, min(forked.usable_cores(), MOST_PROCESSES))
        self._dir = tempfile.mkdtemp(prefix=f"{DIRECTORY_PREFIX}{os.getpid()}-")
        fds = []              # the ends only the processes forked keep, closed here
        try:
            tasks_r, self._tasks = os.pipe()
            fds.append(tasks_r)
            self._done, done_w = os.pipe()
            fds.append(done_w)
            permits_r, self._permits = os.pipe()
            fds.append(permits_r)
            alive = []
            for k in range(count):
                r, w = os.pipe()
                self._alive[r] = k
                alive.append((r, w))
                fds.append(w)
            parent = os.getpid()
            pid = os.fork()
            if pid == 0:
                try:
                    for fd in (self._tasks, self._done, *self._alive):
                        os.close(fd)
                    _worker(parent, tasks_r, done_w, (permits_r, self._permits), [w for _, w in alive], self._dir)
                finally:
                    os._exit(0)       # no atexit handlers, no buffers flushed twice
            self._worker = pid
            os.set_blocking(self._done, False)      # read to its end, never waited on (select does)
            os.write(self._permits, PERMIT * max(1, count - 1))      # this process is busy
        finally:
            for fd in fds:
                os.close(fd)

    def draw(self, specs: dict) -> None:
        """Draw these figures ({file name: spec}): each taken by the first drawing process free."""
        self.start()
        for name, spec in specs.items():
            number = len(self._names)
            self._names.append(name)
            self._specs.append(spec)
            if not self._alive or not self._give(number):
                self._here.append(number)

    def _give(self, number: int) -> bool:
        try:
            path = os.path.join(self._dir, f"{number}.spec")
            if not os.path.exists(path):
                with open(path, "wb") as f:
                    pickle.dump((self._names[number], self._specs[number]), f, protocol=pickle.HIGHEST_PROTOCOL)
            os.write(self._tasks, TASK.pack(number))
            return True
        except (OSError, pickle.PicklingError, TypeError, AttributeError):
            return False

    def result(self) -> dict:
        """{file name: bytes} of every figure given to draw(), in the order given."""
        waiting = {n for n in range(len(self._names)) if n not in self._drawn and n not in self._here}
        self.all_cores()
        while waiting and self._alive:
            ready, _, _ = select.select([self._done, *self._alive], [], [])
            # every record written so far read first (a process that ended wrote its last ones
            # before its end-of-file): what it held is then known
            for number, status, index in self._records():
                if index not in self._alive.values():
                    continue                  # (an ended process's: its figure is given again)
                self._hand[index] = ("taking" if status == TAKING else number if status == TAKEN else None)
                if number not in waiting or status in (TAKING, TAKEN):
                    continue                  # (given twice below, and drawn already)
                if status == DRAWN and self._read_figure(number):
                    waiting.discard(number)
                else:                         # failed there, or its file is unreadable
                    waiting.discard(number)
                    self._here.append(number)
            for fd in [fd for fd in ready if fd in self._alive]:
                # a drawing process ended (its pipe's end-of-file): the figure it held is given
                # again (or drawn here below); if it ended while taking one, not knowing which,
                # every figure no living process holds (some may then be drawn twice)
                index = self._alive.pop(fd)
                os.close(fd)
                self._permit(1)               # the one it may have held
                held = self._hand.pop(index, None)
                living = {n for n in self._hand.values() if isinstance(n, int)}
                again = sorted(n for n in waiting if n not in living) if held == "taking" else [held]
                for number in again:
                    if number in waiting and (not self._alive or not self._give(number)):
                        waiting.discard(number)
                        self._here.append(number)
        self._here.extend(sorted(waiting))
        if self._here:
            numbers = sorted(set(self._here))
            drawn = _draw_here({self._names[n]: self._specs[n] for n in numbers})
            self._drawn.update({n: drawn[self._names[n]] for n in numbers})
            self._here = []
        if self._worker is not None and not self._killed:
            # every figure is here: the worker asked to end now (it kills its idle drawing
            # processes and waits for them, so that they end while this process writes the page;
            # killed with SIGKILL instead, they would be left to end after the command returns,
            # their CPU outside its time: issue 27, item 3); the worker is awaited on leaving the
            # ``with`` block
            try:
                os.kill(self._worker, signal.SIGTERM)
                self._killed = True
            except ProcessLookupError:
                pass
        return {self._names[n]: self._drawn[n] for n in range(len(self._names))}

    def all_cores(self) -> None:
        """This process has little left to do before it waits for the figures (result()): the
        drawing processes may draw on its core too (once)."""
        if self._alive and not self._waiting:
            self._waiting = True
            self._permit(len(self._alive) - max(1, len(self._alive) - 1))

    def _records(self) -> list:
        """Every whole record in the pipe of records now (it is read without waiting)."""
        while True:
            try:
                part = os.read(self._done, DONE.size * 256)
            except BlockingIOError:
                break
            if not part:
                break
            self._buffer += part
        whole = len(self._buffer) - len(self._buffer) % DONE.size
        records, self._buffer = list(DONE.iter_unpack(self._buffer[:whole])), self._buffer[whole:]
        return records

    def _permit(self, count: int) -> None:
        try:
            os.write(self._permits, PERMIT * count)
        except OSError:       # every drawing process ended: drawn here
            pass

    def _read_figure(self, number: int) -> bool:
        try:
            with open(os.path.join(self._dir, f"{number}.figure"), "rb") as f:
                self._drawn[number] = f.read()
            return True
        except OSError:
            return False

    def __exit__(self, *exc) -> None:
        self._stop()

    def _stop(self) -> None:
        """End the worker now (it may be drawing: Ctrl-C, or an error here; the processes it forked
        die with it), close the pipes, remove the directory."""
        if self._worker is not None:
            _end(self._worker, asked=self._killed)
            self._worker = None
        for fd in (self._tasks, self._done, self._permits, *self._alive):
            if fd is not None:
                try:
                    os.close(fd)
                except OSError:
                    pass
        self._tasks = self._done = self._permits = None
        self._alive = {}
        if self._dir is not None:
            shutil.rmtree(self._dir, ignore_errors=True)
            self._dir = None


def read_for_report(capture, cal_doc, job: FigureJob, check_segment=None) -> tuple:
    """Read and summarise ``capture`` as a report needs it (station.estimate.
    summarise_while_importing, the diagnosis' modules imported meanwhile), the longest static
    segment's Allan curves computed where the capture is read (station.estimate.noise.
    LongestStatic) and its figure given to ``job`` (entered before: matplotlib is imported there
    meanwhile).  (NoiseResult or None, note or None)."""
    from station.diagnose import DIAGNOSIS_MODULES
    from station.estimate import summarise_while_importing
    from station.estimate.noise import LongestStatic

    longest = LongestStatic(capture, cal_doc)

    def check(seg) -> None:
        if check_segment is not None:
            check_segment(seg)
        longest.check(seg)

    job.start()       # here: numpy and the capture's modules are imported, the reader not forked
    curves = summarise_while_importing(capture, check, modules=DIAGNOSIS_MODULES, then=longest.curves)
    noise, note = longest.noise(curves)
    if noise is not None:
        job.draw({ALLAN_FIGURE: noise})
    return noise, note
