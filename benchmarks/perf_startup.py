"""Start-up of the command line: `station --help` (and a few light commands) against
`python -c 'import numpy'`, whole processes, paired runs in one go (issue 15's goal: --help
under 2x importing numpy).

Each repetition runs the reference and then every command once, so that machine load hits both
alike; the figures are medians over the repetitions, and the ratio is the median of the
per-repetition ratios.

Usage: python benchmarks/perf_startup.py [--repeat 15]
"""
from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

STATION = str(Path(sys.executable).with_name("station"))
COMMANDS = {
    "station --help": [STATION, "--help"],
    "station estimate --help": [STATION, "estimate", "--help"],
    "station effects": [STATION, "effects"],
    "station plan --scheme optimal9": [STATION, "plan", "--scheme", "optimal9"],
    "station schemes": [STATION, "schemes"],       # every built-in scheme compiled (issue 26)
}
REFERENCE = [sys.executable, "-c", "import numpy"]


def wall(cmd) -> float:
    t0 = time.perf_counter()
    subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=True,
                   env={k: v for k, v in os.environ.items() if not k.startswith("STATION_")})
    return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=15)
    a = ap.parse_args()
    wall(REFERENCE), wall(COMMANDS["station --help"])          # warm the file cache
    ref, times = [], {name: [] for name in COMMANDS}
    for _ in range(a.repeat):
        ref.append(wall(REFERENCE))
        for name, cmd in COMMANDS.items():
            times[name].append(wall(cmd))
    r = statistics.median(ref)
    print(f"{a.repeat} paired runs, {os.cpu_count()} cores; medians of whole processes")
    print(f"  python -c 'import numpy'          {r * 1e3:7.0f} ms")
    for name, ts in times.items():
        ratio = statistics.median(t / x for t, x in zip(ts, ref))
        print(f"  {name:32s} {statistics.median(ts) * 1e3:7.0f} ms  = {ratio:.2f} x import numpy")
    help_ratio = statistics.median(t / x for t, x in zip(times["station --help"], ref))
    print(f"goal --help < 2 x import numpy: {'met' if help_ratio < 2 else 'NOT met'} ({help_ratio:.2f} x)")


if __name__ == "__main__":
    main()
