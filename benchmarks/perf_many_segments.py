"""The least-squares fit's time against the number of segments: a custom table scheme of N
static attitudes (random up directions, 2 s each) and N/5 rotations (+/- pairs about six axes),
simulated at the twin's default rate, summarised once, then `lsq.fit` timed with the dense path
(MINPACK's Levenberg-Marquardt on the whole Jacobian, its SVD for the covariance: what every fit
used before) and with the sparse one (Model.is_large: least_squares' trust region with LSMR
steps on the sparse Jacobian, the covariance from the Jacobian with each segment's own
nuisances eliminated), and the largest difference of the two calibrations in 1-sigma.  The
fit takes the sparse path above lsq.LARGE_MODEL parameters (about 100 segments).

Each segment adds 2-3 parameters (a static's attitude, a rotation's phase) and 6-18 residual
rows: the dense path costs rows x parameters^2 (cubic in N), the sparse one grows linearly.

With --diagnosis, also what `station diagnose` computes from the fit (every candidate's score
test and the leave-one-segment-out scores), on the large model's reduced Jacobian.

With --commands N [N ...] (issue 27 item 4), whole processes on bundles on disk instead: a
scheme of N short statics (0.5 s) and N/10 rotations (90 deg/s, 4 s: one turn) recorded by
`station run --sim --no-estimate`-like dry run (station.simulate.dryrun.record_scheme in a process
of its own), then `station estimate` and `station diagnose` of the bundle, and the manifest alone
(read_capture without the samples: YAML and the reader's checks; and the manifest's text written
again from its parts, as the writer does), each as CPU seconds (user + sys of the process and
its children: wait4's resource usage), wall and peak RSS (the largest resident set of the process
and its children: a line per size, so that memory's linearity is read as time's); then the slope of each against the segments
(least squares of CPU on segments over the sizes given, and each size's CPU per segment), so
that linearity is read from the per-segment figures staying flat.  The load average is printed.

With --manifest N [N ...], the manifest alone up to sizes no simulation reaches here: a bundle
of N segments (a run's manifest fields: name, kind, file, status, up_body or axis_body, samples,
sha256, a quoted started_utc, temperature_c; each segment's file a two-row CSV, written without
fsync), its manifest's text made from its parts as CaptureWriter makes it, then read_capture
without the samples (libyaml's parser, the reader's checks of every field and file), each in a
fresh process, CPU seconds, and the slope.

Usage: python benchmarks/perf_many_segments.py [--statics 50 100 250 500 1000] [--dense-up-to 500] [--diagnosis]
       python benchmarks/perf_many_segments.py --manifest 1000 10000 100000
       python benchmarks/perf_many_segments.py --commands 1000 4000 16000 100000 [--keep DIR] [--auto]
"""
import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import random  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from station.estimate import lsq  # noqa: E402
from station.io.scheme import load_scheme  # noqa: E402
from station.simulate import dryrun  # noqa: E402

AXES = ([1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 0], [1, 0, 1], [0, 1, 1])


def _many(directory: Path, statics: int, *, dwell_s: float, rate_dps: float, rotation_s: float,
          rotations: int, digits: int) -> Path:
    """A scheme of ``statics`` statics at random attitudes and ``rotations`` ± pairs about the six
    axes of AXES in turn (names zero-padded to ``digits``; the statics' attitudes from the seed
    ``statics``)."""
    rng = random.Random(statics)
    lines = [f"name: many{statics}", "title: many short segments", "reference: benchmark",
             "defaults:", f"  dwell_s: {dwell_s}", f"  rate_dps: {rate_dps}", f"  rotation_s: {rotation_s}", "segments:"]
    for i in range(statics):
        up = [rng.gauss(0, 1) for _ in range(3)]
        lines.append(f"  - {{static: s{i:0{digits}d}, up_body: [{up[0]:.4f}, {up[1]:.4f}, {up[2]:.4f}]}}")
    for i in range(rotations):
        lines.append(f"  - {{rotation: r{i:0{digits - 1}d}, axis_body: {AXES[i % 6]}}}")
    path = directory / f"many{statics}.yaml"
    path.write_text("\n".join(lines) + "\n")
    return path


