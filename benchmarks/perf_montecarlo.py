"""Monte Carlo throughput (issue 15's goal: >= 3.5 runs/s on 2 cores) and where a run's time
goes.

1. Whole processes: `station montecarlo --scheme optimal9 --runs N --json` (every usable core,
   one BLAS thread per worker, the Cramér-Rao bound in the same pool), repeated; runs/s =
   N / wall time of the whole command (start-up and the bound included), median.
2. One run, in this process on one BLAS thread: simulating the 306,000-sample optimal9 capture
   (sim_devices through station.simulate.dryrun), summarising it (station.estimate.summaries)
   and fitting (station.estimate.lsq), medians over --split runs, and each stage's share.

Usage: python benchmarks/perf_montecarlo.py [--runs 30] [--repeat 3] [--split 5]
"""
from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

STATION = str(Path(sys.executable).with_name("station"))


def whole(runs: int) -> float:
    t0 = time.perf_counter()
    subprocess.run([STATION, "montecarlo", "--scheme", "optimal9", "--runs", str(runs), "--json"],
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=True)
    return time.perf_counter() - t0


def split(n: int) -> dict:
    from threadpoolctl import threadpool_limits

    from station.estimate import lsq
    from station.estimate.summaries import summarise
    from station.io.scheme import load_scheme
    from station.simulate import dryrun, montecarlo

    scheme, settings = load_scheme("optimal9"), montecarlo.Settings()
    truth = montecarlo.make_truth(settings)
    stages = {"simulate": [], "summarise": [], "fit": []}
    with threadpool_limits(limits=1, user_api="blas"):
        for seed in range(2000, 2000 + n):
            t0 = time.perf_counter()
            capture = dryrun.simulate_capture(scheme, truth, seed)
            t1 = time.perf_counter()
            s = summarise(capture)
            t2 = time.perf_counter()
            lsq.to_calibration(lsq.fit(s), capture.imu.accel_unit, capture.imu.gyro_unit)
            t3 = time.perf_counter()
            for name, dt in zip(stages, (t1 - t0, t2 - t1, t3 - t2)):
                stages[name].append(dt)
    return {name: statistics.median(v) for name, v in stages.items()}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=30)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--split", type=int, default=5)
    a = ap.parse_args()
    from station.core.forked import usable_cores

    walls = [whole(a.runs) for _ in range(a.repeat)]
    rate = a.runs / statistics.median(walls)
    print(f"station montecarlo --scheme optimal9 --runs {a.runs}: {usable_cores()} usable cores; "
          f"wall {', '.join(f'{w:.1f}' for w in walls)} s; median {rate:.2f} runs/s "
          f"(goal >= 3.5 on 2 cores: {'met' if rate >= 3.5 else 'NOT met'})")
    stages = split(a.split)
    total = sum(stages.values())
    print(f"one run on one core (median of {a.split}): " + ", ".join(
        f"{name} {t * 1e3:.0f} ms ({100 * t / total:.0f} %)" for name, t in stages.items())
        + f"; total {total * 1e3:.0f} ms = {1 / total:.2f} runs/s per core")


if __name__ == "__main__":
    main()
