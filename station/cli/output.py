"""What every command prints the same way: the consoles, parameter tables, notes."""
from __future__ import annotations

import math
import os
import re
import sys

EXIT_POOR_FIT = 3      # the calibration file is written, but its fit fails (see --accept-poor-fit)

# what rich does to a string that plain text would not: emoji codes (``:name:``, even with
# markup off), markup tags (``[...]``, when markup is on), control characters it strips, tabs it
# expands
_RICH_ONLY = re.compile(r":\S*:|[\x00-\x08\x0b-\x1f\x7f]")


class LazyConsole:
    """A rich Console made when it is first needed (issue 27: `station estimate` into a pipe or a
    file imports no rich, ~20 ms of a 0.5 s process).  ``print`` of one plain string to a stream
    that is not a terminal writes the very bytes rich would (no styles without a terminal, the
    same width and wrapping rule: only lines that fit are written here, the rest through rich);
    anything else — a table, a terminal, markup, emoji codes, control characters, a forced
    terminal (FORCE_COLOR, TTY_COMPATIBLE) — goes to the rich Console (``.rich``), and every
    other attribute is the Console's (``status``, ``width``, ...).  Tests compare the two
    (tests/test_estimate_output.py)."""

    def __init__(self, *, stderr: bool = False, width: int | None = None):
        self._stderr = stderr
        self._width = width
        self._rich = None

    @property
    def rich(self):
        if self._rich is None:
            from rich.console import Console

            self._rich = Console(stderr=self._stderr, highlight=False, width=self._width)
        return self._rich

    def __getattr__(self, name):
        if name.startswith("__") or name in ("_stderr", "_width", "_rich"):
            raise AttributeError(name)      # not the Console's (copy, pickle, a half-made instance)
        return getattr(self.rich, name)

    def _file(self):
        return sys.stderr if self._stderr else sys.stdout

    def _plain_width(self) -> int:
        """The width rich would wrap at on a stream that is not a terminal (rich.console.Console.size)."""
        if self._width is not None:
            return self._width
        columns = os.environ.get("COLUMNS")
        if columns is not None and columns.isdigit():
            return int(columns) or 80
        width = None
        for fd in (0, 1, 2):
            try:
                width = os.get_terminal_size(fd)[0]
            except (AttributeError, ValueError, OSError):
                continue
            break
        return width or 80

    def _plain(self, objects, kwargs) -> str | None:
        """The text to write for this call without rich, or None when only rich can tell."""
        if self._rich is not None or len(objects) != 1 or type(objects[0]) is not str:
            return None
        if not set(kwargs) <= {"markup", "soft_wrap", "style", "highlight"} or kwargs.get("highlight"):
            return None
        if "FORCE_COLOR" in os.environ or os.environ.get("TTY_COMPATIBLE", "") not in ("", "0"):
            return None
        text = objects[0]
        if (kwargs.get("markup", True) and "[" in text) or _RICH_ONLY.search(text) or "\t" in text:
            return None
        stream = self._file()
        try:
            if stream.isatty():
                return None
        except (AttributeError, ValueError):
            return None
        if not kwargs.get("soft_wrap", False):
            width = self._plain_width()
            per_cell = 1 if text.isascii() else 2      # no character is wider than two cells
            if any(len(line) * per_cell > width for line in text.split("\n")):
                return None
        return text + "\n"

    def print(self, *objects, **kwargs) -> None:
        text = self._plain(objects, kwargs)
        if text is None:
            self.rich.print(*objects, **kwargs)
            return
        stream = self._file()
        stream.write(text)
        stream.flush()


def rich_console(console):
    """The rich Console behind ``console`` (a LazyConsole, or a Console a test put in its place)."""
    return console.rich if isinstance(console, LazyConsole) else console


out = LazyConsole(width=None if sys.stdout.isatty() else 160)
err = LazyConsole(stderr=True)


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
