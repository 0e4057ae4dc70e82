"""Does the diagnose loop close? Hidden effects on the simulated bench, the CLI run as a user
would, and the calibration scored on a held-out test capture (issue 10).

For every case (each library effect at a MEMS size, each effect outside the library, bench
imperfections, clean captures at 10 and 50 deg/s) the script

1. writes a truth YAML (``mems_truth(0)`` plus the hidden effect) and records a TRAINING capture
   through ``station.simulate.dryrun`` (optimal9 at 100 deg/s, or a scheme YAML it writes with
   rotations at three rates where the case needs them);
2. records a separate HELD-OUT TEST capture of the same IMU (another seed, other attitudes: the
   four body diagonals and four tilted attitudes; rotations about other axes at 30, 70 and
   120 deg/s) with the sensor noise switched off, so that the score is the calibration's
   systematic error and not the noise;
3. records the same test capture a second time with an IDEAL sensor (scale 1, no misalignment,
   no bias, no noise, no effect; same bench, motion and seed, time offset 0 so that the truth
   is at the time stamp) and turns it into frame p with the simulated truth's own C_pb
   (``Truth.paper_parameters``, computed in sim_devices): the TRUE specific force and rate of
   every test sample, obtained without the estimator;
4. runs the CLI: ``station diagnose TRAIN --json``, ``station diagnose TRAIN --auto --json``,
   ``station estimate TRAIN -o base.yaml``, ``station estimate TRAIN --add E ... -o auto.yaml``
   (E: what --auto added), ``station apply CAL SEGMENT.csv -o OUT.csv`` for every test segment
   (``--quick``: one file with all test segments back to back);
5. scores RMS(compensated - true) over the test samples (the first and last 0.2 s of each
   segment left out: derivative-based compensations have edge effects there): accelerometer in
   mg, gyro in deg/h, and the gyro on the rotation samples in ppm of the RMS rate; before and
   after --auto.

It prints one markdown table row per case and flags every case whose held-out error grew
after --auto by more than 5 % (and more than 0.002 mg / 0.1 deg/h).  JSON output from the CLI
is parsed defensively: a missing field prints "n/a".

Usage:
    python benchmarks/diagnose_cases.py [--cases NAME ...] [--quick] [--rate-hz 100]
                                        [--seed 3] [--jobs 2] [--keep DIR] [--json FILE]
    python benchmarks/diagnose_cases.py --list
"""
from __future__ import annotations

import argparse
import copy
import json
import math
import os
import shutil
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

G0 = 9.80665
IMU_SEED = 0              # the IMU: mems_truth(0), the same in every case
TEST_SEED_OFFSET = 1000   # the test capture's seed: training seed + this
EDGE_S = 0.2              # left out of the score at both ends of every test segment
GREW_RELATIVE = 0.05      # a held-out error that grew by more than this is flagged ...
GREW_FLOOR = {"accel_mg": 0.002, "gyro_dph": 0.1}   # ... if it also grew by more than this

STATION = [sys.executable, "-m", "station.cli"]


# ---------------------------------------------------------------------------- the cases

@dataclass
class Case:
    name: str
    hidden: str                                   # in words, with sizes
    set: dict = field(default_factory=dict)       # "section.key" -> value in the truth YAML
    training: str = "fast"                        # fast | multirate | slow10 | mid50
    library: bool = True                          # the hidden effect is in the estimator's library


LEVER_MM = [[0.0, 9.0, -12.0], [-10.0, 0.0, 8.0], [11.0, -7.0, 0.0]]

