"""The ``station`` command: the parser and the dispatch; each command group is a module of its own
(run, calibration, diagnose, montecarlo, imports, devices) and prints through station.cli.output."""
from __future__ import annotations

import argparse
import os
import sys

import station
from station.cli.output import err
from station.core.blas import blas_threads, whole_process
from station.core.errors import UserError


class _Parser(argparse.ArgumentParser):
    """argparse with usage errors on one line (exit status 2, as for every user error)."""

    def error(self, message):
        self.exit(2, f"{self.prog}: {message} (see {self.prog} --help)\n")


# the module that adds each command's parser (kept equal to what the modules add by
# tests/test_estimate_imports.py): a command line naming its command first builds that module's
# parsers only, and imports no other command module (issue 27: 15-20 ms of a small estimate)
GROUPS = ("run", "calibration", "montecarlo", "design", "diagnose", "imports", "devices", "export", "noise",
          "history", "fleet", "report", "batch")
COMMAND_GROUPS = {"run": "run", "schemes": "run", "plan": "run", "init": "run",
                  "estimate": "calibration", "apply": "calibration", "show": "calibration",
                  "montecarlo": "montecarlo", "design": "design", "diagnose": "diagnose", "effects": "diagnose",
                  "import": "imports", "sim": "devices", "probe": "devices", "export": "export", "noise": "noise",
                  "history": "history", "diff": "history", "fleet": "fleet", "report": "report", "batch": "batch"}


def build_parser(argv=None) -> argparse.ArgumentParser:
    """The parser of every command; or, when ``argv`` begins with a command's name, of the
    commands of that command's module only (the same parser for that command line: its
    sub-parser, options, help and errors are the whole parser's)."""
    import importlib

    first = argv[0] if argv else None
    groups = (COMMAND_GROUPS[first],) if first in COMMAND_GROUPS else GROUPS

    p = _Parser(prog="station", description="IMU calibration with a rate table.")
    p.add_argument("--version", action="version", version=f"station {station.__version__}")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND", parser_class=_Parser)
    for group in groups:
        importlib.import_module(f"station.cli.{group}").add_parsers(sub)
    return p


# every option that names a file or folder a command writes (``dest`` -> as the user types it):
# checked by the one rule for outputs (station.core.user_files.output_path) before any work
OUTPUT_OPTIONS = {"output": "-o", "out": "--out", "output_dir": "-o", "report": "--report", "drift": "--drift",
                  "plot": "--plot", "emit_effect": "--emit-effect", "state": "--state",
                  "estimate": "--estimate"}     # import … --estimate CAL.yaml (a bare --estimate: True)


def check_outputs(args) -> None:
    """Refuse an output option on a dangling symbolic link before the command does any work (the
    writers check again: the library's callers and the default paths)."""
    from station.core.user_files import output_path

    named = [(opt, getattr(args, dest, None)) for dest, opt in OUTPUT_OPTIONS.items()]
    if getattr(args, "command", None) == "init":
        named.append(("init", getattr(args, "path", None)))
    for opt, value in named:
        if isinstance(value, str):
            output_path(value, f"the output of {opt}")


def main(argv=None) -> int:
    """Exit status: 0 done; 2 bad input (one line naming the file, line or field), or data too
    large for the memory (one line); 3 the calibration was written but its fit fails
    (``--accept-poor-fit`` makes it 0); 130 interrupted (Ctrl-C) at any moment, without a
    traceback."""
    command = "?"
    try:
        argv = sys.argv[1:] if argv is None else list(argv)
        args = build_parser(argv).parse_args(argv)
        command = args.command
        check_outputs(args)
        with whole_process(blas_threads()):       # station/core/blas.py
            return args.func(args)
    except UserError as e:
        err.print(f"station {command}: {e}", markup=False, soft_wrap=True)
        return 2
    except MemoryError as e:
        # a capture too large for this machine's memory (issue 27 item 4): one line, not a traceback
        detail = str(e).strip() or "MemoryError"
        err.print(f"station {command}: out of memory ({detail}): the data are too large for this machine's "
                  "memory; use a machine with more memory, or fewer segments", markup=False, soft_wrap=True)
        return 2
    except KeyboardInterrupt:
        err.print("interrupted", markup=False)
        return 130
    except BrokenPipeError:
        # whatever read the output went away (`station probe ... | head -1`): stop quietly, as rich
        # does for the tables (Python's advice: stdout onto /dev/null, so that the flush at exit
        # does not fail again, and status 1)
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 1


if __name__ == "__main__":
    sys.exit(main())
