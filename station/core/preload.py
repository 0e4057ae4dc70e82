"""Import modules on a background thread while the caller's own thread does work that releases
the GIL (reading a capture: pyarrow's CSV engine, hashlib and numpy's loops run without it).

`station estimate` spends about as long importing scipy (~0.25 s: scipy.optimize, scipy.special)
as reading a 100 Hz capture; done one after the other they add up, on two threads they overlap
(docs/performance.md).

Rules that keep this safe: the caller imports everything its own work needs *before* entering
(so the two threads never wait for each other's module locks in a cycle), and uses the modules
only after the block (which waits for the thread).  A module that fails to import here is simply
left: the caller's own import then raises the error in the caller's thread, with its usual
message.  While the block runs, the interpreter's switch interval is SWITCH_INTERVAL_S instead of
5 ms: the reading thread takes the GIL back after every numpy call and pyarrow block, and would
otherwise wait up to 5 ms each time for the importing thread to let go of it.
"""
from __future__ import annotations

import importlib
import sys
import threading
from contextlib import contextmanager

SWITCH_INTERVAL_S = 2e-4


@contextmanager
def importing(*modules: str):
    """Import ``modules`` in order on a daemon thread while the block runs; wait for them at its
    end (not when the block raises: the error goes out at once, the thread is left to finish)."""

    def run():
        for name in modules:
            try:
                importlib.import_module(name)
            except BaseException:       # noqa: BLE001 - raised again by the caller's own import
                return

    import os
    if os.environ.get("X_NOPRELOAD"):
        run = lambda: None
    thread = threading.Thread(target=run, name="station-preload", daemon=True)
    interval = sys.getswitchinterval()
    sys.setswitchinterval(float(os.environ.get("X_SWITCH", min(interval, SWITCH_INTERVAL_S))))
    thread.start()
    try:
        yield thread
        thread.join()
    finally:
        sys.setswitchinterval(interval)
