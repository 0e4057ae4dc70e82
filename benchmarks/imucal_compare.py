"""station against imucal on imucal's own example Ferraris session (docs/imucal-comparison.md).

imucal is NOT a station dependency.  To run the imucal side, install it beside station, e.g. in
a separate virtual environment that can also see station:

    python -m venv --system-site-packages /tmp/imucal-venv
    /tmp/imucal-venv/bin/pip install imucal          # pulls pandas
    /tmp/imucal-venv/bin/python benchmarks/imucal_compare.py

Without imucal the script still runs (plain ``python benchmarks/imucal_compare.py``) and compares
with the figures published in shared/data/README.md instead.

What it does:
 1. imports the session with ``station import imucal`` (102.4 Hz) into a temporary capture;
 2. asks station to estimate from it (method auto, then zhang2010) and prints its verdict;
 3. runs imucal's FerrarisCalibration (grav 9.81, expected angle -360 deg, its defaults) on the
    original CSV and on the data read back from station's capture, and checks they agree (the
    import keeps every number imucal uses);
 4. prints imucal's parameters next to the published ones, with the gyro gain at 102.4 Hz and at
    204.8 Hz (the rate imucal's own example passes for this file).
"""
from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from station.io.capture import read_capture  # noqa: E402
from station.core.errors import UserError  # noqa: E402
from station.estimate import estimate_capture  # noqa: E402
from station.io.importers import imucal as importer  # noqa: E402

DATA = ROOT.parent / "shared" / "data" / "imucal"
SESSION = DATA / "example_ferraris_session.csv"
SECTIONS = DATA / "example_ferraris_session_list.json"
RATE_HZ = 102.4
PUBLISHED = {  # shared/data/README.md: imucal's published example, "near" these values
    "accel gain": [0.997, 1.002, 1.023],
    "accel bias m/s^2": [0.54, -0.62, 0.40],
    "gyro bias deg/s": [-0.60, -0.37, 0.06],
}


def regions_from_capture(capture):
    """imucal's 18 region arrays from a station capture (section name -> segment)."""
    out = {}
    for seg in capture.segments:
        out[f"acc_{seg.name}"] = seg.data.accel
        out[f"gyr_{seg.name}"] = seg.data.gyro
    return out


def run_imucal(regions: dict, rate_hz: float):
    from imucal import FerrarisCalibration
    from imucal.ferraris_calibration import FerrarisSignalRegions

    cal = FerrarisCalibration()               # grav=9.81, expected_angle=-360: imucal's defaults
    return cal.compute(FerrarisSignalRegions(**regions), sampling_rate_hz=rate_hz,
                       from_acc_unit="m/s^2", from_gyr_unit="deg/s")


def regions_from_csv():
    import pandas as pd
    from imucal import ferraris_regions_from_section_list

    data = pd.read_csv(SESSION, header=0, index_col=0)
    section_list = pd.read_json(SECTIONS).T
    return ferraris_regions_from_section_list(data, section_list)._asdict()


def fmt(v, digits=4):
    return "[" + ", ".join(f"{x:+.{digits}f}" for x in np.ravel(v)) + "]"


