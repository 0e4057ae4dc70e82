"""Start-up: ``station --help``, every command's ``--help`` and the light commands (schemes, plan,
effects) import nothing heavy.  These tests check WHAT a fresh interpreter has imported
(``sys.modules`` after the command), never how long it took; the time is measured by
benchmarks/perf_startup.py (docs/performance.md)."""
from __future__ import annotations

import ast
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

# what building the parser must never import: the estimators' and the figures' libraries
HEAVY = ("scipy", "matplotlib", "allantools", "rich.table", "rich.progress", "sim_devices",
         "station.estimate", "station.diagnose", "station.simulate", "station.model", "numpy",
         "dask", "distributed", "station.batch.cluster")
# what the light commands (schemes, plan, effects) may import (numpy, yaml, rich.table to print
# their table) but not: the fit, the rotations, sparse matrices, statistics, figures
HEAVY_FOR_LIGHT = ("scipy.optimize", "scipy.spatial", "scipy.sparse", "scipy.stats", "scipy.ndimage",
                   "matplotlib", "allantools", "station.estimate", "station.diagnose", "station.simulate",
                   "sim_devices")

COMMANDS_HELP = [[c, "--help"] for c in ("run", "schemes", "plan", "init", "estimate", "show", "apply",
                                         "diagnose", "effects", "report", "export", "noise", "history",
                                         "diff", "montecarlo", "probe", "import", "sim")]
COMMANDS_HELP += [["import", "csv", "--help"], ["import", "imucal", "--help"],
                  ["import", "rosbag", "--help"], ["sim", "serve", "--help"], ["batch", "--help"],
                  ["batch", "estimate", "--help"], ["batch", "export", "--help"]]

RUNNER = """
import contextlib, io, json, sys
from station.cli import main
statuses = []
for argv in json.loads(sys.argv[1]):
    with contextlib.redirect_stdout(io.StringIO()) as out:
        try:
            statuses.append(main(argv))
        except SystemExit as e:
            statuses.append(e.code)
    statuses.append(len(out.getvalue()))
print(json.dumps({"statuses": statuses, "modules": sorted(sys.modules)}))
"""


def _modules_after(argvs, tmp_path) -> tuple[list, set]:
    """Run the commands in one fresh interpreter; (exit statuses and output lengths, modules)."""
    r = subprocess.run([sys.executable, "-c", RUNNER, json.dumps(argvs)], capture_output=True, text=True,
                       cwd=tmp_path, timeout=120,
                       env={k: v for k, v in os.environ.items() if not k.startswith("STATION_")})
    assert r.returncode == 0, r.stderr
    doc = json.loads(r.stdout.strip().splitlines()[-1])
    return doc["statuses"], set(doc["modules"])


def _heavy(modules: set, heavy) -> list:
    return sorted(m for m in modules if any(m == h or m.startswith(h + ".") for h in heavy))


def test_station_help_imports_nothing_heavy(tmp_path):
    statuses, modules = _modules_after([["--help"]], tmp_path)
    assert statuses[0] == 0 and statuses[1] > 500       # the help was printed
    assert _heavy(modules, HEAVY) == []
    assert "scipy.optimize" not in modules and "matplotlib" not in modules


def test_every_commands_help_imports_nothing_heavy(tmp_path):
    statuses, modules = _modules_after(COMMANDS_HELP, tmp_path)
    assert statuses[0::2] == [0] * len(COMMANDS_HELP)
    assert min(statuses[1::2]) > 100
    assert _heavy(modules, HEAVY) == []


def test_light_commands_import_no_fit_rotations_or_figures(tmp_path):
    """plan (the scheme compiler, as ``station schemes`` uses it: the noise scheme, one static,
    compiles in milliseconds) and effects (list and explain) in one interpreter."""
    argvs = [["plan", "--scheme", "noise"], ["effects"], ["effects", "accel_lever_arm"]]
    statuses, modules = _modules_after(argvs, tmp_path)
    assert statuses[0::2] == [0, 0, 0] and min(statuses[1::2]) > 100
    assert _heavy(modules, HEAVY_FOR_LIGHT) == []


def test_the_parsers_static_names_are_the_registries():
    """station/cli/choices.py copies the names so that --help imports none of their owners; the
    copies must stay equal to the registries."""
    from station.cli import choices
    from station.estimate import METHODS
    from station.io.exporters import FORMATS
    from station.io.importers import delimited, imucal, recording, rosbag

    assert tuple(choices.ESTIMATE_METHODS) == tuple(METHODS)
    assert choices.EXPORT_FORMATS == {name: mod.TITLE for name, mod in FORMATS.items()}
    assert tuple(choices.IMUCAL_FORMATS) == tuple(imucal.FORMATS)
    assert choices.IMUCAL_DEFAULT_GRAVITY_MPS2 == imucal.DEFAULT_GRAVITY_MPS2
    assert tuple(choices.CSV_PRESETS) == tuple(sorted(delimited.PRESETS))
    assert choices.RECORDING_MIN_POSES == recording.MIN_POSES
    assert tuple(choices.ROSBAG_STAMPS) == tuple(rosbag.STAMPS)


def test_the_help_offers_every_estimation_method(capsys):
    """The parser built from the static list accepts every method the estimator knows."""
    from station.cli.app import build_parser
    from station.estimate import METHODS

    parser = build_parser()
    for method in METHODS:
        args = parser.parse_args(["estimate", "CAPTURE", "--method", method])
        assert args.method == method


