"""What every command prints the same way: the consoles, parameter tables, notes."""
from __future__ import annotations

import math
import sys

from rich.console import Console

EXIT_POOR_FIT = 3      # the calibration file is written, but its fit fails (see --accept-poor-fit)

out = Console(highlight=False, width=None if sys.stdout.isatty() else 160)
err = Console(stderr=True, highlight=False)


def print_parameters(rows, title: str) -> None:
    """rows: (name, value, unit, 1-sigma or None); scale factors get their 1σ in ppm."""
    from rich.table import Table

    table = Table(title=title)
    table.add_column("parameter")
    table.add_column("value", justify="right")
    table.add_column("± 1σ", justify="right")
    table.add_column("unit")
    blank = []
    for name, value, unit, sigma in rows:
        is_scale = unit in ("1", "raw/(m/s^2)", "raw/(deg/s)")
        if sigma is None or not math.isfinite(sigma):
            spread = "—"
            blank.append(name)
        elif is_scale and value:
            spread = f"{sigma / abs(value) * 1e6:.3g} ppm"
        else:
            spread = f"{sigma:.3g}"
        # scale factors as run and diff print them: 9 decimals, their 1-sigma (and changes) in ppm
        table.add_row(name, f"{value:.9f}" if is_scale else f"{value:.4f}", spread, unit)
    out.print(table)
    if blank:
        out.print(f"—: no 1σ in the file for {', '.join(blank)} (a parameter written without one: a "
                  "method without a covariance, or an older file)", markup=False, soft_wrap=True)


def print_errors(cal, truth) -> None:
    """The estimate against the simulated truth, shown as ``station show`` shows a calibration: a
    scale factor's value dimensionless (unit 1) with 9 decimals, its error and 1σ in ppm beside
    their numbers; a parameter without a 1σ "—", explained under the table."""
    from rich.table import Table

    from station.model.calibration import parameter_errors

    table = Table(title="estimate against the simulated truth")
    for col in ("parameter", "estimate", "truth", "error", "± 1σ", "unit"):
        table.add_column(col, justify="left" if col in ("parameter", "unit") else "right")
    dropped = set(cal.fit.get("not_determined", []))
    blank = []
    for name, value, true, error, unit in parameter_errors(cal, truth):
        if name in dropped:
            continue
        is_scale = "_scale_" in name
        fmt = "{:.9f}" if is_scale else "{:.4f}"
        sigma = cal.sigma.get(name)
        if sigma is None or not math.isfinite(sigma):
            spread = "—"
            blank.append(name)
        elif is_scale:
            spread = f"{sigma / value * 1e6:.4f} ppm"
        else:
            spread = f"{sigma:.4f}"
        table.add_row(name, fmt.format(value), fmt.format(true), f"{error:+.4f}" + (" ppm" if is_scale else ""),
                      spread, "1" if is_scale else unit)
    out.print(table)
    if blank:
        out.print(f"—: no 1σ for {', '.join(blank)} (the method gives none for it)", markup=False, soft_wrap=True)


def print_verdict(verdict: dict) -> None:
    """The fit verdict in one line: passes / fails / untested and why."""
    result = verdict.get("result", "untested")
    style = {"passes": "green", "fails": "bold red", "not converged": "bold red"}.get(result, "yellow")
    out.print(f"fit {result}: {verdict.get('reason', '')}", style=style, markup=False, soft_wrap=True)


def print_notes(cal) -> None:
    for note in cal.fit.get("notes", []):
        err.print(f"note: {note}", markup=False, soft_wrap=True)
