"""Twins at speed: ``station run`` through the serial drivers against the device twins at
--speed 100, 200 and 500, and the bare IMU stream read by the driver at the same speeds.

    python benchmarks/twins_speed.py [--speeds 100,200,500] [--seed 3]

For each speed:
- stream: 150 s of device time of the VectorNav twin read by the driver (15,000 frames at
  100 Hz): wall time, device time / wall time, frames lost (missing in the device time stamps);
- run: ``station run --scheme optimal9 --dwell-s 20 --rotation-s 36`` unattended in a
  subprocess (3-axis acutrol table on a pseudo-terminal with the TCP reply framing, VectorNav
  IMU): wall time, device time on the twins' clock over the run and its ratio to wall time
  (the twins' clock waits while the reader falls behind: BenchOptions.lossless), device time
  recorded (the segments' sample windows), frames lost (gaps in the capture), frames the twin
  could not send (nobody reading: before the run connected), the shortest settle seen (device
  time from the moment the table twin's axes reached their final state, at the goal or at the
  demanded rate, to the first sample of the segment that followed: settle_s = 3 s, less than
  that means samples of a move were recorded), and the estimate's max |z| against the truth.

    python benchmarks/twins_speed.py --no-throttle    # the twins' clock never waits (frames lost)
"""
from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from drivers.base import ImuSettings
from drivers.registry import open_imu
from sim_devices.truth import default_truth
from sim_devices.twins.serve import BenchOptions, BenchServer
from station.io.calfile import read_calfile
from station.io.capture import read_capture
from station.simulate import dryrun

CONFIG = """\
version: 1
table: {axes: 3}
run: {operator: false, settle_s: 3}
"""


def stream(speed: float, seed: int, lossless: bool) -> str:
    n = 15000
    with BenchServer(default_truth(seed), BenchOptions(speed=speed, seed=seed, lossless=lossless)) as server:
        with open_imu(server.imu_path, "vectornav", ImuSettings(frame_timeout_s=2.0)) as imu:
            first = imu.read(1)
            t0 = time.monotonic()
            got = 0
            while got < n:
                s = imu.read(min(1000, n - got))
                got += len(s)
            wall = time.monotonic() - t0
            lost = imu.counters.missing_frames
    device = float(s.t_s[-1] - first.t_s[0])
    return f"{device:>9.1f} {wall:>7.2f} {device / wall:>8.0f} {lost:>6d}"


def shortest_settle_s(capture, table) -> float:
    """The shortest device time between an axis reaching its final state and the first sample
    of the segment recorded after it (over the capture's complete segments)."""
    history = [list(ax.motion.history) for ax in table.axes]
    shortest = np.inf
    for seg in capture.complete():
        t0 = float(seg.data.t[0])
        steady = max(max((st for tc, st in h if tc <= t0), default=-np.inf) for h in history)
        shortest = min(shortest, t0 - steady)
    return shortest


def run(speed: float, seed: int, work: Path, lossless: bool) -> str:
    truth = default_truth(seed)
    out = work / f"cap{speed:g}"
    with BenchServer(truth, BenchOptions(speed=speed, seed=seed, axes=3, lossless=lossless)) as bench:
        t0 = time.monotonic()
        d0 = bench.clock.now()
        proc = subprocess.run([sys.executable, "-m", "station.cli", "run", "--config", str(work / "station.yaml"),
                               "--port", bench.imu_path, "--table-port", bench.table_path, "--scheme", "optimal9",
                               "--dwell-s", "20", "--rotation-s", "36", "--out", str(out)],
                              capture_output=True, text=True)
        wall = time.monotonic() - t0
        device_run = bench.clock.now() - d0
        overflowed = bench.faulter.frames_overflowed
    if proc.returncode != 0:
        return f"failed: {proc.stderr.strip().splitlines()[-1] if proc.stderr.strip() else proc.returncode}"
    cap = read_capture(out)
    device = sum(float(seg.data.t[-1] - seg.data.t[0]) + 0.01 for seg in cap.segments if seg.data is not None)
    gaps = sum(seg.data.gaps for seg in cap.segments if seg.data is not None)
    params = read_calfile(out / "calibration.yaml")["parameters"]
    z = np.array([(params[n]["value"] - true) / params[n]["sigma"]
                  for n, true, _ in dryrun.truth_calibration(truth).parameters()])
    keep_up = [line for line in (proc.stdout + proc.stderr).splitlines() if "cannot keep up" in line]
    settle = shortest_settle_s(cap, bench.table)
    return (f"{wall:>7.1f} {device_run:>9.0f} {device_run / wall:>8.0f} {device:>10.1f} {gaps:>5d} "
            f"{overflowed:>10d} {settle:>9.2f} {np.abs(z).max():>7.2f}"
            + (f"  ({len(keep_up)} keep-up notes)" if keep_up else ""))


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--speeds", default="100,200,500")
    p.add_argument("--seed", type=int, default=3)
    p.add_argument("--no-throttle", action="store_true", help="BenchOptions(lossless=False)")
    args = p.parse_args()
    lossless = not args.no_throttle
    speeds = [float(s) for s in args.speeds.split(",")]
    work = Path(tempfile.mkdtemp())
    (work / "station.yaml").write_text(CONFIG)
    print("stream: 15,000 frames (100 Hz) read by the VectorNav driver")
    print(f"{'speed':>6} {'device s':>9} {'wall s':>7} {'dev/wall':>8} {'lost':>6}")
    for speed in speeds:
        print(f"{speed:>6g} {stream(speed, args.seed, lossless)}", flush=True)
    print("\nstation run --scheme optimal9 --dwell-s 20 --rotation-s 36 (3-axis acutrol, VectorNav)")
    print(f"{'speed':>6} {'wall s':>7} {'device s':>9} {'dev/wall':>8} {'recorded s':>10} {'gaps':>5} "
          f"{'overflowed':>10} {'settle s':>9} {'max|z|':>7}")
    for speed in speeds:
        print(f"{speed:>6g} {run(speed, args.seed, work, lossless)}", flush=True)


if __name__ == "__main__":
    main()
