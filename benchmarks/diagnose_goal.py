"""Issue 25, the goal measured: what the diagnose loop ends with, run as a user runs it, on every
effect of the issue's item 1 hidden in the station's own simulator (sim_devices, written
independently of station.model and station.estimate), on combinations nobody designed for, and
on clean captures at 10-300 deg/s, whole and partial revolutions.

For every case the harness

1. writes a truth YAML (the MEMS IMU ``mems_truth(0)``, or the tactical ``default_truth(0)``,
   plus what the case hides) and records a TRAINING capture (``dryrun.record_scheme``) of a
   scheme it writes (optimal9's attitudes and axes; the case chooses the rates, the lengths and
   the statics' dwell);
2. records a HELD-OUT capture of the same IMU and bench (seed + 1000; eight attitudes and three
   rotation axes optimal9 does not use, at 30, 70 and 120 deg/s; sensor noise off) and the same
   motion once more with an IDEAL sensor: the true specific force and rate of every held-out
   sample, in frame p through the truth's own C_pb, without the estimator
   (benchmarks/diagnose_cases.py's scoring, imported);
3. runs the loop through the CLI: ``station estimate TRAIN -o base.yaml --accept-poor-fit`` (the
   calibration before), ``station diagnose TRAIN --auto --json -o auto.yaml`` (the loop: library
   effects and discovered terms, the calibration of the model it ends with and the plugin
   beside it), ``station apply CAL HELDOUT.csv -o OUT.csv [--plugin auto-discovered.py]`` as the
   diagnosis prints it;
4. scores both calibrations on the held-out capture (RMS error of the compensated specific force
   in ug, of the compensated rate in ppm of the rotations' RMS rate) against the CLEAN FLOOR: the
   held-out error of the clean capture's calibration with the same scheme, IMU and seed (its own
   case, ``floor``).

A hidden-effect case PASSES when the final calibration's fit passes (diagnose -o exits 0, the
file's verdict "passes" or "noise overestimated") and both held-out errors are within 2x the
floor.  A case that does not pass must end with words that name its cause: each case lists the
phrases (regular expressions) that name it; the harness looks for them in the final verdict,
the failures and the failure account.  A clean case raises a FALSE ALARM when the final fit fails
or --auto adds anything.  The held-out error GREW when after > before * 1.05 and by more than
the noise floor's share (0.05 x floor).

Usage (from the repository root):
    PYTHONPATH=$PWD python benchmarks/diagnose_goal.py [--quick] [--jobs N] [--cases NAME ...]
                                                       [--seed 4] [--json FILE] [--keep DIR]
    PYTHONPATH=$PWD python benchmarks/diagnose_goal.py --list
``--quick``: the hidden-effect cases of item 1 and the clean floors only, half the revolutions.
"""
from __future__ import annotations

import argparse
import copy
import json
import math
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent))
import diagnose_cases as dc    # noqa: E402  (the held-out scheme, the ideal recording, the scoring)

STATION = [sys.executable, "-m", "station.cli"]
UG = 9.80665e-6                      # m/s^2 per ug
FLOOR_FACTOR = 2.0                   # the goal: within 2x the clean floor
GREW_RELATIVE = 0.05
WARM = {"temperature.warmup_delta_c": 8.0, "temperature.warmup_time_constant_s": 400.0}


# ---------------------------------------------------------------------------- schemes

