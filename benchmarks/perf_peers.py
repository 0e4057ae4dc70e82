"""station against the tools users would pick instead, and against its own earlier code, whole
processes on the same data (issue 27): CPU seconds (user + sys of the process and of every
process it started and waited for: getrusage(RUSAGE_CHILDREN)), wall seconds, medians of
interleaved runs, and the median of the per-round ratios; the load average is printed before
and after (the machine is shared: CPU is the firmer figure).

Work measured, each a fresh process (two for an import and its estimate):
  numpy       python -c "import numpy" (the floor of any Python tool)
  estimate    station estimate of a 100 Hz optimal9 capture (simulated, 306,000 samples)
  imu_tk log  station import csv --preset imu_tk of a 50,062-row Xsens-style pair (raw counts,
              `t x y z`, 38 hand poses, simulated) + station estimate (accelerometers and gyros)
  imucal      station import imucal + estimate of imucal's own example session (102.4 Hz,
              --turn-deg 360, as imucal assumes), against imucal 2.6's FerrarisCalibration in a
              process of its own (pandas reads the CSV, the sections, compute, the result saved);
              and the same in one process, `station import imucal ... --estimate` (the capture
              written, then estimated as `station estimate` would: the same file).  What each
              calibrates: imucal its Ferraris model (accelerometer and gyro scale and
              misalignment matrices, biases, 21 numbers, no uncertainty); station what the
              session determines (9 parameters here: the rest are left out, not guessed)
  imu_tk      imu_tk's own Xsens log (bin/test_data/xsens_acc.mat, xsens_gyro.mat, 51,175 rows,
              raw counts): its compiled `test_imu_calib ACC GYRO` (it reads both files,
              calibrates the accelerometers and the gyros, writes two .calib files; its verbose
              output draws through gnuplot, a child process counted in its CPU, and waits for
              Enter twice, given on its standard input), and the same with its plots discarded
              (`gnuplot` on its PATH a sink that reads and draws nothing: its calibration's own
              time), against `station import csv --preset imu_tk --gyro-file GYRO
              --gravity-mps2 9.81744` + `station estimate` of the same files, the import alone,
              and `station estimate` alone of that capture (imported once); and the import and the
              estimate in one process (`--estimate`).  Given by --imu-tk
              BIN (or $STATION_IMU_TK) and --imu-tk-data DIR (or $STATION_IMU_TK_DATA; default
              BIN's folder's test_data/, imu_tk's layout); skipped, and said, without them.
              imu_tk is not built by this repository (benchmarks/imu_tk_compare.py says how, and
              compares the parameters the two write)

Every tree's modules are compiled to bytecode first (compileall, as pip does when it installs a
package; numpy, scipy and imucal in site-packages are): with PYTHONDONTWRITEBYTECODE set, as on
this machine, a tree without __pycache__ was compiled again by every process (~0.15 s of an
estimate's CPU, counted against station only).

--before SRC times the same station commands with SRC first on PYTHONPATH (a tree holding the
earlier `station` package, e.g. `git archive main station drivers sim_devices | tar -x -C SRC`),
alternating with this tree in every round.

Usage: python benchmarks/perf_peers.py [--repeat 7] [--before SRC] [--imu-tk BIN [--imu-tk-data DIR]]
       [--xsens-gravity G] [--only WORK,...] [--keep DIR]
"""
from __future__ import annotations

import argparse
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from imu_tk_compare import GRAVITY as IMU_TK_GRAVITY, find_imu_tk  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data" / "imucal"
if not (DATA / "example_ferraris_session.csv").exists():
    DATA = ROOT.parent / "shared" / "data" / "imucal"
COUNTS = (8 * 9.80665 / 32768, 1000.0 / 32768)      # +-8 g, +-1000 deg/s in 16 bits

IMUCAL_SCRIPT = r"""
import json, sys
import pandas as pd
from imucal import FerrarisCalibration, ferraris_regions_from_section_list
data = pd.read_csv(sys.argv[1], header=0, index_col=0)
sections = pd.read_json(sys.argv[2]).T
regions = ferraris_regions_from_section_list(data, sections)
cal = FerrarisCalibration().compute(regions, sampling_rate_hz=102.4, from_acc_unit="m/s^2", from_gyr_unit="deg/s")
cal.to_json_file(sys.argv[3])
"""


