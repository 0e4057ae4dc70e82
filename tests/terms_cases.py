"""Hidden effects OUTSIDE the library for the term search (issue 25 items 3-4): the library's own
effect is taken out of the registry, so the search must find the physics.  Shared by
tests/test_diagnose_terms.py and runnable as a script that prints what the loop ends with:

    PYTHONPATH=$PWD python tests/terms_cases.py [CASE ...]
"""
from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field

import yaml

sys.path.insert(0, __file__.rsplit("/", 1)[0])
import simhelpers  # noqa: E402


@dataclass
class Case:
    name: str
    hidden: dict                       # truth fields (simhelpers.hide)
    library: tuple                     # the library effects taken out (it plays "outside")
    sensor: str                        # the sensor the true term is on
    keys: tuple                        # regressor keys that are the physics (any axis)
    scheme: str = "fast"               # fast | multirate
    warmup_c: float = 2.0


CASES = [
    Case("accel_cubic", {"accel__cubic_ug_per_g3": [3000.0, -2500.0, 3500.0]}, ("accel_cubic",),
         "accel", ("fx3", "fy3", "fz3")),
    Case("gyro_scale_temperature", {"gyro__scale_tempco_ppm_per_c": [300.0, -200.0, 250.0]},
         ("scale_temperature",), "gyro", ("wxT", "wyT", "wzT"), warmup_c=8.0),
    Case("temperature_bias_quadratic", {"accel__bias_tempco2": [8.0, -6.0, 10.0],
                                        "gyro__bias_tempco2": [3.0, -2.0, 2.5]},
         ("temperature_bias_quadratic",), "both", ("T2",), warmup_c=8.0),
    Case("accel_cross_axis", {"accel__cross_coupling_ug_per_g2": [[0.0, 2000.0, -1500.0], [1800.0, 0.0, 1200.0],
                                                                  [-1600.0, 1400.0, 0.0]]},
         ("accel_cross_axis",), "accel", ("fxfy", "fxfz", "fyfz")),
    Case("gyro_rate_odd_squared", {"gyro__rate_odd_squared_ppm_per_dps": [4.0, -3.0, 5.0]},
         ("gyro_rate_nonlinearity", "gyro_scale_asymmetry"), "gyro", ("wxabswx", "wyabswy", "wzabswz"),
         scheme="multirate"),
]
BY_NAME = {c.name: c for c in CASES}

AXES = [("rotx", [1, 0, 0]), ("roty", [0, 1, 0]), ("rotz", [0, 0, 1]),
        ("rotxy", [1, 1, 0]), ("rotxz", [1, 0, 1]), ("rotyz", [0, 1, 1])]
UPS = [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1], [1, 1, 0], [1, 0, 1], [0, 1, 1]]


def scheme_doc(kind: str, dwell_s: float = 20.0) -> dict:
    """optimal9's attitudes and axes: rotations at 100 deg/s (fast), or each body axis at 25,
    60 and 100 deg/s and the diagonals at 60 (multirate)."""
    segs = [{"static": f"pos{i + 1:02d}", "up_body": u} for i, u in enumerate(UPS)]
    rates = {"fast": [(100.0, 10)], "multirate": [(25.0, 3), (60.0, 4), (100.0, 6)]}[kind]
    for name, axis in AXES:
        use = rates if (kind == "fast" or name in ("rotx", "roty", "rotz")) else [(60.0, 4)]
        for rate, n in use:
            segs.append({"rotation": f"{name}{int(rate)}", "axis_body": axis, "rate_dps": rate,
                         "rotation_s": round(360.0 * n / rate, 6)})
    return {"name": f"terms-{kind}", "defaults": {"dwell_s": dwell_s}, "segments": segs}


HELDOUT = {"name": "heldout", "defaults": {"dwell_s": 6.0}, "segments": [
    *({"static": f"test{i + 1:02d}", "up_body": u} for i, u in enumerate(
        [[1, 1, 1], [-1, -1, 1], [1, -1, -1], [-1, 1, -1], [2, -1, 0], [0, 2, -1], [-1, 0, 2], [1, 2, -2]])),
    {"rotation": "rot1m10", "axis_body": [1, -1, 0], "rate_dps": 30.0, "rotation_s": 24.0},
    {"rotation": "rot111", "axis_body": [1, 1, 1], "rate_dps": 70.0, "rotation_s": 360.0 * 2 / 70.0},
    {"rotation": "rot0m11", "axis_body": [0, -1, 1], "rate_dps": 120.0, "rotation_s": 6.0}]}


def truth_of(case: Case | None):
    from sim_devices.truth import mems_truth

    truth = mems_truth(0)
    if case is None:
        return truth
    truth.temperature.warmup_delta_c = case.warmup_c
    return simhelpers.hide(truth, **case.hidden)


def scheme_of(doc: dict, tmp):
    from station.io.scheme import load_scheme

    path = tmp / f"{doc['name']}.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return load_scheme(str(path))


def training(case, seed, tmp, out=None):
    from station.simulate import dryrun

    scheme = scheme_of(scheme_doc(case.scheme if case else "fast"), tmp)
    truth = truth_of(case)
    if out is not None:
        return truth, dryrun.record_scheme(scheme, truth, seed, out)
    return truth, dryrun.simulate_capture(scheme, truth, seed)


def run(case, seed=3, tmp=None):
    """auto.run on the training capture with the case's library effects taken out:
    (steps, final, seconds)."""
    from station.diagnose import auto
    from station.estimate import lsq

    _, capture = training(case, seed, tmp)
    t0 = time.perf_counter()
    reg = simhelpers.registry_without(*(case.library if case else ()))
    steps, final = auto.run(lsq.summarise(capture), registry=reg)
    return steps, final, time.perf_counter() - t0


if __name__ == "__main__":
    import tempfile
    from pathlib import Path

    names = sys.argv[1:] or list(BY_NAME)
    with tempfile.TemporaryDirectory() as d:
        for name in names:
            case = BY_NAME.get(name)          # "clean": no hidden effect
            seed = 3
            if name.startswith("clean"):
                seed = int(name[5:] or 3)
            steps, final, dt = run(case, seed=seed, tmp=Path(d))
            print(f"== {name}: {dt:.1f} s; added {[s.added for s in steps]}; reduced chi2 "
                  f"{(steps[0].before if steps else final).reduced_chi2:.3g} -> {final.reduced_chi2:.3g}")
            p = final.proposal
            if p is not None:
                print(f"   terms (kept={p.kept}, reduced after {p.reduced_after:.3g}, holdout "
                      f"{p.holdout_before:.1f} -> {p.holdout_after:.1f}) {p.reason}")
                for line in p.lines():
                    print("    ", line)
                for f in p.found:
                    for t, c, sep in f.aliases:
                        print(f"      alias of {f.term.name}: {t.name} (cos {c:.3f}): {sep}")
            print("   verdict:", final.verdict[:300])
