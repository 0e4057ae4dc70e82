"""`station estimate` against numpy.loadtxt merely parsing the same CSVs (issue 15, item 3).

Records an optimal9 capture with the simulator at each rate (1 kHz: 3.06 M samples, 4 kHz:
12.2 M), then runs, alternating, in fresh processes:
  estimate   `station estimate CAPTURE` (imports, reading, checks, summaries, fit, file written)
  loadtxt    `python -c` that only imports numpy and np.loadtxt's every segment CSV of the capture
             (float64, the columns the reader uses)
  summaries  `python -c` that reads the capture as estimate does and summarises it, nothing else
             (this reader's own cost: read, hash, parse, check, summarise, one segment at a time)
  before     (with --before SRC) the same as summaries with SRC (a source tree of an earlier
             commit, e.g. `git archive COMMIT station drivers | tar -x -C SRC`) first on the
             module path: the reader's change measured in the same run
  ahead      (with --ahead-pairs N) in this process, N alternating pairs of summarise(read_capture(
             CAPTURE, load_data=False)) with and without reading the next segment ahead
             (ReaderAhead.ahead made a no-op): what reading ahead gains, the rest being equal
and prints for each the median wall time, CPU time (user + system, all threads) and peak RSS of
the child process (os.wait4's rusage: that child alone), and the ratios estimate / loadtxt
measured in this one run.  The machine is shared: compare the ratios, and repeat.

Usage: python benchmarks/perf_reader.py [--rates 1000 4000] [--repeat 3] [--keep DIR] [--before SRC]
                                       [--ahead-pairs N]
"""
import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from station.io.scheme import load_scheme

LOADTXT = """
import sys, numpy as np
for path in sys.argv[1:]:
    with open(path) as f:
        names = f.readline().strip().split(",")
    cols = [names.index(n) for n in ("t", "ax", "ay", "az", "gx", "gy", "gz", "temp") if n in names]
    np.loadtxt(path, delimiter=",", skiprows=1, usecols=cols, dtype=np.float64, comments=None)
"""

SUMMARIES = """
import sys
import station
assert station.__file__.startswith(sys.argv[2]), station.__file__   # the source tree asked for
from station.io.capture import read_capture
from station.estimate.summaries import summarise
summarise(read_capture(sys.argv[1], load_data=False))
"""


RECORD = """
import sys
from pathlib import Path
from station.io.scheme import load_scheme
from station.simulate import dryrun
truth = dryrun.load_truth(None, 1)
truth.sample_rate_hz = float(sys.argv[2])
dryrun.record_scheme(load_scheme("optimal9"), truth, 1, Path(sys.argv[1]))
"""


def run_child(argv, pythonpath=None):
    """(wall s, cpu s, peak RSS MB) of one child process (``pythonpath`` first on its module path)."""
    env = dict(os.environ, PYTHONPATH=pythonpath) if pythonpath else None
    t0 = time.perf_counter()
    child = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env,
                             cwd=tempfile.gettempdir())      # not the checkout: -c puts the cwd first
    _, status, usage = os.wait4(child.pid, 0)
    wall = time.perf_counter() - t0
    child.returncode = os.waitstatus_to_exitcode(status)
    if child.returncode not in (0,):
        sys.exit(f"{argv[:3]} failed ({child.returncode}): {child.stderr.read().decode()[-500:]}")
    child.stderr.close()
    return wall, usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1024


