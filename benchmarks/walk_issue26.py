"""Issue 26's bullets walked again as a new user would, with the exact input each bullet names and
inputs nobody designed for (variants: other nesting, other files of the same kind, other writers
and readers, edge numbers).  Every command runs as a whole process with a timeout; a case is
OK when it ends as expected (mostly: exit status 2, one line on stderr naming the input, no
traceback) within the timeout.

Usage: python benchmarks/walk_issue26.py [--station "python -m station.cli"] [--only WORD] [--markdown]
(run from a clone, with PYTHONPATH set to it or in its venv).  Prints one line per case and a
markdown table with --markdown; exit status 1 when a case failed.
"""
from __future__ import annotations

import argparse
import os
import shlex
import shutil
import sqlite3
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

HERE = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(HERE / "tests"))
TIMEOUT = 90.0


class Walk:
    def __init__(self, station, work: Path, only=None):
        self.station, self.work, self.only = station, work, only
        self.rows = []

    def run(self, argv, *, cwd=None, env=None, timeout=TIMEOUT):
        e = dict(os.environ)
        e.update(env or {})
        t0 = time.perf_counter()
        try:
            p = subprocess.run([*self.station, *map(str, argv)], capture_output=True, text=True, timeout=timeout,
                               cwd=cwd or self.work, env=e, stdin=subprocess.DEVNULL)
            return p.returncode, p.stdout, p.stderr, time.perf_counter() - t0
        except subprocess.TimeoutExpired:
            return None, "", f"HANG: no end within {timeout:.0f} s", time.perf_counter() - t0

    def case(self, item, what, argv, *, expect=2, words=(), check=None, **kw):
        if self.only and self.only not in item and self.only not in what:
            return
        code, out, err, dt = self.run(argv, **kw)
        last = err.strip().splitlines()[-1] if err.strip() else out.strip().splitlines()[-1] if out.strip() else ""
        problems = []
        if code is None:
            problems.append("hang")
        elif "Traceback" in err:
            problems.append("traceback")
        elif code not in (expect if isinstance(expect, tuple) else (expect,)):
            problems.append(f"exit {code} (expected {expect})")
        elif code == 2:
            lines = [ln for ln in err.splitlines() if ln.strip() and not ln.startswith("note:")]
            if len(lines) != 1:
                problems.append(f"{len(lines)} lines on stderr")
            for w in words:
                if w not in err:
                    problems.append(f"does not say {w!r}")
        if check is not None and code is not None:
            msg = check(code, out, err)
            if msg:
                problems.append(msg)
        ok = not problems
        cmd = "station " + " ".join(shlex.quote(str(a)).replace(str(self.work) + "/", "") for a in argv)
        self.rows.append((item, what, cmd, code, last[:200].replace(str(self.work) + "/", ""), ok, problems, dt))
        print(f"{'OK  ' if ok else 'FAIL'} [{item}] {what}: exit {code} {dt:5.1f} s | {last[:160]}"
              + ("" if ok else f"  <-- {'; '.join(problems)}"), flush=True)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--station", default=f"{sys.executable} -m station.cli")
    ap.add_argument("--only")
    ap.add_argument("--markdown", action="store_true")
    ap.add_argument("--keep", action="store_true")
    a = ap.parse_args()
    work = Path(tempfile.mkdtemp(prefix="walk26-"))
    env_store = {"STATION_HISTORY_DIR": str(work / "user-store"), "XDG_CONFIG_HOME": str(work / "xdg-config"),
                 "XDG_CACHE_HOME": str(work / "xdg-cache"), "XDG_DATA_HOME": str(work / "xdg-data")}
    os.environ.update(env_store)
    for k in ("STATION_CONFIG", "STATION_STORE", "STATION_EFFECTS_PATH"):
        os.environ.pop(k, None)
    w = Walk(shlex.split(a.station), work, a.only)
    try:
        walk(w, work)
    finally:
        if not a.keep:
            shutil.rmtree(work, ignore_errors=True)
    bad = [r for r in w.rows if not r[5]]
    print(f"\n{len(w.rows)} cases, {len(w.rows) - len(bad)} as expected, {len(bad)} not")
    if a.markdown:
        print("\n| item | input | command | exit | stderr (last line) | |\n| --- | --- | --- | --- | --- | --- |")
        for item, what, cmd, code, last, ok, problems, dt in w.rows:
            cmd = cmd if len(cmd) < 110 else cmd[:107] + "..."
            print(f"| {item} | {what} | `{cmd}` | {code} | {last.replace('|', '/')[:140]} | "
                  f"{'ok' if ok else 'FAIL: ' + '; '.join(problems)} |")
    return 1 if bad else 0


