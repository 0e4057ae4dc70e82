"""Diagnose's generality (issue 25's loop, fourteenth session): effects nobody designed the goal
harness for, run through ``benchmarks/diagnose_goal.py``'s machinery (the same training schemes,
held-out capture, ideal-sensor scoring, CLI loop and judging).

Every effect here is one the station's library had no model for when the goal harness was
written; the simulator (sim_devices/truth.py, ``_outside_library``) has each from its physics.
For each case: the final verdict, the words, what ``--auto`` kept, the held-out error against
the clean floor (the clean capture of the same training scheme, IMU and seed).

Usage (from the repository root):
    PYTHONPATH=$PWD python benchmarks/diagnose_triad.py [--jobs 2] [--cases NAME ... | --all] [--json F]
    PYTHONPATH=$PWD python benchmarks/diagnose_triad.py --list
"""
from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import diagnose_goal as dg    # noqa: E402

WARM = dg.WARM
TRIAD_CASES = [
    # the three of the thirteenth session's findings
    dg.Case("gyro_tilt_tempco", "x gyro axis tilts towards y by 20 arcsec/degC; 8 degC warm-up",
            {"gyroscope.axis_tilt_tempco_arcsec_per_c": [[20.0, 0.0], [0.0, 0.0], [0.0, 0.0]], **WARM},
            kind="triad", cause=(r"gyro: its misalignment towards . changes with temperature|not revealed[^;]*gyro sensing axes that tilt|gyro_misalignment_temperature",)),
    dg.Case("gyro_scale_tempco2", "gyro scale 20, -15, 25 ppm/degC^2; 8 degC warm-up",
            {"gyroscope.scale_tempco2_ppm_per_c2": [20.0, -15.0, 25.0], **WARM},
            kind="triad", cause=(r"not revealed by this capture: gyro scale factors second order in temperature", "station design --from")),
    dg.Case("gyro_scale_g", "gyro scale with the specific force: x 300 ppm/g along y, y 300 along z, "
            "z 300 along x",
            {"gyroscope.scale_g_ppm_per_g": [[0.0, 300.0, 0.0], [0.0, 0.0, 300.0], [300.0, 0.0, 0.0]]},
            kind="triad", cause=(r"not revealed by this capture: gyro scale factors that change with the specific force", "station design --from")),
    dg.Case("gyro_tilt_tempco_all", "every gyro axis tilts 20 arcsec/degC towards both others (signs mixed); 8 degC warm-up",
            {"gyroscope.axis_tilt_tempco_arcsec_per_c": [[20.0, -20.0], [20.0, 20.0], [-20.0, 20.0]], **WARM},
            kind="triad", cause=(r"gyro: its misalignment towards . changes with temperature|not revealed[^;]*gyro sensing axes that tilt|gyro_misalignment_temperature",)),
    # effects nobody designed for
    dg.Case("accel_force_products", "accelerometer cross-axis products: x 2000 ug/g^2 F_y F_z, "
            "y -1500 F_x F_z, z 1200 F_x^2",
            {"accelerometer.force_products_ug_per_g2": [[0, 0, 0, 0, 0, 2000.0], [0, 0, 0, 0, -1500.0, 0],
                                                         [1200.0, 0, 0, 0, 0, 0]]},
            kind="triad", cause=(r"accelerometer: (a term in the (product|square)|cross-axis)",)),
    dg.Case("gyro_bias_temprate", "gyro bias in dT/dt 40, -30, 35 deg/h per degC/min; 8 degC warm-up",
            {"gyroscope.bias_temprate_dph_per_c_per_min": [40.0, -30.0, 35.0], **WARM},
            kind="triad", cause=(r"gyro: its bias follows the rate of change of the temperature|temperature_bias",)),
    dg.Case("gyro_rate_cubic", "gyro cubic rate 0.02, -0.015, 0.025 ppm/(deg/s)^2; rotations at 25, 60, 100 deg/s",
            {"gyroscope.rate_cubic_ppm_per_dps2": [0.02, -0.015, 0.025]}, dg.MULTIRATE,
            kind="triad", cause=("rate",)),
    dg.Case("accel_scale_tempco2", "accelerometer scale 10, -8, 12 ppm/degC^2; 8 degC warm-up",
            {"accelerometer.scale_tempco2_ppm_per_c2": [10.0, -8.0, 12.0], **WARM},
            kind="triad", cause=(r"accelerometer: its scale factor changes with the square of the temperature|"
                                 r"not revealed by this capture: accelerometer scale factors second order",)),
    dg.Case("gyro_tilt_tempco_yz", "y gyro tilts towards z 20 arcsec/degC, z towards x -15; 8 degC warm-up",
            {"gyroscope.axis_tilt_tempco_arcsec_per_c": [[0.0, 0.0], [0.0, 20.0], [-15.0, 0.0]], **WARM},
            kind="triad", cause=(r"gyro: its misalignment towards . changes with temperature|not revealed[^;]*gyro sensing axes that tilt|gyro_misalignment_temperature",)),
]
for c in TRIAD_CASES:
    dg.CASES.append(c)
    dg.BY_NAME[c.name] = c


def main(argv=None) -> int:
    """``--all``: the goal harness' 35 cases and these together (one run, one table)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if "--all" in argv:
        argv.remove("--all")
        argv += ["--cases"] + [c.name for c in dg.CASES]
    elif "--cases" not in argv and "--list" not in argv:
        argv += ["--cases"] + [c.name for c in TRIAD_CASES]
    return dg.main(argv)


if __name__ == "__main__":
    sys.exit(main())
