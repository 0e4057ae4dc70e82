"""A small capture is instant (issue 27 item 1): `station estimate` imports what it needs and no
more, writes to a pipe what rich would without importing rich, and `station import ...
--estimate` calibrates in the same process what `station estimate` would from the capture."""
from __future__ import annotations

import argparse
import io
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

DATA = Path(__file__).parent / "data" / "imucal"

# modules the estimate of a capture has no use for: the bench, the drivers and pyserial (an
# estimate drives no table), rich (its output is a pipe here and no table was asked), the history
# store (not asked to file), the other commands' modules, numpy.ma (station.estimate.arrays),
# threadpoolctl (no BLAS library loaded when the command starts: the thread count is given
# through the environment), the simulator
FORBIDDEN = ("rich", "station.bench", "drivers", "serial", "station.io.history", "station.io.store_sqlite",
             "sqlite3", "threadpoolctl", "station.simulate", "sim_devices", "station.cli.run", "station.cli.devices",
             "station.cli.diagnose", "station.cli.design", "station.cli.batch", "station.cli.montecarlo",
             "station.cli.imports", "station.cli.export", "station.cli.noise", "station.cli.fleet",
             "station.cli.report", "scipy", "numpy.ma")

SPY = """
import json, sys
from station.cli.app import main
status = main(sys.argv[1:])
print("MODULES", json.dumps(sorted(sys.modules)))
sys.exit(status)
"""


