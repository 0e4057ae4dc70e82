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
    gc.freeze()
    return status


__all__ = ["main", "console_main"]
