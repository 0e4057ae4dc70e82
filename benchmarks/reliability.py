"""Reliability figures for docs/reliability.md (issue 11): every fault of the device twins through
a whole `station run`, and the bad-input table.

    python benchmarks/reliability.py [--speed 20] [--only faults|inputs]

Faults: for each fault of sim_devices/twins (docs/twins.md) optimal9 with short timings is run with ``station run`` in a subprocess against the twins in this process;
printed: the exit status, the last line the user sees, whether the table was at rest
afterwards, and whether ``station run --resume`` against fault-free twins finished the capture.

Inputs: every bad input of the issue, each through the command line in a subprocess (120 s
guard against hangs): exit status, one line or not, traceback or not.
"""
from __future__ import annotations

import argparse
import hashlib
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import yaml

from sim_devices.truth import default_truth
from sim_devices.twins.faults import Faults, ImuFaults
from sim_devices.twins.serve import BenchOptions, BenchServer
from sim_devices.twins.table import TableFaults

SCHEME = """\
name: tiny
defaults: {dwell_s: 4.0, rate_dps: 30.0, rotation_s: 12.0}
segments:
  - {static: zup, up_body: [0, 0, 1]}
  - {static: xup, up_body: [1, 0, 0]}
  - {rotation: rotz, axis_body: [0, 0, 1]}
"""
CONFIG = """\
version: 1
table:
  axes: 3
  limits: [{max_rate_dps: 300, max_accel_dps2: 300, move_rate_dps: 60, move_accel_dps2: 60, rate_accel_dps2: 100}]
run: {operator: false, settle_s: 1}
"""
RUN = ["--scheme", "optimal9", "--dwell-s", "3", "--rotation-s", "12", "--rate-dps", "30"]
FAULTS = {
    "imu garbage every 2 s": Faults(imu=ImuFaults(garbage_every_s=2.0)),
    "imu 0.5 % corrupt frames": Faults(imu=ImuFaults(corrupt_probability=0.005)),
    "imu 5 % frames dropped": Faults(imu=ImuFaults(drop_probability=0.05)),
    "imu stall 3 s at 80 s": Faults(imu=ImuFaults(stall_at_s=80.0, stall_duration_s=3.0)),
    "imu stall for ever at 80 s": Faults(imu=ImuFaults(stall_at_s=80.0)),
    "imu disconnect at 80 s": Faults(imu=ImuFaults(disconnect_at_s=80.0)),
    "table interlock trip axis 1 at 80 s": Faults(table=TableFaults(trip_axis=1, trip_at_s=80.0)),
    "table axis 2 stuck 0.5 deg short": Faults(table=TableFaults(stuck_axis=2, shortfall_deg=0.5)),
    "table stall 3 s at 80 s": Faults(table=TableFaults(stall_at_s=80.0, stall_duration_s=3.0)),
    "table stall for ever at 80 s": Faults(table=TableFaults(stall_at_s=80.0)),
    "table disconnect at 80 s": Faults(table=TableFaults(disconnect_at_s=80.0)),
}


def station(*args, cwd, timeout=300):
    return subprocess.run([sys.executable, "-m", "station.cli", *map(str, args)], capture_output=True,
                          text=True, cwd=cwd, timeout=timeout)


def last_line(text):
    lines = [line for line in text.splitlines() if line.strip()]
    return lines[-1] if lines else ""


def faults(speed: float) -> None:
    print("| fault | exit | what the user sees (last line) | table at rest | resume |")
    print("| --- | --- | --- | --- | --- |")
    for name, fault in FAULTS.items():
        with tempfile.TemporaryDirectory() as tmp:
            tmp = Path(tmp)
            (tmp / "s.yaml").write_text(SCHEME)
            (tmp / "station.yaml").write_text(CONFIG)
            with BenchServer(default_truth(4), BenchOptions(speed=speed, seed=4, axes=3, faults=fault, lossless=True)) as bench:
                done = station("run", *RUN, "--config", "station.yaml", "--port", bench.imu_path,
                               "--table-port", bench.table_path, "--out", tmp / "cap", cwd=tmp)
                try:
                    rest = all(bench.table.read_rate(a) == 0.0 for a in (1, 2, 3))
                except Exception as e:       # noqa: BLE001 - a figure, not a test
                    rest = f"? ({type(e).__name__})"
            tb = "Traceback" in done.stderr
            resumed = "-"
            if done.returncode != 0 and (tmp / "cap" / "manifest.yaml").exists():
                with BenchServer(default_truth(4), BenchOptions(speed=speed, seed=4, axes=3, lossless=True)) as bench:
                    again = station("run", "--resume", tmp / "cap", "--config", "station.yaml", "--port",
                                    bench.imu_path, "--table-port", bench.table_path, cwd=tmp)
                resumed = f"exit {again.returncode}" + (" (traceback)" if "Traceback" in again.stderr else "")
                if again.returncode:
                    resumed += ": " + last_line(again.stderr).replace(str(tmp), "").replace("|", "/")[:100]
            line = last_line(done.stderr if done.returncode else done.stdout).replace("|", "/")
            print(f"| {name} | {done.returncode}{' TRACEBACK' if tb else ''} | {line[:160]} | {rest} | {resumed} |",
                  flush=True)


