"""``station batch estimate|diagnose|report|export CAPTURE...``: one command over many captures
on a Dask cluster (argument parsing and output only; the work: station.batch)."""
from __future__ import annotations

import argparse

from station.cli import argtypes
from station.cli.choices import ESTIMATE_METHODS, EXPORT_FORMATS
from station.cli.output import EXIT_POOR_FIT, err, out, rich_console
from station.core.errors import UserError

COMMANDS = {"estimate": "estimate a calibration from every capture (station estimate)",
            "diagnose": "diagnose every capture, JSON per capture (station diagnose --json)",
            "report": "a report page per capture (station report)",
            "export": "export every capture's calibration (station export)"}


def add_parsers(sub) -> None:
    b = sub.add_parser("batch", help="run estimate, diagnose, report or export on many captures on a Dask "
                       "cluster (every local core by default, or --scheduler)")
    bsub = b.add_subparsers(dest="batch_command", required=True, metavar="COMMAND")
    for name, text in COMMANDS.items():
        p = bsub.add_parser(name, help=text, description=text)
        p.add_argument("captures", nargs="*", metavar="CAPTURE",
                       help="capture folders, globs ('captures/*'), or folders of captures"
                            + (", or calibration files" if name == "export" else ""))
        p.add_argument("--history-query", action="append", default=[], metavar="SERIAL",
                       help="also the captures of every calibration of this IMU serial in the history "
                            "('all': every serial; repeatable)")
        p.add_argument("--scheduler", metavar="tcp://HOST:8786",
                       help="run on this Dask scheduler's workers (they must reach the captures' paths); "
                            "default: a local cluster on every usable core, started and stopped here")
        p.add_argument("--workers", type=argtypes.whole(1), metavar="N",
                       help="local cluster: worker processes (default: one per usable core)")
        p.add_argument("-o", "--output-dir", metavar="DIR",
                       help="write every output into DIR (named after the capture) instead of beside it")
        p.add_argument("--state", metavar="FILE", help="the batch state file (default: "
                       "DIR/.station-batch-COMMAND.jsonl, or in the working folder)")
        p.add_argument("--restart", action="store_true",
                       help="do every capture again (default: skip those done by an earlier batch whose "
                            "capture and output are unchanged)")
        if name == "estimate":
            p.add_argument("--method", choices=ESTIMATE_METHODS, default="auto")
        if name in ("estimate", "diagnose"):
            p.add_argument("--add", action="append", default=[], metavar="EFFECT",
                           help="add an effect to the model (an id, or a plugin FILE.py:CLASS the "
                                "workers reach; repeatable)")
            p.add_argument("--plugin", action="append", default=[], metavar="FILE.py[:CLASS]",
                           help="load an effect plugin (a path the workers reach)")
        if name == "estimate":
            p.add_argument("--max-missing-fraction", type=float, default=0.01, metavar="F")
            p.add_argument("--max-gap-s", type=float, default=1.0, metavar="S")
            p.add_argument("--turn-sigma-deg", type=float, default=None, metavar="DEG")
            p.add_argument("--accept-poor-fit", action="store_true",
                           help=f"exit 0 when fits fail (default: exit status {EXIT_POOR_FIT})")
            p.add_argument("--history", action=argparse.BooleanOptionalAction, default=True,
                           help="file every calibration in the history (default: filed, as a bench run; a "
                                "simulated IMU only in the simulations' own store; only an IMU with a serial)")
            p.add_argument("--store", metavar="DIR", help="the history store (default: $STATION_HISTORY_DIR "
                           "or the user's data directory); also where --history-query looks")
        else:
            p.add_argument("--store", metavar="DIR", help="the history store --history-query looks in")
        if name == "diagnose":
            p.add_argument("--auto", action="store_true", help="add significant effects and refit (diagnose --auto)")
        if name == "report":
            p.add_argument("--no-auto", action="store_true", help="no add-and-refit loop")
        if name == "export":
            p.add_argument("--to", required=True, choices=sorted(EXPORT_FORMATS), metavar="FORMAT",
                           help=", ".join(EXPORT_FORMATS))
        p.set_defaults(func=cmd_batch)


