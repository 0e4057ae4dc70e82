"""Monte Carlo throughput (issue 15's goal: >= 3.5 runs/s on 2 cores) and where a run's time
goes.

1. Whole processes: `station montecarlo --scheme optimal9 --runs N --json` (every usable core,
   one BLAS thread per worker, the Cramér-Rao bound in the same pool), repeated; runs/s =
   N / wall time of the whole command (start-up and the bound included), median.
2. One run, in this process on one BLAS thread: simulating the 306,000-sample optimal9 capture
   (sim_devices through station.simulate.dryrun), summarising it (station.estimate.summaries)
   and fitting (station.estimate.lsq), medians over --split runs, and each stage's share.

3. The ceiling (issue 27 item 5): cores / (CPU of one run alone, item 2's stages in CPU
   seconds) is the most runs/s the machine can give.  The whole command's CPU per run (user + sys
   of it and its workers, getrusage(RUSAGE_CHILDREN), / N) against one run's alone is the share
   of the ceiling its CPU reaches (start-up, the pool, the bound and the results are what it pays
   beyond the runs), and its wall runs/s against cores / CPU per run the share in wall time
   (meaningful only on cores nobody else uses: the load average is printed).

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


def whole(runs: int) -> tuple[float, float]:
    """(wall s, CPU s of the command and its workers)."""
    import resource

    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run([STATION, "montecarlo", "--scheme", "optimal9", "--runs", str(runs), "--json"],
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def split(n: int) -> dict:
    from threadpoolctl import threadpool_limits

    from station.estimate import lsq
    from station.estimate.summaries import summarise
    from station.io.scheme import load_scheme
    from station.simulate import dryrun, montecarlo

    scheme, settings = load_scheme("optimal9"), montecarlo.Settings()
    truth = montecarlo.make_truth(settings)
    stages = {"simulate": [], "summarise": [], "fit": []}
    clock = time.process_time           # CPU: the machine is shared
    with threadpool_limits(limits=1, user_api="blas"):
        for seed in range(2000, 2000 + n):
            t0 = clock()
            capture = dryrun.simulate_capture(scheme, truth, seed)
            t1 = clock()
            s = summarise(capture)
            t2 = clock()
            lsq.to_calibration(lsq.fit(s), capture.imu.accel_unit, capture.imu.gyro_unit)
            t3 = clock()
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

    print(f"load average before: {os.getloadavg()}", flush=True)
    cores = usable_cores()
    results, per_run = [], []
    for _ in range(a.repeat):           # interleaved: the command, then one run alone
        results.append(whole(a.runs))
        stages = split(a.split)
        per_run.append(sum(stages.values()))
    walls = [w for w, _ in results]
    rate = a.runs / statistics.median(walls)
    print(f"station montecarlo --scheme optimal9 --runs {a.runs}: {cores} usable cores; "
          f"wall {', '.join(f'{w:.1f}' for w in walls)} s; median {rate:.2f} runs/s "
          f"(goal >= 3.5 on 2 cores: {'met' if rate >= 3.5 else 'NOT met'})")
    total = sum(stages.values())
    print(f"one run on one core, CPU (median of {a.split}, last round): " + ", ".join(
        f"{name} {t * 1e3:.0f} ms ({100 * t / total:.0f} %)" for name, t in stages.items())
        + f"; total {total * 1e3:.0f} ms = {1 / total:.2f} runs/s per core")
    cpu_cmd = [c / a.runs for _, c in results]
    shares = [alone / cmd for alone, cmd in zip(per_run, cpu_cmd)]
    ceiling = cores / statistics.median(per_run)
    print(f"CPU per run: the command {', '.join(f'{1e3 * c:.0f}' for c in cpu_cmd)} ms, one run alone "
          f"{', '.join(f'{1e3 * c:.0f}' for c in per_run)} ms; share of the CPU ceiling (alone / command) "
          f"{', '.join(f'{x:.3f}' for x in shares)}, median {statistics.median(shares):.3f} (goal >= 0.95)")
    print(f"wall: ceiling {cores} cores / {1e3 * statistics.median(per_run):.0f} ms = {ceiling:.2f} runs/s; "
          f"the command's {rate:.2f} runs/s = {rate / ceiling:.3f} of it (on a shared machine: load below)")
    print(f"load average after: {os.getloadavg()}")


if __name__ == "__main__":
    main()
