"""Diagnostics on simulated captures: false alarms on clean captures, each library effect
hidden at a MEMS-typical size found and estimated, effects outside the library reported as a
failing model, and the time of the whole loop.

Usage:
    python benchmarks/diagnose_effects.py false-alarms [--seeds 20] [--grade tactical|mems]
    python benchmarks/diagnose_effects.py effects [--seed 3]
    python benchmarks/diagnose_effects.py outside [--seed 3]
The scheme is optimal9 with rotations fast enough to excite the effects (100 deg/s, 36 s each
way, 10 revolutions), 100 Hz.
"""
import argparse
import os
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np

FAST = {"rate_dps": 100.0, "rotation_s": 36.0}


def truth_for(grade: str, seed: int = 0):
    from station.simulate import dryrun

    if grade == "mems":
        from sim_devices.truth import mems_truth
        return mems_truth(seed)
    return dryrun.load_truth(None, seed)


def one_clean(args):
    grade, seed = args
    from station.simulate import dryrun
    from station.diagnose.core import diagnose
    from station.estimate import lsq
    from station.io.scheme import load_scheme

    capture = dryrun.simulate_capture(load_scheme("optimal9", FAST), truth_for(grade), seed)
    d = diagnose(lsq.fit(lsq.summarise(capture)))
    flagged = [c.effect for c in d.candidates if c.significant]
    return seed, d.reduced_chi2, d.p_value, flagged


def false_alarms(seeds: int, grade: str):
    t0 = time.perf_counter()
    with ProcessPoolExecutor(min(os.cpu_count() or 1, 2)) as pool:
        rows = list(pool.map(one_clean, [(grade, 100 + i) for i in range(seeds)]))
    alarms = sum(1 for r in rows if r[3])
    for seed, red, p, flagged in rows:
        print(f"seed {seed}: reduced chi2 {red:.3f} (p {p:.3f}); significant: {', '.join(flagged) or 'none'}")
    print(f"{grade}: {alarms} of {seeds} clean captures with a significant candidate "
          f"(false-alarm rate {alarms / seeds:.0%}); {time.perf_counter() - t0:.0f} s")


# effect id -> (truth field path, value) at a MEMS-typical size, and how to read the truth back
HIDDEN = {
    "accel_lever_arm": ("accel.position_m", [[0.012, 0.004, -0.006], [-0.005, 0.009, 0.007], [0.006, -0.008, -0.014]]),
    "accel_nonlinearity": ("accel.nonlinearity_ug_per_g2", [300.0, -200.0, 400.0]),
    "gyro_g_sensitivity": ("gyro.g_sensitivity_dph_per_g", [[30.0, -20.0, 10.0], [15.0, 40.0, -25.0], [-10.0, 20.0, 35.0]]),
    "gyro_scale_asymmetry": ("gyro.scale_asymmetry_ppm", [400.0, -300.0, 500.0]),
    "temperature_bias": ("accel.bias_tempco", [60.0, -40.0, 50.0]),
    "time_offset": ("bench.time_offset_s", 0.005),
}


def _set(truth, path, value):
    obj = truth
    *parents, leaf = path.split(".")
    for p in parents:
        obj = getattr(obj, p)
    setattr(obj, leaf, np.asarray(value, float) if isinstance(value, list) else value)


def effects(seed: int):
    from station.simulate import dryrun
    from station.diagnose import auto
    from station.estimate import lsq
    from station.io.scheme import load_scheme

    for effect, (path, value) in HIDDEN.items():
        truth = truth_for("mems")
        _set(truth, path, value)
        if effect == "temperature_bias":
            truth.temperature.warmup_delta_c = 6.0
        if effect == "time_offset":
            truth.bench.rate_ripple_fraction, truth.bench.rate_ripple_hz = 0.2, 0.9   # a low-grade table
            truth.bench.lever_arm_m = np.zeros(3)   # centred: no tangential force from the ripple
        t0 = time.perf_counter()
        capture = dryrun.simulate_capture(load_scheme("optimal9", FAST), truth, seed)
        steps, final = auto.run(lsq.summarise(capture))
        first = steps[0].before if steps else final
        top = next((c.effect for c in first.candidates if c.significant), "none")
        print(f"{effect}: first significant candidate {top}; added {[s.added for s in steps]}; "
              f"reduced chi2 {first.reduced_chi2:.3g} -> {final.reduced_chi2:.3f}; "
              f"{time.perf_counter() - t0:.1f} s")
        for s in steps:
            print("   " + "; ".join(f"{n} {v:+.4g} ± {sg:.2g} {u}" for n, v, sg, u in s.estimate))


def outside(seed: int):
    from station.simulate import dryrun
    from station.diagnose import auto
    from station.estimate import lsq
    from station.io.scheme import load_scheme

    for label, setup in (("accelerometer cross-coupling", lambda t: _set(t, "accel.cross_coupling_ug_per_g2",
                                                                          [[0, 200, -150], [180, 0, 120], [-160, 140, 0]])),
                         ("table wobble", lambda t: _set(t, "bench.wobble_arcsec", 60.0))):
        truth = truth_for("mems")
        setup(truth)
        capture = dryrun.simulate_capture(load_scheme("optimal9", FAST), truth, seed)
        steps, final = auto.run(lsq.summarise(capture))
        print(f"{label}: added {[s.added for s in steps]}; final reduced chi2 {final.reduced_chi2:.3g}")
        print(f"   verdict: {final.verdict}")
        for f in final.failures:
            print(f"   where: {f}")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("what", choices=("false-alarms", "effects", "outside"))
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--seed", type=int, default=3)
    ap.add_argument("--grade", choices=("tactical", "mems"), default="mems")
    a = ap.parse_args()
    if a.what == "false-alarms":
        false_alarms(a.seeds, a.grade)
    elif a.what == "effects":
        effects(a.seed)
    else:
        outside(a.seed)


if __name__ == "__main__":
    main()