@dataclass(frozen=True)
class Training:
    """optimal9's nine attitudes (dwell_s each) and six axes, each a +/- pair at each rate of
    ``rates`` for ``seconds`` (None: ``revolutions`` whole revolutions)."""
    name: str
    rates: tuple = (100.0,)
    revolutions: float = 10.0
    seconds: float | None = None
    dwell_s: float = 6.0
    imu: str = "mems"                 # mems | tactical

    def doc(self, quick: bool) -> dict:
        segs = [{"static": f"pos{i + 1:02d}", "up_body": up} for i, up in enumerate(dc.OPTIMAL9_UPS)]
        for name, axis in dc.OPTIMAL9_AXES:
            for rate in self.rates:
                revs = self.revolutions * (0.5 if quick and self.seconds is None and self.revolutions >= 2 else 1)
                secs = self.seconds if self.seconds is not None else dc._revolution_s(rate, revs)
                tag = f"{name}{int(rate)}" if len(self.rates) > 1 else name
                segs.append({"rotation": tag, "axis_body": axis, "rate_dps": rate, "rotation_s": secs})
        return {"name": f"goal-{self.name}", "title": f"optimal9 attitudes and axes ({self.name})",
                "defaults": {"dwell_s": self.dwell_s}, "segments": segs}


STD = Training("100dps-whole", dwell_s=20.0)                         # 10 revolutions at 100 deg/s
MULTIRATE = Training("25-60-100dps", rates=(25.0, 60.0, 100.0), revolutions=4.0)
SLOW = Training("10dps-whole", rates=(10.0,), revolutions=1.0)
SLOW_PART = Training("10dps-partial", rates=(10.0,), seconds=20.0)    # 200 deg
FAST_PART = Training("100dps-partial", seconds=2.5)                   # 250 deg
V300 = Training("300dps-whole", rates=(300.0,), revolutions=10.0)
V300_PART = Training("300dps-partial", rates=(300.0,), seconds=0.8)   # 240 deg
TACTICAL = Training("tactical-100dps", imu="tactical", dwell_s=20.0)
TRAININGS = [STD, MULTIRATE, SLOW, SLOW_PART, FAST_PART, V300, V300_PART, TACTICAL]


# ---------------------------------------------------------------------------- cases

@dataclass
class Case:
    name: str
    hidden: str                        # in words, with sizes
    set: dict = field(default_factory=dict)
    training: Training = STD
    kind: str = "effect"               # effect (item 1) | combination | clean
    cause: tuple = ()                  # phrases (regex) that name the cause when it does not pass


LEVEL_K3 = [3000.0, -2500.0, 3500.0]
CROSS = [[0.0, 2000.0, -1500.0], [1800.0, 0.0, 1200.0], [-1600.0, 1400.0, 0.0]]
GSENS = [[30.0, -20.0, 10.0], [15.0, 40.0, -25.0], [-10.0, 20.0, 35.0]]
ANISO = [[0.0, 0.0, 20.0, 30.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0, 0.0, 40.0], [0.0, 0.0, 0.0, 0.0, -35.0, 0.0]]

