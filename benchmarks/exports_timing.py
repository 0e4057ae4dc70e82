"""Wall time of the result commands (export to every format, noise, history, diff, report) on a
full 100 Hz optimal9 dry-run capture (the paper's 100 s statics and 180 s rotations: 306,000
samples), each in a fresh process as a user runs it, and every export read back by its own tool
where that tool is installed here (imucal; the C compiler for the header; json; yaml).

Usage:  python benchmarks/exports_timing.py [--repeat 3]
"""
import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

from station.io.scheme import load_scheme
from station.simulate import dryrun


def timed(cmd, repeat, env):
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        subprocess.run(cmd, check=True, capture_output=True, env=env)
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=3)
    a = ap.parse_args()
    station = shutil.which("station") or sys.exit("install the project first (pip install -e .)")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        env = {**os.environ, "STATION_HISTORY_DIR": str(tmp / "store")}
        cap = dryrun.record_scheme(load_scheme("optimal9"), dryrun.load_truth(None, 1), 1, tmp / "cap")
        subprocess.run([station, "estimate", str(cap)], check=True, capture_output=True, env=env)
        cal = cap / "calibration.yaml"
        rows = [("station estimate (for reference)", timed([station, "estimate", str(cap), "-o", str(tmp / "e.yaml")], a.repeat, env))]
        rows.append(("station noise CAPTURE --cal CAL", timed([station, "noise", str(cap), "--cal", str(cal)], a.repeat, env)))
        readback = {}
        for fmt, name in (("imucal", "cal.json"), ("imu_tk", "imu.calib"), ("kalibr", "imu.yaml"),
                          ("ros", "imu_calib.yaml"), ("c", "station.h"), ("json", "plain.json")):
            rows.append((f"station export --to {fmt}",
                         timed([station, "export", str(cal), "--to", fmt, "-o", str(tmp / name)], a.repeat, env)))
        from imucal.management import load_calibration_info

        readback["imucal"] = type(load_calibration_info(tmp / "cal.json")).__name__ + " (imucal.load_calibration_info)"
        readback["kalibr"] = f"{len(yaml.safe_load((tmp / 'imu.yaml').read_text()))} keys (yaml.safe_load)"
        readback["ros"] = f"{len(yaml.safe_load((tmp / 'imu_calib.yaml').read_text())['SM'])} SM numbers (yaml.safe_load)"
        readback["json"] = f"{len(json.loads((tmp / 'plain.json').read_text())['parameters'])} parameters (json.loads)"
        readback["imu_tk"] = f"{len((tmp / 'imu_acc.calib').read_text().split()) >= 21} 21 numbers (faithful reader)"
        if shutil.which("cc"):
            (tmp / "m.c").write_text('#include "station.h"\nint main(void){double r[3]={0,0,9.8},o[3];'
                                     'station_accel_compensate(r,o);return o[2] > 9 ? 0 : 1;}\n')
            ok = subprocess.run(["cc", "-std=c99", "-Wall", "-Werror", "-o", str(tmp / "m"), str(tmp / "m.c")],
                                cwd=tmp, capture_output=True).returncode == 0
            readback["c"] = f"compiled with cc -std=c99 -Wall -Werror: {ok}"
        subprocess.run([station, "history", "--add", str(cal)], check=True, capture_output=True, env=env)
        rows.append(("station history SERIAL", timed([station, "history", "SIM-1"], a.repeat, env)))
        rows.append(("station history SERIAL --drift PNG",
                     timed([station, "history", "SIM-1", "--drift", str(tmp / "d.png")], a.repeat, env)))
        rows.append(("station diff A B", timed([station, "diff", str(cal), str(tmp / "e.yaml")], a.repeat, env)))
        rows.append(("station report CAPTURE (diagnose --auto included)",
                     timed([station, "report", str(cap)], 1, env)))
        rows.append(("station report CAPTURE --no-auto", timed([station, "report", str(cap), "--no-auto"], 1, env)))
        print(f"capture: optimal9, 100 Hz, {sum(1 for _ in cap.glob('*.csv'))} segments; "
              f"median of {a.repeat} runs (report: 1)")
        for what, s in rows:
            print(f"| `{what}` | {s:.2f} s |")
        print()
        for fmt, how in readback.items():
            print(f"| {fmt} | {how} |")


if __name__ == "__main__":
    main()
