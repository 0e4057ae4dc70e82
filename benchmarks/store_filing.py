"""Filing calibrations into the shared store from concurrent writer processes: a real PostgreSQL
server started here from the system's binaries (fsync on, as a lab's server runs; stopped at the
end), and the same load on the SQLite store for comparison.

DISTINCT calibrations of distinct captures (UNITS units) are split among WRITERS processes; each
writer also files OVERLAP of another writer's calibrations (the same bytes, racing) and OVERLAP
re-estimates (the same capture and model, other bytes: must not be filed).  Checked after: one
row per capture (0 duplicated), every capture present (0 lost), every row's file whole (its
sha256), 21 numbers per row.  Then the time of ``station fleet --json`` over the whole store.

Usage:  python benchmarks/store_filing.py [--calibrations 10000] [--writers 8] [--backend both|postgresql|sqlite]
        python benchmarks/store_filing.py --verify-cost [--calibrations 10000] [--pairs 5]

``--verify-cost`` (issue 26): the cost of checking every row against its file's sha256, on a SQLite
store of CALIBRATIONS files put in place and indexed by ``Store.rebuild`` (timed too, it reads
every file): ``Store.filed()`` without and with the check in interleaved pairs (CPU time of this
process; the ratio is what matters on a loaded machine), then ``station fleet --json`` (whole
processes, wall and CPU of the child).
"""
import argparse
import hashlib
import os
import random
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests"))

from pg_server import Server, unavailable  # noqa: E402

WRITER = HERE.parent / "tests" / "_store_writer.py"


def base_calibration(tmp: Path) -> str:
    out = tmp / "cap"
    subprocess.run([sys.executable, "-m", "station.cli", "run", "--scheme", "optimal9", "--sim", "--seed", "13",
                    "--out", str(out), "--dwell-s", "20", "--rotation-s", "36", "--no-history"],
                   check=True, capture_output=True)
    return (out / "calibration.yaml").read_text()


def variant(text: str, serial: str, capture: str, date: str, bias: float) -> str:
    text = re.sub(r"(?m)^  imu_serial: .*$", f"  imu_serial: {serial}", text)
    text = re.sub(r"(?m)^  capture_sha256: .*$", f"  capture_sha256: {capture}", text)
    text = re.sub(r"(?m)^  date_utc: .*$", f"  date_utc: '{date}'", text)
    return re.sub(r"(accel_bias_x:\n    value: )[^\n]+", lambda m: f"{m.group(1)}{bias!r}", text)


def make(tmp: Path, n: int, units: int) -> tuple:
    text = base_calibration(tmp)
    folder = tmp / "cals"
    folder.mkdir()
    paths, again, keys = [], [], set()
    rng = random.Random(1)
    for k in range(n):
        serial, capture = f"SN-{k % units:05d}", hashlib.sha256(f"capture {k}".encode()).hexdigest()
        date = f"20{30 + k // units % 60:02d}-01-01T00:00:00Z"
        for store, second in ((paths, "00"), (again, "01")):
            path = folder / f"{k:05d}-{second}.yaml"
            path.write_text(variant(text, serial, capture, date[:-3] + second + "Z", 1600 + rng.gauss(0, 50)))
            store.append(path)
        keys.add((serial, capture))
    return paths, again, keys


def check(location, files, keys) -> dict:
    from station.io.history import Store

    with Store(location, files=files) as s:
        filed = s.filed()
    seen = [(f.entry.serial, f.entry.path) for f in filed]
    captures = {}
    for f in filed:
        data = f.entry.path.read_bytes()
        assert hashlib.sha256(data).hexdigest() == f.entry.sha256, f.entry.path
        assert len(f.numbers) == 21, f.entry.id
        capture = re.search(rb"capture_sha256: (\w+)", data).group(1).decode()
        captures[(f.entry.serial, capture)] = captures.get((f.entry.serial, capture), 0) + 1
    return {"rows": len(seen), "lost": len(keys - set(captures)),
            "duplicated": sum(c - 1 for c in captures.values()) + len(set(captures) - keys)}