CASES = [
    # -- item 1: every effect, at a MEMS size, the training scheme a user would choose for it
    Case("accel_cubic", "accelerometer K3 3000, -2500, 3500 ug/g^3",
         {"accelerometer.cubic_ug_per_g3": LEVEL_K3}, cause=("cubic|third-order|K3",)),
    Case("accel_cross_axis", "accelerometer cross-axis C_ij 1200-2000 ug/g^2",
         {"accelerometer.cross_coupling_ug_per_g2": CROSS}, cause=("cross-axis|cross_axis",)),
    Case("gyro_anisoelastic", "gyro anisoelastic 20-40 deg/h/g^2 (f_x f_y on x, f_y f_z on y, f_x f_z on z, f_z^2 on x)",
         {"gyroscope.anisoelastic_dph_per_g2": ANISO}, cause=("anisoelastic",)),
    Case("gyro_g_sensitivity", "gyro g-sensitivity 10-40 deg/h/g, 9 terms",
         {"gyroscope.g_sensitivity_dph_per_g": GSENS}, cause=("g.sensitiv",)),
    Case("gyro_rate_squared", "gyro r^2 4, -3, 5 ppm/(deg/s); rotations at 25, 60, 100 deg/s",
         {"gyroscope.rate_squared_ppm_per_dps": [4.0, -3.0, 5.0]}, MULTIRATE, cause=("rate",)),
    Case("gyro_rate_odd_squared", "gyro r|r| 4, -3, 5 ppm/(deg/s); rotations at 25, 60, 100 deg/s",
         {"gyroscope.rate_odd_squared_ppm_per_dps": [4.0, -3.0, 5.0]}, MULTIRATE, cause=("rate",)),
    Case("accel_scale_tempco", "accelerometer scale 100, -80, 60 ppm/degC; 8 degC warm-up",
         {"accelerometer.scale_tempco_ppm_per_c": [100.0, -80.0, 60.0], **WARM}, cause=("temperature",)),
    Case("gyro_scale_tempco", "gyro scale 300, -200, 250 ppm/degC; 8 degC warm-up",
         {"gyroscope.scale_tempco_ppm_per_c": [300.0, -200.0, 250.0], **WARM}, cause=("temperature",)),
    Case("temperature_bias_quadratic", "bias (T-T_ref)^2: accel 8, -6, 10 ug/degC^2, gyro 3, -2, 2.5 "
         "deg/h/degC^2; 8 degC warm-up",
         {"accelerometer.bias_tempco2_ug_per_c2": [8.0, -6.0, 10.0],
          "gyroscope.bias_tempco2_dph_per_c2": [3.0, -2.0, 2.5], **WARM}, cause=("temperature",)),
    Case("gyro_bias_step", "gyro z bias step +50 deg/h at 300 s",
         {"gyroscope.bias_step_dph": [0.0, 0.0, 50.0], "gyroscope.bias_step_time_s": 300.0},
         cause=("step",)),
    Case("accel_bias_step", "accelerometer y bias step +1500 ug at 400 s",
         {"accelerometer.bias_step_ug": [0.0, 1500.0, 0.0], "accelerometer.bias_step_time_s": 400.0},
         cause=("step",)),
    Case("bias_drift", "bias drift: accel 300, -200, 250 ug/h, gyro 30, -20, 25 deg/h per hour",
         {"accelerometer.bias_drift_ug_per_h": [300.0, -200.0, 250.0],
          "gyroscope.bias_drift_dph_per_h": [30.0, -20.0, 25.0]}, cause=("drift|time",)),
    Case("table_encoder_scale", "the table turns 300 ppm more than its encoder reads",
         {"bench.encoder_scale_error_ppm": 300.0}, cause=("encoder",)),
    Case("rotation_axis_offsets", "an offset per table axis: 20 mm along z about y, 15 mm along x about z",
         {"bench.axis_offsets_m": [[0.0, 0.0, 0.0], [0.0, 0.0, 0.02], [0.015, 0.0, 0.0]]},
         cause=("remounted|moved|axes do not meet",)),
    Case("remount_per_segment", "the IMU placed anew for every static and rotation: 0.1 deg (1 sigma per axis)",
         {"bench.remount_error_arcsec": 360.0, "bench.remount_rotations": True},
         cause=("moved|remount",)),
    Case("table_wobble", "the platter's axis wobbles by 30 arcsec (once per revolution)",
         {"bench.wobble_arcsec": 30.0}, cause=("wobbl|twice per revolution",)),
    Case("vibration_once_per_rev", "the table vibrates once per revolution: 1 mg along its axis, 0.5 mg across",
         {"bench.vibration_mg": [1.0, 0.5, 0.5]}, cause=("once per revolution",)),
    # -- combinations and conditions nobody designed for
    Case("K3+gyro_scale_tempco", "K3 3000, -2500, 3500 ug/g^3 and gyro scale 300, -200, 250 ppm/degC; 8 degC warm-up",
         {"accelerometer.cubic_ug_per_g3": LEVEL_K3, "gyroscope.scale_tempco_ppm_per_c": [300.0, -200.0, 250.0],
          **WARM}, kind="combination", cause=("cubic|K3", "temperature")),
    Case("g_sens+cross_axis", "gyro g-sensitivity 10-40 deg/h/g and accelerometer cross-axis 1200-2000 ug/g^2",
         {"gyroscope.g_sensitivity_dph_per_g": GSENS, "accelerometer.cross_coupling_ug_per_g2": CROSS},
         kind="combination", cause=("g.sensitiv", "cross")),
    Case("encoder+gyro_step", "encoder scale 300 ppm and a gyro z bias step +50 deg/h at 300 s",
         {"bench.encoder_scale_error_ppm": 300.0, "gyroscope.bias_step_dph": [0.0, 0.0, 50.0],
          "gyroscope.bias_step_time_s": 300.0}, kind="combination", cause=("encoder", "step")),
    Case("K3_at_10dps", "K3 3000, -2500, 3500 ug/g^3; one slow revolution at 10 deg/s",
         {"accelerometer.cubic_ug_per_g3": LEVEL_K3}, SLOW, kind="combination", cause=("cubic|K3",)),
    Case("rate_odd_one_rate", "gyro r|r| 4, -3, 5 ppm/(deg/s); every rotation at 100 deg/s",
         {"gyroscope.rate_odd_squared_ppm_per_dps": [4.0, -3.0, 5.0]}, kind="combination",
         cause=("rate|asymmetr",)),
    Case("cross_axis_partial", "accelerometer cross-axis 1200-2000 ug/g^2; partial revolutions (250 deg at 100 deg/s)",
         {"accelerometer.cross_coupling_ug_per_g2": CROSS}, FAST_PART, kind="combination", cause=("cross",)),
    Case("tactical_aniso+K2", "tactical IMU: gyro anisoelastic 2-4 deg/h/g^2 and accelerometer K2 50, -40, 60 ug/g^2",
         {"gyroscope.anisoelastic_dph_per_g2": [[v / 10 for v in r] for r in ANISO],
          "accelerometer.nonlinearity_ug_per_g2": [50.0, -40.0, 60.0]}, TACTICAL, kind="combination",
         cause=("anisoelastic", "nonlinear")),
    Case("gyro_scale_tempco_2C", "gyro scale 300, -200, 250 ppm/degC over the default 2 degC warm-up",
         {"gyroscope.scale_tempco_ppm_per_c": [300.0, -200.0, 250.0]}, kind="combination",
         cause=("temperature",)),
    Case("encoder_per_axis", "a three-axis table whose encoders read 300, -150 and 0 ppm short (axes 1-3)",
         {"bench.table_axes": 3, "bench.encoder_scale_error_per_axis_ppm": [300.0, -150.0, 0.0]},
         kind="combination", cause=("encoder",)),
    Case("wobble+g_sens", "30 arcsec wobble and gyro g-sensitivity 10-40 deg/h/g",
         {"bench.wobble_arcsec": 30.0, "gyroscope.g_sensitivity_dph_per_g": GSENS}, kind="combination",
         cause=("wobbl|twice per revolution", "g.sensitiv")),
] + [Case(f"clean_{t.name}", f"nothing ({t.name}{', tactical IMU' if t.imu == 'tactical' else ''})", {}, t,
          kind="clean") for t in TRAININGS]