CASES = [
    # -- in the library, at MEMS sizes
    Case("accel_lever_arm", "accelerometer elements 7-12 mm off the reference point "
         "(cross components; own-axis components 0, the point the estimator defines)",
         {"accelerometer.position_m": [[v / 1000 for v in row] for row in LEVER_MM]}),
    Case("accel_nonlinearity", "K2 = 300, -200, 400 ug/g^2",
         {"accelerometer.nonlinearity_ug_per_g2": [300.0, -200.0, 400.0]}),
    Case("gyro_g_sensitivity", "G 10-40 deg/h/g, 9 terms",
         {"gyroscope.g_sensitivity_dph_per_g": [[30.0, -20.0, 10.0], [15.0, 40.0, -25.0],
                                                [-10.0, 20.0, 35.0]]}),
    Case("gyro_scale_asymmetry", "A = 400, -300, 500 ppm",
         {"gyroscope.scale_asymmetry_ppm": [400.0, -300.0, 500.0]}),
    Case("temperature_bias", "accel 60, -40, 50 ug/degC, gyro 30, -20, 25 deg/h/degC; 6 degC warm-up",
         {"accelerometer.bias_tempco_ug_per_c": [60.0, -40.0, 50.0],
          "gyroscope.bias_tempco_dph_per_c": [30.0, -20.0, 25.0],
          "temperature.warmup_delta_c": 6.0}),
    Case("time_offset", "5 ms; table with 20 % rate ripple at 0.9 Hz; IMU centred",
         {"bench.time_offset_s": 0.005, "bench.rate_ripple_fraction": 0.2,
          "bench.rate_ripple_hz": 0.9, "bench.lever_arm_m": [0.0, 0.0, 0.0]}),
    # -- outside the library
    Case("gyro_rate_squared", "q = 4, -3, 5 ppm/(deg/s) on r^2; rotations at 25, 60, 100 deg/s",
         {"gyroscope.rate_squared_ppm_per_dps": [4.0, -3.0, 5.0]}, "multirate", False),
    Case("gyro_rate_squared_1rate", "q = 4, -3, 5 ppm/(deg/s) on r^2; rotations at 100 deg/s only "
         "(aliases with scale asymmetry)",
         {"gyroscope.rate_squared_ppm_per_dps": [4.0, -3.0, 5.0]}, "fast", False),
    Case("accel_scale_asymmetry", "A = 400, -300, 500 ppm",
         {"accelerometer.scale_asymmetry_ppm": [400.0, -300.0, 500.0]}, library=False),
    Case("accel_cross_coupling", "C_ij a_i a_j 1500-2000 ug/g^2",
         {"accelerometer.cross_coupling_ug_per_g2": [[0.0, 2000.0, -1500.0], [1800.0, 0.0, 1200.0],
                                                     [-1600.0, 1400.0, 0.0]]}, library=False),
    Case("gyro_anisoelastic", "N 20-40 deg/h/g^2 on F_x F_y (x), F_y F_z (y), F_x F_z (z), "
         "F_z^2 (x)",
         {"gyroscope.anisoelastic_dph_per_g2": [[0.0, 0.0, 20.0, 30.0, 0.0, 0.0],
                                                [0.0, 0.0, 0.0, 0.0, 0.0, 40.0],
                                                [0.0, 0.0, 0.0, 0.0, -35.0, 0.0]]}, library=False),
    Case("scale_tempco", "scale 100, -80, 60 ppm/degC (accel), 300, -200, 250 ppm/degC (gyro); "
         "6 degC warm-up",
         {"accelerometer.scale_tempco_ppm_per_c": [100.0, -80.0, 60.0],
          "gyroscope.scale_tempco_ppm_per_c": [300.0, -200.0, 250.0],
          "temperature.warmup_delta_c": 6.0}, library=False),
    Case("bias_step", "accel +1000, -500, 0 ug and gyro 0, 0, +100 deg/h from bench time 300 s",
         {"accelerometer.bias_step_ug": [1000.0, -500.0, 0.0], "accelerometer.bias_step_time_s": 300.0,
          "gyroscope.bias_step_dph": [0.0, 0.0, 100.0], "gyroscope.bias_step_time_s": 300.0},
         library=False),
    Case("vibration_1rev", "once per revolution, 1 mg along the table axis and 1 mg across it "
         "(horizontal)", {"bench.vibration_mg": [1.0, 0.0, 1.0], "bench.vibration_phase_deg": 30.0},
         library=False),
    Case("remount_1deg", "1 deg (1 sigma per axis) placement error at every static",
         {"bench.remount_error_arcsec": 3600.0}, library=False),
    Case("remount_1deg_rotations", "1 deg (1 sigma per axis) placement error at every static and "
         "every rotation segment (each half of a +/- pair)",
         {"bench.remount_error_arcsec": 3600.0, "bench.remount_rotations": True}, library=False),
    Case("stamp_jitter_1ms", "1 ms (1 sigma) jitter of the time stamps",
         {"bench.time_stamp_jitter_ms": 1.0}, library=False),
    Case("wobble_30arcsec", "table axis wobbling by 30 arcsec once per revolution",
         {"bench.wobble_arcsec": 30.0}, library=False),
    Case("ripple_offset_5cm", "20 % rate ripple at 0.9 Hz, IMU 5 cm off the axis "
         "(tangential acceleration)", {"bench.rate_ripple_fraction": 0.2, "bench.rate_ripple_hz": 0.9},
         library=False),
    # -- clean
    Case("clean_10dps", "nothing; optimal9 at 10 deg/s", {}, "slow10"),
    Case("clean_50dps", "nothing; optimal9 at 50 deg/s", {}, "mid50"),
]
CASE_NAMES = [c.name for c in CASES]


