"""Is the 1-sigma honest?  The figures of docs/testing.md (issue 30 items 1 and 2), with more runs
than the suite affords:

* lsq and zhang2010 on optimal9 (10 s dwells, 36 s turns, the Monte Carlo defaults): the Monte
  Carlo rms error and the mean reported 1-sigma per parameter group against the independent
  Cramér–Rao bound (tests/independent_crb.py), and the coverage at 1 and 2 sigma;
* the Fourier method on the screwdriver scheme (MEMS noise, high variant): fourier.propagate's
  1-sigma against the Monte Carlo rms, and its coverage;
* hand sessions (sim_devices.hand, mems_truth, 16 poses, hand turns of unknown angle): the
  reported 1-sigma against the Monte Carlo rms, and its coverage, per group.

Usage:
    python benchmarks/honesty.py [--runs 300] [--fourier-runs 100] [--hand-runs 40] [--workers 2]

Each method's runs go to a pool of --workers processes (one BLAS thread each).  Prints markdown.
"""
import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import math  # noqa: E402
import multiprocessing  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from scipy import stats  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

GROUPS = {"accel scale (ppm)": [0, 1, 2], "accel misalignment (arcsec)": [3, 4, 5],
          "gyro scale (ppm)": [6, 7, 8], "gyro misalignment (arcsec)": [9, 10, 11],
          "accel bias (µg)": [12, 13, 14], "gyro bias (°/h)": [15, 16, 17],
          "inter-triad (arcsec)": [18, 19, 20]}
P1, P2 = 2 * stats.norm.cdf(1) - 1, 2 * stats.norm.cdf(2) - 1


def rms(x):
    return float(np.sqrt(np.nanmean(np.asarray(x) ** 2)))


def coverage(errors, sigmas, idx):
    z = np.abs(errors[:, idx] / sigmas[:, idx])
    z = z[np.isfinite(z)]
    return float(np.mean(z < 1)), float(np.mean(z < 2)), len(z)


# ------------------------------------------------------------------------------ Fourier

def _fourier_truth(accel_ug=150.0, gyro_dph=10.0):
    from station.simulate import dryrun

    truth = dryrun.load_truth(None, 0)
    truth.accel.noise_density, truth.gyro.noise_density = accel_ug, gyro_dph
    truth.bench.rate_drift_fraction = -0.2
    return truth


def _fourier_run(seed):
    from station.estimate import fourier
    from station.io.scheme import load_scheme
    from station.model.calibration import parameter_errors
    from station.simulate import dryrun

    truth = _fourier_truth()
    cal = fourier.estimate(dryrun.simulate_capture(load_scheme("screwdriver", {"rotation_s": 10.0}), truth, seed), "high")
    return [e[3] for e in parameter_errors(cal, dryrun.truth_calibration(truth))]


def fourier_sigma():
    from station.core import units
    from station.estimate import fourier
    from station.io.scheme import load_scheme
    from station.model.calibration import parameter_errors
    from station.simulate import dryrun

    scheme = load_scheme("screwdriver", {"rotation_s": 10.0})
    quiet = _fourier_truth(0.0, 0.0)
    s = fourier.summarise(dryrun.simulate_capture(scheme, quiet, 0))
    t = _fourier_truth()
    sigma = fourier.propagate(s, "high", t.accel.noise_density * units.UG_MPS2, t.gyro.noise_density / 3600,
                              t.sample_rate_hz)
    cal = fourier.estimate(dryrun.simulate_capture(scheme, quiet, 0), "high")
    return np.array([sigma[e[0]] for e in parameter_errors(cal, dryrun.truth_calibration(quiet))])


# ------------------------------------------------------------------------------ hand sessions

def _hand_run(seed):
    from sim_devices.hand import hand_session
    from sim_devices.truth import mems_truth
    from station import api
    from station.estimate import estimate_capture
    from station.model.calibration import parameter_errors
    from station.simulate.dryrun import truth_calibration

    truth = mems_truth(7)
    hs = hand_session(truth, seed, poses=16, dwell_s=(2.5, 3.5), turn_s=(1.0, 1.8))
    with tempfile.TemporaryDirectory() as d:
        log = Path(d) / "log.csv"
        np.savetxt(log, np.column_stack([hs.t, hs.accel, hs.gyro]), delimiter=",", header="t,ax,ay,az,gx,gy,gz",
                   comments="", fmt="%.10g")
        import contextlib
        import io

        with contextlib.redirect_stdout(io.StringIO()):
            api.import_csv(log, Path(d) / "cap", gravity_mps2=hs.truth["gravity_mps2"], preset="station")
            cal, _, _ = estimate_capture(Path(d) / "cap")
    errors, sigmas = [], []
    for name, value, _, err, _ in parameter_errors(cal, truth_calibration(truth)):
        s = cal.sigma.get(name, math.nan)
        errors.append(err)
        sigmas.append(s / value * 1e6 if "_scale_" in name else s)
    return errors, sigmas


