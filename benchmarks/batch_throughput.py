"""Batch throughput (docs/fleet.md, "Batches"): `station batch estimate` over N simulated
captures on a local Dask cluster and on a scheduler + workers started as separate processes,
against the ceiling "single-process estimate rate x cores".

    python benchmarks/batch_throughput.py make DIR [--n 1000]      # the captures (simulator)
    python benchmarks/batch_throughput.py run DIR [--single 100]   # the measurements

Every figure is given as wall time and as CPU time (user + sys of every process of the run,
from /proc of the workers, or RUSAGE_CHILDREN for the command), with the load average: the
machine is shared.  The captures: optimal9 with 5 s dwells and 5 s rotations (21 segments,
~0.65 MB each), each its own seed, made by station.api.simulate (the simulated bench)."""
from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import socket
import subprocess
import sys
import time
from pathlib import Path

DWELL_S = ROTATION_S = 5.0


def make(directory: Path, n: int) -> None:
    from station import api

    directory.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    for i in range(n):
        out = directory / f"cap{i:04d}"
        if (out / "manifest.yaml").exists():
            continue
        api.simulate("optimal9", out, seed=1 + i, dwell_s=DWELL_S, rotation_s=ROTATION_S)
    print(f"{n} captures in {directory} ({time.perf_counter() - started:.0f} s)")


if __name__ == "__main__" and len(sys.argv) > 1 and sys.argv[1] == "make":
    p = argparse.ArgumentParser()
    p.add_argument("what")
    p.add_argument("directory", type=Path)
    p.add_argument("--n", type=int, default=1000)
    a = p.parse_args()
    make(a.directory, a.n)
    sys.exit(0)