# ---------------------------------------------------------------------------- schemes

OPTIMAL9_UPS = [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1],
                [1, 1, 0], [1, 0, 1], [0, 1, 1]]
OPTIMAL9_AXES = [("rotx", [1, 0, 0]), ("roty", [0, 1, 0]), ("rotz", [0, 0, 1]),
                 ("rotxy", [1, 1, 0]), ("rotxz", [1, 0, 1]), ("rotyz", [0, 1, 1])]


def _revolution_s(rate_dps: float, revolutions: float) -> float:
    return round(360.0 * revolutions / rate_dps, 6)


def training_scheme(kind: str, quick: bool) -> dict:
    """The training scheme as a YAML document (optimal9's attitudes and axes)."""
    dwell = 20.0 if quick else 100.0
    revs = 0.5 if quick else 1.0
    segments = [{"static": f"pos{i + 1:02d}", "up_body": up} for i, up in enumerate(OPTIMAL9_UPS)]
    if kind == "multirate":
        # each axis at a low, middle and high rate (the rate^2 vs |rate| separation), the
        # diagonals at the middle rate
        for name, axis in OPTIMAL9_AXES[:3]:
            for rate, n in ((25.0, 4), (60.0, 6), (100.0, 10)):
                segments.append({"rotation": f"{name}{int(rate)}", "axis_body": axis, "rate_dps": rate,
                                 "rotation_s": _revolution_s(rate, n * revs)})
        for name, axis in OPTIMAL9_AXES[3:]:
            segments.append({"rotation": name, "axis_body": axis, "rate_dps": 60.0,
                             "rotation_s": _revolution_s(60.0, 6 * revs)})
    else:
        rate, n = {"fast": (100.0, 10), "slow10": (10.0, 4), "mid50": (50.0, 5)}[kind]
        for name, axis in OPTIMAL9_AXES:
            segments.append({"rotation": name, "axis_body": axis, "rate_dps": rate,
                             "rotation_s": _revolution_s(rate, n * revs)})
    return {"name": f"optimal9-{kind}", "title": f"optimal9 attitudes and axes, {kind} rotations",
            "defaults": {"dwell_s": dwell}, "segments": segments}


def test_scheme() -> dict:
    """The held-out scheme: attitudes and axes that optimal9 does not use, other rates."""
    ups = [[1, 1, 1], [-1, -1, 1], [1, -1, -1], [-1, 1, -1], [2, -1, 0], [0, 2, -1], [-1, 0, 2],
           [1, 2, -2]]
    segments = [{"static": f"test{i + 1:02d}", "up_body": up} for i, up in enumerate(ups)]
    for name, axis, rate in (("rot1m10", [1, -1, 0], 30.0), ("rot111", [1, 1, 1], 70.0),
                             ("rot0m11", [0, -1, 1], 120.0)):
        segments.append({"rotation": name, "axis_body": axis, "rate_dps": rate,
                         "rotation_s": _revolution_s(rate, 2)})
    return {"name": "heldout", "title": "held-out test attitudes and rates",
            "defaults": {"dwell_s": 10.0}, "segments": segments}