def _pool(workers, fn, seeds):
    with multiprocessing.get_context("fork").Pool(workers) as pool:
        return pool.map(fn, seeds)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=300)
    ap.add_argument("--fourier-runs", type=int, default=100)
    ap.add_argument("--hand-runs", type=int, default=40)
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args(argv)

    from independent_crb import IndependentBound
    from station.io.scheme import load_scheme
    from station.simulate import montecarlo as mc

    scheme = load_scheme("optimal9", {"dwell_s": 10.0, "rotation_s": 36.0})
    t0 = time.perf_counter()
    bound = IndependentBound(scheme, mc.make_truth(mc.Settings()), 1000)
    print(f"independent bound: {time.perf_counter() - t0:.1f} s\n")
    station_bound = mc.cramer_rao(scheme, mc.Settings())
    for method in ("lsq", "zhang2010"):
        t0 = time.perf_counter()
        st = mc.study(scheme, mc.Settings(method=method), args.runs, first_seed=1000, workers=args.workers)
        dt = time.perf_counter() - t0
        print(f"### {method}: optimal9, {args.runs} runs ({dt:.0f} s on {args.workers} workers)\n")
        print("| group | independent bound | station's own bound / independent | MC rms / bound "
              "| mean reported 1σ / bound | inside 1σ | inside 2σ |")
        print("|---|---:|---:|---:|---:|---:|---:|")
        for g, idx in GROUPS.items():
            b = bound.sigma[idx]
            mc_ratio = rms(st.errors[:, idx] / b)
            reported = np.isfinite(st.sigmas[:, idx]).any()
            rep = f"{np.nanmean(st.sigmas[:, idx] / b):.4f}" if reported else "none reported"
            c1, c2, n = coverage(st.errors, st.sigmas, idx) if reported else (0, 0, 0)
            cov_text = (f"{c1:.3f} | {c2:.3f}" if n else "– | –")
            print(f"| {g} | {np.mean(b):.4g} | {np.mean(station_bound[idx] / b):.4f} | {mc_ratio:.3f} "
                  f"| {rep} | {cov_text} |")
        print(f"\n(expected inside 1σ {P1:.3f}, 2σ {P2:.3f}; relative sd of an rms over {args.runs} runs of 3 "
              f"parameters ≈ {1 / math.sqrt(6 * args.runs):.3f})\n")

    t0 = time.perf_counter()
    errors = np.array(_pool(args.workers, _fourier_run, range(1, args.fourier_runs + 1)))
    sigma = fourier_sigma()
    print(f"### Fourier (high variant): screwdriver, 10 s per direction, MEMS noise, {args.fourier_runs} runs "
          f"({time.perf_counter() - t0:.0f} s)\n")
    print("| group | propagated 1σ | MC rms / 1σ | inside 1σ | inside 2σ |")
    print("|---|---:|---:|---:|---:|")
    sig = np.tile(sigma, (len(errors), 1))
    for g, idx in GROUPS.items():
        c1, c2, _ = coverage(errors, sig, idx)
        print(f"| {g} | {np.mean(sigma[idx]):.4g} | {rms(errors[:, idx] / sigma[idx]):.3f} | {c1:.3f} | {c2:.3f} |")
    print()

    if args.hand_runs:
        t0 = time.perf_counter()
        rows = _pool(args.workers, _hand_run, range(100, 100 + args.hand_runs))
        errors = np.array([r[0] for r in rows])
        sigmas = np.array([r[1] for r in rows])
        print(f"### Hand sessions: mems_truth(7), 16 poses, {args.hand_runs} runs "
              f"({time.perf_counter() - t0:.0f} s)\n")
        print("| group | mean reported 1σ | MC rms / mean 1σ | inside 1σ | inside 2σ | draws |")
        print("|---|---:|---:|---:|---:|---:|")
        for g, idx in GROUPS.items():
            c1, c2, n = coverage(errors, sigmas, idx)
            mean_sigma = np.nanmean(sigmas[:, idx])
            print(f"| {g} | {mean_sigma:.4g} | {rms(errors[:, idx] / np.nanmean(sigmas[:, idx], axis=0)):.3f} "
                  f"| {c1:.3f} | {c2:.3f} | {n} |")
        print()


if __name__ == "__main__":
    main()
