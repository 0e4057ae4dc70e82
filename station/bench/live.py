"""What a run shows while it runs: the step and its purpose, progress with ETA for the step and
the run, live |f| and |w|, table angles and rates, temperature, frame and error counters.

``make_display(console)`` gives a rich live view on a terminal and a few plain lines otherwise
(CI, pipes, files): the title, a progress line at every tenth of the run, the notes and prompts
as they come, and how it ended (an optimal9 run: 267 lines before, one per step and three per
long step, now 14).  The sequencer calls ``step``, ``advance``, ``values_update``, ``saved``,
``note`` and ``prompt``; progress is in device seconds (a twin at --speed 100 fills the bars 100
times faster).
"""
from __future__ import annotations

import time

from rich.console import Group
from rich.live import Live
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn
from rich.table import Table

TENTHS = tuple(k / 10 for k in range(1, 10))     # a plain progress line as the run passes each


def format_values(v: dict) -> str:
    """One line of live values (missing ones left out)."""
    parts = []
    if v.get("f_mps2") is not None:
        parts.append(f"|f| {v['f_mps2']:.5f} m/s^2")
    if v.get("w_dps") is not None:
        parts.append(f"|w| {v['w_dps']:.4f} deg/s")
    if v.get("positions_deg") is not None:
        parts.append("table " + ", ".join(f"{p % 360.0:.3f}".replace("360.000", "0.000")
                                          for p in v["positions_deg"]) + " deg")
    if v.get("rates_dps") is not None:
        parts.append(", ".join(f"{r:+.3f}" for r in v["rates_dps"]) + " deg/s")
    if v.get("temp_c") is not None:
        parts.append(f"T {v['temp_c']:.2f} C")
    c = v.get("counters")
    if c is not None:
        parts.append(f"frames {c.frames}, checksum errors {c.checksum_errors}, resyncs {c.resyncs}, "
                     f"gaps {c.gaps}")
    return "; ".join(parts)


def imu_lines(v: dict) -> list:
    """Several IMUs in one run: one line per IMU (its |f|, |w|, temperature and counters, or
    that it was lost); [] for a one-IMU run."""
    lines = []
    for imu in v.get("imus") or []:
        if imu.get("lost"):
            lines.append(f"IMU {imu['label']}: LOST ({imu['lost']})")
        else:
            values = {k: x for k, x in imu.items() if k not in ("label", "lost")}
            lines.append(f"IMU {imu['label']}: {format_values(values) or 'no data yet'}")
    return lines


class PlainDisplay:
    """Lines for logs: no cursor movement, no colour, and a few of them for a whole run (a log
    of a pipe or CI is read afterwards): the title; a progress line as the run passes each tenth
    of its device time (the step under way, the segments saved, the live values); notes and
    prompts as they come; at the end the steps done, or the step the run stopped in."""

    def __init__(self, console, total_s: float, title: str):
        self.console = console
        self.total_s = total_s
        self.title = title
        self.done_before = 0.0      # estimates of the finished steps
        self.values: dict = {}
        self._step = None
        self._index = self._count = 0
        self._saved: list[str] = []
        self._marks = list(TENTHS)
        self._t0 = time.monotonic()

    def _print(self, text: str) -> None:
        self.console.print(text, markup=False, highlight=False, soft_wrap=True)

    def __enter__(self):
        self._print(f"{self.title}: estimated {self.total_s:.0f} s of device time")
        return self

    def __exit__(self, exc_type, *exc):
        wall = f"{time.monotonic() - self._t0:.0f} s wall"
        if exc_type is None:
            self._print(f"{self.title}: {self._count} steps done, {len(self._saved)} segments saved ({wall})")
        elif self._step is not None:
            self._print(f"{self.title}: stopped in step [{self._index + 1}/{self._count}] "
                        f"{self._step.describe()} ({len(self._saved)} segments saved, {wall})")
        return False

    def step(self, step, index: int, count: int) -> None:
        if self._step is not None:
            self.done_before += self._step.estimate_s
        self._step, self._index, self._count = step, index, count
        self._progress(0.0)

    def advance(self, done_s: float, total_s: float) -> None:
        self._progress(done_s)

    def _progress(self, done_s: float) -> None:
        run = min(1.0, (self.done_before + done_s) / self.total_s) if self.total_s > 0 else 1.0
        if not self._marks or run < self._marks[0]:
            return
        while self._marks and run >= self._marks[0]:
            self._marks.pop(0)
        shown = ({k: x for k, x in self.values.items() if k in ("positions_deg", "rates_dps")}
                 if self.values.get("imus") else self.values)
        values = format_values(shown)
        self._print(f"run {run:.0%} ({self.done_before + done_s:.0f}/{self.total_s:.0f} s, "
                    f"{time.monotonic() - self._t0:.0f} s wall): step [{self._index + 1}/{self._count}] "
                    f"{self._step.describe() if self._step is not None else ''}; {len(self._saved)} segments "
                    f"saved" + (f"; {values}" if values else ""))
        for line in imu_lines(self.values):
            self._print(f"  {line}")

    def values_update(self, values: dict) -> None:
        self.values.update(values)

    def saved(self, segment: str) -> None:
        """A segment's data are safe on disk (counted; on a terminal, a line)."""
        self._saved.append(segment)

    def note(self, text: str) -> None:
        self._print(f"      {text}")

    def prompt(self, text: str) -> None:
        self._print(f">>> {text}")