# ---------------------------------------------------------------------------- truths

def _put(doc: dict, path: str, value) -> None:
    section, key = path.split(".")
    doc.setdefault(section, {})[key] = value


def case_truth_doc(case: Case, rate_hz: float) -> dict:
    from sim_devices.truth import mems_truth

    doc = mems_truth(IMU_SEED).to_yaml_dict()
    doc["sample_rate_hz"] = float(rate_hz)
    for path, value in case.set.items():
        _put(doc, path, value)
    return doc


def noise_free(doc: dict) -> dict:
    """The same IMU and bench without random sensor noise or acceleration disturbance."""
    out = copy.deepcopy(doc)
    out["accelerometer"]["noise_density_ug_rthz"] = 0.0
    out["gyroscope"]["noise_density_dph_rthz"] = 0.0
    out["bench"]["accel_disturbance_ug"] = 0.0
    return out


def ideal_sensor(doc: dict) -> dict:
    """The same bench, temperature and motion with an ideal sensor (every sensor field at its
    ideal default) and the time offset at 0 (the truth belongs to the time stamp)."""
    out = copy.deepcopy(doc)
    out["accelerometer"] = {"noise_density_ug_rthz": 0.0}
    out["gyroscope"] = {"noise_density_dph_rthz": 0.0}
    out["bench"]["time_offset_s"] = 0.0
    out["bench"]["accel_disturbance_ug"] = 0.0
    return out


# ---------------------------------------------------------------------------- CLI

def run_cli(args: list[str], cwd: Path, log: list) -> tuple[int, str, str, float]:
    t0 = time.perf_counter()
    p = subprocess.run(STATION + args, cwd=cwd, capture_output=True, text=True)
    dt = time.perf_counter() - t0
    log.append({"args": args, "rc": p.returncode, "seconds": round(dt, 2),
                "stderr": p.stderr.strip().splitlines()[-3:]})
    return p.returncode, p.stdout, p.stderr, dt


def parse_json(text: str):
    """The JSON document in the output, or None."""
    i = text.find("{")
    if i < 0:
        return None
    try:
        return json.loads(text[i:])
    except ValueError:
        try:
            return json.JSONDecoder().raw_decode(text[i:])[0]
        except ValueError:
            return None


def get(d, *keys, default=None):
    for k in keys:
        if isinstance(d, dict) and k in d:
            d = d[k]
        elif isinstance(d, list) and isinstance(k, int) and -len(d) <= k < len(d):
            d = d[k]
        else:
            return default
    return d


BASE_EFFECTS = {"base_triads", "inter_triad"}


def auto_added(doc) -> list[str]:
    """The effects --auto added: from its steps, else the final model's effects beyond the base."""
    steps = get(doc, "steps")
    if isinstance(steps, list) and steps:
        added = [get(s, "added") for s in steps]
        if all(isinstance(a, str) for a in added):
            return added
    effects = get(doc, "effects")
    if isinstance(effects, list):
        return [e for e in effects if isinstance(e, str) and e not in BASE_EFFECTS]
    return []


# ---------------------------------------------------------------------------- scoring

def read_csv(path: Path) -> dict[str, np.ndarray]:
    with open(path) as fh:
        header = fh.readline().strip().split(",")
    data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    return {name: data[:, i] for i, name in enumerate(header)}


def truth_segments(ideal_doc: dict, scheme_path: Path, seed: int):
    """True f_p (m/s^2) and w_p (deg/s) per test segment, from the ideal-sensor recording."""
    from sim_devices.truth import Truth
    from station.io.scheme import load_scheme
    from station.simulate import dryrun

    ideal = Truth.from_dict(ideal_doc, "ideal truth")
    capture = dryrun.simulate_capture(load_scheme(str(scheme_path)), ideal, seed)
    return {s.name: (s.kind, s.data.t, s.data.accel, s.data.gyro, s.rate_dps) for s in capture.segments}


