"""``station montecarlo``: repeat simulate -> estimate, compare with the Cramér-Rao bound."""
from __future__ import annotations

import contextlib

from station.cli import argtypes, plugins
from station.cli.output import err, out, rich_console


def add_parsers(sub) -> None:
    mc = sub.add_parser("montecarlo", help="repeat simulate -> estimate; compare with the Cramér-Rao bound")
    mc.add_argument("--scheme", default="optimal9", help="built-in scheme name or scheme file (default optimal9)")
    mc.add_argument("--runs", type=argtypes.whole(2), default=100,
                    help="simulate -> estimate repetitions, at least 2 (default 100)")
    # bounds: what a MEMS IMU on a poor table reaches, ten times over
    mc.add_argument("--accel-noise-ug", type=argtypes.between(1e-3, 1e5), default=100.0, help="µg/√Hz (default 100)")
    mc.add_argument("--gyro-noise-dph", type=argtypes.between(1e-6, 1e5), default=0.03, help="°/h/√Hz (default 0.03)")
    mc.add_argument("--table-angle-arcsec", type=argtypes.between(0, 3600), default=2.0,
                    help="1σ table angle error (default 2)")
    mc.add_argument("--accel-disturbance-ug", type=argtypes.between(0, 1e5), default=50.0,
                    help="1σ white acceleration disturbance (default 50, the 2010 paper's)")
    mc.add_argument("--method", choices=("lsq", "zhang2010"), default="lsq",
                    help="estimation method (default lsq)")
    mc.add_argument("--add", action="append", default=[], metavar="EFFECT",
                    help="an effect the lsq fit adds (an id: station effects lists them; or FILE.py:CLASS, as "
                         "station estimate and station design take them); repeatable: its parameters' spread, "
                         "bound and 1σ are reported too (against zero: the simulated IMU has none of the effects)")
    plugins.add_arguments(mc)
    mc.add_argument("--seed", type=argtypes.seed, default=1000, help="first seed (runs use seed, seed+1, ...)")
    mc.add_argument("--scheduler", metavar="tcp://HOST:8786",
                    help="run the repetitions on this Dask scheduler's workers (default: a pool of "
                         "worker processes on this machine's cores)")
    mc.add_argument("--config", metavar="FILE",
                    help="station.yaml: the table whose rate_accel_dps2 the recorded ramps take (as station run "
                         "--sim) and the temperature chamber a scheme that sets one (chamber_c) runs with "
                         "(default: $STATION_CONFIG, ./station.yaml)")
    mc.add_argument("--json", action="store_true",
                    help="print the per-parameter table as JSON on stdout (error std, Cramér–Rao bound, mean 1σ)")
    mc.set_defaults(func=cmd_montecarlo)


@contextlib.contextmanager
def _progress_bar(runs: int):
    """A progress bar on stderr (a terminal only: nothing in logs or pipes); yields the
    ``progress(done, total)`` callback of station.simulate.montecarlo.study."""
    from rich.progress import (BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn,
                               TimeRemainingColumn)

    bar = Progress(TextColumn("dry runs"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                   TextColumn("left"), TimeRemainingColumn(), console=rich_console(err),
                   transient=True, disable=not err.is_terminal)
    task = bar.add_task("runs", total=runs)
    with bar:
        yield lambda done, total: bar.update(task, completed=done, total=total)


def cmd_montecarlo(args) -> int:
    import json
    import time

    from station import api

    with contextlib.ExitStack() as stack:
        executor, workers = None, None
        if args.scheduler:
            from station.batch.cluster import open_client, worker_count

            client = stack.enter_context(open_client(args.scheduler))
            executor, workers = client.get_executor(pure=False), worker_count(client)
        started = time.perf_counter()
        with _progress_bar(args.runs) as progress:
            mc = api.montecarlo(args.scheme, args.runs, seed=args.seed, accel_noise_ug=args.accel_noise_ug,
                                gyro_noise_dph=args.gyro_noise_dph, table_angle_arcsec=args.table_angle_arcsec,
                                accel_disturbance_ug=args.accel_disturbance_ug, method=args.method,
                                effects=args.add, progress=progress, executor=executor, workers=workers,
                                **plugins.options(args))
        elapsed = time.perf_counter() - started
    err.print(f"{args.runs} dry runs and the Cramér-Rao bound in {elapsed:.1f} s on {mc.workers} "
              f"{'Dask worker thread(s) at ' + args.scheduler if args.scheduler else 'worker process(es)'}: "
              f"{args.runs / elapsed:.2f} runs/s", markup=False, soft_wrap=True)
    if args.json:
        print(json.dumps({"scheme": mc.scheme, "runs": mc.runs, "method": mc.method, "effects": list(mc.effects),
                          "settings": mc.settings, "parameters": mc.parameters,
                          "not_revealed": mc.not_revealed}, indent=1))
        return 0
    from rich.table import Table

    table = Table(title=f"{mc.scheme}: {args.runs} dry runs, {args.method}; errors against the "
                        "simulated truth (scale factors relative)")
    for col in ("parameter", "std", "CRLB", "std/CRLB", "mean 1σ", "1σ/std", "mean error", "unit"):
        table.add_column(col, justify="left" if col in ("parameter", "unit") else "right")
    for r in mc.parameters:
        ms = r["mean_sigma"]
        crlb = r["crlb"]
        # a parameter revealed in some runs only: its row is over every run (the nominal 0 where
        # held), it says in how many it was revealed, and has no mean 1σ (api.montecarlo)
        name = r["name"] + (f" (revealed in {r['revealed_runs']} of {mc.runs})" if "revealed_runs" in r else "")
        table.add_row(name, f"{r['std']:.4g}", "not revealed" if crlb is None else f"{crlb:.4g}",
                      # (a partly-held row's spread, its held runs exact at the twin's 0, is no
                      # unbiased estimator's: not compared with the bound, as not with a 1σ)
                      "" if crlb is None or "revealed_runs" in r else f"{r['std'] / crlb:.2f}",
                      "" if ms is None else f"{ms:.4g}", "" if ms is None else f"{ms / r['std']:.2f}",
                      f"{r['mean_error']:+.3g}", r["unit"])
    out.print(table)
    if mc.not_revealed:
        # a row over the runs that revealed it would be selected on the outcome (a prior the data
        # contradict is released by its value's size): over every run, of what is compensated
        rows = {r["name"] for r in mc.parameters}
        out.print("not revealed by the capture (held by its prior, not written): "
                  + ", ".join(f"{n} in {k} of {mc.runs} runs"
                              + (" (its row: every run, the value each calibration compensates with -- the nominal 0 "
                                 "where held --, no mean 1σ)" if n in rows else " (no row: no run revealed it)")
                              for n, k in mc.not_revealed.items()),
                  markup=False, soft_wrap=True)
    return 0