def _options(args) -> dict:
    c = args.batch_command
    if c == "estimate":
        if not (0 <= args.max_missing_fraction < 1 and args.max_gap_s > 0):
            raise UserError("--max-missing-fraction must be within [0, 1) and --max-gap-s > 0")
        if args.turn_sigma_deg is not None and not (0 <= args.turn_sigma_deg < 90):
            raise UserError(f"--turn-sigma-deg {args.turn_sigma_deg}: must be within [0, 90) degrees")
        return {"method": args.method, "add": list(args.add), "plugins": list(args.plugin),
                "max_missing_fraction": args.max_missing_fraction, "max_gap_s": args.max_gap_s,
                "turn_sigma_deg": args.turn_sigma_deg}
    if c == "diagnose":
        return {"add": list(args.add), "plugins": list(args.plugin), "auto": bool(args.auto)}
    if c == "report":
        return {"no_auto": bool(args.no_auto)}
    return {"to": args.to}


def _progress(total: int):
    from rich.progress import (BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn,
                               TimeRemainingColumn)

    return Progress(TextColumn("captures"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                    TextColumn("left"), TimeRemainingColumn(), console=rich_console(err),
                    transient=True, disable=not err.is_terminal)


def _terminate_as_interrupt() -> None:
    """SIGTERM and SIGHUP end a batch as Ctrl-C does: the cluster is closed on the way out."""
    import signal

    def stop(signum, frame):
        raise KeyboardInterrupt

    for sig in (signal.SIGTERM, signal.SIGHUP):
        signal.signal(sig, stop)


def cmd_batch(args) -> int:
    from station.batch import inputs
    from station.batch.cluster import open_client
    from station.batch.filing import Filer
    from station.batch.runner import run_batch
    from station.batch.state import State, default_path

    command = args.batch_command
    options = _options(args)
    sources = inputs.expand(args.captures, allow_files=command == "export")
    if args.history_query:
        sources += [c for c in inputs.from_history(args.history_query, args.store) if c not in sources]
    if not sources:
        raise UserError(f"batch {command}: no capture given (CAPTURE..., a glob, or --history-query SERIAL)")
    items = inputs.plan(command, sources, args.output_dir, options.get("to"))
    state = State(args.state or default_path(command, args.output_dir), fresh=args.restart)
    filer = Filer(args.store) if command == "estimate" and args.history else None
    _terminate_as_interrupt()
    with open_client(args.scheduler, args.workers) as client, state, _progress(len(items)) as bar:
        task = bar.add_task("captures", total=len(items))

        def on_result(o) -> None:
            bar.advance(task)
            if o.status == "failed":
                err.print(f"failed: {o.source}: {o.message}", markup=False, soft_wrap=True, highlight=False)
            elif filer is not None and o.status != "skipped" and o.calibration:
                filer.file(o.calibration, o.imu_serial)

        where = args.scheduler or "a local cluster"
        summary = run_batch(client, command, items, options, state, on_result)
    _print_summary(command, summary, where, filer, state.path)
    if summary.count("failed"):
        return 2
    if summary.poor_fits and not getattr(args, "accept_poor_fit", False):
        err.print(f"station batch: {summary.poor_fits} fit(s) fail (exit status {EXIT_POOR_FIT}); "
                  "their files say so; --accept-poor-fit accepts them", markup=False, soft_wrap=True)
        return EXIT_POOR_FIT
    return 0


def _print_summary(command, summary, where, filer, state_path) -> None:
    from collections import Counter

    from rich.table import Table

    n = len(summary.outcomes)
    computed = summary.computed
    out.print(f"station batch {command}: {n} capture(s) on {where} ({summary.workers} worker thread(s))",
              markup=False, soft_wrap=True)
    t = Table()
    t.add_column("")
    t.add_column("captures", justify="right")
    for status in ("done", "poor fit", "failed", "skipped"):
        t.add_row(status + (" (by an earlier batch)" if status == "skipped" else ""), str(summary.count(status)))
    if command == "estimate":
        for verdict, k in sorted(Counter(o.verdict for o in computed if o.verdict).items()):
            t.add_row(f"  fit {verdict}", str(k))
    if filer is not None:
        for what, k in sorted(filer.counts.items()):
            t.add_row(f"history: {what}", str(k))
    cpu = sum(o.cpu_s for o in computed)
    rate = len(computed) / summary.wall_s if summary.wall_s > 0 else 0.0
    t.add_row("wall time", f"{summary.wall_s:.1f} s")
    t.add_row("CPU time in the workers", f"{cpu:.1f} s")
    t.add_row("throughput", f"{rate:.2f} captures/s")
    out.print(t)
    for w in (filer.warnings if filer is not None else [])[:10]:
        err.print(f"warning: {w}", markup=False, soft_wrap=True)
    out.print(f"state: {state_path} (a batch started again skips what is done)", markup=False, soft_wrap=True)
