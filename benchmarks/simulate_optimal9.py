"""Time to simulate the full optimal9 scheme (306,000 samples at 100 Hz) in memory.

Usage: python benchmarks/simulate_optimal9.py [--repeat 5]
"""
import argparse
import time

from station.simulate import dryrun
from station.io.scheme import load_scheme


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=5)
    a = ap.parse_args()
    scheme, truth = load_scheme("optimal9"), dryrun.load_truth(None, 0)
    times = []
    for i in range(a.repeat):
        t0 = time.perf_counter()
        capture = dryrun.simulate_capture(scheme, truth, i)
        times.append(time.perf_counter() - t0)
    n = sum(len(s.data.t) for s in capture.segments)
    print(f"optimal9, {n} samples: simulated in {min(times):.3f} s (best of {a.repeat})")


if __name__ == "__main__":
    main()