def _capture(tmp: Path) -> Path:
    from station.io.scheme import scheme_from_text
    from station.simulate import dryrun

    scheme = SCHEME.replace("{static: xup", "{static: xdn, up_body: [-1, 0, 0]}\n  - {static: xup")
    scheme += "".join(f"  - {{static: p{i}, up_body: {v}}}\n" for i, v in
                      enumerate(([0, 1, 0], [0, -1, 0], [0, 0, -1], [1, 1, 0], [1, 0, 1], [0, 1, 1])))
    scheme += "  - {rotation: rotx, axis_body: [1, 0, 0]}\n  - {rotation: roty, axis_body: [0, 1, 0]}\n"
    return dryrun.record_scheme(scheme_from_text(scheme, "bench"), dryrun.load_truth(None, 5), 5, tmp / "good")


def _edit(cap, change):
    doc = yaml.safe_load((cap / "manifest.yaml").read_text())
    change(doc)
    (cap / "manifest.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))


def _csv(cap, name, change):
    doc = yaml.safe_load((cap / "manifest.yaml").read_text())
    entry = next(e for e in doc["segments"] if e["name"] == name)
    lines = (cap / entry["file"]).read_text().splitlines()
    text = "\n".join(change(lines)) + "\n"
    (cap / entry["file"]).write_text(text)
    entry["sha256"] = hashlib.sha256(text.encode()).hexdigest()
    entry["samples"] = len(text.splitlines()) - 1
    (cap / "manifest.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))


def inputs() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        good = _capture(tmp)
        assert station("estimate", good, cwd=tmp).returncode == 0
        cal = good / "calibration.yaml"
        cases = []

        def case(name, prepare, argv):
            cases.append((name, prepare, argv))

        def quantise(lines):
            return [lines[0]] + [",".join([v.split(",")[0]] + [f"{round(float(x) / 0.05) * 0.05:.6g}"
                                                               for x in v.split(",")[1:4]] + v.split(",")[4:])
                                 for v in lines[1:]]
        statics = lambda d: d.update(segments=[s for s in d["segments"] if s["kind"] == "static"])  # noqa: E731
        case("statics only + --add accel_nonlinearity", lambda c: _edit(c, statics),
             ["estimate", "{c}", "--add", "accel_nonlinearity"])
        case("statics only, no latitude, diagnose --auto",
             lambda c: _edit(c, lambda d: (statics(d), d["site"].pop("latitude_deg"))), ["diagnose", "{c}", "--auto"])
        case("coarse quantisation (0.05 m/s^2 steps)", lambda c: _csv(c, "zup", quantise), ["estimate", "{c}"])
        case("1e300 in a CSV", lambda c: _csv(c, "zup", lambda ls: [ls[0], ",".join(
            ls[1].split(",")[:1] + ["1e300"] + ls[1].split(",")[2:])] + ls[2:]),
             ["estimate", "{c}"])
        for key, value in (("gravity_mps2", 1e300), ("latitude_deg", 1e300)):
            case(f"site.{key}: {value:g}", lambda c, k=key, v=value: _edit(c, lambda d: d["site"].update({k: v})),
                 ["estimate", "{c}"])
        case("imu.sample_rate_hz: 1e300", lambda c: _edit(c, lambda d: d["imu"].update(sample_rate_hz=1e300)),
             ["estimate", "{c}"])
        case("rate_dps: 1e300", lambda c: _edit(c, lambda d: next(s for s in d["segments"] if s["kind"] == "rotation")
                                                .update(rate_dps=1e300)), ["estimate", "{c}"])
        case("billion laughs in imu.serial", lambda c: (c / "manifest.yaml").write_text(
            "l0: &l0 lol\n" + "".join(f"l{i}: &l{i} [{', '.join([f'*l{i - 1}'] * 9)}]\n" for i in range(1, 10))
            + (c / "manifest.yaml").read_text().replace("serial: SIM-5", "serial: *l9")), ["estimate", "{c}"])
        case("FIFO as an incomplete segment's file", lambda c: (
            _edit(c, lambda d: next(s for s in d["segments"] if s["name"] == "rotz_m").update(status="incomplete")),
            (c / "rotz_m.csv").unlink(), os.mkfifo(c / "rotz_m.csv")), ["estimate", "{c}"])
        case("FIFO as a complete segment's file", lambda c: ((c / "zup.csv").unlink(), os.mkfifo(c / "zup.csv")),
             ["estimate", "{c}"])
        case("raw units + --add", lambda c: _edit(c, lambda d: d["imu"].update(accel_unit="raw", gyro_unit="raw")),
             ["estimate", "{c}", "--add", "accel_nonlinearity"])
        case("run --resume DIR --sim", lambda c: None, ["run", "--resume", "{c}", "--sim"])
        case("symlinked calibration.yaml.tmp", lambda c: ((c / "calibration.yaml.tmp").symlink_to(tmp / "outside"),
                                                          (tmp / "outside").write_text("x")), ["estimate", "{c}"])
        for name, content in (("non-UTF-8 calibration file", b"format: station-calibration/1\nx: \xff\n"),
                              ("effects: 5", None), ("billion laughs in a calibration file", "laughs"),
                              ("FIFO as calibration file", "fifo")):
            def prepare(c, content=content):
                target = c / "bad.yaml"
                if content == "fifo":
                    os.mkfifo(target)
                elif content == "laughs":
                    target.write_text("a: &a [x, x]\nb: &b [*a, *a]\n" + cal.read_text().replace(
                        "serial: SIM-5", "serial: *b"))
                elif content is None:
                    doc = yaml.safe_load(cal.read_text())
                    doc["effects"] = 5
                    target.write_text(yaml.safe_dump(doc, sort_keys=False))
                else:
                    target.write_bytes(content)
            case(name + " (show)", prepare, ["show", "{c}/bad.yaml"])
            case(name + " (apply)", prepare, ["apply", "{c}/bad.yaml", "{c}/zup.csv", "-o", "{c}/o.csv"])
        case("calibration of another serial (apply)", lambda c: _edit(c, lambda d: d["imu"].update(serial="X")),
             ["apply", str(cal), "{c}/zup.csv", "-o", "{c}/o.csv"])
        case("calibration of another serial (diagnose --calib)", lambda c: _edit(c, lambda d: d["imu"].update(serial="X")),
             ["diagnose", "{c}", "--calib", str(cal)])

        print("| bad input | exit | one line | traceback | message (start) |")
        print("| --- | --- | --- | --- | --- |")
        clean = tracebacks = 0
        for i, (name, prepare, argv) in enumerate(cases):
            c = Path(shutil.copytree(good, tmp / f"c{i}"))
            prepare(c)
            try:
                done = station(*[a.replace("{c}", str(c)) for a in argv], cwd=tmp, timeout=120)
                status, err = done.returncode, done.stderr
            except subprocess.TimeoutExpired:
                status, err = "HANG", ""
            one = err.count("\n") == 1 or (status == 0)
            tb = "Traceback" in err
            clean += status in (0, 2) and not tb
            tracebacks += tb
            message = last_line(err).replace(str(c), "CAP").replace("|", "/")[:110]
            print(f"| {name} | {status} | {'yes' if one else 'no'} | {'YES' if tb else 'no'} | {message} |",
                  flush=True)
        print(f"\n{len(cases)} bad inputs: {clean} clean (exit 2, or 0 with a correct result), "
              f"{tracebacks} tracebacks")


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--speed", type=float, default=20.0)
    p.add_argument("--only", choices=("faults", "inputs"))
    a = p.parse_args()
    if a.only != "faults":
        inputs()
    if a.only != "inputs":
        print()
        faults(a.speed)


if __name__ == "__main__":
    main()
