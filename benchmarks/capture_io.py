"""Capture bundle I/O speed: write and read one 300,000-row segment (with temp), and, paired in
the same loop, numpy.loadtxt merely parsing the same CSV (the ratio is what to compare: the
machine is shared).

Usage: python benchmarks/capture_io.py [--rows 300000] [--repeat 5]
"""
import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from station.io.capture import CaptureWriter, ImuInfo, Site, read_capture


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--rows", type=int, default=300_000)
    ap.add_argument("--repeat", type=int, default=5)
    a = ap.parse_args()
    rng = np.random.default_rng(1)
    t = 1e6 + np.arange(a.rows) / 1000.0
    accel, gyro = rng.normal(size=(a.rows, 3)), rng.normal(size=(a.rows, 3)) * 100
    writes, reads, loadtxts = [], [], []
    for i in range(a.repeat):
        with tempfile.TemporaryDirectory() as tmp:
            writer = CaptureWriter(Path(tmp) / "cap", ImuInfo(1000.0, "g", "deg/s"), Site(9.8))
            t0 = time.perf_counter()
            with writer.begin_segment("big", "static") as seg:
                seg.write(t, accel, gyro, np.full(a.rows, 25.0))
            t1 = time.perf_counter()
            read_capture(Path(tmp) / "cap")
            t2 = time.perf_counter()
            np.loadtxt(Path(tmp) / "cap" / "big.csv", delimiter=",", skiprows=1, comments=None)
            t3 = time.perf_counter()
            writes.append(t1 - t0)
            reads.append(t2 - t1)
            loadtxts.append(t3 - t2)
    print(f"{a.rows} rows: write best {min(writes):.3f} s (median {np.median(writes):.3f}), "
          f"read best {min(reads):.3f} s (median {np.median(reads):.3f}); numpy.loadtxt of the same file "
          f"best {min(loadtxts):.3f} s: read / loadtxt {np.median(np.array(reads) / np.array(loadtxts)):.2f} "
          f"(median of paired runs)")


if __name__ == "__main__":
    main()
