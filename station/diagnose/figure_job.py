"""The report's figures drawn in a second process while this one reads and fits.

A report's figures cost more CPU than its fit (docs/performance.md, "Diagnose and the report"):
importing matplotlib (~0.25 s) and drawing five figures (0.06-0.12 s each).  ``FigureJob()``
forks a worker at once (Linux) that imports matplotlib while this process reads the capture and
fits; ``draw(specs)`` gives it figures to draw as plain numbers ({file name: SegmentsFigure,
CandidateFigure or NoiseResult}: the diagnosis objects stay here), as soon as each is known; the
worker shares them out between itself and a forked process per other core (matplotlib already
imported there), so the figures are drawn on every core while this process waits.  ``result()``
returns {file name: bytes} (the format of each name: station.diagnose.figures.figure_format).
This process never imports matplotlib.

Where fork is not used (station.core.forked.available: Linux), or the worker fails or dies, the
figures are drawn here, in order, with the same pixels.  The worker and the processes it forks
are killed when this process ends, however it ends.  The worker ignores Ctrl-C (the parent is
interrupted, ends it on leaving the ``with`` block and exits 130 without a traceback from
either).
"""
from __future__ import annotations

import gc
import multiprocessing
import os
import signal

from station.core import forked

ALLAN_FIGURE = "allan.svg"                          # the report's figures, by file name
SEGMENTS_FIGURE = "residuals_per_segment.svg"


def _start_worker(parent: int) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    forked.end_with_parent(parent)        # killed with this process, however it ends
    gc.disable()      # it lives for one command: the collector only costs time (7-10 % of drawing)


def _import_matplotlib() -> None:
    from station.diagnose.figures import pyplot

    pyplot()


def _draw_here(specs: dict) -> dict:
    from station.diagnose.figures import draw

    return draw(specs)


def _draw_task(specs: dict) -> dict:
    """In the worker: the figures shared out between this process and a forked one per other
    core, each drawing every n-th figure.  (A fork of a process with matplotlib costs the pages
    it copies: one per core, not one per figure; and a process forked for the Allan figure alone,
    to leave this one free for the next task, measured 5 % slower in all.)"""
    names = list(specs)
    shares = max(1, min(len(names), forked.usable_cores()))
    parts = [{name: specs[name] for name in names[k::shares]} for k in range(shares)]
    children = []
    try:
        for part in parts[1:]:
            try:
                children.append((part, forked.Forked(lambda part=part: _draw_here(part))))
            except OSError:           # no process to spare: drawn here below
                children.append((part, None))
        drawn = _draw_here(parts[0])
        for part, child in children:
            try:
                drawn.update(child.result() if child is not None else _draw_here(part))
            except forked.ChildLost:
                drawn.update(_draw_here(part))
        return {name: drawn[name] for name in names}
    finally:
        for _, child in children:
            if child is not None:
                child.close()


class FigureJob:
    """``with FigureJob() as job: job.draw({name: spec}); ...; figures = job.result()``"""

    def __init__(self):
        self._pool = None
        self._tasks = []              # (specs, Future or None), in the order given

    def __enter__(self) -> "FigureJob":
        if forked.available():
            from concurrent.futures import ProcessPoolExecutor

            try:
                # a worker that dies fails its futures (BrokenProcessPool): drawn here instead
                self._pool = ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("fork"),
                                                 initializer=_start_worker, initargs=(os.getpid(),))
                self._pool.submit(_import_matplotlib)
            except OSError:           # no process to spare: drawn here, in result()
                self._pool = None
        return self

    def draw(self, specs: dict) -> None:
        """Draw these figures ({file name: spec}) in the worker, after those given before."""
        specs = dict(specs)
        if specs:
            pending = None
            if self._pool is not None:
                try:
                    pending = self._pool.submit(_draw_task, specs)
                except RuntimeError:  # the worker is gone (BrokenProcessPool): drawn here
                    pending = None
            self._tasks.append((specs, pending))

    def result(self) -> dict:
        """{file name: bytes} of every figure given to draw(), in the order given."""
        figures = {}
        for specs, pending in self._tasks:
            drawn = None
            if pending is not None:
                try:
                    drawn = pending.result()
                except Exception:     # noqa: BLE001 -- the worker failed: drawn here, which says why
                    drawn = None
            figures.update(drawn if drawn is not None else _draw_here(specs))
        return figures

    def __exit__(self, *exc) -> None:
        pool, self._pool = self._pool, None
        if pool is None:
            return
        # end the worker now (it may be drawing: Ctrl-C, or an error here), not after its task
        kill = getattr(pool, "kill_workers", None)                  # Python 3.14
        if kill is not None:
            kill()
        else:
            for process in list((getattr(pool, "_processes", None) or {}).values()):
                process.kill()        # what kill_workers does, before 3.14
        pool.shutdown(wait=True, cancel_futures=True)


def read_for_report(capture, cal_doc, stack, check_segment=None) -> tuple:
    """Read and summarise ``capture`` as a report needs it (station.estimate.
    summarise_while_importing, the diagnosis' modules imported meanwhile): a FigureJob entered
    on ``stack`` once the reading has begun, the longest static segment's Allan curves computed
    where the capture is read (station.estimate.noise.LongestStatic) and its figure given to the
    job.  (job, NoiseResult or None, note or None)."""
    from station.diagnose import DIAGNOSIS_MODULES
    from station.estimate import summarise_while_importing
    from station.estimate.noise import LongestStatic

    job, longest = FigureJob(), LongestStatic(capture, cal_doc)

    def check(seg) -> None:
        if check_segment is not None:
            check_segment(seg)
        longest.check(seg)

    curves = summarise_while_importing(capture, check, modules=DIAGNOSIS_MODULES, then=longest.curves,
                                       meanwhile=lambda: stack.enter_context(job))
    noise, note = longest.noise(curves)
    if noise is not None:
        job.draw({ALLAN_FIGURE: noise})
    return job, noise, note
