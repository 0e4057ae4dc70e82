"""The command line: argument parsing and output only; the work is done by the layers below
(docs/architecture.md)."""


def main(argv=None) -> int:
    """The ``station`` command.  Imports lazily, inside the handler of Ctrl-C, so that an
    interrupt at any moment of start-up ends with "interrupted" and exit status 130, never a
    traceback."""
    try:
        from station.cli.app import main as run

        return run(argv)
    except KeyboardInterrupt:
        import sys

        print("interrupted", file=sys.stderr)
        return 130


def console_main() -> int:
    """The ``station`` console script: main(), then the objects made so far are frozen out of the
    cyclic garbage collector (gc.freeze) because the process ends right after: the collections
    the interpreter runs while it shuts down then skip them (numpy, scipy, pyarrow and the
    capture's summaries: ~50 ms of a 0.6 s `station estimate`, docs/performance.md).  Nothing
    else changes: every file is closed and flushed, atexit handlers run.  Not in main(), which
    tests and other programs call many times in one process.

    The cyclic collector also runs less often while the command runs (a young generation of
    10,000 allocations, not 700; each older one after 20 of the younger, not 10): a command's
    process makes its modules and arrays once and few cycles, and the collections that walked
    them while they were being made were ~4-5 % of a small `station estimate`'s CPU (issue 27;
    measured in interleaved pairs, docs/performance.md).  Garbage cycles are still collected."""
    import gc

    gc.set_threshold(10_000, 20, 20)
    status = main()
    if status == 130:
        _end_interrupted(status)
    gc.freeze()
    return status


def _end_interrupted(status: int) -> None:
    """End an interrupted command (Ctrl-C: "interrupted" said, status 130) without the
    interpreter's own shutdown: what that shutdown does first is done as it does it (the threads
    that are not daemons joined, threading._shutdown, with the executors' exit hooks; then the
    atexit handlers: the reads a Ctrl-C left are awaited there, station.io.capture), the output
    flushed, then os._exit.  Interrupted in their first 0.3-1.5 s, 7 of 100 estimates of a 1 kHz
    capture (its segments parsed on the CSV engine's own threads) ended with SIGABRT in the
    interpreter's shutdown (exit status -6, "terminate called without an active exception": a
    C++ thread torn down by the runtime's exit); 0 of 40 run by main() alone (without console_main's
    collector settings and gc.freeze), and 0 of 100 ended this way
    (issue 27, eighteenth session).  Every file station writes is complete or absent by then
    (written atomically, fsynced); nothing else is lost by skipping the interpreter's shutdown."""
    import atexit
    import os
    import sys
    import threading

    try:
        getattr(threading, "_shutdown", lambda: None)()
        atexit._run_exitfuncs()
    except KeyboardInterrupt:       # a second Ctrl-C: end now
        pass
    finally:
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except (OSError, ValueError):
                pass
        os._exit(status)


__all__ = ["main", "console_main"]
