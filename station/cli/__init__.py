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


__all__ = ["main"]
