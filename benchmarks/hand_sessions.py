"""Real and simulated hand recordings in: import time, statics found vs true, accelerometer and
gyro errors against the truth with their 1-sigma, and the time of a 51,000-row, 38-pose session
against imu_tk's 0.42 s (docs/real-recordings.md); the least-squares fit alone (CPU seconds,
residual evaluations) paired with the per-segment formulation it replaced (tests/lsq_reference.py).

    python benchmarks/hand_sessions.py [--seeds N] [--quick]

BLAS is held to one thread (the machine is shared; imu_tk's figure is single-threaded C++).
Timings are wall clock on this machine, the median of repeats.
"""
import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import shutil  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from sim_devices.hand import hand_session  # noqa: E402
from sim_devices.truth import mems_truth  # noqa: E402
from station import cli  # noqa: E402
from station.estimate import estimate_with  # noqa: E402
from station.io.capture import read_capture  # noqa: E402
from station.io.importers.rosbag import write_imu_bag  # noqa: E402
from station.model.calibration import Calibration, parameter_errors  # noqa: E402
from station.simulate.dryrun import truth_calibration  # noqa: E402
from estimate_optimal9 import CountedReference, fit_figures  # noqa: E402
from station.estimate import lsq  # noqa: E402
from station.estimate.summaries import summarise  # noqa: E402

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "imucal"
COUNTS = (8 * 9.80665 / 32768, 1000.0 / 32768)      # +-8 g, +-1000 deg/s in 16 bits
IMU_TK_S = 0.42
GROUPS = [("accel scale", "accel_scale", "ppm"), ("accel misalignment", "accel_misalignment", "arcsec"),
          ("accel bias", "accel_bias", None), ("gyro scale", "gyro_scale", "ppm"),
          ("gyro misalignment", "gyro_misalignment", "arcsec"), ("gyro bias", "gyro_bias", None),
          ("inter-triad", "inter_triad", "arcsec")]


CPU = {}


def timed(fn, repeats=1):
    """(result, median wall time); the median CPU time of this process goes to CPU[fn]: on a
    shared machine the wall time includes waiting for a core."""
    times, cpu, out = [], [], None
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        out = fn()
        times.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    CPU["last"] = float(np.median(cpu))
    return out, float(np.median(times))


def quiet(argv):
    """station CLI with its output swallowed (the figures are printed here)."""
    import contextlib
    import io

    with contextlib.redirect_stdout(io.StringIO()):
        code = cli.main(argv)
    if code:
        sys.exit(f"station {' '.join(argv)}: exit {code}")


def counts_truth(truth, counts):
    t = truth_calibration(truth)
    return Calibration(accel_unit="raw", gyro_unit="raw", accel_scale=t.accel_scale / counts[0], accel_T=t.accel_T,
                       accel_bias=t.accel_bias / counts[0], gyro_scale=t.gyro_scale / counts[1], gyro_T=t.gyro_T,
                       gyro_bias=t.gyro_bias / counts[1], R_po=t.R_po)


def errors(cal, truth_cal):
    """{group: (rms error, rms 1-sigma, unit, max |error / sigma|)}."""
    out = {}
    rows = parameter_errors(cal, truth_cal)
    for label, prefix, unit in GROUPS:
        errs, sigmas, z = [], [], []
        for name, _, true, err, u in rows:
            if not name.startswith(prefix):
                continue
            s = cal.sigma[name] / true * 1e6 if "_scale_" in name else cal.sigma[name]
            errs.append(err)
            sigmas.append(s)
            z.append(err / s)
            unit = unit or u
        out[label] = (float(np.sqrt(np.mean(np.square(errs)))), float(np.sqrt(np.mean(np.square(sigmas)))), unit,
                      float(np.max(np.abs(z))), z)
    return out


def found_vs_true(capture, hs):
    dt = hs.t[1] - hs.t[0]
    found = capture.complete("static")
    inside = 0
    for seg in found:
        a, b = int(round(seg.data.t[0] / dt)), int(round(seg.data.t[-1] / dt))
        inside += any(s <= a and b < e for s, e in hs.statics)
    return len(found), inside, len(hs.statics)


def print_errors(title, errs, cal):
    print(f"  {title}: reduced chi2 {cal.fit['reduced_chi2']:.3f} ({cal.fit['dof']} dof), "
          f"{cal.fit['hand_rotations']} hand turns")
    print(f"    {'parameter':20s} {'rms error':>10s} {'rms 1-sigma':>12s}  unit    max |err|/sigma")
    for label, (e, s, unit, zmax, _) in errs.items():
        print(f"    {label:20s} {e:10.3g} {s:12.3g}  {unit:7s} {zmax:5.2f}")


