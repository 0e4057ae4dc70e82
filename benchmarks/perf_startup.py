"""Start-up of the command line: `station --help` (and a few light commands) against
`python -c 'import numpy'`, whole processes, paired runs in one go (issue 15's goal: --help
under 2x importing numpy).

Each repetition runs the reference and then every command once, so that machine load hits both
alike; the figures are medians over the repetitions, and the ratio is the median of the
per-repetition ratios.

`station schemes` and `station plan` are measured with the compiled plans' cache
(station/bench/compile_cache.py) warm (a cache folder of this run's, filled by the warm-up) and
off (STATION_CACHE_DIR=off: every scheme compiled, as a first run).  Besides wall time each
process's CPU time (user + system, from wait4) is kept: on a loaded machine it is the steadier.

Usage: python benchmarks/perf_startup.py [--repeat 15]
"""
from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

STATION = str(Path(sys.executable).with_name("station"))
COMMANDS = {
    "station --help": [STATION, "--help"],
    "station estimate --help": [STATION, "estimate", "--help"],
    "station effects": [STATION, "effects"],
    "station plan --scheme optimal9": [STATION, "plan", "--scheme", "optimal9"],
    "station plan --scheme optimal9 (no cache)": ["off", STATION, "plan", "--scheme", "optimal9"],
    "station schemes": [STATION, "schemes"],       # every built-in scheme: from the cache (issue 26)
    "station schemes (no cache)": ["off", STATION, "schemes"],    # every one compiled
}
REFERENCE = [sys.executable, "-c", "import numpy"]
CACHE = tempfile.mkdtemp(prefix="perf-startup-cache-")
CPU: dict = {}


def wall(cmd) -> float:
    """Wall time of the whole process; its CPU time (user + system) into CPU[tuple(cmd)]."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("STATION_")}
    env["STATION_CACHE_DIR"] = CACHE
    if cmd[0] == "off":
        env["STATION_CACHE_DIR"], cmd = "off", cmd[1:]
    t0 = time.perf_counter()
    p = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
    _, status, usage = os.wait4(p.pid, 0)
    p.returncode = os.waitstatus_to_exitcode(status)
    elapsed = time.perf_counter() - t0
    if p.returncode != 0:
        raise SystemExit(f"{cmd}: exit status {p.returncode}")
    CPU.setdefault(tuple(cmd) + (env["STATION_CACHE_DIR"] == "off",), []).append(usage.ru_utime + usage.ru_stime)
    return elapsed


def cpu(cmd) -> list:
    off = cmd[0] == "off"
    return CPU[tuple(cmd[1:] if off else cmd) + (off,)]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=15)
    a = ap.parse_args()
    for cmd in (REFERENCE, *COMMANDS.values()):     # warm the file cache and the plans' cache
        wall(cmd)
    CPU.clear()
    ref, times = [], {name: [] for name in COMMANDS}
    for _ in range(a.repeat):
        ref.append(wall(REFERENCE))
        for name, cmd in COMMANDS.items():
            times[name].append(wall(cmd))
    r = statistics.median(ref)
    ref_cpu = cpu(REFERENCE)
    print(f"{a.repeat} paired runs, {os.cpu_count()} cores, load {os.getloadavg()[0]:.1f} at the end; "
          "medians of whole processes (wall, CPU)")
    print(f"  {'python -c import numpy':42s} {r * 1e3:7.0f} ms wall {statistics.median(ref_cpu) * 1e3:6.0f} ms CPU")
    for name, ts in times.items():
        ratio = statistics.median(t / x for t, x in zip(ts, ref))
        cs = cpu(COMMANDS[name])
        cratio = statistics.median(c / x for c, x in zip(cs, ref_cpu))
        print(f"  {name:42s} {statistics.median(ts) * 1e3:7.0f} ms wall = {ratio:.2f} x import numpy; "
              f"{statistics.median(cs) * 1e3:6.0f} ms CPU = {cratio:.2f} x")
    help_ratio = statistics.median(t / x for t, x in zip(times["station --help"], ref))
    print(f"goal --help < 2 x import numpy: {'met' if help_ratio < 2 else 'NOT met'} ({help_ratio:.2f} x)")


if __name__ == "__main__":
    main()