def main() -> int:
    with tempfile.TemporaryDirectory() as tmp:
        path = importer.import_imucal(SESSION, Path(tmp) / "capture", rate_hz=RATE_HZ, sections_path=SECTIONS)
        capture = read_capture(path)
        print(f"imported {SESSION.name}: {len(capture.segments)} segments, "
              f"gyro kinematic correlation {capture.extra['import']['gyro_kinematic_correlation']:+.2f}")
        for seg in capture.complete("rotation"):
            print(f"  {seg.name}: rate_dps {seg.rate_dps:+.1f} (direction only), no angle_deg")

        print("\nstation estimate:")
        for method in ("auto", "zhang2010", "fourier-high"):
            try:
                cal, _, prov = estimate_capture(path, method)
                what = "with the gyros" if cal.fit.get("gyro_calibrated", True) else "accelerometer-only calibration"
                print(f"  {method}: estimated ({prov['method']}, {what})")
            except UserError as e:
                print(f"  {method}: refused: {e}")

        # with imucal's own assumption made explicit: each hand turn is exactly 360 deg, each pose
        # within 1 deg of axis up or down (a prior, not a certainty)
        path360 = importer.import_imucal(SESSION, Path(tmp) / "capture360", rate_hz=RATE_HZ,
                                         sections_path=SECTIONS, turn_deg=360.0, placement_deg=1.0)
        cal, _, _ = estimate_capture(path360, "auto")
        p = {n: (v, cal.sigma.get(n)) for n, v, _ in cal.parameters()}
        print("\nstation estimate --method lsq after `station import imucal --turn-deg 360`"
              f" ({cal.fit['dof']} degrees of freedom, reduced chi2 {cal.fit['reduced_chi2']:.2f}):")
        result = {}
        for label, key, names, k in (("accel gain", "K_a", [f"accel_scale_{a}" for a in "xyz"], 1.0),
                                     ("accel bias m/s^2", "b_a", [f"accel_bias_{a}" for a in "xyz"], 9.80665e-6),
                                     ("gyro gain", "K_g", [f"gyro_scale_{a}" for a in "xyz"], 1.0),
                                     ("gyro bias deg/s", "b_g", [f"gyro_bias_{a}" for a in "xyz"], 1 / 3600)):
            if any(None in p.get(n, (None, None)) for n in names):     # not determined: not written
                print(f"  {label:18s} not written")
                continue
            print(f"  {label:18s} " + ", ".join(f"{p[n][0] * k:+.4f} ± {p[n][1] * k:.4f}" for n in names))
            result[key] = [p[n][0] * k for n in names]
        for note in cal.fit.get("notes", []):
            if note.startswith("accelerometer-only"):
                print(f"  note: {note}")
        print("  " + json.dumps({k: np.round(v, 4).tolist() for k, v in result.items()}))

        try:
            import imucal  # noqa: F401
        except ImportError:
            print("\nimucal is not installed here: published figures (shared/data/README.md) only:")
            for k, v in PUBLISHED.items():
                print(f"  {k:18s} {fmt(v, 3)}")
            return 0

        mine = regions_from_capture(capture)
        theirs = regions_from_csv()
        worst = max(float(np.max(np.abs(np.asarray(theirs[k]) - mine[k]))) for k in theirs)
        print(f"\nimucal regions from the original CSV vs from station's capture: largest difference {worst:.3g}")
        a = run_imucal(theirs, RATE_HZ)
        b = run_imucal(mine, RATE_HZ)
        same = all(np.allclose(getattr(a, k), getattr(b, k), rtol=1e-9, atol=1e-12)
                   for k in ("K_a", "R_a", "b_a", "K_g", "R_g", "K_ga", "b_g"))
        print(f"imucal result identical on both inputs: {same}")
        slow = run_imucal(theirs, 204.8)
        print("\nimucal FerrarisCalibration on this session (grav 9.81, expected angle -360 deg):")
        print(f"  accel gain K_a         {fmt(np.diag(a.K_a))}   published {fmt(PUBLISHED['accel gain'], 3)}")
        print(f"  accel bias b_a m/s^2   {fmt(a.b_a)}   published {fmt(PUBLISHED['accel bias m/s^2'], 2)}")
        print(f"  gyro bias b_g deg/s    {fmt(a.b_g)}   published {fmt(PUBLISHED['gyro bias deg/s'], 2)}")
        print(f"  gyro gain K_g @102.4Hz {fmt(np.diag(a.K_g))}")
        print(f"  gyro gain K_g @204.8Hz {fmt(np.diag(slow.K_g))}   (the rate imucal's example passes)")
        print(f"  accel axes R_a, off-diagonal deg {fmt(np.degrees(a.R_a[~np.eye(3, dtype=bool)]), 2)}")
        print(f"  gyro axes R_g, off-diagonal deg  {fmt(np.degrees(a.R_g[~np.eye(3, dtype=bool)]), 2)}")
        # imucal's bias keeps only the diagonal of (U_p + U_a)/2: the calibrated static readings
        # are left off the axis imucal assumes by the angles below, and off 9.81 in magnitude
        print("  static attitudes after imucal's calibration: angle off the assumed axis, |f| - 9.81:")
        for seg in capture.complete("static"):
            f = np.linalg.solve(a.K_a @ a.R_a, seg.data.accel.mean(axis=0) - a.b_a)
            off = np.degrees(np.arccos(min(1.0, abs(f @ seg.up_body) / np.linalg.norm(f))))
            print(f"    {seg.name}: {off:.2f} deg, {np.linalg.norm(f) - 9.81:+.4f} m/s^2")
        print("\n" + json.dumps({"K_a": np.diag(a.K_a).round(4).tolist(), "b_a": np.round(a.b_a, 4).tolist(),
                                 "b_g": np.round(a.b_g, 4).tolist(), "K_g_102.4": np.diag(a.K_g).round(4).tolist(),
                                 "K_g_204.8": np.diag(slow.K_g).round(4).tolist()}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
