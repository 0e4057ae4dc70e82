"""How soon the lossless twins see the IMU's reader, and the frames they drop before: the
stream of tests/test_twins_speed.py (csv at --speed 500, 20,000 frames read by the driver in
blocks of 2,000), one process per trial, optionally against another commit's twins in pairs
and with busy processes loading the machine (the test dropped frames only under load).

Per trial: wall s from opening the IMU port to the twins' first seeing a reader
(``BenchServer._reader_seen``; "never" if it did not during the read), frames dropped after the
first block was read (what the test asserts is 0), wall s the twins' clock waited for the
reader (``SimClock.held_wall_s``).

Usage: python benchmarks/twins_reader_seen.py [--trials 25] [--load 4] [--against REF]
  --against REF   also run REF's sim_devices and drivers (git archive into a temporary
                  directory), alternating with this tree, trial by trial
  --load N        N busy-loop processes while measuring (ended when done)
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

TRIAL = r"""
import json, time
from drivers.base import ImuSettings
from drivers.registry import open_imu
from sim_devices.truth import default_truth
from sim_devices.twins.serve import BenchOptions, BenchServer
with BenchServer(default_truth(2), BenchOptions(speed=500.0, imu_protocol="csv")) as server:
    seen, opened = [None], [None]
    serve_imu = server._serve_imu
    def watched(readable, now, active):
        out = serve_imu(readable, now, active)
        if seen[0] is None and opened[0] is not None and server._reader_seen:
            seen[0] = time.monotonic() - opened[0]
        return out
    server._serve_imu = watched
    opened[0] = time.monotonic()
    with open_imu(server.imu_path, "csv", ImuSettings(frame_timeout_s=2.0)) as imu:
        imu.read(2000)
        before = server.faulter.frames_overflowed
        for _ in range(9):
            imu.read(2000)
        dropped = server.faulter.frames_overflowed - before
print(json.dumps({"seen_s": seen[0], "dropped": dropped, "held_s": server.clock.held_wall_s}))
"""


def trial(path: Path) -> dict:
    env = dict(os.environ, PYTHONPATH=str(path))
    out = subprocess.run([sys.executable, "-c", TRIAL], env=env, capture_output=True, text=True)
    if out.returncode != 0:         # the reader gave up (a timeout): counted, said why
        return {"failed": (out.stderr.strip().splitlines() or [str(out.returncode)])[-1]}
    return json.loads(out.stdout.strip().splitlines()[-1])


def summary(rows: list[dict]) -> str:
    failed = [r["failed"] for r in rows if "failed" in r]
    rows = [r for r in rows if "failed" not in r]
    if not rows:
        return f"every trial failed: {failed[-1]}"
    seen = [r["seen_s"] for r in rows if r["seen_s"] is not None]
    never = len(rows) - len(seen)
    seen = seen or [float("nan")]
    dropped = [r["dropped"] for r in rows]
    return (f"reader seen after {statistics.median(seen):.3f} s median, {max(seen):.3f} s max, "
            f"{sum(s > 0.5 for s in seen)} after 0.5 s, {never} never; "
            f"frames dropped in {sum(d > 0 for d in dropped)} of {len(rows)} trials ({sum(dropped)} frames); "
            f"clock held {statistics.median(r['held_s'] for r in rows):.2f} s median"
            + (f"; {len(failed)} trials failed ({failed[-1]})" if failed else ""))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=25)
    ap.add_argument("--load", type=int, default=0)
    ap.add_argument("--against", default=None)
    args = ap.parse_args()
    sides = {"this tree": ROOT}
    tmp = tempfile.TemporaryDirectory()
    if args.against:
        archive = subprocess.run(["git", "-C", str(ROOT), "archive", args.against, "sim_devices", "drivers",
                                  "station"], capture_output=True, check=True).stdout
        subprocess.run(["tar", "-x", "-C", tmp.name], input=archive, check=True)
        sides = {args.against: Path(tmp.name), **sides}
    busy = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(args.load)]
    rows = {name: [] for name in sides}
    try:
        for i in range(args.trials):
            for name, path in sides.items():
                rows[name].append(trial(path))
            print(f"\r{i + 1}/{args.trials}", end="", file=sys.stderr, flush=True)
    finally:
        for p in busy:
            p.kill()
            p.wait()
        tmp.cleanup()
    print(file=sys.stderr)
    print(f"csv at --speed 500, 20,000 frames, {args.trials} trials, {args.load} busy processes")
    for name, r in rows.items():
        print(f"{name}: {summary(r)}")


if __name__ == "__main__":
    main()
