"""Is the emitted effect right as written? Effects the station's library has NO model for, hidden
in the simulated IMU (sim_devices/truth.py: written from physics, independently of the term
search), one at a time and in pairs; the loop run as a user runs it (issue 25 items 3-4).

For every case the script

1. records a TRAINING capture (tests/terms_cases.py's scheme: optimal9's nine attitudes, 20 s
   each, and its six axes at 100 deg/s, or each body axis at 25, 60 and 100 deg/s where the case
   needs rates) and a HELD-OUT TEST capture of the same IMU, noise off (other attitudes; rotations
   at 30, 70 and 120 deg/s about other axes), and the same test motion with an ideal sensor (the
   truth);
2. runs, each a whole process as a user would:
       station diagnose TRAIN --auto --json --emit-effect found.py
       python found.py                                          (the plugin's own self-test)
       station estimate TRAIN --add E ... --add found.py:DiscoveredTerms -o auto.yaml
       station apply auto.yaml TEST.csv --plugin found.py:DiscoveredTerms -o OUT.csv
   with the emitted file UNCHANGED (E: the library effects --auto added), and the same without
   any addition (base.yaml) for the error before;
3. scores
   - loads and fits: the plugin's self-test exits 0 and `estimate --add` exits 0 (its verdict
     passes; exit 3 is a fit that still fails);
   - the physical term: every true term found on its sensor, axis and regressor, and no term on
     a sensor that has none;
   - held-out error (RMS compensated - true, accelerometer in mg and gyro in deg/h) within 2x of
     the clean floor (a clean capture's calibration scored the same way);
   - words: the diagnosis names each true term with its natural unit (ppm/degC, ug/g^2 ...);
   "right as written" = all four.

A case with nothing to emit (a clean capture) must exit 0 with one line saying so.

Usage:
    PYTHONPATH=$PWD python benchmarks/emit_cases.py [CASE ...] [--keep DIR] [--json FILE]
    PYTHONPATH=$PWD python benchmarks/emit_cases.py --list
"""
from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "benchmarks"))
import diagnose_cases as dc  # noqa: E402
import terms_cases as tc  # noqa: E402

FLOOR_FACTOR = 2.0        # the goal: the held-out error at the clean floor within 2x


@dataclass
class Case:
    name: str
    physics: str                       # in words, with sizes
    hidden: dict                       # truth fields (simhelpers.hide: section__field)
    terms: dict                        # (sensor, axis, regressor key) -> natural unit the words must give
    scheme: str = "fast"               # tests/terms_cases.scheme_doc: fast | multirate
    temperature: dict = field(default_factory=dict)     # TemperatureTruth fields
    pair: bool = False


# a warm-up that peaks and cools (8 degC with a 300 s time constant, -30 degC/h drift: the
# temperature rises for ~6 min, then falls): dT/dt is not a function of T, so a bias in dT/dt can be
# told from one in T (on a bare exponential warm-up dT/dt = (T_end - T) / tau exactly)
PEAK = {"warmup_delta_c": 8.0, "warmup_time_constant_s": 300.0, "drift_c_per_h": -30.0}
# a 10 degC warm-up (time constant 900 s): the repeated scheme spans ~8 degC of it; HOT: 20 degC
WARM = {"warmup_delta_c": 10.0}
HOT = {"warmup_delta_c": 20.0}