def at_compensated_stamps(t_comp, t_true, f_true, w_true):
    """The truth at the compensated samples' time stamps.  The ideal recording's stamps are the
    table's time (time offset 0); a calibration with a time_offset corrects the stamps
    (t - offset), and its samples must be scored against the truth at the corrected time, not at
    the uncorrected one (a cubic spline through the 100 Hz truth: its error, ~g (w dt)^4 / 384,
    is far below a µg).  Unchanged stamps keep the sample-by-sample comparison (the stamps of a
    jittering clock are not the sample times)."""
    t_comp = np.asarray(t_comp, float)
    if len(t_comp) == len(t_true) and np.max(np.abs(t_comp - t_true), initial=0.0) < 1e-9:
        return f_true, w_true
    from scipy.interpolate import CubicSpline

    tq = np.clip(t_comp, t_true[0], t_true[-1])
    return CubicSpline(t_true, f_true, axis=0)(tq), CubicSpline(t_true, w_true, axis=0)(tq)



def join_segments(frames: list, path: Path) -> Path:
    """The segments' columns (read_csv's dicts) back to back in one CSV at ``path`` (time
    increases across them): one `station apply` for a whole held-out capture."""
    cols = list(frames[0])
    with open(path, "w") as fh:
        fh.write(",".join(cols) + "\n")
        np.savetxt(fh, np.column_stack([np.concatenate([fr[c] for fr in frames]) for c in cols]),
                   delimiter=",", fmt="%.12g")
    return path


def split_segments(comp: dict, names: list, frames: list) -> dict:
    """join_segments' file after `station apply` (read_csv's dict), cut back into its segments."""
    outputs, k = {}, 0
    for n, fr in zip(names, frames):
        m = len(fr["t"])
        outputs[n] = {c: v[k:k + m] for c, v in comp.items()}
        k += m
    return outputs


def score(outputs: dict, truth: dict, C_pb: np.ndarray, rate_hz: float) -> dict:
    """RMS of compensated minus true over the test samples, per triad and axis."""
    edge = int(round(EDGE_S * rate_hz))
    acc_err, gyr_err, rot_err, rot_rate = [], [], [], []
    for name, comp in outputs.items():
        kind, t, f_b, w_b, _ = truth[name]
        n = len(t)
        if comp is None or len(comp["t"]) != n:
            raise RuntimeError(f"test segment {name}: {0 if comp is None else len(comp['t'])} "
                               f"compensated samples for {n} true ones")
        sl = slice(edge, n - edge) if n > 2 * edge + 1 else slice(None)
        f_true, w_true = at_compensated_stamps(comp["t"], t, f_b, w_b)
        f_true = f_true[sl] @ C_pb.T
        w_true = w_true[sl] @ C_pb.T
        f = np.column_stack([comp[c][sl] for c in ("ax", "ay", "az")])
        w = np.column_stack([comp[c][sl] for c in ("gx", "gy", "gz")])
        acc_err.append(f - f_true)
        gyr_err.append(w - w_true)
        if kind == "rotation":
            rot_err.append(w - w_true)
            rot_rate.append(np.linalg.norm(w_true, axis=1))
    a = np.vstack(acc_err) / (G0 * 1e-3)           # mg
    g = np.vstack(gyr_err) * 3600.0                # deg/h
    out = {"accel_mg": float(np.sqrt(np.mean(a**2))),
           "accel_mg_axes": [float(x) for x in np.sqrt(np.mean(a**2, axis=0))],
           "gyro_dph": float(np.sqrt(np.mean(g**2))),
           "gyro_dph_axes": [float(x) for x in np.sqrt(np.mean(g**2, axis=0))]}
    if rot_err:
        e = np.vstack(rot_err)
        r = np.concatenate(rot_rate)
        out["gyro_ppm_of_rate"] = float(np.sqrt(np.mean(e**2)) / np.sqrt(np.mean(r**2)) * 1e6)
    return out