def ahead_pairs(cap, pairs):
    """Median (wall s, cpu s) of summarising ``cap`` in this process with and without reading ahead."""
    from station.estimate.summaries import summarise
    from station.io import capture as capture_io

    real = capture_io.ReaderAhead.ahead
    runs = {"with reading ahead": [], "without": []}
    try:
        for _ in range(pairs):
            for name in runs:
                capture_io.ReaderAhead.ahead = real if name.startswith("with ") else (lambda self: None)
                wall, cpu = time.perf_counter(), time.process_time()
                summarise(capture_io.read_capture(cap, load_data=False))
                runs[name].append((time.perf_counter() - wall, time.process_time() - cpu))
    finally:
        capture_io.ReaderAhead.ahead = real
    for name, values in runs.items():
        print(f"  in process, {name}: wall {statistics.median(v[0] for v in values):.3f} s, "
              f"cpu {statistics.median(v[1] for v in values):.3f} s (medians of {pairs})")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--rates", type=float, nargs="+", default=[1000.0, 4000.0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--keep", metavar="DIR", help="record the captures here and keep them (reused if there)")
    ap.add_argument("--ahead-pairs", type=int, default=0, metavar="N",
                    help="also time summarising in this process with and without reading ahead, N pairs")
    ap.add_argument("--before", metavar="SRC", help="a source tree of an earlier commit: its reader and "
                    "summaries timed in the same run (row 'before')")
    a = ap.parse_args()
    station = shutil.which("station") or sys.exit("install the project first (pip install -e .)")
    scheme = load_scheme("optimal9")
    with tempfile.TemporaryDirectory() as tmp:
        base = Path(a.keep) if a.keep else Path(tmp)
        for rate in a.rates:
            cap = base / f"optimal9_{rate:g}Hz"
            if not (cap / "manifest.yaml").exists():
                # in a process of its own: a child forked from this one after it simulated 12 M
                # samples would start with this one's memory, counted in its peak RSS
                subprocess.run([sys.executable, "-c", RECORD, str(cap), str(rate)], check=True)
            csvs = sorted(str(p) for p in cap.glob("*.csv"))
            megabytes = sum(os.path.getsize(p) for p in csvs) / 1e6
            samples = int(scheme.duration_s * rate)
            here = str(Path(__file__).resolve().parents[1])
            runs = {"estimate": [], "loadtxt": [], "summaries": []} | ({"before": []} if a.before else {})
            for _ in range(a.repeat):          # alternating: all see the same load
                runs["estimate"].append(run_child([station, "estimate", str(cap), "-o", str(Path(tmp) / "cal.yaml")]))
                runs["loadtxt"].append(run_child([sys.executable, "-c", LOADTXT, *csvs]))
                runs["summaries"].append(run_child([sys.executable, "-c", SUMMARIES, str(cap), here], here))
                if a.before:
                    before = str(Path(a.before).resolve())
                    runs["before"].append(run_child([sys.executable, "-c", SUMMARIES, str(cap), before], before))
            med = {k: [statistics.median(r[i] for r in v) for i in range(3)] for k, v in runs.items()}
            print(f"optimal9 at {rate:g} Hz: {samples / 1e6:.2f} M samples, {len(csvs)} CSV files, {megabytes:.0f} MB")
            for k, (wall, cpu, rss) in med.items():
                print(f"  {k:9s} wall {wall:6.2f} s  cpu {cpu:6.2f} s  peak RSS {rss:5.0f} MB  "
                      f"({1e9 * wall / samples:.0f} ns and {rss * 2**20 / samples:.0f} bytes per sample)")
            (wl, cl, _) = med["loadtxt"]
            for k in ("estimate", "summaries"):
                print(f"  {k} / loadtxt: wall {med[k][0] / wl:.2f}x, cpu {med[k][1] / cl:.2f}x "
                      f"(medians of {a.repeat} runs, alternating)")
            if a.before:
                pairs = list(zip(runs["summaries"], runs["before"]))
                print(f"  summaries / before: wall {statistics.median(n[0] / b[0] for n, b in pairs):.2f}x, "
                      f"cpu {statistics.median(n[1] / b[1] for n, b in pairs):.2f}x, peak RSS "
                      f"{statistics.median(n[2] / b[2] for n, b in pairs):.2f}x (medians of the per-pair ratios)")
            if a.ahead_pairs:
                ahead_pairs(cap, a.ahead_pairs)


if __name__ == "__main__":
    main()