def test_the_estimate_path_imports_none_of_the_modules_it_does_not_need(optimal9_run, tmp_path):
    env = {k: v for k, v in os.environ.items() if k not in ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")}
    env["PYTHONPATH"] = os.pathsep.join(sys.path)
    r = subprocess.run([sys.executable, "-c", SPY, "estimate", str(optimal9_run), "-o", str(tmp_path / "c.yaml")],
                       capture_output=True, text=True, timeout=120, env=env)
    assert r.returncode == 0, r.stderr
    modules = json.loads(r.stdout.split("MODULES ", 1)[1])
    found = [m for m in modules if any(m == f or m.startswith(f + ".") for f in FORBIDDEN)]
    assert found == []
    assert "station.estimate.lsq" in modules and (tmp_path / "c.yaml").is_file()     # it did estimate


# ---------------------------------------------------------------- numpy's unique and median


def test_distinct_and_median_are_numpys():
    """station.estimate.arrays: np.unique and np.median without numpy.ma, the same numbers, on
    values with repeats, signed zeros, infinities and NaNs."""
    from station.estimate.arrays import distinct, median

    rng = np.random.default_rng(27)
    for _ in range(400):
        n = int(rng.integers(1, 40))
        a = rng.integers(-3, 4, n).astype(float) * 10.0 ** float(rng.integers(-6, 6))
        a[rng.random(n) < 0.1] = -0.0
        a[rng.random(n) < 0.05] = np.inf
        if rng.random() < 0.3:
            a[rng.random(n) < 0.2] = np.nan
        assert distinct(a).tobytes() == np.unique(a).tobytes()
        expected = float(np.median(a))
        assert median(a) == expected or (np.isnan(expected) and np.isnan(median(a)))
        b = rng.normal(size=(n, 3))
        if rng.random() < 0.2:
            b[rng.integers(0, n), 1] = np.nan
        assert np.array_equal(median(b, axis=0), np.median(b, axis=0), equal_nan=True)
    assert distinct(np.zeros(0)).shape == (0,)


# ---------------------------------------------------------------- plain lines as rich writes them

TEXTS = ["fit: chi2 207.6 for 183 degrees of freedom (reduced 1.135)", "", "a\nb", "trailing  ", "x" * 159,
         "x" * 160, "x" * 161, "y" * 59, "y" * 60, "y" * 61, "word " * 40, "σ ± 1σ, 25.0–27.0 °C, χ²", "σ" * 30,
         "σ" * 31, "漢字" * 20, "note: see :smile: here", "at 12:30:45", "[bold]not markup[/bold]", "a\tb", "bell\x07",
         "cr\rlf", "a\x1b[31mred", "ends with a newline\n"]
KWARGS = [{}, {"markup": False}, {"markup": False, "soft_wrap": True}, {"soft_wrap": True},
          {"markup": False, "style": "bold red", "soft_wrap": True}, {"style": "green"}]


@pytest.mark.parametrize("width", [160, None])
def test_the_lazy_console_writes_what_rich_writes(monkeypatch, width):
    """station.cli.output.LazyConsole into a stream that is not a terminal: every string and
    option the commands print with gives rich's bytes, whether written plainly or handed to
    rich; the plain lines the estimate prints are written without rich."""
    from rich.console import Console

    from station.cli.output import LazyConsole

    for name in ("FORCE_COLOR", "TTY_COMPATIBLE", "TTY_INTERACTIVE", "NO_COLOR"):
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setenv("COLUMNS", "60")
    plain = 0
    for text in TEXTS:
        for kwargs in KWARGS:
            expected = io.StringIO()
            Console(file=expected, highlight=False, width=width).print(text, **kwargs)
            got = io.StringIO()
            monkeypatch.setattr(sys, "stdout", got)
            lazy = LazyConsole(width=width)
            plain += lazy._plain((text,), kwargs) is not None
            lazy.print(text, **kwargs)
            assert got.getvalue() == expected.getvalue(), (text, kwargs, width)
    assert plain > len(TEXTS) * len(KWARGS) // 3          # most are written without rich
    monkeypatch.setattr(sys, "stdout", io.StringIO())
    assert LazyConsole(width=160)._plain(("calibration file: /tmp/c.yaml",), {"markup": False}) is not None


# ---------------------------------------------------------------- the parser of one command


def test_each_command_is_built_by_the_module_named_for_it():
    """station.cli.app.COMMAND_GROUPS (a command line naming its command builds that module's
    parsers only) is what the modules add."""
    import importlib

    from station.cli import app

    found = {}
    for group in app.GROUPS:
        sub = argparse.ArgumentParser().add_subparsers()
        importlib.import_module(f"station.cli.{group}").add_parsers(sub)
        found.update({name: group for name in sub.choices})
    assert found == app.COMMAND_GROUPS


# ---------------------------------------------------------------- import ... --estimate


@pytest.fixture(scope="module")
def imucal_estimated(tmp_path_factory):
    """imucal's example session imported with --estimate CAL, and the same capture estimated
    by `station estimate` (both in this process)."""
    from station.cli import main

    tmp = tmp_path_factory.mktemp("import-estimate")
    argv = ["import", "imucal", str(DATA / "example_ferraris_session.csv"), "--sections",
            str(DATA / "example_ferraris_session_list.json"), "--rate-hz", "102.4", "--turn-deg", "360",
            "-o", str(tmp / "cap")]
    one = main(argv + ["--estimate", str(tmp / "one.yaml")])
    two = main(["estimate", str(tmp / "cap"), "-o", str(tmp / "two.yaml")])
    return tmp, one, two


def _without_date(path: Path) -> str:
    return "".join(line for line in path.read_text().splitlines(True) if "date_utc" not in line)


def test_import_with_estimate_writes_the_capture_and_what_estimate_writes(imucal_estimated):
    tmp, one, two = imucal_estimated
    assert one == two == 0
    assert (tmp / "cap" / "manifest.yaml").is_file()
    assert _without_date(tmp / "one.yaml") == _without_date(tmp / "two.yaml")
    assert "parameters:" in (tmp / "one.yaml").read_text()


@pytest.mark.parametrize("extra, words", [
    (["--estimate", " "], "--estimate: an empty file name"),
    (["--accept-poor-fit"], "--accept-poor-fit: only with --estimate"),
    (["--no-table"], "--table/--no-table: only with --estimate"),
])
def test_bad_estimate_options_are_one_line_before_anything_is_imported(tmp_path, capsys, extra, words):
    from station.cli import main

    argv = ["import", "csv", str(DATA / "example_ferraris_session.csv"), "--preset", "imucal", "-o",
            str(tmp_path / "cap"), *extra]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert words in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert not (tmp_path / "cap").exists()


def test_a_small_capture_is_read_line_by_line_as_the_engine_reads_it(imucal_estimated, monkeypatch):
    """station.io.capture: a capture of at most SMALL_CAPTURE_ROWS rows is read by the
    line-by-line reader while the CSV engine is not imported (its import costs more than the
    rows): the same samples and hashes as the engine's; in a fresh process the engine is not
    imported for it."""
    import station.io.capture as capture_module

    tmp, _, _ = imucal_estimated
    read = {}
    for small in (True, False):
        monkeypatch.setattr(capture_module, "_small", lambda capture, small=small: small)
        cap = capture_module.read_capture(tmp / "cap")
        read[small] = [(s.content_sha256, s.data.t.tobytes(), s.data.accel.tobytes(), s.data.gyro.tobytes(),
                        None if s.data.temp is None else s.data.temp.tobytes()) for s in cap.segments]
    assert read[True] == read[False] and len(read[True]) == 9
    code = ("import sys; from station.io.capture import read_capture; read_capture(sys.argv[1]); "
            "print('pyarrow' in sys.modules)")
    r = subprocess.run([sys.executable, "-c", code, str(tmp / "cap")], capture_output=True, text=True, timeout=60,
                       env=dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path)))
    assert r.returncode == 0 and r.stdout.split() == ["False"], r.stderr


def test_a_small_capture_is_summarised_in_this_process(imucal_estimated, monkeypatch):
    """station.estimate.summarise_while_importing forks no reader for a small capture (its rows
    take less than the fork), and gives the summaries the forked reader gives."""
    from station.core import forked
    from station.estimate import summaries, summarise_while_importing
    from station.io.capture import is_small, read_capture

    tmp, _, _ = imucal_estimated
    here = read_capture(tmp / "cap", load_data=False)
    assert is_small(here)

    def no_fork(*args, **kwargs):
        raise AssertionError("a small capture forked a reader")
    with monkeypatch.context() as m:
        m.setattr(forked, "Forked", no_fork)
        summarise_while_importing(here)
    child = read_capture(tmp / "cap", load_data=False)
    if forked.available():
        summarise_while_importing(child, then=lambda: None)     # with ``then``: the forked reader
    import pickle

    a, b = summaries.kept(here), summaries.kept(child)
    assert a is not None and pickle.dumps(a) == pickle.dumps(b)