def write_true_calibration(truth, path: Path) -> None:
    """The simulated truth's base parameters as a calibration file (the harness's self-check:
    applied to a clean test capture it must give the true values to rounding)."""
    from station.io.calfile import write_calfile
    from station.simulate import dryrun

    write_calfile(path, dryrun.truth_calibration(truth), {"method": "simulated truth"})


def apply_and_score(cal: Path, test_dir: Path, names: list[str], truth: dict, C_pb, rate_hz,
                    quick: bool, work: Path, tag: str, log: list) -> dict:
    outputs: dict = {}
    if quick:
        # every test segment back to back in one file (time increases across them)
        frames = [read_csv(test_dir / f"{n}.csv") for n in names]
        both = join_segments(frames, work / f"test_all_{tag}_in.csv")
        out = work / f"test_all_{tag}.csv"
        # --force: the test capture is the same simulated IMU under another seed (serial SIM-<seed>)
        rc, _, err, _ = run_cli(["apply", str(cal), str(both), "-o", str(out), "--force"], work, log)
        if rc != 0:
            raise RuntimeError(f"station apply failed: {err.strip()[-200:]}")
        outputs.update(split_segments(read_csv(out), names, frames))
    else:
        for n in names:
            out = work / f"{n}_{tag}.csv"
            rc, _, err, _ = run_cli(["apply", str(cal), str(test_dir / f"{n}.csv"), "-o", str(out), "--force"],
                                    work, log)
            if rc != 0:
                raise RuntimeError(f"station apply failed on {n}: {err.strip()[-200:]}")
            outputs[n] = read_csv(out)
    return score(outputs, truth, C_pb, rate_hz)


# ---------------------------------------------------------------------------- one case

