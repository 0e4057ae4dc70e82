"""`station noise` on a long static recording (the noise scheme's use: hours still): wall time,
CPU time and peak memory, and the memory per sample (issue 15, item 3: memory that does not grow
with the recording but by what one segment needs).

Writes a capture of one static segment of white noise (--minutes at --rate-hz, default one hour
at 1 kHz: 3.6 M samples, 450 MB of CSV) and a short one (one minute), then runs, alternating, in
fresh processes, `station noise` on each; with --before SRC (a source tree of an earlier commit,
e.g. `git archive COMMIT station drivers | tar -x -C SRC`) the same with SRC first on the module
path.  Prints the medians and the bytes per sample: (peak long - peak short) / (samples long -
samples short), the part of the memory that grows with the recording.

Usage: python benchmarks/perf_noise.py [--minutes 60] [--rate-hz 1000] [--repeat 3] [--keep DIR]
                                       [--before SRC]
"""
import argparse
import hashlib
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

STATION = str(Path(sys.executable).with_name("station"))


def write_capture(directory: Path, samples: int, rate: float) -> None:
    """One complete static segment of white noise (accelerometers ~100 µg/√Hz, z up; gyros)."""
    if (directory / "manifest.yaml").exists():
        return
    directory.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(1)
    digest = hashlib.sha256()
    with open(directory / "still.csv", "wb") as f:
        header = b"t,ax,ay,az,gx,gy,gz,temp\n"
        f.write(header)
        digest.update(header)
        for start in range(0, samples, 200_000):
            n = min(200_000, samples - start)
            rows = np.column_stack([10.0 + np.arange(start, start + n) / rate,
                                    3e-3 * rng.standard_normal((n, 6)) + [0, 0, 9.806, 0, 0, 0],
                                    25.0 + 0.01 * rng.standard_normal(n)])
            text = "".join("%.4f,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.5f\n" % tuple(r) for r in rows).encode()
            f.write(text)
            digest.update(text)
    (directory / "manifest.yaml").write_text(
        "format: station-capture/1\n"
        f"imu: {{sample_rate_hz: {rate}, accel_unit: m/s^2, gyro_unit: deg/s, model: synthetic, serial: NOISE-1}}\n"
        "site: {gravity_mps2: 9.80619776937321, latitude_deg: 45.0}\nscheme: noise\nsegments:\n"
        f"- {{name: still, kind: static, file: still.csv, status: complete, up_body: [0, 0, 1], "
        f"samples: {samples}, sha256: {digest.hexdigest()}}}\n")


def run_child(capture: Path, pythonpath=None) -> tuple:
    """(wall s, cpu s, peak RSS MB) of `station noise CAPTURE` in a fresh process."""
    env = dict(os.environ, PYTHONPATH=pythonpath) if pythonpath else None
    t0 = time.perf_counter()
    child = subprocess.Popen([STATION, "noise", str(capture)], stdout=subprocess.DEVNULL,
                             stderr=subprocess.PIPE, env=env, cwd=tempfile.gettempdir())
    _, status, usage = os.wait4(child.pid, 0)
    wall = time.perf_counter() - t0
    if os.waitstatus_to_exitcode(status) != 0:
        sys.exit(f"station noise {capture} failed: {child.stderr.read().decode()[-500:]}")
    child.stderr.close()
    return wall, usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1024


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, default=60.0)
    ap.add_argument("--rate-hz", type=float, default=1000.0)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--keep", metavar="DIR", help="write the captures here and keep them (reused if there)")
    ap.add_argument("--before", metavar="SRC", help="a source tree of an earlier commit, measured alongside")
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        base = Path(a.keep) if a.keep else Path(tmp)
        n_long, n_short = int(a.minutes * 60 * a.rate_hz), int(60 * a.rate_hz)
        long_cap = base / f"still_{a.minutes:g}min_{a.rate_hz:g}Hz"
        short_cap = base / f"still_1min_{a.rate_hz:g}Hz"
        write_capture(long_cap, n_long, a.rate_hz)
        write_capture(short_cap, n_short, a.rate_hz)
        trees = {"now": None} | ({"before": a.before} if a.before else {})
        runs = {(name, which): [] for name in trees for which in ("long", "short")}
        for _ in range(a.repeat):
            for name, src in trees.items():
                runs[name, "long"].append(run_child(long_cap, src))
                runs[name, "short"].append(run_child(short_cap, src))
        size = (long_cap / "still.csv").stat().st_size / 1e6
        print(f"one static segment, {n_long / 1e6:.2f} M samples at {a.rate_hz:g} Hz ({a.minutes:g} min, {size:.0f} MB of CSV)")
        for name in trees:
            med = [statistics.median(r[i] for r in runs[name, "long"]) for i in range(3)]
            short = statistics.median(r[2] for r in runs[name, "short"])
            per_sample = (med[2] - short) * 2**20 / (n_long - n_short)
            print(f"  {name:6s} wall {med[0]:6.2f} s  cpu {med[1]:6.2f} s  peak RSS {med[2]:6.0f} MB "
                  f"(one minute: {short:.0f} MB): {per_sample:.0f} bytes per sample "
                  f"(medians of {a.repeat}, alternating)")


if __name__ == "__main__":
    main()