BY_NAME = {c.name: c for c in CASES}


def floor_case(case: Case) -> str:
    return f"clean_{case.training.name}"


# ---------------------------------------------------------------------------- truths

def truth_doc(case: Case, seed_imu: int = 0) -> dict:
    from sim_devices.truth import default_truth, mems_truth

    base = default_truth(seed_imu) if case.training.imu == "tactical" else mems_truth(seed_imu)
    doc = base.to_yaml_dict()
    for path, value in case.set.items():
        section, key = path.split(".")
        doc.setdefault(section, {})[key] = value
    return doc


# ---------------------------------------------------------------------------- the CLI

def cli(args: list[str], cwd: Path, log: list) -> tuple[int, str, str, float]:
    t0 = time.perf_counter()
    env = dict(os.environ, STATION_BLAS_THREADS="1")
    p = subprocess.run(STATION + args, cwd=cwd, capture_output=True, text=True, env=env)
    dt = time.perf_counter() - t0
    log.append({"args": args, "rc": p.returncode, "seconds": round(dt, 2),
                "stderr": p.stderr.strip().splitlines()[-4:]})
    return p.returncode, p.stdout, p.stderr, dt


def verdict_of(cal: Path) -> dict:
    doc = yaml.safe_load(cal.read_text())
    fit = doc.get("fit", {}) if isinstance(doc, dict) else {}
    v = fit.get("verdict", {}) if isinstance(fit, dict) else {}
    return v if isinstance(v, dict) else {}


