"""The least-squares fit's time against the number of segments: a custom table scheme of N
static attitudes (random up directions, 2 s each) and N/5 rotations (+/- pairs about six axes),
simulated at the twin's default rate, summarised once, then `lsq.fit` timed with the dense path
(MINPACK's Levenberg-Marquardt on the whole Jacobian, its SVD for the covariance: what every fit
used before) and with the sparse one (Model.is_large: least_squares' trust region with LSMR
steps on the sparse Jacobian, the covariance from the Jacobian with each segment's own
nuisances eliminated), and the largest difference of the two calibrations in 1-sigma.  The
fit takes the sparse path above lsq.LARGE_MODEL parameters (about 100 segments).

Each segment adds 2-3 parameters (a static's attitude, a rotation's phase) and 6-18 residual
rows: the dense path costs rows x parameters^2 (cubic in N), the sparse one grows linearly.

With --diagnosis, also what `station diagnose` computes from the fit (every candidate's score
test and the leave-one-segment-out scores), on the large model's reduced Jacobian.

Usage: python benchmarks/perf_many_segments.py [--statics 50 100 250 500 1000] [--dense-up-to 500] [--diagnosis]
"""
import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import random  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from station.estimate import lsq  # noqa: E402
from station.io.scheme import load_scheme  # noqa: E402
from station.simulate import dryrun  # noqa: E402

AXES = ([1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 0], [1, 0, 1], [0, 1, 1])


def scheme_file(directory: Path, statics: int) -> Path:
    rng = random.Random(statics)
    lines = [f"name: many{statics}", "title: many short segments", "reference: benchmark",
             "defaults:", "  dwell_s: 2.0", "  rate_dps: 30.0", "  rotation_s: 12.0", "segments:"]
    for i in range(statics):
        up = [rng.gauss(0, 1) for _ in range(3)]
        lines.append(f"  - {{static: s{i:05d}, up_body: [{up[0]:.4f}, {up[1]:.4f}, {up[2]:.4f}]}}")
    for i in range(max(6, statics // 5)):
        lines.append(f"  - {{rotation: r{i:04d}, axis_body: {AXES[i % 6]}}}")
    path = directory / f"many{statics}.yaml"
    path.write_text("\n".join(lines) + "\n")
    return path


def timed_fit(s, large: bool):
    lsq.LARGE_MODEL = 0 if large else 10**9
    t0, c0 = time.perf_counter(), time.process_time()
    result = lsq.fit(s)
    return result, time.perf_counter() - t0, time.process_time() - c0


def timed_diagnosis(result) -> float:
    """Wall seconds of what `station diagnose` computes from a fit: the score tests of every
    library candidate (station.diagnose.core.diagnose) and the leave-one-segment-out scores."""
    from station.diagnose.core import diagnose
    from station.diagnose.holdout import leave_one_segment_out

    t0 = time.perf_counter()
    diagnose(result)
    leave_one_segment_out(result)
    return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--statics", type=int, nargs="+", default=[50, 100, 250, 500, 1000])
    ap.add_argument("--dense-up-to", type=int, default=500, help="statics above which the dense path is not timed")
    ap.add_argument("--diagnosis", action="store_true",
                    help="also time the diagnosis of the sparse fit (score tests, leave-one-segment-out)")
    a = ap.parse_args()
    default = lsq.LARGE_MODEL
    with tempfile.TemporaryDirectory() as tmp:
        for n in a.statics:
            scheme = load_scheme(str(scheme_file(Path(tmp), n)))
            s = lsq.summarise(dryrun.simulate_capture(scheme, dryrun.load_truth(None, 0), 1))
            sparse, wall_s, cpu_s = timed_fit(s, True)
            size, rows = sparse.model.layout.size, len(sparse.residuals)
            line = (f"{len(s.statics):5d} statics {len(s.rotations):4d} rotations: {size:5d} parameters, "
                    f"{rows:6d} rows; sparse {wall_s:7.2f} s (cpu {cpu_s:6.2f} s)")
            if a.diagnosis:
                line += f", its diagnosis {timed_diagnosis(sparse):6.2f} s"
            if n <= a.dense_up_to:
                dense, wall_d, cpu_d = timed_fit(s, False)
                _, v_s, _, cov_s = lsq.reported(sparse, "m/s^2", "deg/s")
                _, v_d, _, cov_d = lsq.reported(dense, "m/s^2", "deg/s")
                sigma = np.sqrt(np.diag(cov_d))
                line += (f", dense {wall_d:7.2f} s (cpu {cpu_d:6.2f} s): {wall_d / wall_s:5.1f} x; "
                         f"largest difference {np.max(np.abs(v_s - v_d) / sigma):.1e} sigma, 1-sigma "
                         f"{np.max(np.abs(np.sqrt(np.diag(cov_s)) / sigma - 1)):.1e} relative")
            print(line, flush=True)
    lsq.LARGE_MODEL = default
    print(f"(estimate takes the sparse path above {default} parameters)")


if __name__ == "__main__":
    main()
