"""station run through the serial drivers against the device twins, against the in-process dry
run, over several seeds: errors against the truth in units of the reported 1 sigma.

    python benchmarks/sequencer_twins.py [--seeds 5] [--speed 100]

For each seed: the twins (BenchServer, 3-axis acutrol table, VectorNav IMU, default_truth(seed))
on pseudo-terminals in this process; ``station run --scheme optimal9 --dwell-s 20 --rotation-s 36``
unattended in a subprocess; the same scheme simulated in process (station.simulate.dryrun) with the same
truth.  Prints max |z| and rms z (z = error / sigma over the 21 parameters) of both.
"""
from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from sim_devices.truth import default_truth
from sim_devices.twins.serve import BenchOptions, BenchServer
from station.simulate import dryrun
from station.io.calfile import read_calfile
from station.model.calibration import parameter_errors
from station.estimate import estimate_with
from station.io.scheme import load_scheme

CONFIG = """\
version: 1
table: {axes: 3}
run: {operator: false, settle_s: 3}
"""


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--seeds", type=int, default=5)
    p.add_argument("--speed", type=float, default=100.0)
    args = p.parse_args()
    work = Path(tempfile.mkdtemp())
    (work / "station.yaml").write_text(CONFIG)
    scheme = load_scheme("optimal9", {"dwell_s": 20, "rotation_s": 36})
    print(f"{'seed':>4} {'wall s':>7} {'twins max|z|':>12} {'rms z':>6} {'dry max|z|':>10} {'rms z':>6}")
    for seed in range(1, args.seeds + 1):
        truth = default_truth(seed)
        out = work / f"cap{seed}"
        with BenchServer(truth, BenchOptions(speed=args.speed, seed=seed, axes=3)) as bench:
            t0 = time.monotonic()
            subprocess.run([sys.executable, "-m", "station.cli", "run", "--config", str(work / "station.yaml"),
                            "--port", bench.imu_path, "--table-port", bench.table_path, "--scheme", "optimal9",
                            "--dwell-s", "20", "--rotation-s", "36", "--out", str(out)],
                           check=True, capture_output=True)
            wall = time.monotonic() - t0
        params = read_calfile(out / "calibration.yaml")["parameters"]
        z_twin = np.array([(params[n]["value"] - true) / params[n]["sigma"]
                           for n, true, _ in dryrun.truth_calibration(truth).parameters()])
        dry, _ = estimate_with(dryrun.simulate_capture(scheme, truth, seed), "lsq")
        z_dry = np.array([(v - t) / dry.sigma[n]
                          for n, v, t, _, _ in parameter_errors(dry, dryrun.truth_calibration(truth))])
        print(f"{seed:>4} {wall:>7.1f} {np.abs(z_twin).max():>12.2f} {np.sqrt(np.mean(z_twin**2)):>6.2f} "
              f"{np.abs(z_dry).max():>10.2f} {np.sqrt(np.mean(z_dry**2)):>6.2f}", flush=True)


if __name__ == "__main__":
    main()
