"""Monte Carlo throughput: optimal9 dry runs (simulate 306,000 samples + lsq estimate) per second,
on one worker and on all cores.

Usage: python benchmarks/montecarlo_throughput.py [--runs 20]
"""
import argparse
import os
import time

from station.simulate import montecarlo
from station.io.scheme import load_scheme


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=20)
    a = ap.parse_args()
    scheme = load_scheme("optimal9")
    for method in ("lsq", "zhang2010"):
        settings = montecarlo.Settings(method=method)
        for workers in sorted({1, os.cpu_count() or 1}):
            t0 = time.perf_counter()
            montecarlo.run(scheme, settings, a.runs, workers=workers)
            wall = time.perf_counter() - t0
            print(f"{method:9s} {workers} worker(s): {a.runs} runs in {wall:.1f} s = "
                  f"{a.runs / wall:.2f} runs/s")


if __name__ == "__main__":
    main()
