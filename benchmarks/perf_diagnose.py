"""`station diagnose CAPTURE --auto --report DIR` against `station estimate CAPTURE` on the same
simulated optimal9 capture (100 Hz, 306,000 samples), whole processes, paired runs (issue 15's
goal: diagnose --auto --report under 1.5x estimate).

Two captures: the default simulated IMU (the model explains it: no effect to add), and the same
with a hidden accelerometer non-linearity (300, -200, 400 µg/g²: --auto adds it, one refit).
Each repetition runs estimate then diagnose on a capture; medians over the repetitions, the
ratio is the median of the per-repetition ratios.  --stages also times the parts of a diagnose
in this process (one BLAS thread, as the command).

Usage: python benchmarks/perf_diagnose.py [--repeat 5] [--stages]
"""
from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

STATION = str(Path(sys.executable).with_name("station"))


def wall(cmd) -> float:
    return timed(cmd)[0]


def timed(cmd) -> tuple:
    """(wall s, CPU s of the process and every process it started and waited for)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    r = subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    elapsed = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if r.returncode not in (0, 3):
        raise SystemExit(f"{' '.join(cmd)}: exit {r.returncode}: {r.stderr}")
    return elapsed, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def make_captures(tmp: Path) -> dict:
    from sim_devices.truth import default_truth

    truth = default_truth(5).to_yaml_dict()
    truth["accelerometer"]["nonlinearity_ug_per_g2"] = [300.0, -200.0, 400.0]
    (tmp / "hidden.yaml").write_text(yaml.safe_dump(truth))
    captures = {"optimal9, default IMU": tmp / "plain",
                "optimal9, hidden non-linearity": tmp / "hidden"}
    wall([STATION, "run", "--scheme", "optimal9", "--sim", "--seed", "3", "--out", str(captures["optimal9, default IMU"])])
    wall([STATION, "run", "--scheme", "optimal9", "--sim", "--seed", "5", "--sim-truth", str(tmp / "hidden.yaml"),
          "--out", str(captures["optimal9, hidden non-linearity"])])
    return captures


def stages(capture: Path) -> None:
    """The parts of a diagnose --report one after the other in this process (CPU = wall here)."""
    from threadpoolctl import threadpool_limits

    t = [time.perf_counter()]
    from station.diagnose import auto
    from station.diagnose.figures import draw, pyplot
    from station.diagnose.report import diagnosis_figure_specs, noise_of
    from station.estimate import lsq
    from station.io.capture import read_capture
    t.append(time.perf_counter())
    with threadpool_limits(limits=1, user_api="blas"):
        cap = read_capture(capture)
        t.append(time.perf_counter())
        s = lsq.summarise(cap)
        t.append(time.perf_counter())
        steps, final = auto.run(s, [])
        t.append(time.perf_counter())
        noise, _ = noise_of(cap)
        t.append(time.perf_counter())
        pyplot()
        t.append(time.perf_counter())
        draw({"allan.svg": noise})
        t.append(time.perf_counter())
        draw(diagnosis_figure_specs(steps[0].before if steps else final, steps))
        t.append(time.perf_counter())
    names = ("imports", "read", "summarise", f"auto loop ({len(steps)} added)", "noise", "matplotlib import",
             "Allan figure", "diagnosis figures")
    print("    in process: " + ", ".join(f"{n} {(b - a) * 1e3:.0f} ms" for n, a, b in zip(names, t, t[1:])))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--stages", action="store_true")
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        os.environ["STATION_HISTORY_DIR"] = str(tmp / "history")      # not the user's history
        for label, capture in make_captures(tmp).items():
            est, diag = [], []
            for k in range(a.repeat):
                est.append(timed([STATION, "estimate", str(capture), "-o", str(tmp / "cal.yaml"), "--accept-poor-fit"]))
                diag.append(timed([STATION, "diagnose", str(capture), "--auto", "--report", str(tmp / f"report{k}")]))
            ratio = statistics.median(d[0] / e[0] for d, e in zip(diag, est))
            print(f"{label}: estimate {statistics.median(e[0] for e in est):.2f} s, diagnose --auto --report "
                  f"{statistics.median(d[0] for d in diag):.2f} s: {ratio:.2f} x (goal < 1.5: {'met' if ratio < 1.5 else 'NOT met'}; "
                  f"{a.repeat} paired runs, medians); CPU of all their processes "
                  f"{statistics.median(e[1] for e in est):.2f} s and {statistics.median(d[1] for d in diag):.2f} s")
            if a.stages:
                stages(capture)


if __name__ == "__main__":
    main()