def run_case(args) -> dict:
    case_name, opts = args
    from sim_devices.truth import Truth
    from station.io.scheme import load_scheme
    from station.simulate import dryrun

    case = next(c for c in CASES if c.name == case_name)
    work = Path(opts["work"]) / case.name
    if work.exists():
        shutil.rmtree(work)
    work.mkdir(parents=True)
    log: list = []
    res: dict = {"case": case.name, "hidden": case.hidden, "library": case.library,
                 "training": case.training, "log": log}
    t_start = time.perf_counter()
    try:
        doc = case_truth_doc(case, opts["rate_hz"])
        (work / "truth.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
        truth = Truth.from_yaml(work / "truth.yaml")          # validated like a user's file
        train_scheme = work / "train_scheme.yaml"
        train_scheme.write_text(yaml.safe_dump(training_scheme(case.training, opts["quick"]),
                                               sort_keys=False))
        held_scheme = work / "test_scheme.yaml"
        held_scheme.write_text(yaml.safe_dump(test_scheme(), sort_keys=False))
        train = dryrun.record_scheme(load_scheme(str(train_scheme)), truth, opts["seed"], work / "train")
        test_seed = opts["seed"] + TEST_SEED_OFFSET
        test_doc = noise_free(doc)
        test = dryrun.record_scheme(load_scheme(str(held_scheme)), Truth.from_dict(test_doc, "test truth"),
                                    test_seed, work / "test")
        truth_by_segment = truth_segments(ideal_sensor(test_doc), held_scheme, test_seed)
        C_pb = truth.paper_parameters()["C_pb"]
        names = list(truth_by_segment)
        res["record_s"] = round(time.perf_counter() - t_start, 1)

        t_loop = time.perf_counter()
        rc, out, _, _ = run_cli(["diagnose", str(train), "--json"], work, log)
        base = parse_json(out)
        rc, out, _, _ = run_cli(["diagnose", str(train), "--auto", "--json"], work, log)
        auto = parse_json(out)
        added = auto_added(auto) if auto is not None else []
        res.update(
            verdict=get(base, "verdict"), failures=get(base, "failures"),
            candidates=[get(c, "effect") for c in (get(base, "candidates") or [])
                        if get(c, "significant")],
            reduced_chi2_before=get(base, "reduced_chi2"),
            reduced_chi2_after=get(auto, "reduced_chi2"),
            verdict_after=get(auto, "verdict"), failures_after=get(auto, "failures"),
            added=added if auto is not None else None)
        # --accept-poor-fit: the base model is expected to fail where an effect is hidden (exit 3)
        rc, _, err, _ = run_cli(["estimate", str(train), "-o", str(work / "base.yaml"), "--accept-poor-fit"],
                                work, log)
        if rc != 0:
            raise RuntimeError(f"station estimate refused: {err.strip()[-200:]}")
        res["before"] = apply_and_score(work / "base.yaml", test, names, truth_by_segment, C_pb,
                                        opts["rate_hz"], opts["quick"], work, "base", log)
        if added:
            cmd = ["estimate", str(train), "-o", str(work / "auto.yaml"), "--accept-poor-fit"]
            for e in added:
                cmd += ["--add", e]
            rc, _, err, _ = run_cli(cmd, work, log)
            if rc != 0:
                raise RuntimeError(f"station estimate --add failed: {err.strip()[-200:]}")
            res["after"] = apply_and_score(work / "auto.yaml", test, names, truth_by_segment, C_pb,
                                           opts["rate_hz"], opts["quick"], work, "auto", log)
        else:
            res["after"] = res["before"]
        res["loop_s"] = round(time.perf_counter() - t_loop, 1)
        # self-check: the true base calibration on the same test capture (0 for a clean case;
        # otherwise what the hidden effect costs a perfect base calibration)
        write_true_calibration(truth, work / "true_base.yaml")
        res["true_base"] = apply_and_score(work / "true_base.yaml", test, names, truth_by_segment,
                                           C_pb, opts["rate_hz"], True, work, "true", log)
    except Exception as exc:     # one failing case must not stop the others: report it
        res["error"] = f"{type(exc).__name__}: {exc}"
    res["seconds"] = round(time.perf_counter() - t_start, 1)
    if not opts["keep"]:
        shutil.rmtree(work, ignore_errors=True)
    return res


# ---------------------------------------------------------------------------- table

def _words(text, n: int) -> str:
    if not isinstance(text, str) or not text:
        return "n/a" if text is None else "(empty)"
    w = text.replace("|", "/").split()
    return " ".join(w[:n]) + (" …" if len(w) > n else "")


def _num(v, fmt: str) -> str:
    return format(v, fmt) if isinstance(v, (int, float)) and math.isfinite(v) else "n/a"


def grew(res: dict) -> list[str]:
    out = []
    b, a = res.get("before"), res.get("after")
    if not (isinstance(b, dict) and isinstance(a, dict)):
        return out
    for key, label in (("accel_mg", "accel"), ("gyro_dph", "gyro")):
        x, y = b.get(key), a.get(key)
        if isinstance(x, float) and isinstance(y, float) and y > x * (1 + GREW_RELATIVE) \
                and y - x > GREW_FLOOR[key]:
            out.append(f"{label} ×{y / x:.2g}")
    return out


def row(res: dict) -> str:
    if "error" in res and "before" not in res:
        return f"| {res['case']} | error: {_words(res['error'], 20)} | | | | | | |"
    failures = res.get("failures")
    where = _words(failures[0], 12) if isinstance(failures, list) and failures else \
        ("(empty)" if isinstance(failures, list) else "n/a")
    added = res.get("added")
    added_s = "n/a" if added is None else (", ".join(added) or "nothing")
    b, a = res.get("before", {}), res.get("after", {})
    flag = grew(res)
    return (f"| {res['case']} | {_words(res.get('verdict'), 6)} | {where} | {added_s} | "
            f"{_num(res.get('reduced_chi2_before'), '.3g')} → {_num(res.get('reduced_chi2_after'), '.3g')} | "
            f"{_num(b.get('accel_mg'), '.3g')} → {_num(a.get('accel_mg'), '.3g')} | "
            f"{_num(b.get('gyro_dph'), '.3g')} → {_num(a.get('gyro_dph'), '.3g')} "
            f"({_num(b.get('gyro_ppm_of_rate'), '.3g')} → {_num(a.get('gyro_ppm_of_rate'), '.3g')} ppm) | "
            f"{'**GREW: ' + ', '.join(flag) + '**' if flag else ('error' if 'error' in res else 'ok')} |")


HEADER = ("| case | diagnose: verdict | where it fails (first words) | --auto adds | reduced χ² "
          "before → after | held-out accel RMS, mg, before → after | held-out gyro RMS, °/h "
          "(ppm of rate) before → after | held-out error |\n"
          "| --- | --- | --- | --- | --- | --- | --- | --- |")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", nargs="+", metavar="NAME", choices=CASE_NAMES,
                    help="run only these cases (default: all)")
    ap.add_argument("--quick", action="store_true",
                    help="short training capture (20 s dwells, half the revolutions) and one "
                         "apply call per calibration")
    ap.add_argument("--rate-hz", type=float, default=100.0, help="IMU sample rate (default 100)")
    ap.add_argument("--seed", type=int, default=3, help="training capture seed (test: +1000)")
    ap.add_argument("--jobs", type=int, default=min(2, os.cpu_count() or 1))
    ap.add_argument("--keep", metavar="DIR", help="keep every capture, calibration and output here")
    ap.add_argument("--json", metavar="FILE", help="write every result (with the CLI log) here")
    ap.add_argument("--list", action="store_true", help="list the cases and exit")
    a = ap.parse_args(argv)
    if a.list:
        for c in CASES:
            print(f"{c.name:26s} {'library' if c.library else 'outside'}  {c.training:9s} {c.hidden}")
        return 0
    names = a.cases or CASE_NAMES
    work = Path(a.keep) if a.keep else Path(tempfile.mkdtemp(prefix="diagnose_cases_"))
    work.mkdir(parents=True, exist_ok=True)
    opts = {"work": str(work), "quick": a.quick, "rate_hz": a.rate_hz, "seed": a.seed,
            "keep": bool(a.keep)}
    t0 = time.perf_counter()
    print(f"IMU mems_truth({IMU_SEED}), {a.rate_hz:g} Hz, training seed {a.seed}, test seed "
          f"{a.seed + TEST_SEED_OFFSET} (noise-free); {'quick' if a.quick else 'full'} training; "
          f"{len(names)} cases on {a.jobs} processes\n", flush=True)
    print(HEADER, flush=True)
    results = []
    with ProcessPoolExecutor(max(1, a.jobs)) as pool:
        for res in pool.map(run_case, [(n, opts) for n in names]):
            results.append(res)
            print(row(res), flush=True)
    print()
    for res in results:
        extra = f"; after --auto: {_words(res.get('verdict_after'), 14)}" if res.get("added") else ""
        err = f"; ERROR {res['error']}" if "error" in res else ""
        print(f"- {res['case']} ({'in' if res['library'] else 'outside'} the library, "
              f"{res['training']} training): {res['hidden']}; significant first: "
              f"{', '.join(res.get('candidates') or []) or 'none'}{extra}; the true base "
              f"calibration scores {_num(get(res, 'true_base', 'accel_mg'), '.3g')} mg, "
              f"{_num(get(res, 'true_base', 'gyro_dph'), '.3g')} deg/h; CLI loop "
              f"{_num(res.get('loop_s'), '.0f')} s{err}")
    bad = [r["case"] for r in results if grew(r)]
    print(f"\nheld-out error grew after --auto in {len(bad)} of {len(results)} cases"
          f"{': ' + ', '.join(bad) if bad else ''}; {time.perf_counter() - t0:.0f} s in all")
    if a.json:
        Path(a.json).write_text(json.dumps(results, indent=1, default=float))
    if not a.keep:
        shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
