"""Issue 25 (item 1 rest, item 5): what `diagnose --auto` ends with on the bench and time effects
added to the library -- a gyro bias step, a table encoder scale error, a mounting offset per
rotation axis -- and on a table vibrating once per revolution (named, not compensated), against
the clean floor: reduced chi2 before/after, the held-out error of the calibration the loop ends
with (tests/effect_recovery.held_out_error: noise-free samples the truth gives at random
attitudes and rates up to 150 deg/s, compensated), the loop's time; and the false alarms of the
new effects on clean captures at 10-300 deg/s, whole and partial revolutions.

Usage (from the repository root):
    PYTHONPATH=$PWD:$PWD/tests python benchmarks/diagnose_effects_25b.py [CASE ...]
Scheme: optimal9, 6 s statics, 36 s rotations at 100 deg/s (ten revolutions each way), 100 Hz.
"""
import sys
import time


import simhelpers
from effect_recovery import held_out_error

SHORT = {"rate_dps": 100.0, "rotation_s": 36.0, "dwell_s": 6.0}
CASES = {
    "clean": {},
    "gyro_bias_step": dict(gyro__bias_step=[0.0, 0.0, 50.0], gyro__bias_step_time_s=400.0),
    "accel_bias_step": dict(accel__bias_step=[0.0, 1500.0, 0.0], accel__bias_step_time_s=400.0),
    "table_encoder_scale": dict(bench__encoder_scale_error_ppm=300.0),
    "rotation_axis_offsets": dict(bench__axis_offsets_m=[[0.0, 0.0, 0.0], [0.0, 0.0, 0.02], [0.015, 0.0, 0.0]]),
    "vibration_once_per_rev": dict(bench__vibration_mg=[1.0, 0.5, 0.5]),
}
CLEAN_RATES = [(10.0, 36.0), (10.0, 20.0), (100.0, 36.0), (100.0, 2.5), (300.0, 12.0), (300.0, 0.8)]


def loop(name, seed=4):
    from station.diagnose import auto
    from station.estimate import lsq

    truth, cap = simhelpers.mems_capture(seed, "optimal9", SHORT, **CASES[name])
    s = lsq.summarise(cap)
    t0 = time.perf_counter()
    steps, final = auto.run(s)
    dt = time.perf_counter() - t0
    first = steps[0].before if steps else final
    before, after = held_out_error(first.result, truth), held_out_error(final.result, truth)
    print(f"{name}: added {[st.added for st in steps]}; reduced chi2 {first.reduced_chi2:.3g} -> "
          f"{final.reduced_chi2:.3g}; held-out accel {before.accel_ug:.1f} -> {after.accel_ug:.1f} µg, gyro "
          f"{before.gyro_ppm:.1f} -> {after.gyro_ppm:.1f} ppm; loop {dt:.1f} s")
    for st in steps:
        for c in st.caveats[:2]:
            print("    ", c[:220])
    for f in final.failures[:2]:
        print("   where:", f[:220])
    for line in final.account:
        print("   account:", line[:220])


def clean_alarms(seeds=(3, 4, 5)):
    from station.diagnose.core import diagnose, fit_fails
    from station.estimate import lsq

    new = ("bias_step", "table_encoder_scale", "rotation_axis_offsets")
    for rate, seconds in CLEAN_RATES:
        alarms = 0
        for seed in seeds:
            _, cap = simhelpers.mems_capture(seed, "optimal9", {"rate_dps": rate, "rotation_s": seconds,
                                                                "dwell_s": 6.0})
            d = diagnose(lsq.fit(lsq.summarise(cap)))
            flagged = [c.effect for c in d.candidates if c.effect in new and c.significant]
            words = [f for f in d.failures if "once per revolution along" in f or "a step in time" in f]
            alarms += bool(flagged or words or fit_fails(d.result))
        print(f"clean {rate:g} °/s x {seconds:g} s ({rate * seconds:g}°): {alarms} alarms in {len(seeds)} seeds")


if __name__ == "__main__":
    names = sys.argv[1:] or [*CASES, "clean-alarms"]
    for n in names:
        if n == "clean-alarms":
            clean_alarms()
        else:
            loop(n)
