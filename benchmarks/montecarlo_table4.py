"""Reproduce the 2010 paper's Monte Carlo tables with dry runs of `optimal9`.

Prints, per parameter, the standard deviation of the estimation error over N seeded dry runs
next to the paper's value.  Usage:
    python benchmarks/montecarlo_table4.py [--runs 50] [--table 4|3]
"""
import argparse
import time

import numpy as np

from station.simulate import montecarlo
from station.io.scheme import load_scheme

# Zhang et al. 2010, tables 3 and 4 (standard deviations of the errors, 500 runs)
PAPER = {
    3: dict(accel=500.0, gyro=0.1, values=[34.92, 35.92, 36.90, 26.57, 28.66, 27.96, 0.23, 0.23, 0.25,
                                           0.11, 0.11, 0.11, 32.84, 36.20, 35.86, 0.0081, 0.0103, 0.0087,
                                           26.16, 28.89, 29.45]),
    4: dict(accel=100.0, gyro=0.03, values=[7.22, 7.13, 7.21, 5.46, 5.54, 5.27, 0.18, 0.19, 0.19,
                                            0.09, 0.09, 0.09, 7.37, 7.32, 6.98, 0.0024, 0.0033, 0.0025,
                                            5.30, 5.56, 5.45]),
}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=50)
    ap.add_argument("--table", type=int, choices=(3, 4), default=4)
    a = ap.parse_args()
    paper = PAPER[a.table]
    settings = montecarlo.Settings(accel_noise_ug=paper["accel"], gyro_noise_dph=paper["gyro"])
    t0 = time.perf_counter()
    settings.method = "zhang2010"
    names, errors, _ = montecarlo.run(load_scheme("optimal9"), settings, a.runs)
    wall = time.perf_counter() - t0
    std = errors.std(axis=0, ddof=1)
    print(f"optimal9, {a.runs} dry runs, accel {paper['accel']} ug/rtHz, gyro {paper['gyro']} deg/h/rtHz, "
          f"2 arcsec table angle error, 50 ug disturbance; {wall:.1f} s wall")
    print(f"| parameter | unit | std of error ({a.runs} runs) | paper table {a.table} (500 runs) | mean error |")
    print("|---|---|---:|---:|---:|")
    for (name, unit), s, p, m in zip(names, std, paper["values"], errors.mean(axis=0)):
        print(f"| {name} | {unit} | {s:.4g} | {p:.4g} | {m:+.3g} |")


if __name__ == "__main__":
    main()
