"""The report's noise section (Allan deviation of the longest static segment and its figure),
computed in a second process while this one fits and diagnoses.

The two do not depend on each other, and the noise side is the slowest part of a report that
is not a fit (importing allantools and scipy.stats ~0.8 s, the analysis ~0.3 s, the figure
~0.4 s at 100 Hz).  A forked child inherits the capture already read (nothing is copied to
it); it sends back the NoiseResult, the note, and the PNG of the figure.  Where fork is not
available, or the child fails, the same work is done here, in order, with the same result.

matplotlib is imported before the fork, so that both processes have it for one import.
The child ignores Ctrl-C (the parent is interrupted, ends the child and exits 130 without a
traceback from either).
"""
from __future__ import annotations

import multiprocessing
import signal

from station.core.errors import UserError

_INPUT = None          # (capture, cal_doc): set in the parent just before the fork


def _ignore_interrupts() -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def noise_of(capture, cal_doc=None):
    """(NoiseResult or None, note) from the capture's longest static segment."""
    from station.estimate import noise

    try:
        result = noise.from_capture(capture, None, cal_doc)
    except UserError as e:
        return None, f"Not characterised: {e}"
    return result, None


def noise_section(capture, cal_doc=None) -> tuple:
    """(NoiseResult or None, note or None, Allan figure PNG bytes or None)."""
    from station.diagnose.figures import allan_figure

    result, note = noise_of(capture, cal_doc)
    return result, note, (allan_figure(result) if result is not None else None)


def _child() -> tuple:
    capture, cal_doc = _INPUT
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1, user_api="blas"):
        return noise_section(capture, cal_doc)


class NoiseJob:
    """``with NoiseJob(capture, cal_doc) as job: ...; noise, note, png = job.result()``"""

    def __init__(self, capture, cal_doc=None):
        self.capture, self.cal_doc = capture, cal_doc
        self._pool = self._pending = None

    def __enter__(self) -> "NoiseJob":
        global _INPUT
        if "fork" in multiprocessing.get_all_start_methods():
            from station.diagnose.figures import pyplot

            pyplot()        # imported once, before the fork: both processes draw (0.4 s saved)
            _INPUT = (self.capture, self.cal_doc)
            try:
                self._pool = multiprocessing.get_context("fork").Pool(1, initializer=_ignore_interrupts)
                self._pending = self._pool.apply_async(_child)
            except OSError:           # no process to spare: do it here, in result()
                self._pool = self._pending = None
            finally:
                _INPUT = None
        return self

    def result(self) -> tuple:
        if self._pending is not None:
            try:
                return self._pending.get()
            except Exception:         # noqa: BLE001 -- the child failed: the same work here says why
                pass
        return noise_section(self.capture, self.cal_doc)

    def __exit__(self, *exc) -> None:
        if self._pool is not None:
            self._pool.terminate()
            self._pool.join()
            self._pool = self._pending = None