CASES = [
    Case("gyro_cubic_x", "x gyro: cubic rate nonlinearity 0.02 ppm/(deg/s)^2 (200 ppm at 100 deg/s)",
         {"gyro__rate_cubic_ppm_per_dps2": [0.02, 0.0, 0.0]}, {("gyro", 0, "wx3"): "ppm/(deg/s)^2"},
         scheme="wide"),
    Case("gyro_scale_g", "x gyro: scale changes with the force along y, 800 ppm/g",
         {"gyro__scale_g_ppm_per_g": [[0.0, 800.0, 0.0], [0, 0, 0], [0, 0, 0]]},
         {("gyro", 0, "wxfy"): "ppm/g"}),
    Case("accel_tilt_temperature", "x accelerometer axis tilts towards y by 20 arcsec/degC (10 degC warm-up)",
         {"accel__axis_tilt_tempco_arcsec_per_c": [[20.0, 0.0], [0, 0], [0, 0]]},
         {("accel", 0, "fyT"): "arcsec/degC"}, scheme="fast+repeat", temperature=WARM),
    Case("accel_other_axes_product", "x accelerometer += 2000 ug/g^2 F_y F_z; y += -1500 ug/g^2 F_x F_z",
         {"accel__force_products_ug_per_g2": [[0, 0, 0, 0, 0, 2000.0], [0, 0, 0, 0, -1500.0, 0], [0] * 6]},
         {("accel", 0, "fyfz"): "ug/g^2", ("accel", 1, "fxfz"): "ug/g^2"}),
    Case("gyro_bias_temperature_rate", "gyro bias follows dT/dt: 40, -30, 35 deg/h per degC/min",
         {"gyro__bias_temprate_per_c_per_min": [40.0, -30.0, 35.0]},
         {("gyro", i, "temprate"): "deg/h per degC/min" for i in range(3)}, temperature=PEAK),
    Case("accel_bias_temperature_rate", "accelerometer bias follows dT/dt: 400, -300, 350 ug per degC/min",
         {"accel__bias_temprate_per_c_per_min": [400.0, -300.0, 350.0]},
         {("accel", i, "temprate"): "ug per degC/min" for i in range(3)}, temperature=PEAK),
    Case("gyro_scale_temperature2", "gyro scale second order in temperature: 4, -3, 5 ppm/degC^2 (20 degC warm-up)",
         {"gyro__scale_tempco2_ppm_per_c2": [4.0, -3.0, 5.0]},
         {("gyro", i, f"w{'xyz'[i]}T2"): "ppm/degC^2" for i in range(3)}, scheme="fast+repeat", temperature=HOT),
    Case("accel_scale_temperature2", "accelerometer scale second order in temperature: 5, -4, 6 ppm/degC^2 (20 degC warm-up)",
         {"accel__scale_tempco2_ppm_per_c2": [5.0, -4.0, 6.0]},
         {("accel", i, f"f{'xyz'[i]}T2"): "ppm/degC^2" for i in range(3)}, scheme="fast+repeat", temperature=HOT),
    Case("accel_x_fy_squared", "x accelerometer += 2500 ug/g^2 F_y^2 (the square of another axis' force)",
         {"accel__force_products_ug_per_g2": [[0, 2500.0, 0, 0, 0, 0], [0] * 6, [0] * 6]},
         {("accel", 0, "fyfy"): "ug/g^2"}),
    # pairs
    Case("pair_gyro_cubic_and_scale_g", "the x gyro's cubic (0.02 ppm/(deg/s)^2) and its scale with F_y (800 ppm/g)",
         {"gyro__rate_cubic_ppm_per_dps2": [0.02, 0.0, 0.0],
          "gyro__scale_g_ppm_per_g": [[0.0, 800.0, 0.0], [0, 0, 0], [0, 0, 0]]},
         {("gyro", 0, "wx3"): "ppm/(deg/s)^2", ("gyro", 0, "wxfy"): "ppm/g"}, scheme="wide", pair=True),
    Case("pair_accel_product_and_gyro_scale_t2", "x accel F_y F_z 2000 ug/g^2 and gyro scale 4, -3, 5 ppm/degC^2",
         {"accel__force_products_ug_per_g2": [[0, 0, 0, 0, 0, 2000.0], [0] * 6, [0] * 6],
          "gyro__scale_tempco2_ppm_per_c2": [4.0, -3.0, 5.0]},
         {("accel", 0, "fyfz"): "ug/g^2", **{("gyro", i, f"w{'xyz'[i]}T2"): "ppm/degC^2" for i in range(3)}},
         scheme="fast+repeat", temperature=HOT, pair=True),
    Case("pair_accel_tilt_and_gyro_temperature_rate", "x accel tilt 20 arcsec/degC and gyro bias in dT/dt",
         {"accel__axis_tilt_tempco_arcsec_per_c": [[20.0, 0.0], [0, 0], [0, 0]],
          "gyro__bias_temprate_per_c_per_min": [40.0, -30.0, 35.0]},
         {("accel", 0, "fyT"): "arcsec/degC", **{("gyro", i, "temprate"): "deg/h per degC/min" for i in range(3)}},
         scheme="fast+repeat", temperature=PEAK, pair=True),
]
BY_NAME = {c.name: c for c in CASES}


