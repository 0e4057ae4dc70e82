"""What a bench run prints while it runs when its output is not a terminal (a pipe, CI, a file):
a few lines for the whole run, not one per step or update (issue 26: 267 lines for optimal9
piped through `cat`); on a terminal the live view."""
import io

import pytest
from rich.console import Console

from station.bench.compile import compile_scheme
from station.bench.config import Config, RunConfig, TableConfig
from station.bench.live import PlainDisplay, RichDisplay, make_display
from station.bench.plan import Checkpoint
from station.io.scheme import load_scheme


def pipe_console():
    return Console(file=io.StringIO(), width=160)      # a file: not a terminal


def drive(display, steps, updates_per_step=50, fail_at=None):
    """What the sequencer does: step(), then advance() and values_update() many times in each
    timed step, saved() at each checkpoint, a note now and then."""
    with display:
        for i, step in enumerate(steps):
            display.step(step, i, len(steps))
            if fail_at == i:
                raise RuntimeError("device gone")
            if isinstance(step, Checkpoint):
                display.saved(step.segment)
                continue
            for k in range(1, updates_per_step + 1):
                display.values_update({"f_mps2": 9.80665, "w_dps": 0.001 * k, "positions_deg": [0.0, 90.0, 0.0]})
                display.advance(step.estimate_s * k / updates_per_step, step.estimate_s)


@pytest.fixture(scope="module")
def optimal9_steps():
    config = Config(table=TableConfig(axes=3), run=RunConfig(operator=False))
    return compile_scheme(load_scheme("optimal9"), config).steps


def test_a_whole_run_to_a_pipe_is_a_few_lines(optimal9_steps):
    console = pipe_console()
    display = make_display(console, sum(s.estimate_s for s in optimal9_steps), "optimal9 on 3-axis table")
    assert type(display) is PlainDisplay
    drive(display, optimal9_steps)
    lines = console.file.getvalue().splitlines()
    # the title, one line per tenth of the run (9: 10 % ... 90 %), the end: 11, whatever the
    # number of steps (72) and updates (50 per step)
    assert len(optimal9_steps) > 60 and len(lines) == 11, lines
    assert [ln.split(" (")[0] for ln in lines[1:10]] == [f"run {k}0%" for k in range(1, 10)]
    assert "72 steps done, 21 segments saved" in lines[-1]
    assert all("\x1b" not in ln for ln in lines)                  # no cursor movement, no colour
    assert "|f| 9.80665 m/s^2" in lines[5] and "segments saved" in lines[5]


def test_notes_prompts_and_where_a_run_stopped_are_always_printed(optimal9_steps):
    console = pipe_console()
    display = PlainDisplay(console, sum(s.estimate_s for s in optimal9_steps), "run")
    with pytest.raises(RuntimeError):
        with display:
            display.note("pos01: bad recording: kept aside")
            display.prompt("turn the IMU")
            drive(display, optimal9_steps, fail_at=30)
    text = console.file.getvalue()
    assert "      pos01: bad recording: kept aside" in text and ">>> turn the IMU" in text
    assert f"run: stopped in step [31/{len(optimal9_steps)}] {optimal9_steps[30].describe()}" in text


def test_on_a_terminal_the_live_view_says_each_step_and_saved_segment(optimal9_steps):
    console = Console(file=io.StringIO(), width=160, force_terminal=True)
    display = make_display(console, sum(s.estimate_s for s in optimal9_steps[:8]), "t")
    assert type(display) is RichDisplay
    drive(display, optimal9_steps[:8], updates_per_step=3)
    text = console.file.getvalue()
    assert "[1/8]" in text and "[8/8]" in text and "pos01: saved" in text