def simulated(tmp: Path, seed: int, kind: str, poses: int, dwell, verbose=True):
    truth = mems_truth(seed)
    counts = COUNTS if kind == "raw counts, no time" else None
    hs = hand_session(truth, seed, poses=poses, dwell_s=dwell, counts=counts)
    g = f"{hs.truth['gravity_mps2']:.6f}"
    out = tmp / f"cap-{kind.split()[0]}-{len(kind)}-{seed}"
    if kind.startswith("csv t,ax..gz"):
        src = tmp / f"log{seed}.csv"
        np.savetxt(src, np.column_stack([hs.t, hs.accel, hs.gyro]), delimiter=",", header="t,ax,ay,az,gx,gy,gz",
                   comments="", fmt="%.10g")
        argv = ["import", "csv", str(src), "--preset", "station"]
        if "latitude" in kind:
            argv += ["--latitude-deg", f"{hs.truth['latitude_deg']:g}"]
    elif kind == "raw counts, no time":
        src = tmp / f"raw{seed}.txt"
        np.savetxt(src, np.column_stack([hs.accel, hs.gyro]), delimiter=";", fmt="%d")
        argv = ["import", "csv", str(src), "--columns", "ax=0,ay=1,az=2,gx=3,gy=4,gz=5", "--accel-unit", "raw",
                "--gyro-unit", "raw", "--rate-hz", "100"]
    else:
        src = tmp / f"bag{seed}"
        write_imu_bag(src, hs.t, hs.accel, np.radians(hs.gyro), fmt="mcap")
        argv = ["import", "rosbag", str(src)]
    _, t_import = timed(lambda: quiet(argv + ["-o", str(out), "--gravity-mps2", g]))
    c_import = CPU["last"]
    capture = read_capture(out)
    (cal, _), t_est = timed(lambda: estimate_with(capture))
    c_est = CPU["last"]
    errs = errors(cal, counts_truth(truth, counts) if counts else truth_calibration(truth))
    found, inside, true = found_vs_true(capture, hs)
    if verbose:
        print(f"\nsimulated hand session, {kind} (mems_truth seed {seed}): {len(hs.t)} rows, {poses} poses")
        print(f"  import {t_import:.2f} s (CPU {c_import:.2f} s); statics found {found} (inside a true still "
              f"interval: {inside}) of {true} true; estimate {t_est:.2f} s (CPU {c_est:.2f} s)")
        print_errors("errors against the truth", errs, cal)
    return errs, cal, t_import, t_est


def fit_pair(capture, title, repeats=3, latitude=None):
    """The fit alone on the capture's summaries: vectorised against the per-segment formulation."""
    s = summarise(capture)
    if latitude is not None:
        s.latitude_deg = latitude
    t_new, n_new, new = fit_figures(s, (), lsq.Model, repeats)
    t_old, n_old, old = fit_figures(s, (), CountedReference, repeats)
    dz = np.max(np.abs(new.x - old.x)[(old.covariance_columns if old.covariance_columns is not None else slice(None))]
                / np.sqrt(np.maximum(np.diag(old.covariance), 1e-300)))   # (a large model: its calibration's columns)
    print(f"  fit alone{title}: {t_new:.3f} s CPU, {n_new} residual evaluations ({1e3 * t_new / n_new:.2f} ms each); "
          f"before (per segment): {t_old:.3f} s, {n_old} evaluations: {t_old / t_new:.1f}x faster; solutions "
          f"within {dz:.1e} sigma")


