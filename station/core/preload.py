"""Import modules on a background thread while the caller's own thread does work that releases
the GIL (reading a capture: pyarrow's CSV engine, hashlib and numpy run without it).

`station estimate` spends about as long importing scipy (~0.25 s: scipy.optimize, scipy.special)
as reading a 100 Hz capture; done one after the other they add up, on two threads they overlap.

Rules that keep this safe: the caller imports everything its own work needs *before* start()
(so the two threads never wait for each other's module locks in a cycle), and join()s the thread
before it uses the modules.  A module that fails to import here is simply left: the caller's own
import then raises the error in the caller's thread, with its usual message.
"""
from __future__ import annotations

import importlib
import threading


def start(*modules: str) -> threading.Thread:
    """A started daemon thread importing ``modules`` in order; join() it before using them."""

    def run():
        for name in modules:
            try:
                importlib.import_module(name)
            except BaseException:       # noqa: BLE001 - raised again by the caller's own import
                return

    thread = threading.Thread(target=run, name="station-preload", daemon=True)
    thread.start()
    return thread