def run(cmd, env, *, stdin: bytes | None = None, cwd=None) -> tuple[float, float]:
    """(wall s, CPU s of the process tree it waited for)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    r = subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, input=stdin, env=env,
                       cwd=cwd or tempfile.gettempdir())
    elapsed = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if r.returncode not in (0, 3):
        raise SystemExit(f"{' '.join(map(str, cmd))}: exit {r.returncode}: "
                         f"{r.stderr.decode(errors='replace')[-2000:]}")
    return elapsed, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def compile_tree(tree: Path) -> None:
    """Bytecode for the tree's packages (what an installed package has; see the module doc)."""
    for package in ("station", "sim_devices", "drivers"):
        if (tree / package).is_dir():
            subprocess.run([sys.executable, "-m", "compileall", "-q", str(tree / package)], check=True,
                           stdout=subprocess.DEVNULL, env=dict(os.environ, PYTHONDONTWRITEBYTECODE=""))


def env_for(tree: Path | None) -> dict:
    env = dict(os.environ)
    env.pop("PYTHONPATH", None)
    env["PYTHONPATH"] = str(tree or ROOT)
    return env


def station(*argv) -> list:
    # the console script as installed (console_main: gc.freeze before the exit), importing the
    # tree on PYTHONPATH
    # (-P: the working directory is not put on sys.path, where it would shadow PYTHONPATH's tree)
    return [sys.executable, "-P", "-c", "import sys; from station.cli import console_main; sys.argv[0] = 'station'; "
            "sys.exit(console_main())", *map(str, argv)]


XSENS_GRAVITY = [IMU_TK_GRAVITY]      # --xsens-gravity


def import_xsens(xsens: Path, out: Path) -> list:
    """station's import of imu_tk's Xsens log, with the gravity test_imu_calib uses (or
    --xsens-gravity's)."""
    return station("import", "csv", xsens / "xsens_acc.mat", "--preset", "imu_tk", "--gyro-file",
                   xsens / "xsens_gyro.mat", "--gravity-mps2", XSENS_GRAVITY[0], "-o", out)


