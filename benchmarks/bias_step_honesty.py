"""Issue 28 (honesty): is a located bias step's stated 1-sigma its scatter?  A Monte Carlo over
the simulator's seeds (sim_devices: the twins, written independently of station.model; the
scatter of the estimates over seeds is the reference, sharing no code with the estimator's
covariance): the goal harness's scheme (optimal9, 20 s statics, 36 s rotations at 100 deg/s,
100 Hz, the MEMS IMU), a step inside a static (gyro z in pos09), inside a rotation (accelerometer
y in rotx_m) and between two segments (the gaps pos08 -> pos09 and rotx_m -> roty_p), large and
small against the noise.  Each run locates the step as station estimate does
(profile.fit_located) and records the step's and the base biases' estimates with two stated
1-sigmas: the fit's with the step's time held where the profile put it ("held", before issue 28's
fix) and with it freed (lsq._held_values_freed, the covariance the fit now states).

Usage (from the repository root; ~2.5 s of CPU a run):
    OMP_NUM_THREADS=1 PYTHONPATH=$PWD:$PWD/tests python benchmarks/bias_step_honesty.py [--runs N] [--jobs J] [CASE ...]
Prints, per case and parameter, spread / stated (RMS of the stated 1-sigma) for both, the mean
error over its standard error, and where the step was located; the sampling error of a ratio
is ~1/sqrt(2 N).
"""
import argparse
import json
import multiprocessing
import sys

import numpy as np

GOAL = {"rate_dps": 100.0, "rotation_s": 36.0, "dwell_s": 20.0}
# name: (hidden effect, the parameter that steps and its size)
CASES = {
    "static_large": dict(gyro__bias_step=[0.0, 0.0, 50.0], gyro__bias_step_time_s=300.0),
    "static_small": dict(gyro__bias_step=[0.0, 0.0, 8.0], gyro__bias_step_time_s=300.0),
    "rotation_large": dict(accel__bias_step=[0.0, 1500.0, 0.0], accel__bias_step_time_s=400.0),
    "rotation_small": dict(accel__bias_step=[0.0, 150.0, 0.0], accel__bias_step_time_s=400.0),
    "between_static_large": dict(gyro__bias_step=[0.0, 0.0, 50.0], gyro__bias_step_time_s=287.5),
    "between_static_small": dict(gyro__bias_step=[0.0, 0.0, 8.0], gyro__bias_step_time_s=287.5),
    "between_rotation_large": dict(accel__bias_step=[0.0, 1500.0, 0.0], accel__bias_step_time_s=424.5),
    "between_rotation_small": dict(accel__bias_step=[0.0, 150.0, 0.0], accel__bias_step_time_s=424.5),
}
WATCH = {"gyro": ["gyro_bias_step_z", "gyro_bias_z", "gyro_bias_step_x", "gyro_bias_x"],
         "accel": ["accel_bias_step_y", "accel_bias_y", "accel_bias_step_z", "accel_bias_z"]}


def run(job):
    case, seed = job
    import simhelpers
    from station.estimate import lsq, profile
    from station.model.bias_step import BiasStep

    held = {}
    freed = lsq._held_values_freed

    def spy(model, x, cov, reduced):
        held["cov"] = cov.copy()
        return freed(model, x, cov, reduced)

    lsq._held_values_freed = spy
    try:
        _, cap = simhelpers.mems_capture(seed, "optimal9", GOAL, **CASES[case])
        effect = BiasStep()
        result = profile.fit_located(lsq.summarise(cap), [effect])
    finally:
        lsq._held_values_freed = freed
    names, values, _, cov = lsq.reported(result, "m/s^2", "deg/s")
    result.covariance = held["cov"]
    _, _, _, cov_held = lsq.reported(result, "m/s^2", "deg/s")
    watch = WATCH["gyro" if "gyro__bias_step" in CASES[case] else "accel"]
    out = {"case": case, "seed": seed, "segment": effect.segment,
           "time_s": effect.step_time_s + effect.origin_s,
           "time_sigma_s": getattr(effect, "step_time_s_sigma", None)}
    for n in watch:
        i = names.index(n)
        out[n] = [float(values[i]), float(np.sqrt(cov[i, i])), float(np.sqrt(cov_held[i, i]))]
    return out


def summary(rows):
    by = {}
    for r in rows:
        by.setdefault(r["case"], []).append(r)
    for case, rs in by.items():
        n = len(rs)
        truth = CASES[case]
        where = {}
        for r in rs:
            where[r["segment"] or "boundary"] = where.get(r["segment"] or "boundary", 0) + 1
        t = np.array([r["time_s"] for r in rs])
        ts = np.array([r["time_sigma_s"] or np.nan for r in rs])
        print(f"{case}: {n} runs (ratio's sampling error {1 / np.sqrt(2 * n):.3f}); located {where}; "
              f"time {t.mean():.2f} s, spread {t.std(ddof=1):.2f} s, stated 1σ (freed) {np.sqrt(np.nanmean(ts ** 2)):.2f} s")
        size = truth.get("gyro__bias_step") or truth.get("accel__bias_step")
        for name in [k for k in rs[0] if "bias" in k]:
            v = np.array([r[name][0] for r in rs])
            s_free = np.sqrt(np.mean([r[name][1] ** 2 for r in rs]))
            s_held = np.sqrt(np.mean([r[name][2] ** 2 for r in rs]))
            spread = v.std(ddof=1)
            true = None
            if "step" in name:
                true = size["xyz".index(name[-1])]
            bias = f", mean error {(v.mean() - true) / (spread / np.sqrt(n)):+.1f} SE" if true is not None else ""
            print(f"  {name:18s} mean {v.mean():10.2f} spread {spread:8.3f}  stated held {s_held:8.3f} "
                  f"freed {s_free:8.3f}  spread/stated held {spread / s_held:.3f} freed {spread / s_free:.3f}{bias}")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("cases", nargs="*", default=list(CASES))
    ap.add_argument("--runs", type=int, default=80)
    ap.add_argument("--seed0", type=int, default=1000)
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--out", default=None, help="append each run as a JSON line")
    ap.add_argument("--read", nargs="*", default=None, help="summarise these JSON-lines files only")
    a = ap.parse_args()
    if a.read:
        summary([json.loads(line) for f in a.read for line in open(f)])
        return
    jobs = [(c, a.seed0 + k) for c in a.cases for k in range(a.runs)]
    rows = []
    with multiprocessing.Pool(a.jobs) as pool:
        for r in pool.imap_unordered(run, jobs):
            rows.append(r)
            if a.out:
                with open(a.out, "a") as f:
                    f.write(json.dumps(r) + "\n")
    summary(rows)


if __name__ == "__main__":
    sys.exit(main())
