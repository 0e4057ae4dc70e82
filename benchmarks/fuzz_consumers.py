"""The long run of tests/test_fuzz_consumers.py: a real calibration file and capture manifest
mutated in their structure and run through show, apply, export (every format), diff,
diagnose --calib and estimate, with fresh random examples (the explore profile), and the number
of cases and of commands run counted from Hypothesis' statistics.

Usage: python benchmarks/fuzz_consumers.py [--examples 400] [--workers 2]
A finding fails the run and prints Hypothesis' falsifying example (its @reproduce_failure).
"""
from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent.parent


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--examples", type=int, default=400, help="examples per fuzz test")
    ap.add_argument("--workers", type=int, default=2)
    a = ap.parse_args()
    env = dict(os.environ, STATION_FUZZ_EXAMPLES=str(a.examples), PYTHONPATH=str(HERE))
    t0 = time.perf_counter()
    p = subprocess.run([sys.executable, "-m", "pytest", "tests/test_fuzz_consumers.py", "-n", str(a.workers),
                        "-p", "no:cacheprovider", "--hypothesis-profile", "explore", "--hypothesis-show-statistics"],
                       cwd=HERE, env=env, capture_output=True, text=True)
    elapsed = time.perf_counter() - t0
    text = p.stdout + p.stderr
    cases = sum(int(n) for n in re.findall(r"- (\d+) passing examples", text))
    events = re.findall(r"\* ([\d.]+)%, (\w+): exit (\d+)", text)
    print(f"{cases} mutated documents run through the commands in {elapsed:.0f} s "
          f"({a.examples} examples asked per test; pytest exit status {p.returncode})")
    for line in text.splitlines():
        if re.search(r"passing examples|exit \d|Falsifying|reproduce_failure|Error|FAILED", line):
            print(line)
    return p.returncode


if __name__ == "__main__":
    sys.exit(main())