def make_data(tmp: Path, xsens: Path | None = None, wanted=lambda work: True) -> dict:
    env = env_for(None)
    cap = tmp / "optimal9"
    if not cap.exists() and wanted("estimate"):
        run(station("run", "--scheme", "optimal9", "--sim", "--seed", "1", "--out", cap), env)
    pair = tmp / "imu_tk"
    if not (pair / "gyr.txt").exists() and wanted("imu_tk log"):
        pair.mkdir(exist_ok=True)
        code = ("import numpy as np, sys\n"
                "from sim_devices.hand import hand_session\nfrom sim_devices.truth import mems_truth\n"
                f"hs = hand_session(mems_truth(3), 3, poses=38, dwell_s=(10, 14), counts={COUNTS!r})\n"
                "np.savetxt(sys.argv[1] + '/acc.txt', np.column_stack([hs.t, hs.accel + 32768]), fmt='%.7f %d %d %d')\n"
                "np.savetxt(sys.argv[1] + '/gyr.txt', np.column_stack([hs.t, hs.gyro + 32768]), fmt='%.7f %d %d %d')\n")
        subprocess.run([sys.executable, "-c", code, str(pair)], check=True, env=env)
    data = {"optimal9": cap, "pair": pair}
    if xsens is not None:
        # imu_tk's `gnuplot` for "imu_tk without plots": reads its commands and draws nothing
        sink = tmp / "gnuplot-sink"
        sink.mkdir(exist_ok=True)
        (sink / "gnuplot").write_text("#!/bin/sh\nexec cat > /dev/null\n")
        (sink / "gnuplot").chmod(0o755)
        data["gnuplot sink"] = sink
    if xsens is not None and (wanted("imu_tk") or wanted("xsens estimate")):
        data["xsens capture"] = tmp / "xsens"
        if not (tmp / "xsens" / "manifest.yaml").exists():
            run(import_xsens(xsens, tmp / "xsens"), env)
    return data


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=7)
    ap.add_argument("--before", type=Path, help="a tree with the earlier station package, timed alternately")
    ap.add_argument("--imu-tk", type=Path, help="imu_tk's compiled test_imu_calib (or $STATION_IMU_TK)")
    ap.add_argument("--imu-tk-data", type=Path, help="imu_tk's bin/test_data (or $STATION_IMU_TK_DATA)")
    ap.add_argument("--only", help="the work to time, comma-separated: numpy, estimate, imu_tk log, imucal, "
                                   "imu_tk (the Xsens log: imu_tk and station's four), or one of those five: "
                                   "imu_tk test_imu_calib, xsens import + estimate, xsens import, xsens estimate, "
                                   "xsens import --estimate")
    ap.add_argument("--xsens-gravity", type=float, default=IMU_TK_GRAVITY,
                    help=f"the gravity station imports the Xsens log with (default imu_tk's {IMU_TK_GRAVITY})")
    ap.add_argument("--keep", type=Path, help="keep the data here (made once)")
    args = ap.parse_args()
    XSENS_GRAVITY[0] = args.xsens_gravity
    imu_tk, xsens, why_not = find_imu_tk(args.imu_tk, args.imu_tk_data)
    if imu_tk is None:
        print(f"imu_tk skipped: {why_not}")
    tmp = args.keep or Path(tempfile.mkdtemp(prefix="perf-peers-"))
    tmp.mkdir(parents=True, exist_ok=True)
    only = {w.strip() for w in args.only.split(",")} if args.only else None
    wanted = (lambda w: only is None or w in only)
    data = make_data(tmp, xsens, wanted)
    out = tmp / "out"
    trees = {"now": None} | ({"before": args.before.resolve()} if args.before else {})
    for tree in trees.values():
        compile_tree(tree or ROOT)
    try:
        import imucal  # noqa: F401
        have_imucal = (DATA / "example_ferraris_session.csv").exists()
    except ImportError:
        have_imucal = False

    def work(name, tree):
        env = env_for(tree)
        shutil.rmtree(out, ignore_errors=True)
        out.mkdir()
        if name == "numpy":
            return run([sys.executable, "-P", "-c", "import numpy"], env)
        if name == "estimate":
            return run(station("estimate", data["optimal9"], "-o", out / "c.yaml"), env)
        if name == "imu_tk log":
            a = run(station("import", "csv", data["pair"] / "acc.txt", "--preset", "imu_tk", "--gyro-file",
                            data["pair"] / "gyr.txt", "-o", out / "cap"), env)
            b = run(station("estimate", out / "cap", "-o", out / "c.yaml"), env)
            return a[0] + b[0], a[1] + b[1]
        if name == "imucal session":
            a = run(station("import", "imucal", DATA / "example_ferraris_session.csv", "--sections",
                            DATA / "example_ferraris_session_list.json", "--rate-hz", "102.4", "--turn-deg", "360",
                            "-o", out / "cap"), env)
            b = run(station("estimate", out / "cap", "-o", out / "c.yaml"), env)
            return a[0] + b[0], a[1] + b[1]
        if name == "imucal session, one process":
            return run(station("import", "imucal", DATA / "example_ferraris_session.csv", "--sections",
                               DATA / "example_ferraris_session_list.json", "--rate-hz", "102.4", "--turn-deg",
                               "360", "-o", out / "cap", "--estimate", out / "c.yaml"), env)
        if name == "imu_tk log, one process":
            return run(station("import", "csv", data["pair"] / "acc.txt", "--preset", "imu_tk", "--gyro-file",
                               data["pair"] / "gyr.txt", "-o", out / "cap", "--estimate", out / "c.yaml"), env)
        if name == "imucal 2.6":
            return run([sys.executable, "-P", "-c", IMUCAL_SCRIPT, DATA / "example_ferraris_session.csv",
                        DATA / "example_ferraris_session_list.json", out / "imucal.json"], env)
        if name in ("imu_tk test_imu_calib", "imu_tk without plots"):
            # waitForKey twice (getchar until a newline): the newlines on its standard input
            if name == "imu_tk without plots":   # its `gnuplot` a sink: the calibration without the plots
                env = dict(env, PATH=f"{data['gnuplot sink']}{os.pathsep}{env.get('PATH', '')}")
            return run([str(imu_tk), xsens / "xsens_acc.mat", xsens / "xsens_gyro.mat"], env, stdin=b"\n" * 4,
                       cwd=out)
        if name == "xsens import + estimate":
            a = run(import_xsens(xsens, out / "cap"), env)
            b = run(station("estimate", out / "cap", "-o", out / "c.yaml"), env)
            return a[0] + b[0], a[1] + b[1]
        if name == "xsens import":
            return run(import_xsens(xsens, out / "cap"), env)
        if name == "xsens import --estimate":
            return run(import_xsens(xsens, out / "cap") + ["--estimate", out / "c.yaml"], env)
        if name == "xsens estimate":
            return run(station("estimate", data["xsens capture"], "-o", out / "c.yaml"), env)
        raise ValueError(name)

    jobs = [("numpy", "now")] if wanted("numpy") else []
    jobs += [(w, t) for w in ("estimate", "imu_tk log") if wanted(w) for t in trees]
    if wanted("imu_tk log"):
        jobs += [("imu_tk log, one process", "now")]
    if have_imucal and wanted("imucal"):
        jobs += [(("imucal session"), t) for t in trees] + [("imucal session, one process", "now"),
                                                           ("imucal 2.6", "now")]
    if imu_tk is not None:
        xsens_work = ("imu_tk test_imu_calib", "imu_tk without plots", "xsens import + estimate", "xsens import",
                      "xsens estimate", "xsens import --estimate")
        jobs += [(w, t) for w in xsens_work if wanted("imu_tk") or wanted(w)
                 for t in (("now",) if w.startswith("imu_tk") or w.endswith("--estimate") else trees)]
    print(f"load average before: {os.getloadavg()}; {args.repeat} rounds of {len(jobs)} processes, interleaved")
    times = {j: [] for j in jobs}
    for k in range(args.repeat):
        for j in (jobs if k % 2 == 0 else jobs[::-1]):
            times[j].append(work(j[0], trees[j[1]]))
    print(f"load average after: {os.getloadavg()}")
    print(f"\n{'work':24s} {'tree':7s} {'wall s':>8s} {'CPU s':>8s}")
    for (name, tree), vals in times.items():
        print(f"{name:24s} {tree:7s} {statistics.median(v[0] for v in vals):8.3f} "
              f"{statistics.median(v[1] for v in vals):8.3f}")

    def ratio(a, b, i):
        return statistics.median(x[i] / y[i] for x, y in zip(times[a], times[b]))

    print("\nratios (median of the per-round ratios), CPU; wall")
    pairs = [(("estimate", "now"), ("numpy", "now"), "100 Hz optimal9 estimate / import numpy")]
    if "before" in trees:
        pairs += [((w, "now"), (w, "before"), f"{w}: now / before") for w in ("estimate", "imu_tk log")]
    pairs.append((("imu_tk log, one process", "now"), ("imu_tk log", "now"), "imu_tk log: one process / two"))
    if have_imucal:
        pairs.append((("imucal session", "now"), ("imucal 2.6", "now"), "imucal session: station / imucal 2.6"))
        pairs.append((("imucal session, one process", "now"), ("imucal 2.6", "now"),
                      "imucal session, one process: station / imucal 2.6"))
        pairs.append((("imucal session, one process", "now"), ("imucal session", "now"),
                      "imucal session: one process / two"))
        if "before" in trees:
            pairs.append((("imucal session", "now"), ("imucal session", "before"), "imucal session: now / before"))
    for w in ("xsens import + estimate", "xsens import", "xsens estimate", "xsens import --estimate"):
        pairs += [((w, t), ("imu_tk test_imu_calib", "now"), f"{w} ({t}) / imu_tk") for t in trees]
        pairs += [((w, t), ("imu_tk without plots", "now"), f"{w} ({t}) / imu_tk without plots")
                  for t in trees]
        if "before" in trees:
            pairs.append(((w, "now"), (w, "before"), f"{w}: now / before"))
    for a, b, label in pairs:
        if a in times and b in times:
            print(f"  {label:48s} {ratio(a, b, 1):6.2f} x; {ratio(a, b, 0):6.2f} x")
    if imu_tk is None:
        print(f"  (imu_tk skipped: {why_not})")
    if not args.keep:
        shutil.rmtree(tmp, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