def scheme_doc(kind: str) -> dict:
    """tests/terms_cases.py's training scheme; "KIND+repeat": all of it again after it, later in
    the warm-up (at another temperature): what separates a term in temperature from the base
    model's constant one (a static's free attitude absorbs an axis tilt; the rotations measure it,
    and only rotations at two temperatures see it change)."""
    base, _, repeat = kind.partition("+")
    doc = tc.scheme_doc("multirate" if base == "wide" else base)
    if base == "wide":        # the body axes at 30, 100 and 300 deg/s (a cubic against w|w| and w²)
        doc["name"] = "terms-wide"
        rates = {25: (30.0, 3), 60: (100.0, 6), 100: (300.0, 10)}
        for seg in doc["segments"]:
            if "rotation" in seg and seg["rotation"][:4] in ("rotx", "roty", "rotz") and seg["rotation"][4:].isdigit():
                rate, n = rates[int(seg["rotation"][4:])]
                seg.update(rotation=f"{seg['rotation'][:4]}{int(rate)}", rate_dps=rate, rotation_s=round(360.0 * n / rate, 6))
    if repeat:
        doc["name"] += "-repeat"
        again = []
        for seg in doc["segments"]:
            seg = dict(seg)
            key = "static" if "static" in seg else "rotation"
            seg[key] = f"{seg[key]}_again"
            again.append(seg)
        doc["segments"] += again
    return doc


def truth_of(case: Case | None):
    import simhelpers
    from sim_devices.truth import mems_truth

    truth = mems_truth(0)
    if case is None:
        return truth
    for k, v in case.temperature.items():
        setattr(truth.temperature, k, v)
    return simhelpers.hide(truth, **case.hidden)


def _cli(args, cwd, timeout=600):
    t0 = time.perf_counter()
    p = subprocess.run([sys.executable, "-m", "station.cli", *args], cwd=cwd, capture_output=True, text=True,
                       timeout=timeout)
    return p.returncode, p.stdout, p.stderr, time.perf_counter() - t0


def _scored(cal, work, both, names, frames, true, C_pb, extra=()):
    out = work / (Path(cal).stem + "_test.csv")
    rc, _, err, _ = _cli(["apply", str(cal), str(both), "-o", str(out), "--force", *extra], work)
    if rc != 0:
        raise RuntimeError(f"station apply {' '.join(extra)}: exit {rc}: {err.strip()[-300:]}")
    comp = dc.read_csv(out)
    return dc.score(dc.split_segments(comp, names, frames), true, C_pb, 100.0)


def _estimate_and_score(res, tag, train, adds, extra, work, both, names, frames, true, C_pb):
    """estimate --add ... (exit 0: its verdict passes; 3: the fit fails, estimated again with
    --accept-poor-fit to be scored) and apply on the held-out capture; res["fits_" + tag]."""
    if not adds:
        return res["before"]
    out = work / f"{tag}.yaml"
    rc, _, err, _ = _cli(["estimate", str(train), *adds, "-o", str(out)], work)
    res[f"fits_{tag}"] = rc == 0
    if rc == 3:
        res[f"estimate_{tag}"] = err.strip()[-300:]
        rc, _, err, _ = _cli(["estimate", str(train), *adds, "-o", str(out), "--accept-poor-fit"], work)
    if rc != 0:
        raise RuntimeError(f"estimate {' '.join(adds)}: exit {rc}: {err.strip()[-300:]}")
    return _scored(out, work, both, names, frames, true, C_pb, extra)


def found_terms(plugin_text: str) -> set:
    """(sensor, axis, regressor key) of the emitted plugin's parameters (sensor_axis_key)."""
    out = set()
    for name in re.findall(r'Param\("(\w+)"', plugin_text or ""):
        sensor, axis, key = name.split("_", 2)
        out.add((sensor, "xyz".index(axis), key))
    return out