def scheme_file(directory: Path, statics: int) -> Path:
    return _many(directory, statics, dwell_s=2.0, rate_dps=30.0, rotation_s=12.0,
                 rotations=max(6, statics // 5), digits=5)


def timed_fit(s, large: bool):
    lsq.LARGE_MODEL = 0 if large else 10**9
    t0, c0 = time.perf_counter(), time.process_time()
    result = lsq.fit(s)
    return result, time.perf_counter() - t0, time.process_time() - c0


def timed_diagnosis(result) -> float:
    """Wall seconds of what `station diagnose` computes from a fit: the score tests of every
    library candidate (station.diagnose.core.diagnose) and the leave-one-segment-out scores."""
    from station.diagnose.core import diagnose
    from station.diagnose.holdout import leave_one_segment_out

    t0 = time.perf_counter()
    diagnose(result)
    leave_one_segment_out(result)
    return time.perf_counter() - t0


def command_scheme(directory: Path, statics: int) -> Path:
    return _many(directory, statics, dwell_s=0.5, rate_dps=90.0, rotation_s=4.0,
                 rotations=max(6, statics // 10), digits=6)


def _process(argv) -> tuple[float, float, float]:
    """(wall s, CPU s of the process tree, peak RSS in MB) of one command, run to its end: the
    process waited for with wait4, whose resource usage is that process's own and its waited
    children's (CPU summed, RSS the largest of them: a forked reader's or figure worker's too)."""
    import subprocess
    import sys
    import tempfile as _tempfile

    with _tempfile.TemporaryFile() as errors:
        t0 = time.perf_counter()
        p = subprocess.Popen([sys.executable, *argv], stdout=subprocess.DEVNULL, stderr=errors)
        _, status, usage = os.wait4(p.pid, 0)
        wall = time.perf_counter() - t0
        p.returncode = os.waitstatus_to_exitcode(status)
        if p.returncode not in (0, 3):
            errors.seek(0)
            raise SystemExit(f"{argv}: exit {p.returncode}: {errors.read()[-1500:].decode(errors='replace')}")
    return wall, usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1024.0


RECORD = ("import sys; from station.io.scheme import load_scheme; from station.simulate import dryrun; "
          "dryrun.record_scheme(load_scheme(sys.argv[1]), dryrun.load_truth(None, 0), 1, sys.argv[2])")
MANIFEST = ("import sys, time; from station.io import capture as C\n"
            "t0 = time.process_time(); cap = C.read_capture(sys.argv[1], load_data=False); t1 = time.process_time()\n"
            "m = C.yaml_text.safe_load(C.read_regular_file(cap.path / C.MANIFEST, limit=C.MAX_MANIFEST_BYTES))\n"
            "t2 = time.process_time(); texts = [C._yaml([e]) for e in m['segments']]; t3 = time.process_time()\n"
            "print(t1 - t0, t3 - t2, len(cap.segments))")
STATION = ("import sys; from station.cli import console_main; sys.argv[0] = 'station'; sys.exit(console_main())")


MANIFEST_ONLY = """
import hashlib, sys, time
from pathlib import Path
from station.io import capture as C
n, d = int(sys.argv[1]), Path(sys.argv[2])
d.mkdir()
row = b"t,ax,ay,az,gx,gy,gz\\n0,0,0,9.8,0,0,0\\n0.01,0,0,9.8,0,0,0\\n"
digest = hashlib.sha256(row).hexdigest()
entries = []
for i in range(n):
    rot = i % 10 == 9
    name = f"r{i:06d}" if rot else f"s{i:06d}"
    (d / f"{name}.csv").write_bytes(row)
    e = {"name": name, "kind": "rotation" if rot else "static", "file": f"{name}.csv", "status": "complete"}
    e.update({"axis_body": [0.0, 0.0, 1.0], "rate_dps": 90.0} if rot else {"up_body": [0.1234, -0.5678, 0.8]})
    e.update({"samples": 2, "sha256": digest, "started_utc": "2026-11-27T14:00:00+00:00", "temperature_c": 25.0})
    entries.append(e)
head = C._yaml({"format": C.FORMAT, "imu": {"sample_rate_hz": 100.0, "accel_unit": "m/s^2", "gyro_unit": "deg/s"},
                "site": {"gravity_mps2": 9.80665}, "scheme": "many"})
t0 = time.process_time()
text = head + "segments:\\n" + "".join(C._yaml([e]) for e in entries)
(d / C.MANIFEST).write_text(text)
t1 = time.process_time()
print(t1 - t0, len(text))
"""
READ_ONLY = ("import sys, time; from station.io import capture as C\n"
             "t0 = time.process_time(); cap = C.read_capture(sys.argv[1], load_data=False); t1 = time.process_time()\n"
             "assert len(cap.segments) == int(sys.argv[2]); print(t1 - t0)")


def manifests(sizes) -> None:
    import shutil
    import subprocess
    import sys

    print(f"load average before: {os.getloadavg()}", flush=True)
    x, write, read = [], [], []
    with tempfile.TemporaryDirectory() as tmp:
        for n in sizes:
            d = Path(tmp) / f"m{n}"
            w, size = subprocess.run([sys.executable, "-c", MANIFEST_ONLY, str(n), str(d)], capture_output=True,
                                     text=True, check=True).stdout.split()
            r = subprocess.run([sys.executable, "-c", READ_ONLY, str(d), str(n)], capture_output=True, text=True,
                               check=True).stdout.split()[0]
            x.append(n)
            write.append(float(w))
            read.append(float(r))
            print(f"{n:7d} segments, manifest {int(size) / 1e6:6.1f} MB: made from its parts {float(w):6.2f} s, "
                  f"read_capture (no samples) {float(r):7.2f} s CPU = {1e6 * float(r) / n:5.0f} us a segment; "
                  f"load {os.getloadavg()[0]:.1f}", flush=True)
            shutil.rmtree(d)
    print(f"load average after: {os.getloadavg()}")
    for name, y in (("made from its parts", write), ("read_capture", read)):
        slope, icpt = np.polyfit(np.array(x, float), np.array(y), 1)
        print(f"{name:20s} slope {1e6 * slope:6.1f} us CPU a segment, intercept {icpt:6.3f} s")


def commands(sizes, keep: Path | None, auto: bool = False) -> None:
    import shutil
    import subprocess
    import sys

    print(f"load average before: {os.getloadavg()}", flush=True)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        base = keep or Path(tmp)
        base.mkdir(parents=True, exist_ok=True)
        for n in sizes:
            cap = base / f"cap{n}"
            scheme = command_scheme(base, n)
            if not (cap / "manifest.yaml").exists():
                shutil.rmtree(cap, ignore_errors=True)
                rec = _process(["-c", RECORD, str(scheme), str(cap)])
            else:
                rec = (float("nan"), float("nan"), float("nan"))
            out = subprocess.run([sys.executable, "-c", MANIFEST, str(cap)], capture_output=True, text=True, check=True)
            read_s, write_s, segments = out.stdout.split()
            est = _process(["-c", STATION, "estimate", str(cap), "-o", str(base / "c.yaml"), "--no-table"])
            dia = _process(["-c", STATION, "diagnose", str(cap), "--json"])
            row = dict(segments=int(segments), record=rec, manifest_read=float(read_s),
                       manifest_write=float(write_s), estimate=est, diagnose=dia)
            if auto:
                row["auto"] = _process(["-c", STATION, "diagnose", str(cap), "--auto", "--json"])
            rows.append(row)
            print(f"{row['segments']:7d} segments: record {rec[1]:8.2f} s CPU ({rec[0]:8.2f} wall); "
                  f"manifest read {row['manifest_read']:7.2f} s, its parts written {row['manifest_write']:6.2f} s; "
                  f"estimate {est[1]:8.2f} s CPU ({est[0]:8.2f} wall, {est[2]:7.0f} MB peak); diagnose "
                  f"{dia[1]:8.2f} s CPU ({dia[0]:8.2f} wall, {dia[2]:7.0f} MB peak)"
                  + (f"; diagnose --auto {row['auto'][1]:8.2f} s CPU ({row['auto'][0]:8.2f} wall, "
                     f"{row['auto'][2]:7.0f} MB peak)" if auto else "")
                  + f"; load {os.getloadavg()[0]:.1f}", flush=True)
            if not keep:
                shutil.rmtree(cap, ignore_errors=True)
    print(f"load average after: {os.getloadavg()}")
    x = np.array([r["segments"] for r in rows], dtype=float)
    # (name, value of a row, its unit, the unit of its share a segment and that unit in the value's)
    series = [("record", lambda r: r["record"][1], "s", "ms CPU", 1e-3),
              ("manifest read", lambda r: r["manifest_read"], "s", "ms CPU", 1e-3),
              ("manifest parts written", lambda r: r["manifest_write"], "s", "ms CPU", 1e-3),
              ("estimate", lambda r: r["estimate"][1], "s", "ms CPU", 1e-3),
              ("diagnose", lambda r: r["diagnose"][1], "s", "ms CPU", 1e-3)]
    series += [(f"{c} peak RSS", lambda r, c=c: r[c][2], "MB", "kB", 1e-3) for c in ("estimate", "diagnose")]
    if any("auto" in r for r in rows):
        series += [("diagnose --auto", lambda r: r.get("auto", (np.nan,) * 3)[1], "s", "ms CPU", 1e-3),
                   ("diagnose --auto peak RSS", lambda r: r.get("auto", (np.nan,) * 3)[2], "MB", "kB", 1e-3)]
    for name, get, unit, per_unit, scale in series:
        y = np.array([get(r) for r in rows], dtype=float)
        ok = np.isfinite(y)
        if ok.sum() >= 2:
            slope, icpt = np.polyfit(x[ok], y[ok], 1)
            per = ", ".join(f"{v / s / scale:.2f}" for v, s in zip(y[ok], x[ok]))
            print(f"{name:24s} slope {slope / scale:7.3f} {per_unit} a segment, intercept {icpt:7.2f} {unit}; "
                  f"a segment at each size: {per} {per_unit}")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--statics", type=int, nargs="+", default=[50, 100, 250, 500, 1000])
    ap.add_argument("--dense-up-to", type=int, default=500, help="statics above which the dense path is not timed")
    ap.add_argument("--diagnosis", action="store_true",
                    help="also time the diagnosis of the sparse fit (score tests, leave-one-segment-out)")
    ap.add_argument("--commands", type=int, nargs="+", metavar="N",
                    help="whole processes on bundles of N statics + N/10 rotations (record, manifest, estimate, diagnose)")
    ap.add_argument("--keep", type=Path, help="with --commands: keep the bundles here (recorded once)")
    ap.add_argument("--auto", action="store_true", help="with --commands: also time `station diagnose --auto`")
    ap.add_argument("--manifest", type=int, nargs="+", metavar="N",
                    help="the manifest alone: made and read with N segments (read_capture without samples)")
    a = ap.parse_args()
    if a.manifest:
        manifests(a.manifest)
        return
    if a.commands:
        commands(a.commands, a.keep, a.auto)
        return
    default = lsq.LARGE_MODEL
    with tempfile.TemporaryDirectory() as tmp:
        for n in a.statics:
            scheme = load_scheme(str(scheme_file(Path(tmp), n)))
            s = lsq.summarise(dryrun.simulate_capture(scheme, dryrun.load_truth(None, 0), 1))
            sparse, wall_s, cpu_s = timed_fit(s, True)
            size, rows = sparse.model.layout.size, len(sparse.residuals)
            line = (f"{len(s.statics):5d} statics {len(s.rotations):4d} rotations: {size:5d} parameters, "
                    f"{rows:6d} rows; sparse {wall_s:7.2f} s (cpu {cpu_s:6.2f} s)")
            if a.diagnosis:
                line += f", its diagnosis {timed_diagnosis(sparse):6.2f} s"
            if n <= a.dense_up_to:
                dense, wall_d, cpu_d = timed_fit(s, False)
                _, v_s, _, cov_s = lsq.reported(sparse, "m/s^2", "deg/s")
                _, v_d, _, cov_d = lsq.reported(dense, "m/s^2", "deg/s")
                sigma = np.sqrt(np.diag(cov_d))
                line += (f", dense {wall_d:7.2f} s (cpu {cpu_d:6.2f} s): {wall_d / wall_s:5.1f} x; "
                         f"largest difference {np.max(np.abs(v_s - v_d) / sigma):.1e} sigma, 1-sigma "
                         f"{np.max(np.abs(np.sqrt(np.diag(cov_s)) / sigma - 1)):.1e} relative")
            print(line, flush=True)
    lsq.LARGE_MODEL = default
    print(f"(estimate takes the sparse path above {default} parameters)")


if __name__ == "__main__":
    main()