def run(location, files, lists) -> float:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(HERE.parent), *sys.path])}
    t0 = time.perf_counter()
    procs = [subprocess.Popen([sys.executable, str(WRITER), location, str(files), str(lst)], env=env,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for lst in lists]
    outs = [p.communicate() for p in procs]
    wall = time.perf_counter() - t0
    for p, (out, err) in zip(procs, outs):
        if p.returncode != 0:
            raise SystemExit(f"a writer failed: {err[-2000:]}")
    new = sum(int(out.split()[1]) for out, _ in outs)
    print(f"  writers said: {new} filed new, {sum(int(out.split()[2]) for out, _ in outs)} already filed")
    return wall


def fleet_time(location, files) -> float:
    """Wall time of ``station fleet --json`` over the whole store (a fresh process)."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(HERE.parent), *sys.path]), "STATION_HISTORY_DIR": str(files)}
    t0 = time.perf_counter()
    r = subprocess.run([sys.executable, "-m", "station.cli", "fleet", "--store", location, "--json"], env=env,
                       capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if r.returncode != 0:
        raise SystemExit(f"station fleet failed: {r.stderr[-2000:]}")
    return wall


def verify_cost(n: int, units: int, pairs: int) -> None:
    from station.io.history import Store, serial_folder

    with tempfile.TemporaryDirectory(prefix="store-verify-") as tmp:
        tmp = Path(tmp)
        text = base_calibration(tmp)
        root = tmp / "store"
        rng = random.Random(1)
        t0 = time.perf_counter()
        for k in range(n):
            serial = f"SN-{k % units:05d}"
            body = variant(text, serial, hashlib.sha256(f"capture {k}".encode()).hexdigest(),
                           f"20{30 + k // units % 60:02d}-01-01T00:00:00Z", 1600 + rng.gauss(0, 50))
            folder = root / serial_folder(serial)
            folder.mkdir(parents=True, exist_ok=True)
            (folder / f"{k:05d}.yaml").write_text(body)
        print(f"{n} calibration files ({sum(p.stat().st_size for p in root.rglob('*.yaml')) / n / 1024:.1f} kB each) "
              f"written in {time.perf_counter() - t0:.1f} s; {os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}")
        with Store(root) as store:
            c0, w0 = time.process_time(), time.perf_counter()
            r = store.rebuild()
            print(f"history --rebuild: {len(r.filed)} filed, {len(r.skipped)} skipped in {time.perf_counter() - w0:.1f} s "
                  f"wall, {time.process_time() - c0:.1f} s CPU")
            plain, checked = [], []
            for _ in range(pairs):
                for verify, into in ((False, plain), (True, checked)):
                    c0 = time.process_time()
                    filed = store.filed(verify=verify)
                    into.append(time.process_time() - c0)
                    assert len(filed) == n and not any(f.entry.problem for f in filed)
        print(f"Store.filed() on {n} rows, CPU s (min of {pairs}, interleaved): without the check {min(plain):.2f}, "
              f"with it {min(checked):.2f} (+{min(checked) - min(plain):.2f} s, {min(checked) / min(plain):.2f} x; "
              f"{(min(checked) - min(plain)) / n * 1e3:.3f} ms a row)")
        env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(HERE.parent), *sys.path])}
        for _ in range(2):
            t0 = time.perf_counter()
            before = os.times()
            r = subprocess.run([sys.executable, "-m", "station.cli", "fleet", "--store", str(root), "--json"], env=env,
                               capture_output=True, text=True)
            after = os.times()
            if r.returncode != 0:
                raise SystemExit(f"station fleet failed: {r.stderr[-2000:]}")
            print(f"station fleet --json on {n}: {time.perf_counter() - t0:.1f} s wall, "
                  f"{after.children_user + after.children_system - before.children_user - before.children_system:.1f} s CPU")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--verify-cost", action="store_true")
    ap.add_argument("--pairs", type=int, default=5)
    ap.add_argument("--calibrations", type=int, default=10_000)
    ap.add_argument("--writers", type=int, default=8)
    ap.add_argument("--units", type=int, default=500)
    ap.add_argument("--backend", choices=("both", "postgresql", "sqlite"), default="both")
    a = ap.parse_args()
    if a.verify_cost:
        return verify_cost(a.calibrations, a.units, a.pairs)
    with tempfile.TemporaryDirectory(prefix="store-bench-") as tmp:
        tmp = Path(tmp)
        t0 = time.perf_counter()
        paths, again, keys = make(tmp, a.calibrations, a.units)
        print(f"{len(paths)} calibrations and {len(again)} re-estimates written in {time.perf_counter() - t0:.1f} s")
        share = [paths[w::a.writers] for w in range(a.writers)]
        overlap = max(1, len(paths) // a.writers // 10)
        lists = []
        for w in range(a.writers):
            mine = list(share[w]) + share[(w + 1) % a.writers][:overlap] + again[w::a.writers][:overlap]
            random.Random(w).shuffle(mine)
            lst = tmp / f"writer{w}.txt"
            lst.write_text("".join(f"{p}\n" for p in mine))
            lists.append(lst)
        attempts = sum(len(lst.read_text().splitlines()) for lst in lists)
        print(f"{a.writers} writers, {attempts} filings ({overlap} of another writer's and {overlap} re-estimates "
              f"each); {os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}")
        backends = ("postgresql", "sqlite") if a.backend == "both" else (a.backend,)
        for backend in backends:
            files = tmp / f"files-{backend}"
            server = None
            if backend == "postgresql":
                why = unavailable()
                if why:
                    print(f"postgresql: skipped: {why}")
                    continue
                server = Server(fsync=True).start()
                location = server.create_database("bench")
            else:
                location = str(files)
            try:
                wall = run(location, files, lists)
                result = check(location, files, keys)
                fleet_s = fleet_time(location, files)
            finally:
                if server is not None:
                    server.stop()
            print(f"{backend}: {a.calibrations} calibrations from {a.writers} writers in {wall:.1f} s "
                  f"({attempts / wall:.0f} filings/s, {a.calibrations / wall:.0f} new/s); rows {result['rows']}, "
                  f"lost {result['lost']}, duplicated {result['duplicated']}; station fleet --json on them: {fleet_s:.1f} s")


if __name__ == "__main__":
    main()