def run_case(case: Case | None, work: Path, seed: int = 3) -> dict:
    from sim_devices.truth import Truth

    from station.simulate import dryrun

    work.mkdir(parents=True, exist_ok=True)
    res = {"case": case.name if case else "clean", "physics": case.physics if case else "no hidden effect"}
    t_start = time.perf_counter()
    try:
        truth = truth_of(case)
        scheme = tc.scheme_of(scheme_doc(case.scheme if case else "fast"), work)
        # the truth's reference temperature at the calibration's T_ref (the mean temperature of the
        # training statics): a sensing axis that tilts with temperature then defines the same frame
        # p in the truth and in the calibration (the accelerometer x axis is the frame's x axis);
        # otherwise the score would count a constant rotation of the frame (20 arcsec/degC x 5 degC
        # = 100 arcsec, 0.5 mg) that no calibration can know.  Only constant offsets of the biases
        # change with it: the same IMU, described at another temperature.
        probe = dryrun.simulate_capture(scheme, truth, seed)
        truth.temperature.reference_c = float(np.mean([np.mean(sg.data.temp) for sg in probe.segments
                                                       if sg.kind == "static"]))
        doc = truth.to_yaml_dict()
        (work / "truth.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
        truth = Truth.from_yaml(work / "truth.yaml")           # validated like a user's file
        train = dryrun.record_scheme(scheme, truth, seed, work / "train")
        test_doc = dc.noise_free(doc)
        held = tc.scheme_of(tc.HELDOUT, work)
        test = dryrun.record_scheme(held, Truth.from_dict(test_doc, "test"), seed + 1000, work / "test")
        true = {s.name: (s.kind, s.data.t, s.data.accel, s.data.gyro, s.rate_dps)
                for s in dryrun.simulate_capture(held, Truth.from_dict(dc.ideal_sensor(test_doc), "ideal"),
                                                 seed + 1000).segments}
        C_pb = truth.paper_parameters()["C_pb"]
        names = list(true)
        frames = [dc.read_csv(test / f"{n}.csv") for n in names]
        both = dc.join_segments(frames, work / "test_all.csv")

        plugin = work / "found.py"
        t0 = time.perf_counter()
        rc, out, err, dt = _cli(["diagnose", str(train), "--auto", "--json", "--emit-effect", str(plugin)], work)
        res["diagnose_s"] = round(dt, 1)
        res["diagnose_rc"] = rc
        d = json.loads(out) if rc == 0 else {}
        res["stderr"] = err.strip().splitlines()
        steps = d.get("steps", [])
        res["added"] = [s["added"] for s in steps]
        res["reduced_after"] = d.get("reduced_chi2")
        res["verdict"] = d.get("verdict", err.strip()[-300:])
        text = plugin.read_text() if plugin.exists() else None
        res["plugin"] = text
        res["found"] = sorted(found_terms(text))
        # the plugin's own self-test, as its docstring tells the user
        if text is not None:
            rc_t, _, err_t = (lambda p: (p.returncode, p.stdout, p.stderr))(
                subprocess.run([sys.executable, str(plugin)], cwd=work, capture_output=True, text=True, timeout=120))
            res["selftest"] = rc_t == 0
            if rc_t:
                res["selftest_error"] = err_t.strip()[-300:]
        rc, _, err, _ = _cli(["estimate", str(train), "-o", str(work / "base.yaml"), "--accept-poor-fit"], work)
        if rc != 0:
            raise RuntimeError(f"estimate (base): {err.strip()[-300:]}")
        res["before"] = _scored(work / "base.yaml", work, both, names, frames, true, C_pb)
        adds, extra = [], []
        for a in res["added"]:
            if a == "discovered_terms":
                adds += ["--add", f"{plugin}:DiscoveredTerms"]
                extra = ["--plugin", f"{plugin}:DiscoveredTerms"]
            else:
                adds += ["--add", a]
        # what the loop ends with: --auto's additions (the emitted plugin among them when --auto kept it)
        res["after"] = _estimate_and_score(res, "auto", train, adds, extra, work, both, names, frames, true, C_pb)
        if text is not None and not extra:
            # emitted but not carried by --auto (NOT kept): the plugin as a user would still try it
            res["with_plugin"] = _estimate_and_score(
                res, "plugin", train, adds + ["--add", f"{plugin}:DiscoveredTerms"],
                ["--plugin", f"{plugin}:DiscoveredTerms"], work, both, names, frames, true, C_pb)
        res["loop_s"] = round(time.perf_counter() - t0, 1)
    except Exception as exc:         # one failing case must not stop the others: report it
        res["error"] = f"{type(exc).__name__}: {exc}"
    res["seconds"] = round(time.perf_counter() - t_start, 1)
    return res


def judge(case: Case, r: dict, floor: dict) -> dict:
    """The four scores and "right as written"."""
    truth = set(case.terms)
    got = set(tuple(x) for x in r.get("found", []))
    sensors = {s for s, _, _ in truth}
    s = {}
    used = "with_plugin" if "with_plugin" in r else "after"
    s["loads_fits"] = (bool(r.get("plugin")) and bool(r.get("selftest"))
                       and bool(r.get("fits_plugin" if used == "with_plugin" else "fits_auto")))
    s["physical_term"] = truth <= got and all(x[0] in sensors for x in got)
    a = r.get(used)
    s["at_floor"] = (a is not None and a["accel_mg"] <= FLOOR_FACTOR * floor["accel_mg"]
                     and a["gyro_dph"] <= FLOOR_FACTOR * floor["gyro_dph"])
    verdict = r.get("verdict") or ""
    s["words"] = all(unit in verdict for unit in case.terms.values()) and "outside the library" in verdict
    s["right"] = all(s.values())
    e = r.get("after")          # what --auto ends with (GREW thresholds of diagnose_cases.py)
    s["never_grew"] = (e is not None and r.get("before") is not None
                       and e["accel_mg"] <= r["before"]["accel_mg"] * 1.05 + 0.002
                       and e["gyro_dph"] <= r["before"]["gyro_dph"] * 1.05 + 0.1)
    return s


def _yn(v):
    return "yes" if v else "**no**"


def table(rows, floor) -> str:
    lines = [f"clean floor (held-out, a clean capture's calibration): accel {floor['accel_mg']:.4f} mg, "
             f"gyro {floor['gyro_dph']:.2f} deg/h", "",
             "| case | hidden (not in the library) | found (emitted) | loads + fits | physical term | "
             "held-out accel mg before -> after --auto | gyro deg/h before -> after | within 2x floor | words in units | "
             "right as written | loop s |",
             "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for case, r, s in rows:
        b, a = r.get("before") or {}, r.get("after") or {}
        found = ", ".join(f"{sn} {'xyz'[ax]} {k}" for sn, ax, k in r.get("found", [])) or "(none)"
        lib = [x for x in r.get("added", []) if x != "discovered_terms"]
        if lib:
            found += f"; library: {', '.join(lib)}"
        err = f" ({r['error']})" if "error" in r else ""
        w = r.get("with_plugin")
        if w is not None:
            found += " (emitted NOT kept; with it: " + f"{w['accel_mg']:.4f} mg, {w['gyro_dph']:.2f} deg/h)"
        lines.append(
            f"| {case.name} | {case.physics} | {found}{err} | {_yn(s['loads_fits'])} | {_yn(s['physical_term'])} | "
            f"{b.get('accel_mg', float('nan')):.4f} -> {a.get('accel_mg', float('nan')):.4f} | "
            f"{b.get('gyro_dph', float('nan')):.2f} -> {a.get('gyro_dph', float('nan')):.2f} | "
            f"{_yn(s['at_floor'])} | {_yn(s['words'])} | {_yn(s['right'])} | {r.get('loop_s', float('nan'))} |")
    k = sum(s["right"] for _, _, s in rows)
    lines += ["", f"right as written: {k} of {len(rows)}"]
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("cases", nargs="*")
    ap.add_argument("--list", action="store_true")
    ap.add_argument("--keep", metavar="DIR")
    ap.add_argument("--json", metavar="FILE")
    ap.add_argument("--seed", type=int, default=3)
    a = ap.parse_args(argv)
    if a.list:
        for c in CASES:
            print(f"{c.name}: {c.physics}")
        return 0
    cases = [BY_NAME[n] for n in a.cases] if a.cases else CASES
    root = Path(a.keep) if a.keep else Path(tempfile.mkdtemp(prefix="emit_cases_"))
    try:
        clean = run_case(None, root / "clean", a.seed)
        if "error" in clean:
            print("clean:", clean["error"])
            return 1
        floor = clean["before"]
        nothing = [line for line in clean["stderr"] if "nothing to emit" in line]
        print(f"clean capture: diagnose exit {clean['diagnose_rc']}, added {clean['added']}, "
              f"{len(nothing)} line(s) 'nothing to emit', plugin written: {clean['plugin'] is not None}", flush=True)
        rows = []
        for case in cases:
            r = run_case(case, root / case.name, a.seed)
            s = judge(case, r, floor)
            rows.append((case, r, s))
            print(f"{case.name}: found {r.get('found')} added {r.get('added')} scores {s} "
                  f"before {r.get('before')} after {r.get('after')} with_plugin {r.get('with_plugin')} "
                  f"{r.get('error', '')} {r.get('estimate_auto', '')} {r.get('estimate_plugin', '')}", flush=True)
            print("   verdict:", (r.get("verdict") or "")[:600], flush=True)
        print()
        print(table(rows, floor))
        if a.json:
            Path(a.json).write_text(json.dumps({"floor": floor, "clean": {k: v for k, v in clean.items() if k != "plugin"},
                                                "rows": [{"case": c.name, "scores": s, **{k: v for k, v in r.items()}}
                                                         for c, r, s in rows]}, indent=1, default=str))
    finally:
        if not a.keep:
            shutil.rmtree(root, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
