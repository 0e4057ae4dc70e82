"""Wall time and peak memory of `station estimate` on a full optimal9 dry-run capture.

Records the capture once per sample rate, then times the command (a fresh process each time,
reading the files included).  Usage:
    python benchmarks/estimate_optimal9.py [--rates 100 1000] [--repeat 3]
"""
import argparse
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from station.simulate import dryrun
from station.io.scheme import load_scheme


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--rates", type=float, nargs="+", default=[100.0])
    ap.add_argument("--repeat", type=int, default=3)
    a = ap.parse_args()
    station = shutil.which("station") or sys.exit("install the project first (pip install -e .)")
    scheme = load_scheme("optimal9")
    for rate in a.rates:
        with tempfile.TemporaryDirectory() as tmp:
            truth = dryrun.load_truth(None, 1)
            truth.sample_rate_hz = rate
            cap = dryrun.record_scheme(scheme, truth, 1, Path(tmp) / "cap")
            samples = int(scheme.duration_s * rate)
            walls = []
            for _ in range(a.repeat):
                t0 = time.perf_counter()
                subprocess.run([station, "estimate", str(cap), "-o", str(Path(tmp) / "cal.yaml")],
                               check=True, capture_output=True)
                walls.append(time.perf_counter() - t0)
            peak_mb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
            print(f"optimal9 at {rate:g} Hz ({samples} samples): station estimate best {min(walls):.2f} s "
                  f"wall (of {a.repeat}), peak RSS {peak_mb:.0f} MB")


if __name__ == "__main__":
    main()