def imucal_sessions(tmp: Path):
    if not DATA.exists():
        print("shared/data/imucal not present: imucal sessions skipped")
        return
    import json

    sections = json.loads((DATA / "example_ferraris_session_list.json").read_text())
    for title, argv, annotated in (
            ("example_ferraris_session.csv (m/s^2, deg/s, 102.4 Hz)",
             ["import", "csv", str(DATA / "example_ferraris_session.csv"), "--preset", "imucal", "--rate-hz", "102.4",
              "--gravity-mps2", "9.81"], sections),):
        # (annotated_session.csv holds only the annotated sections, sorted by label, with their
        # sample numbers in a recording that is not there: not a continuous log; station import
        # csv refuses it, station import imucal reads it)
        out = tmp / f"imucal-{len(title)}"
        _, t_import = timed(lambda: quiet(argv + ["-o", str(out)]))
        capture = read_capture(out)
        (cal, _), t_est = timed(lambda: estimate_with(capture))
        statics = capture.complete("static")
        print(f"\nimucal {title}: import {t_import:.2f} s, {len(statics)} statics and "
              f"{cal.fit['hand_rotations']} hand turns found; estimate {t_est:.2f} s, reduced chi2 "
              f"{cal.fit['reduced_chi2']:.1f}")
        fit_pair(capture, "")
        if annotated:       # imucal's authors' static sections inside the poses found
            inside = sum(any(int(s.data.t[0] * 102.4) - 2 <= annotated[lab]["start"] + 10 and
                             annotated[lab]["end"] - 10 <= int(s.data.t[-1] * 102.4) + 2 for s in statics)
                         for lab in ("x_p", "x_a", "y_p", "y_a", "z_p", "z_a"))
            print(f"  imucal's 6 annotated static sections lying inside a pose found: {inside}")
        p = {n: (v, u) for n, v, u in cal.parameters()}
        for block in ("accel_scale", "accel_bias", "gyro_scale", "gyro_bias"):
            vals = [p[f"{block}_{a}"] for a in "xyz"]
            sig = [cal.sigma[f"{block}_{a}"] for a in "xyz"]
            print(f"  {block:12s} " + "  ".join(f"{v:.6g} +- {s:.2g}" for (v, _), s in zip(vals, sig)) + f" {vals[0][1]}")


def speed(tmp: Path, repeats: int):
    truth = mems_truth(3)
    hs = hand_session(truth, 3, poses=38, dwell_s=(10.0, 14.0), init_rest_s=20.0)
    src = tmp / "big.csv"
    np.savetxt(src, np.column_stack([hs.t, hs.accel, hs.gyro]), delimiter=",", header="t,ax,ay,az,gx,gy,gz",
               comments="", fmt="%.10g")
    g = f"{hs.truth['gravity_mps2']:.6f}"
    times, cpu = [], []
    for k in range(repeats):
        out = tmp / f"big{k}"
        times.append(timed(lambda: quiet(["import", "csv", str(src), "--preset", "station", "-o", str(out),
                                          "--gravity-mps2", g]))[1])
        cpu.append(CPU["last"])
    capture = read_capture(tmp / "big0")
    estimate_with(capture)          # warm (imports, caches)
    (cal, _), t_est = timed(lambda: estimate_with(capture), repeats)
    c_est = CPU["last"]
    errs = errors(cal, truth_calibration(truth))
    print(f"\nspeed: {len(hs.t)} rows, 38 poses, 37 hand turns (mems_truth seed 3)")
    print(f"  station import csv (parse, detect, check, write the bundle): {np.median(times):.2f} s "
          f"(CPU {np.median(cpu):.2f} s)")
    print(f"  station estimate (accelerometer and gyro, with covariance): {t_est:.3f} s, CPU {c_est:.3f} s "
          f"(imu_tk: {IMU_TK_S} s: {'faster' if c_est < IMU_TK_S else 'slower'})")
    print_errors("errors against the truth", errs, cal)
    fit_pair(capture, "", repeats)
    fit_pair(capture, f" (latitude {hs.truth['latitude_deg']:g} deg known: the poses' full attitudes)", repeats,
             hs.truth["latitude_deg"])


def honesty(tmp: Path, seeds: int):
    z = {label: [] for label, _, _ in GROUPS}
    chi = []
    for seed in range(100, 100 + seeds):
        errs, cal, _, _ = simulated(tmp, seed, "csv t,ax..gz", 16, (2.5, 3.5), verbose=False)
        for label in z:
            z[label] += list(errs[label][4])
        chi.append(cal.fit["reduced_chi2"])
        shutil.rmtree(tmp / f"cap-csv-{len('csv t,ax..gz')}-{seed}")
    print(f"\n1-sigma honesty over {seeds} simulated 16-pose sessions: std of error / reported 1-sigma "
          f"(1 when honest; +- {1 / np.sqrt(2 * 3 * seeds):.2f} from the finite sample)")
    for label, values in z.items():
        print(f"  {label:20s} {np.std(values):.2f}")
    print(f"  reduced chi2: mean {np.mean(chi):.3f}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=10, help="sessions for the 1-sigma check (default 10)")
    ap.add_argument("--quick", action="store_true", help="fewer repeats, no 1-sigma check")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        imucal_sessions(tmp)
        for kind in ("csv t,ax..gz", "csv t,ax..gz, latitude known (Earth rate modelled)", "raw counts, no time",
                     "ROS 2 bag (MCAP)"):
            simulated(tmp, 11, kind, 38, (2.5, 4.0))
        speed(tmp, 1 if args.quick else 3)
        if not args.quick:
            honesty(tmp, args.seeds)


if __name__ == "__main__":
    main()
