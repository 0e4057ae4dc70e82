"""Where the fit's time goes, in one process (issue 27): per phase of a capture's estimate (the
joint fit, the pose check with its poses-only fit, to_calibration) the CPU (thread time, medians
of --repeat runs after a warm-up) and the calls it makes: Jacobian builds, residual evaluations
and the factorisations of the Jacobian (numpy.linalg's svd, eigh, lstsq, qr, cholesky on
matrices of 20 rows or more, by caller), each call's CPU summed.

The calls are counted through wrappers (a few µs each; the CPU figures include them), so the
phases' CPU is a little above the unwrapped estimate's; the counts are exact.

Usage: [PYTHONPATH=TREE] python benchmarks/fit_linear_algebra.py [CAPTURE] [--repeat 7]
       (no CAPTURE: the 100 Hz optimal9 capture of benchmarks/perf_peers.py, simulated with seed
       1 into a temporary folder)
"""
from __future__ import annotations

import argparse
import collections
import os
import statistics
import sys
import tempfile
import time
import traceback
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if not os.environ.get("PYTHONPATH"):          # (else the tree on PYTHONPATH: an earlier one, to compare)
    sys.path.insert(0, str(ROOT))

from station.core.blas import whole_process  # noqa: E402

FACTORISATIONS = ("svd", "eigh", "lstsq", "qr", "cholesky")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("capture", nargs="?", type=Path)
    ap.add_argument("--repeat", type=int, default=7)
    args = ap.parse_args()
    with whole_process(1), tempfile.TemporaryDirectory() as tmp:
        return run(args, Path(tmp))


def run(args, tmp: Path) -> int:
    from station import api
    from station.estimate import lsq, poses, solver
    from station.estimate.summaries import summarise
    from station.io.capture import read_capture

    capture_path = args.capture
    if capture_path is None:
        capture_path = tmp / "optimal9"
        api.simulate("optimal9", capture_path, seed=1)
    calls: dict = collections.defaultdict(lambda: [0, 0.0])
    phase = ["-"]

    def wrap(owner, name, label, keep=lambda a: True):
        real = getattr(owner, name)

        def counted(*a, **k):
            if not keep(a):
                return real(*a, **k)
            t = time.thread_time()
            try:
                return real(*a, **k)
            finally:
                caller = traceback.extract_stack(limit=2)[0]
                where = f"{Path(caller.filename).name}:{caller.name}" if label.startswith("np.") else ""
                entry = calls[(phase[0], label, where)]
                entry[0] += 1
                entry[1] += time.thread_time() - t
        setattr(owner, name, counted)

    for name in FACTORISATIONS:
        wrap(np.linalg, name, f"np.linalg.{name}", keep=lambda a: np.ndim(a[0]) == 2 and np.shape(a[0])[0] >= 20)
    wrap(lsq.Model, "jacobian", "Jacobian builds")
    wrap(lsq.Model, "residuals", "residual evaluations")
    capture = read_capture(capture_path)
    s = summarise(capture)
    au, gu = capture.imu.accel_unit, capture.imu.gyro_unit
    cpu = collections.defaultdict(list)
    for i in range(args.repeat + 1):
        calls.clear()
        before = dict(getattr(solver, "FACTORISATIONS", {}))
        phase[0] = "joint fit"
        t0 = time.thread_time()
        joint = lsq.fit(s)
        phase[0] = "pose check"
        t1 = time.thread_time()
        record, refit = poses.check(s, joint, au)
        phase[0] = "to_calibration"
        t2 = time.thread_time()
        lsq.to_calibration(refit if refit is not None else joint, au, gu)
        t3 = time.thread_time()
        if i:
            for k, v in (("joint fit", t1 - t0), ("pose check", t2 - t1), ("to_calibration", t3 - t2),
                         ("all", t3 - t0)):
                cpu[k].append(v)
    kinds = {k: v - before.get(k, 0) for k, v in getattr(solver, "FACTORISATIONS", {}).items()}
    print(f"capture {capture_path}: {len(s.statics)} statics, {len(s.rotations)} rotations; "
          f"joint J {joint.model.jacobian(joint.x).shape}; CPU medians of {args.repeat} (thread time, ms):")
    for k, v in cpu.items():
        print(f"  {k:16s} {1e3 * statistics.median(v):7.2f}")
    print("calls in one estimate (the last), per phase: count, CPU ms")
    for (ph, label, where), (n, t) in sorted(calls.items(), key=lambda kv: (kv[0][0], -kv[1][1])):
        print(f"  {ph:15s} {label:22s} {where:36s} {n:4d} {1e3 * t:7.2f}")
    if kinds:
        print("the solver's step factorisations (solver.FACTORISATIONS):", kinds)
    return 0


if __name__ == "__main__":
    sys.exit(main())