def apply_score(cal: Path, plugin: str | None, test_dir: Path, names: list[str], truth: dict, C_pb,
                rate_hz: float, work: Path, tag: str, log: list) -> tuple[dict, float]:
    """``station apply`` on every held-out segment back to back (one file), scored; and its time."""
    frames = [dc.read_csv(test_dir / f"{n}.csv") for n in names]
    both = dc.join_segments(frames, work / f"heldout_{tag}_in.csv")
    out = work / f"heldout_{tag}.csv"
    cmd = ["apply", str(cal), str(both), "-o", str(out), "--force"] + (["--plugin", plugin] if plugin else [])
    rc, _, err, dt = cli(cmd, work, log)
    if rc != 0:
        raise RuntimeError(f"station apply ({tag}) failed: {err.strip()[-300:]}")
    s = dc.score(dc.split_segments(dc.read_csv(out), names, frames), truth, C_pb, rate_hz)
    return {"accel_ug": s["accel_mg"] * 1000.0, "gyro_ppm": s.get("gyro_ppm_of_rate", float("nan")),
            "gyro_dph": s["gyro_dph"]}, dt


def run_case(arg) -> dict:
    name, opts = arg
    from sim_devices.truth import Truth
    from station.io.scheme import load_scheme
    from station.simulate import dryrun

    case = BY_NAME[name]
    work = Path(opts["work"]) / re.sub(r"[^A-Za-z0-9_.-]", "_", name)
    shutil.rmtree(work, ignore_errors=True)
    work.mkdir(parents=True)
    log: list = []
    res: dict = {"case": name, "kind": case.kind, "hidden": case.hidden, "training": case.training.name,
                 "log": log}
    t0 = time.perf_counter()
    try:
        doc = truth_doc(case)
        rate_hz = float(doc["sample_rate_hz"])
        (work / "truth.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
        truth = Truth.from_yaml(work / "truth.yaml")
        train_scheme = work / "train_scheme.yaml"
        train_scheme.write_text(yaml.safe_dump(case.training.doc(opts["quick"]), sort_keys=False))
        held_scheme = work / "heldout_scheme.yaml"
        held_scheme.write_text(yaml.safe_dump(dc.test_scheme(), sort_keys=False))
        train = dryrun.record_scheme(load_scheme(str(train_scheme)), truth, opts["seed"], work / "train")
        test_seed = opts["seed"] + dc.TEST_SEED_OFFSET
        test_doc = dc.noise_free(doc)
        test = dryrun.record_scheme(load_scheme(str(held_scheme)), Truth.from_dict(test_doc, "held-out truth"),
                                    test_seed, work / "heldout")
        true_by_seg = dc.truth_segments(dc.ideal_sensor(test_doc), held_scheme, test_seed)
        C_pb = truth.paper_parameters()["C_pb"]
        names = list(true_by_seg)

        # before: the base calibration
        rc, _, err, _ = cli(["estimate", str(train), "-o", str(work / "base.yaml"), "--accept-poor-fit"], work, log)
        if rc != 0:
            raise RuntimeError(f"station estimate refused (exit {rc}): {err.strip()[-300:]}")
        v0 = verdict_of(work / "base.yaml")
        res["before"], _ = apply_score(work / "base.yaml", None, test, names, true_by_seg, C_pb, rate_hz, work,
                                       "base", log)
        res["reduced_chi2_before"] = v0.get("reduced_chi2")
        res["verdict_before"] = v0.get("result")

        # the loop, as a user runs it
        rc, out, err, t_diag = cli(["diagnose", str(train), "--auto", "--json", "-o", str(work / "auto.yaml")],
                                   work, log)
        d = dc.parse_json(out)
        if d is None or not (work / "auto.yaml").is_file():
            raise RuntimeError(f"station diagnose --auto -o failed (exit {rc}): {err.strip()[-300:]}")
        m = re.search(r"to apply it: station apply \S+ RAW\.csv -o COMPENSATED\.csv --plugin (\S+)", err)
        plugin = m.group(1) if m else None
        res["after"], t_apply = apply_score(work / "auto.yaml", plugin, test, names, true_by_seg, C_pb, rate_hz,
                                            work, "auto", log)
        v1 = verdict_of(work / "auto.yaml")
        res.update(exit=rc, verdict_after=v1.get("result"), reduced_chi2_after=v1.get("reduced_chi2"),
                   diagnosis=dc.get(d, "verdict"), failures=dc.get(d, "failures") or [],
                   account=dc.get(d, "failure_account") or [],
                   design=(dc.get(d, "design_suggestions") or []) + (dc.get(d, "not_revealed") or []),
                   added=[(dc.get(s, "added"), bool(dc.get(s, "discovered")), dc.get(s, "instead_of"))
                          for s in (dc.get(d, "steps") or [])],
                   removed=[dc.get(r, "effect") for s in (dc.get(d, "steps") or []) for r in (dc.get(s, "removed") or [])],
                   effects=[e for e in (dc.get(d, "effects") or []) if e not in ("base_triads", "inter_triad")],
                   caveats=[c for s in (dc.get(d, "steps") or []) for c in (dc.get(s, "caveats") or [])][:6],
                   plugin=plugin, loop_s=round(t_diag + t_apply, 1), diagnose_s=round(t_diag, 1))
    except Exception as exc:        # one case failing must not stop the others: it is reported
        res["error"] = f"{type(exc).__name__}: {exc}"
    res["seconds"] = round(time.perf_counter() - t0, 1)
    if not opts["keep"]:
        shutil.rmtree(work, ignore_errors=True)
    return res


# ---------------------------------------------------------------------------- judging

def passes(res) -> bool:
    return res.get("exit") == 0 and res.get("verdict_after") in ("passes", "noise overestimated")


def within_floor(res, floor) -> bool | None:
    if floor is None or "after" not in res or "after" not in floor:
        return None
    a, f = res["after"], floor["after"]
    ok = a["accel_ug"] <= FLOOR_FACTOR * f["accel_ug"]
    if math.isfinite(a["gyro_ppm"]) and math.isfinite(f["gyro_ppm"]):
        ok = ok and a["gyro_ppm"] <= FLOOR_FACTOR * f["gyro_ppm"]
    return ok


def grew(res, floor) -> list[str]:
    out = []
    b, a = res.get("before"), res.get("after")
    if not (b and a):
        return out
    for key, label in (("accel_ug", "accel"), ("gyro_ppm", "gyro")):
        x, y = b[key], a[key]
        fl = (floor or {}).get("after", {}).get(key, 0.0) if floor else 0.0
        if math.isfinite(x) and math.isfinite(y) and y > x * (1 + GREW_RELATIVE) and y - x > 0.05 * fl:
            out.append(f"{label} x{y / x:.2g}")
    return out


def words_of(res) -> str:
    """Everything the loop said: the verdict, the failures, the account, the caveats of its steps
    and the effects it added (an effect added by name names its cause)."""
    return " ".join([str(res.get("diagnosis") or "")] + [str(a[0]) for a in res.get("added", [])] + [str(x) for x in res.get("failures", [])]
                    + [str(x) for x in res.get("account", [])] + [str(x) for x in res.get("caveats", [])]
                    + [str(x) for x in res.get("design", [])])


def named(res, case: Case) -> bool:
    text = words_of(res)
    return bool(case.cause) and all(re.search(p, text, re.I) for p in case.cause)


def judge(results: dict) -> dict:
    for name, res in results.items():
        case = BY_NAME[name]
        floor = results.get(floor_case(case))
        res["floor"] = floor_case(case)
        res["passes"] = passes(res)
        res["at_floor"] = within_floor(res, floor)
        res["grew"] = grew(res, floor)
        if case.kind == "clean":
            res["false_alarm"] = (not res["passes"]) or bool(res.get("added"))
        else:
            res["goal"] = bool(res["passes"] and res["at_floor"])
            res["named"] = named(res, case)
    return results


# ---------------------------------------------------------------------------- the table

def _n(v, fmt=".3g"):
    return format(v, fmt) if isinstance(v, (int, float)) and math.isfinite(v) else "n/a"


def _added(res) -> str:
    if not res.get("added"):
        return "nothing"
    parts = []
    for a, disc, instead in res["added"]:
        parts.append(f"{a}{' (discovered' + (', instead of ' + instead if instead else '') + ')' if disc else ''}")
    if res.get("removed"):
        parts.append("removed " + ", ".join(res["removed"]))
    return "; ".join(parts)


def _short(text, n=28) -> str:
    w = str(text).replace("|", "/").split()
    return " ".join(w[:n]) + (" …" if len(w) > n else "")


def row(res) -> str:
    if "error" in res:
        return f"| {res['case']} | {res['kind']} | error: {_short(res['error'], 30)} | | | | | | |"
    b, a = res["before"], res["after"]
    f = res.get("_floor_after") or {}
    if res["kind"] == "clean":
        outcome = "**false alarm**" if res.get("false_alarm") else "clean: no alarm"
    elif res.get("goal"):
        outcome = "**passes, at floor**"
    else:
        why = "fit fails" if not res["passes"] else "above 2x floor"
        outcome = f"{why}; cause {'named' if res.get('named') else '**NOT named**'}"
    if res.get("grew"):
        outcome += f"; **GREW {', '.join(res['grew'])}**"
    words = "" if res.get("goal") or res["kind"] == "clean" else _short(res.get("diagnosis") or "", 24)
    return (f"| {res['case']} | {res['training']} | {res.get('verdict_after')} | "
            f"{_n(res.get('reduced_chi2_before'))} → {_n(res.get('reduced_chi2_after'))} | "
            f"{_n(b['accel_ug'], '.1f')} → {_n(a['accel_ug'], '.1f')} ({_n(f.get('accel_ug'), '.1f')}) | "
            f"{_n(b['gyro_ppm'], '.1f')} → {_n(a['gyro_ppm'], '.1f')} ({_n(f.get('gyro_ppm'), '.1f')}) | "
            f"{_added(res)} | {outcome} | {words} | {_n(res.get('loop_s'), '.1f')} |")


HEADER = ("| case | training | final verdict | reduced χ² before → after | held-out accel µg before → after "
          "(floor) | held-out gyro ppm before → after (floor) | added | outcome | words when it does not pass "
          "| loop s |\n| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")


def summary(results: dict) -> list[str]:
    hidden = [r for r in results.values() if r["kind"] != "clean" and "error" not in r]
    clean = [r for r in results.values() if r["kind"] == "clean" and "error" not in r]
    errors = [r["case"] for r in results.values() if "error" in r]
    goal = [r for r in hidden if r.get("goal")]
    rest = [r for r in hidden if not r.get("goal")]
    named_rest = [r for r in rest if r.get("named")]
    alarms = [r["case"] for r in clean if r.get("false_alarm")]
    grown = [f"{r['case']} ({', '.join(r['grew'])})" for r in results.values() if r.get("grew")]
    lines = []
    for kind in ("effect", "combination"):
        ks = [r for r in hidden if r["kind"] == kind]
        lines.append(f"{kind} cases: {sum(bool(r.get('goal')) for r in ks)} of {len(ks)} pass at <= 2x the floor")
    lines += [
        f"hidden-effect cases that pass AND sit within 2x the floor: {len(goal)} of {len(hidden)}"
        f" ({100.0 * len(goal) / max(1, len(hidden)):.0f} %; goal >= 90 %)",
        f"the rest ending with words that name the cause: {len(named_rest)} of {len(rest)}"
        + (f" (not named: {', '.join(r['case'] for r in rest if not r.get('named'))})" if len(named_rest) < len(rest) else ""),
        f"false alarms on clean captures: {len(alarms)} of {len(clean)}" + (f" ({', '.join(alarms)})" if alarms else ""),
        f"held-out error grew: {len(grown)} of {len(results) - len(errors)}" + (f": {'; '.join(grown)}" if grown else ""),
    ]
    if errors:
        lines.append(f"errors: {', '.join(errors)}")
    loops = [r["loop_s"] for r in results.values() if "loop_s" in r]
    if loops:
        lines.append(f"loop time (diagnose --auto -o + apply): median {np.median(loops):.1f} s, max {max(loops):.1f} s")
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", nargs="+", metavar="NAME", help="only these cases (their floors are added)")
    ap.add_argument("--quick", action="store_true", help="item 1's cases and their floors only; half the revolutions")
    ap.add_argument("--seed", type=int, default=4, help="training seed (held-out: +1000)")
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--keep", metavar="DIR", help="keep every capture, calibration and output here")
    ap.add_argument("--json", metavar="FILE", help="every result, with the CLI log, as JSON")
    ap.add_argument("--list", action="store_true")
    a = ap.parse_args(argv)
    if a.list:
        for c in CASES:
            print(f"{c.name:28s} {c.kind:12s} {c.training.name:16s} {c.hidden}")
        return 0
    names = a.cases or [c.name for c in CASES if not a.quick or c.kind != "combination"]
    unknown = [n for n in names if n not in BY_NAME]
    if unknown:
        ap.error(f"unknown case(s): {', '.join(unknown)} (--list)")
    if a.quick and not a.cases:
        names = [n for n in names if BY_NAME[n].kind != "clean"]
    names += [f for f in dict.fromkeys(floor_case(BY_NAME[n]) for n in names) if f not in names]
    work = Path(a.keep) if a.keep else Path(tempfile.mkdtemp(prefix="diagnose_goal_"))
    work.mkdir(parents=True, exist_ok=True)
    opts = {"work": str(work), "quick": a.quick, "seed": a.seed, "keep": bool(a.keep)}
    t0 = time.perf_counter()
    print(f"{len(names)} cases on {a.jobs} processes; training seed {a.seed}, held-out seed "
          f"{a.seed + dc.TEST_SEED_OFFSET} (noise-free); {'quick' if a.quick else 'full'}", file=sys.stderr, flush=True)
    results = {}
    with ProcessPoolExecutor(max(1, a.jobs)) as pool:
        futs = {pool.submit(run_case, (n, opts)): n for n in names}
        for fut in as_completed(futs):
            res = fut.result()
            results[res["case"]] = res
            print(f"  {res['case']}: {res.get('verdict_after', res.get('error'))} "
                  f"({res['seconds']:.0f} s, {len(results)}/{len(names)})", file=sys.stderr, flush=True)
    results = judge({n: results[n] for n in names})
    for r in results.values():
        fl = results.get(r["floor"], {})
        r["_floor_after"] = fl.get("after")
    print(HEADER)
    for n in names:
        print(row(results[n]))
    print()
    for line in summary(results):
        print("- " + line)
    print(f"\n{time.perf_counter() - t0:.0f} s in all")
    if a.json:
        Path(a.json).write_text(json.dumps(results, indent=1, default=float))
    if not a.keep:
        shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