class RichDisplay(PlainDisplay):
    """A live view on a terminal."""

    def __init__(self, console, total_s: float, title: str):
        super().__init__(console, total_s, title)
        columns = (TextColumn("{task.description}"), BarColumn(), TextColumn("{task.percentage:>3.0f}%"),
                   TimeElapsedColumn(), TextColumn("ETA"), TimeRemainingColumn())
        self.progress = Progress(*columns, console=console, auto_refresh=False)
        self.run_task = self.progress.add_task(f"run {title}", total=max(total_s, 1e-9))
        self.step_task = self.progress.add_task("step", total=1.0)
        self.live = Live(self._render(), console=console, refresh_per_second=4, transient=False)

    def _render(self):
        table = Table.grid(padding=(0, 2))
        table.add_column(style="bold")
        table.add_column()
        step = self._step
        table.add_row("step", "" if step is None else step.describe())
        table.add_row("purpose", "" if step is None else step.purpose)
        lines = imu_lines(self.values)
        if lines:
            shown = {k: x for k, x in self.values.items() if k in ("positions_deg", "rates_dps")}
            table.add_row("table", format_values(shown))
            for i, line in enumerate(lines):
                table.add_row("IMUs" if i == 0 else "", line)
        else:
            table.add_row("live", format_values(self.values))
        return Group(self.progress, table)

    def __enter__(self):
        self.live.__enter__()
        return self

    def __exit__(self, *exc):
        self.live.update(self._render(), refresh=True)
        return self.live.__exit__(*exc)

    def step(self, step, index: int, count: int) -> None:
        if self._step is not None:
            self.done_before += self._step.estimate_s
        self._step, self._index, self._count = step, index, count
        self.progress.reset(self.step_task, total=max(step.estimate_s, 1e-9),
                            description=f"[{index + 1}/{count}] {type(step).__name__}")
        self.progress.update(self.run_task, completed=self.done_before)
        self.live.console.print(f"[{index + 1}/{count}] {step.describe()}", markup=False, highlight=False)
        self.live.update(self._render())

    def advance(self, done_s: float, total_s: float) -> None:
        self.progress.update(self.step_task, completed=done_s, total=max(total_s, 1e-9))
        self.progress.update(self.run_task, completed=min(self.total_s, self.done_before + done_s))
        self.live.update(self._render())

    def saved(self, segment: str) -> None:
        self._saved.append(segment)
        self.note(f"{segment}: saved")

    def note(self, text: str) -> None:
        self.live.console.print(f"      {text}", markup=False, highlight=False)

    def prompt(self, text: str) -> None:
        self.live.console.print(f">>> {text}", style="bold yellow", markup=False, highlight=False)


def make_display(console, total_s: float, title: str):
    """A rich live display on a terminal, plain lines otherwise."""
    cls = RichDisplay if console.is_terminal else PlainDisplay
    return cls(console, total_s, title)