def test_no_runtime_module_imports_scipy_stats():
    """scipy.stats costs ~0.5 s to import for chi2.sf / norm.isf; scipy.special has both."""
    offenders = []
    for path in sorted((ROOT / "station").rglob("*.py")) + sorted((ROOT / "drivers").rglob("*.py")):
        text = path.read_text()
        if "stats" not in text:         # every import the walk below can find names it: the same
            continue                    # answer, without parsing the ~95 % of files that cannot
        for node in ast.walk(ast.parse(text, str(path))):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module:
                names = [node.module] + [f"{node.module}.{a.name}" for a in node.names]
            if any(n == "scipy.stats" or n.startswith("scipy.stats.") for n in names):
                offenders.append(f"{path.relative_to(ROOT)}:{node.lineno}")
    assert offenders == []


READER = """
import sys
from station.estimate import choose_method
from station.estimate.summaries import summarise
from station.io.capture import read_capture
capture = read_capture(sys.argv[1], load_data=False)
method = choose_method(capture)
s = summarise(capture)
print(method, len(s.statics), len(s.rotations),
      " ".join(sorted(m for m in sys.modules if m.split(".")[0] == "scipy" or m == "numpy.ma")))
"""


def test_reading_and_summarising_a_capture_imports_no_scipy(optimal9_run):
    """`station estimate` reads the capture in a forked child while it imports scipy (~0.2 s)
    itself (station.estimate.summarise_while_importing): the reading must not need scipy, or the
    child would spend that time importing it too; nor numpy.ma (~7 ms, which np.unique and
    np.median import: station.estimate.arrays, issue 27)."""
    r = subprocess.run([sys.executable, "-c", READER, str(optimal9_run)], capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 0, r.stderr
    method, statics, rotations, *scipy_modules = r.stdout.split()
    assert (method, statics, rotations) == ("lsq", "9", "12")   # six +/- pairs
    assert scipy_modules == []


SPY = """
import json, os, sys
import station.io.capture as capture_module
readers = set()
original = capture_module.read_csv_pieces
def spy(*args, **kwargs):
    readers.add(os.getpid())
    return original(*args, **kwargs)
capture_module.read_csv_pieces = spy
import station.estimate
if sys.argv[2:] == ["fork"]:        # the forked reader (diagnose's), given to the estimate
    station.estimate.ESTIMATE_FORKS = True
from station.estimate import estimate_capture
cal, capture, provenance = estimate_capture(sys.argv[1])
print(json.dumps([sorted(readers) == [os.getpid()], "station.estimate.lsq" in sys.modules,
                  provenance["capture_sha256"], cal.fit["chi2"],
                  [(s.name, s.status, s.content_sha256) for s in capture.segments]]))
"""


def _estimate_spied(capture_dir, *args, **env):
    r = subprocess.run([sys.executable, "-c", SPY, str(capture_dir), *args], capture_output=True, text=True,
                       timeout=120, env={**os.environ, **env})
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout.strip().splitlines()[-1])


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the forked reader is used on Linux only")
def test_the_forked_reader_gives_what_reading_in_this_process_gives(optimal9_run):
    """`station estimate` reads the capture in its own process (the fit's modules, ~7 ms, are too
    little to overlap with a forked reader: issue 27); the forked reader (diagnose's, which
    imports ~0.1 s meanwhile) reads its files in another process (not one read here), and what
    comes back (segments' sha256 and status, the capture's digest, the fit) is what reading in
    this process gives."""
    read_here, imported, digest, chi2, segments = _estimate_spied(optimal9_run, "fork")
    assert not read_here and imported
    read_here_too, _, digest_here, chi2_here, segments_here = _estimate_spied(optimal9_run)
    assert read_here_too
    assert (digest, segments) == (digest_here, segments_here)
    assert chi2 == chi2_here
    assert all(sha for _, status, sha in segments if status == "complete")


BLAS = """
import json, os, sys
for name in ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "OMP_NUM_THREADS", "STATION_BLAS_THREADS"):
    os.environ.pop(name, None)
from station.cli import main
status = main(["estimate", sys.argv[1], "-o", sys.argv[2]])
from threadpoolctl import threadpool_info
print(json.dumps([status, [(i["prefix"], i["num_threads"]) for i in threadpool_info()
                           if i["user_api"] == "blas"]]))
"""


def test_estimate_runs_blas_on_one_thread(optimal9_run, tmp_path):
    """Every BLAS library the fit loads (numpy's and scipy's OpenBLAS, loaded after main() set
    its limit: the CLI imports them lazily) runs one thread: two threads spinning over the fit's
    200 x 100 SVDs took 6 s of CPU on a busy machine instead of 0.8 s."""
    r = subprocess.run([sys.executable, "-c", BLAS, str(optimal9_run), str(tmp_path / "cal.yaml")],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    status, libraries = json.loads(r.stdout.strip().splitlines()[-1])
    assert status == 0 and libraries, r.stdout
    assert all(threads == 1 for _, threads in libraries), libraries


def test_the_installed_console_script_passes_the_exit_status(optimal9_run, tmp_path):
    """The `station` script (station.cli:console_main, which freezes the garbage collector
    before the process ends) exits with main()'s status (0, and 2 for a user error with its one
    line), and what it wrote is complete."""
    script = Path(sys.executable).with_name("station")
    assert script.is_file(), "the project is installed as the README says (pip install -e '.[dev]')"
    ok = subprocess.run([str(script), "estimate", str(optimal9_run), "-o", str(tmp_path / "cal.yaml")],
                        capture_output=True, text=True, timeout=120)
    assert ok.returncode == 0, ok.stderr
    assert "calibration file:" in ok.stdout and (tmp_path / "cal.yaml").read_text().startswith("format:")
    bad = subprocess.run([str(script), "estimate", str(tmp_path / "nothing")], capture_output=True, text=True,
                         timeout=120)
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1, bad.stderr