def walk(w: Walk, work: Path):
    from simhelpers import scheme_yaml
    from test_import_recordings import session, write_csv

    # ---------------------------------------------------------------- inputs
    scheme = work / "small.yaml"
    scheme.write_text(scheme_yaml("small", 5.0))
    cap = work / "cap"
    code, _, err, _ = w.run(["run", "--sim", "--scheme", scheme, "--seed", "5", "--out", cap])
    assert code == 0, err
    cal = cap / "calibration.yaml"
    _, hs = session(poses=6, dwell_s=(2.5, 3.0))
    log = write_csv(work / "log.csv", hs)
    good_doc = yaml.safe_load(cal.read_text())

    def edited_cal(name, change):
        doc = yaml.safe_load(cal.read_text())
        change(doc)
        p = work / f"{name}.yaml"
        p.write_text(yaml.safe_dump(doc, sort_keys=False))
        return p

    deep_flow = "a: " + "[" * 5000 + "]" * 5000 + "\n"
    deep_map = "a: " + "{a: " * 3000 + "1" + "}" * 3000 + "\n"
    deep_block = "".join(" " * i + f"k{i}:\n" for i in range(0, 300)) + " " * 300 + "v\n"
    deep_key = "? " + "[" * 2000 + "]" * 2000 + "\n: 1\n"
    laughs = "a: &a [x, x, x, x, x, x, x, x, x, x]\n" + "".join(
        f"{c}: &{c} [*{p}, *{p}, *{p}, *{p}, *{p}, *{p}, *{p}, *{p}, *{p}, *{p}]\n"
        for p, c in zip("abcdefgh", "bcdefghi"))
    deeps = {"flow-5000": deep_flow, "map-3000": deep_map, "block-300": deep_block, "key-2000": deep_key,
             "billion-laughs": laughs}

    # ---------------------------------------------------------------- 1. deeply nested YAML
    for kind, text in deeps.items():
        f = work / f"deep-{kind}.yaml"
        f.write_text(text)
        expect_words = [str(f.name)]
        w.case("deep YAML", f"scheme {kind}", ["plan", "--scheme", f], words=expect_words)
        w.case("deep YAML", f"station.yaml --config {kind}", ["plan", "--config", f], words=expect_words)
        w.case("deep YAML", f"$STATION_CONFIG {kind}", ["schemes"], env={"STATION_CONFIG": str(f)},
               words=expect_words)
        w.case("deep YAML", f"--sim-truth {kind}", ["run", "--sim", "--scheme", scheme, "--sim-truth", f, "--out",
                                                    work / f"o-{kind}"], words=expect_words)
        w.case("deep YAML", f"sim serve --faults {kind}", ["sim", "serve", "--faults", f], words=expect_words)
        w.case("deep YAML", f"export --noise {kind}", ["export", cal, "--to", "kalibr", "--noise", f, "-o",
                                                       work / f"k-{kind}.yaml"], words=expect_words)
        w.case("deep YAML", f"calibration file {kind}", ["show", f], words=expect_words)
        c2 = work / f"cap-{kind}"
        shutil.copytree(cap, c2)
        (c2 / "manifest.yaml").write_text(text)
        w.case("deep YAML", f"capture manifest {kind}", ["estimate", c2, "-o", work / "x.yaml"], words=["manifest"])
        w.case("deep YAML", f"import csv --segments {kind}", ["import", "csv", log, "--segments", f, "-o",
                                                             work / f"ic-{kind}"], words=expect_words)

    # ---------------------------------------------------------------- 2. scheme defaults
    for dv in ("[1, 2]", "5", "abc", "null", "{dwell_s: [1]}", "{dwell_s: .nan}", "{dwell_s: 1e400}",
               "{dwell_s: -3}", "{rate_dps: 1e300}", "{rotation_s: 1e300}", "{dwell_s: 1e300}", "{dwell_s: true}",
               "{unknown: 1}"):
        s = work / "defaults.yaml"
        s.write_text(f"name: s\ndefaults: {dv}\nsegments:\n  - static: a\n    up_body: [0, 0, 1]\n"
                     "  - rotation: r\n    axis_body: [0, 0, 1]\n")
        w.case("scheme defaults", f"defaults: {dv}", ["plan", "--scheme", s], words=["defaults.yaml"])
    for body in ("segments: {a: 1}", "segments: null", "segments: [abc]", "segments: [[1, 2]]",
                 "segments: [{static: a, up_body: [0, 0, 0], dwell_s: 1}]",
                 "segments: [{static: a, up_body: [.nan, 0, 1], dwell_s: 1}]",
                 "segments: [{static: a, up_body: [0, 0, 1, 4], dwell_s: 1}]",
                 "segments: [{static: a, up_body: '001', dwell_s: 1}]",
                 "segments: [{rotation: r, axis_body: [0, 0, 1], rate_dps: 1e308, rotation_s: 1e308}]",
                 "segments: [{static: a, up_body: [0, 0, 1], dwell_s: 1}, {static: a, up_body: [0, 0, 1], dwell_s: 1}]",
                 "segments: []", "[1, 2, 3]", "'just text'", ""):
        s = work / "segs.yaml"
        s.write_text(f"name: s\n{body}\n" if not body.startswith(("[", "'")) and body else body)
        w.case("scheme shapes", body[:60] or "empty file", ["plan", "--scheme", s], words=["segs.yaml"])
        w.case("scheme shapes", "run --sim " + (body[:50] or "empty file"),
               ["run", "--sim", "--scheme", s, "--out", work / "o-segs"], words=["segs.yaml"])

    # ---------------------------------------------------------------- 3. import csv time base
    cols = "ax=1,ay=2,az=3,gx=4,gy=5,gz=6"
    for opts in (["--time-unit", "ns"], ["--time-unit", "us"], ["--time-unit", "ms"],
                 ["--rate-hz", "1e300", "--columns", cols], ["--rate-hz", "1e-300", "--columns", cols],
                 ["--rate-hz", "inf", "--columns", cols], ["--rate-hz", "nan", "--columns", cols],
                 ["--rate-hz", "-100", "--columns", cols], ["--rate-hz", "0", "--columns", cols],
                 ["--rate-hz", "1e309", "--columns", cols], ["--rate-hz", "2e6", "--columns", cols],
                 ["--rate-hz", "100", "--time-unit", "s"], ["--accel-nominal", "0"], ["--accel-nominal", "nan"],
                 ["--gyro-nominal", "-1e308"], ["--latitude-deg", "91"], ["--latitude-deg", "nan"],
                 ["--gravity-mps2", "0"], ["--gravity-mps2", "1e308"], ["--accel-unit", "furlong"],
                 ["--delimiter", ""], ["--delimiter", "\\t\\t"], ["--columns", "t=0,ax=99,ay=2,az=3,gx=4,gy=5,gz=6"],
                 ["--columns", "t=-1,ax=1,ay=2,az=3,gx=4,gy=5,gz=6"], ["--columns", "t=0,ax=1"],
                 ["--columns", "ax=1,ay=1,az=1,gx=4,gy=5,gz=6,t=0"], ["--columns", "t=0,ax=1,ay=2,az=3,gx=4,gy=4,gz=4"],
                 ["--columns", "t=0,ax=1,ay=2,az=3,gx=4,gy=5,gz=6,temp=6"], ["--columns", "t=0;ax=1"],
                 ["--columns", "t=0,ax=1,ay=2,az=3,gx=4,gy=5,gz=6,ax=2"]):
        w.case("import csv options", " ".join(opts), ["import", "csv", log, "-o", work / "ic", *opts])
    for name, text in {"seconds-as-ns-huge": "t,ax,ay,az,gx,gy,gz\n" + "".join(
            f"{i * 1e15:.0f},0,0,9.8,0,0,0\n" for i in range(200)),
            "time-backwards": "t,ax,ay,az,gx,gy,gz\n" + "".join(f"{-i * 0.01},0,0,9.8,0,0,0\n" for i in range(500)),
            "time-all-equal": "t,ax,ay,az,gx,gy,gz\n" + "1,0,0,9.8,0,0,0\n" * 500,
            "inf-values": "t,ax,ay,az,gx,gy,gz\n" + "".join(f"{i * 0.01},inf,0,9.8,0,0,0\n" for i in range(500)),
            "huge-values": "t,ax,ay,az,gx,gy,gz\n" + "".join(f"{i * 0.01},1e308,1e308,1e308,0,0,0\n" for i in range(500)),
            "header-only": "t,ax,ay,az,gx,gy,gz\n", "empty": "", "nul-bytes": "t,ax\x00\n\x00\x00\x00",
            "one-column": "\n".join(str(i) for i in range(500)), "latin1": "t,ax,ay,az,gx,gy,gz\n\xe9\xff,1\n",
            "long-line": "t,ax,ay,az,gx,gy,gz\n" + "1," * 200000 + "\n"}.items():
        f = work / f"{name}.csv"
        f.write_bytes(text.encode("latin-1"))
        w.case("import csv logs", name, ["import", "csv", f, "-o", work / "ic"], words=[f.name])

    # ---------------------------------------------------------------- 4. FIFOs, devices, folders as files
    fifo = work / "fifo.csv"
    os.mkfifo(fifo)
    fifo_bag = work / "fifo.bag"
    os.mkfifo(fifo_bag)
    fifo_yaml = work / "fifo.yaml"
    os.mkfifo(fifo_yaml)
    for what, argv in {
            "import csv FIFO": ["import", "csv", fifo, "-o", work / "f1"],
            "import rosbag FIFO": ["import", "rosbag", fifo_bag, "-o", work / "f2"],
            "import imucal FIFO": ["import", "imucal", fifo, "--sections", fifo_yaml, "--rate-hz", "100", "-o", work / "f3"],
            "import csv --gyro-file FIFO": ["import", "csv", log, "--gyro-file", fifo, "-o", work / "f4"],
            "import csv --segments FIFO": ["import", "csv", log, "--segments", fifo_yaml, "-o", work / "f5"],
            "apply IN.csv FIFO": ["apply", cal, fifo, "-o", work / "a.csv"],
            "apply CAL FIFO": ["apply", fifo_yaml, log, "-o", work / "a.csv"],
            "noise FILE.csv FIFO": ["noise", fifo],
            "noise bag FIFO": ["noise", fifo_bag],
            "show FIFO": ["show", fifo_yaml], "export FIFO": ["export", fifo_yaml, "--to", "json", "-o", work / "e.json"],
            "export --noise FIFO": ["export", cal, "--to", "kalibr", "--noise", fifo_yaml, "-o", work / "k.yaml"],
            "plan --scheme FIFO": ["plan", "--scheme", fifo_yaml], "plan --config FIFO": ["plan", "--config", fifo_yaml],
            "run --sim-truth FIFO": ["run", "--sim", "--scheme", scheme, "--sim-truth", fifo_yaml, "--out", work / "f6"],
            "sim serve --faults FIFO": ["sim", "serve", "--faults", fifo_yaml],
            "diff FIFO": ["diff", fifo_yaml, cal], "history --add FIFO": ["history", "--add", fifo_yaml],
            "diagnose --calib FIFO": ["diagnose", cap, "--calib", fifo_yaml],
            "import csv /dev/zero": ["import", "csv", "/dev/zero", "-o", work / "f7"],
            "apply /dev/urandom": ["apply", cal, "/dev/urandom", "-o", work / "a.csv"],
            "show a folder": ["show", work], "import csv a folder": ["import", "csv", work, "-o", work / "f8"],
            "estimate manifest FIFO": None}.items():
        if argv is None:
            c3 = work / "cap-fifo"
            shutil.copytree(cap, c3)
            (c3 / "manifest.yaml").unlink()
            os.mkfifo(c3 / "manifest.yaml")
            argv = ["estimate", c3, "-o", work / "x.yaml"]
        w.case("FIFO/device", what, argv, timeout=30)
    c4 = work / "cap-segfifo"
    shutil.copytree(cap, c4)
    (c4 / "pos01.csv").unlink()
    os.mkfifo(c4 / "pos01.csv")
    w.case("FIFO/device", "estimate, a segment CSV is a FIFO", ["estimate", c4, "-o", work / "x.yaml"], timeout=30)

    # ---------------------------------------------------------------- 5. outputs on a dangling symlink
    def dangling(name):
        p = work / name
        if p.is_symlink() or p.exists():
            p.unlink()
        p.symlink_to(work / "nowhere" / name)
        return p

    for what, argv, expect in (
            ("import csv -o", ["import", "csv", log, "-o", dangling("d-import")], 2),
            ("run --out", ["run", "--sim", "--scheme", scheme, "--out", dangling("d-run")], 2),
            # files written atomically (a new file renamed over the path) replace a link, never
            # write through it (station/io/calfile.py write_calfile): 0, the link now a file
            ("export -o", ["export", cal, "--to", "json", "-o", dangling("d.json")], (0, 2)),
            ("export imu_tk -o", ["export", cal, "--to", "imu_tk", "-o", dangling("d-imutk")], (0, 2)),
            ("apply -o", ["apply", cal, cap / "pos01.csv", "-o", dangling("d.csv")], 2),
            ("estimate -o", ["estimate", cap, "-o", dangling("d-est.yaml")], (0, 2)),
            ("diagnose -o", ["diagnose", cap, "-o", dangling("d-diag.yaml")], (0, 2)),
            ("report -o", ["report", cap, "--no-auto", "-o", dangling("d.html")], 2),
            ("diagnose --report DIR", ["diagnose", cap, "--report", dangling("d-rep")], 2),
            ("noise --plot", ["noise", log, "--plot", dangling("d.svg")], 2),
            ("init PATH", ["init", dangling("d-station.yaml")], 2),
            ("history SERIAL --drift", ["history", "SIM-5", "--store", work / "store-d", "--add", cal, "--drift",
                                        dangling("d.png")], (0, 2))):
        w.case("dangling -o", what, argv, expect=expect,
               check=lambda c, o, e: "wrote through to nowhere" if (work / "nowhere").exists() else None)

    # ---------------------------------------------------------------- 6. damaged bags
    from station.io.importers.rosbag import write_imu_bag
    rng = np.random.default_rng(26)
    for fmt in ("rosbag1", "rosbag2", "mcap"):
        try:
            bag = write_imu_bag(work / f"good-{fmt}.{'bag' if fmt == 'rosbag1' else fmt}", hs.t, hs.accel,
                                np.radians(hs.gyro), fmt=fmt)
        except Exception as e:       # noqa: BLE001 - a format this machine cannot write
            print(f"skip {fmt}: {e}")
            continue
        data = bag.read_bytes() if bag.is_file() else None
        if data is None:
            continue
        for trial in range(12):
            bad = bytearray(data)
            for i in rng.integers(0, len(bad), int(rng.integers(1, 6))):
                bad[i] ^= int(rng.integers(1, 256))
            if trial == 10:
                bad = bad[: len(bad) // 2]
            if trial == 11:
                bad = bytearray(data[:64])
            p = work / f"bad{trial}-{bag.name}"
            p.write_bytes(bad)
            for cmd in (["import", "rosbag", p, "-o", work / f"ib-{fmt}-{trial}"], ["noise", p]):
                code, _, err, _ = w.run(cmd, timeout=60)
                if code == 0:
                    continue                     # the flipped bytes were in a sample's value: read
                w.case("damaged bag", f"{fmt} {'truncated' if trial >= 10 else 'flipped'} #{trial} {cmd[0]}",
                       cmd, timeout=60)

    # ---------------------------------------------------------------- 7. history index
    store = work / "store"
    w.run(["history", "--store", store, "--add", cal])         # (the store the cases damage, with --only too)
    w.case("history", "history --add a sim calibration (filed when asked)",
           ["history", "--store", store, "--add", cal], expect=0)
    index = store / "index.sqlite"
    saved = index.read_bytes() if index.exists() else b""
    variants = {
        "zero bytes": lambda: index.write_bytes(b""),
        "random bytes": lambda: index.write_bytes(os.urandom(4096)),
        "sqlite header then garbage": lambda: index.write_bytes(saved[:100] + os.urandom(4000)),
        "truncated": lambda: index.write_bytes(saved[: len(saved) // 3]),
        "foreign schema": lambda: _foreign(index),
        "future schema version": lambda: _future(index, saved),
        "a folder": lambda: (index.unlink(), index.mkdir()),
        "NULL and blob fields": lambda: _nulls(index, saved),
        "wal garbage": lambda: (index.write_bytes(saved), (store / "index.sqlite-wal").write_bytes(os.urandom(5000))),
    }
    for what, damage in variants.items():
        if index.is_dir():
            index.rmdir()
        for extra in ("index.sqlite-wal", "index.sqlite-shm"):
            (store / extra).unlink(missing_ok=True)
        damage()
        for cmd in (["history", "--store", store], ["diff", "#1", "#2", "--store", store],
                    ["fleet", "--store", store, "--json"], ["history", "--store", store, "--add", cal]):
            w.case("history index", f"{what}: {cmd[0]}", cmd, words=["index.sqlite"],
                   expect=(0, 2) if what in ("zero bytes", "NULL and blob fields", "wal garbage") else 2)
    for extra in ("index.sqlite-wal", "index.sqlite-shm"):
        (store / extra).unlink(missing_ok=True)
    if index.is_dir():
        index.rmdir()
    index.write_bytes(saved)
    other = edited_cal("other", lambda d: d["provenance"].update(date_utc="2030-01-01T00:00:00Z",
                                                                   capture_sha256="e" * 64))
    w.run(["history", "--store", store, "--add", other])
    for path in ("/etc/passwd", "../../outside.yaml", "/dev/zero", str(fifo_yaml), "a/../../b.yaml", "",
                 "x" * 5000, "\x00"):
        db = sqlite3.connect(index)
        try:
            db.execute("UPDATE calibrations SET file = ? WHERE id = 2", (path,))
            db.commit()
        finally:
            db.close()
        for cmd in (["diff", "#1", "#2", "--store", store], ["fleet", "--store", store, "--json"],
                    ["history", "SIM-5", "--store", store, "--drift", work / "drift.png"]):
            w.case("tampered history path", f"file={path[:20]!r}: {cmd[0]}", cmd, timeout=30,
                   expect=(0, 2) if cmd[0] == "fleet" else 2,
                   check=lambda c, o, e: "printed /etc/passwd" if "root:" in o + e else None)
    db = sqlite3.connect(index)
    db.execute("UPDATE calibrations SET file = (SELECT file FROM calibrations WHERE id = 1) WHERE id = 2")
    db.commit()
    db.close()

    # ---------------------------------------------------------------- 8. calibration files
    zero = [[0.0] * 3 for _ in range(3)]
    cal_changes = {
        "all-zero accel_matrix": lambda d: d["compensation"].update(accel_matrix=zero),
        "all-zero gyro_matrix": lambda d: d["compensation"].update(gyro_matrix=zero),
        "NaN in accel_matrix": lambda d: d["compensation"]["accel_matrix"][0].__setitem__(0, float("nan")),
        "inf in gyro_matrix": lambda d: d["compensation"]["gyro_matrix"][1].__setitem__(1, float("inf")),
        "1e308 accel_matrix": lambda d: d["compensation"].update(accel_matrix=[[1e308, 0, 0], [0, 1e308, 0], [0, 0, 1e308]]),
        "1e-308 accel_matrix": lambda d: d["compensation"].update(accel_matrix=[[1e-308, 0, 0], [0, 1e-308, 0], [0, 0, 1e-308]]),
        "2x3 accel_matrix": lambda d: d["compensation"].update(accel_matrix=[[1, 0, 0], [0, 1, 0]]),
        "ragged accel_matrix": lambda d: d["compensation"].update(accel_matrix=[[1, 0, 0], [0, 1], [0, 0, 1]]),
        "string accel_matrix": lambda d: d["compensation"].update(accel_matrix="identity"),
        "accel_bias strings": lambda d: d["compensation"].update(accel_bias=["a", "b", "c"]),
        "accel_bias 1e308": lambda d: d["compensation"].update(accel_bias=[1e308, -1e308, 1e308]),
        "NaN sigma": lambda d: d["parameters"]["accel_bias_x"].update(sigma=float("nan")),
        "sigma string": lambda d: d["parameters"]["accel_bias_x"].update(sigma="small"),
        "sigma -0.0": lambda d: d["parameters"]["accel_bias_x"].update(sigma=-0.0),
        "value NaN": lambda d: d["parameters"]["accel_scale_x"].update(value=float("nan")),
        "value a list": lambda d: d["parameters"]["accel_scale_x"].update(value=[1, 2]),
        "parameter a number": lambda d: d["parameters"].update(accel_scale_x=1.0),
        "parameters a list": lambda d: d.update(parameters=[1, 2]),
        "gyro params removed": lambda d: d.update(parameters={k: v for k, v in d["parameters"].items()
                                                              if not k.startswith("gyro_")}),
        "one gyro param removed": lambda d: d["parameters"].pop("gyro_scale_y"),
        "accel params removed": lambda d: d.update(parameters={k: v for k, v in d["parameters"].items()
                                                               if not k.startswith("accel_")}),
        "compensation missing": lambda d: d.pop("compensation"),
        "compensation a list": lambda d: d.update(compensation=[1]),
        "format unknown": lambda d: d.update(format="station-calibration/99"),
        "units swapped": lambda d: d.get("units", {}).update(accel="deg/s") if isinstance(d.get("units"), dict) else d.update(units="x"),
        "verdict garbage": lambda d: d.update(verdict={"status": 7}) if "verdict" in d else d.update(verdict=7),
        "effects garbage": lambda d: d.update(effects=[{"id": "no_such_effect", "parameters": {"x": 1}}]),
        "effects a string": lambda d: d.update(effects="accel_lever_arm"),
        "provenance a list": lambda d: d.update(provenance=[1]),
        "serial a mapping": lambda d: d.setdefault("imu", {}).update(serial={"a": 1}) if isinstance(d.get("imu"), dict) else d.update(imu=[1]),
        "unicode keys": lambda d: d["parameters"].update({"accel_bias_\u212a": {"value": 1, "sigma": 1}}),
    }
    noise = work / "noise.yaml"
    for what, change in cal_changes.items():
        try:
            p = edited_cal("edited", change)
        except Exception as e:       # noqa: BLE001 - the change does not apply to this file's layout
            print(f"skip {what}: {e}")
            continue
        for cmd in (["show", p], ["apply", p, cap / "pos01.csv", "-o", work / "ap.csv"],
                    ["export", p, "--to", "imu_tk", "-o", work / "exp-imutk"], ["export", p, "--to", "c", "-o", work / "exp.h"],
                    ["export", p, "--to", "kalibr", "-o", work / "exp-k.yaml"], ["diff", p, cal],
                    ["diagnose", cap, "--calib", p]):
            code, out, err, _ = w.run(cmd)
            if code == 0 and "Traceback" not in err:
                note = None
                if what in ("all-zero accel_matrix", "NaN sigma", "gyro params removed", "NaN in accel_matrix",
                            "all-zero gyro_matrix", "1e-308 accel_matrix", "value NaN", "sigma string"):
                    note = "accepted"
                if note is None:
                    continue
            w.case("calibration file", f"{what}: {cmd[0]}{' ' + cmd[3] if cmd[0] == 'export' else ''}", cmd)

    # ---------------------------------------------------------------- 9. one column, three axes
    for colspec in ("t=0,ax=1,ay=1,az=1,gx=4,gy=5,gz=6", "t=0,ax=1,ay=2,az=3,gx=4,gy=4,gz=4",
                    "t=t,ax=ax,ay=ax,az=ax,gx=gx,gy=gy,gz=gz", "t=0,ax=1,ay=2,az=3,gx=1,gy=2,gz=3",
                    "t=0,ax=0,ay=0,az=0,gx=0,gy=0,gz=0"):
        w.case("one column, many axes", colspec, ["import", "csv", log, "--columns", colspec, "-o", work / "oc"],
               words=["--columns"])

    # ---------------------------------------------------------------- 10. ./station.yaml plugins
    down = work / "download"
    shutil.copytree(cap, down)
    marker = work / "RAN"
    (down / "evil.py").write_text(f"import pathlib\npathlib.Path({str(marker)!r}).write_text('ran')\n")
    for cfg in ("effects:\n  plugins: [evil.py]\n", "effects:\n  folders: [.]\n",
                f"effects:\n  plugins: [{down / 'evil.py'}]\n", "effects:\n  plugins: [evil.py:Evil]\n"):
        (down / "station.yaml").write_text(cfg)
        for cmd in (["estimate", ".", "-o", work / "pe.yaml"], ["diagnose", "."], ["effects"],
                    ["apply", "calibration.yaml", "pos01.csv", "-o", work / "pa.csv"], ["report", ".", "-o", work / "r.html"],
                    ["show", "calibration.yaml"], ["export", "calibration.yaml", "--to", "json", "-o", work / "pj.json"],
                    ["diagnose", ".", "--auto"], ["noise", "."], ["batch", "estimate", ".", "--workers", "1", "-o", work / "pb"]):
            marker.unlink(missing_ok=True)
            w.case("./station.yaml plugins", f"{cfg.split(':', 1)[1].strip()[:30]}: {cmd[0]} {cmd[1] if cmd[0] == 'batch' else ''}",
                   cmd, cwd=down, expect=0, timeout=180,
                   check=lambda c, o, e: "RAN the capture's code" if marker.exists() else None)

    # ---------------------------------------------------------------- 11. stale temporaries
    out = work / "stale"
    out.mkdir()
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    (out / f".cal.yaml.{dead.pid}_00000000000000aa.tmp").write_text("half")
    live = out / f".cal.yaml.{os.getpid()}_00000000000000bb.tmp"
    live.write_text("being written")
    (out / "keep.tmp").write_text("mine")
    precious = work / "precious"
    precious.write_text("precious")
    (out / f".cal.yaml.{dead.pid}_00000000000000cc.tmp").symlink_to(precious)
    w.case("stale temporaries", "estimate -o beside a dead writer's, a live one's, a link", ["estimate", cap, "-o", out / "cal.yaml"],
           expect=0, check=lambda c, o, e: (
               "the dead writer's temp left" if (out / f".cal.yaml.{dead.pid}_00000000000000aa.tmp").exists() else
               "a live writer's temp removed" if not live.exists() else
               "a link followed" if precious.read_text() != "precious" else
               "not ours removed" if not (out / "keep.tmp").exists() else None))

    # ---------------------------------------------------------------- 12. history pollution
    ustore = Path(os.environ["STATION_HISTORY_DIR"])

    def n_filed():
        idx = ustore / "index.sqlite"
        if not idx.exists():
            return 0
        db = sqlite3.connect(idx)
        try:
            return db.execute("SELECT count(*) FROM calibrations").fetchone()[0]
        finally:
            db.close()

    before = n_filed()
    w.case("history pollution", "estimate of a simulated capture: not filed", ["estimate", cap, "-o", work / "h1.yaml"],
           expect=0, check=lambda c, o, e: "filed" if n_filed() != before else None)
    w.case("history pollution", "run --sim: not filed", ["run", "--sim", "--scheme", scheme, "--out", work / "h-run"],
           expect=0, check=lambda c, o, e: "filed" if n_filed() != before else None)
    _, hs12 = session(poses=12)              # (a hand calibration needs 9 poses or more)
    log12 = write_csv(work / "log12.csv", hs12)
    w.case("history pollution", "import csv without a serial then estimate: not filed",
           ["import", "csv", log12, "-o", work / "h-imp"], expect=0)
    w.case("history pollution", "estimate of an import with unknown serial: not filed",
           ["estimate", work / "h-imp", "-o", work / "h2.yaml"], expect=0,
           check=lambda c, o, e: "filed" if n_filed() != before else None)
    w.case("history pollution", "estimate --history of a sim capture (asked: own store)",
           ["estimate", cap, "-o", work / "h3.yaml", "--history"], expect=0, check=lambda c, o, e: None)
    w.case("history pollution", "estimate --history twice: no duplicate",
           ["estimate", cap, "-o", work / "h4.yaml", "--history"], expect=0,
           check=lambda c, o, e: None if "already" in (o + e).lower() or "not filed" in (o + e).lower() else
           "did not say it was filed already")

    # ---------------------------------------------------------------- 13. diagnose --report's calibration line
    rep = work / "rep"
    w.case("diagnose --report", "the page names the capture's calibration", ["diagnose", cap, "--report", rep],
           expect=0, check=lambda c, o, e: None if (rep / "index.html").exists() and "No calibration file" not in
           (rep / "index.html").read_text() and "calibration.yaml" in (rep / "index.html").read_text() else
           "the page does not name calibration.yaml")
    w.case("smaller", "plan --scheme screwdriver: not a table scheme", ["plan", "--scheme", "screwdriver"],
           words=["not a table scheme"])
    w.case("smaller", "noise FILE.csv writes NAME-noise.yaml beside it", ["noise", log], expect=0,
           check=lambda c, o, e: None if (work / "log-noise.yaml").exists() else "no log-noise.yaml")


def _foreign(index):
    index.unlink(missing_ok=True)
    db = sqlite3.connect(index)
    db.execute("CREATE TABLE calibrations (id INTEGER PRIMARY KEY, name TEXT)")
    db.execute("INSERT INTO calibrations (name) VALUES ('x')")
    db.commit()
    db.close()


def _future(index, saved):
    index.write_bytes(saved)
    db = sqlite3.connect(index)
    db.execute("PRAGMA user_version = 999")
    for (name,) in db.execute("SELECT name FROM sqlite_master WHERE type='table'").fetchall():
        if "version" in name or "meta" in name or "migration" in name:
            try:
                db.execute(f"UPDATE {name} SET version = 999")
            except sqlite3.Error:
                pass
    db.commit()
    db.close()


def _nulls(index, saved):
    index.write_bytes(saved)
    db = sqlite3.connect(index)
    cols = [r[1] for r in db.execute("PRAGMA table_info(calibrations)")]
    for c in cols:
        if c != "id":
            try:
                db.execute(f"UPDATE calibrations SET {c} = NULL WHERE id = 1")
            except sqlite3.Error:
                pass
    db.commit()
    db.close()


if __name__ == "__main__":
    sys.exit(main())
