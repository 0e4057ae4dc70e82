"""The temperature goal of issue 28 (docs/design.md, thirteenth session), as whole processes:
`station design` for temperature_bias (worst 1σ of the temperature coefficients, --centred,
3715 s), its CPU (children included), the design's worst 1σ against the best built-in's at the
same time, then `station montecarlo --scheme` on the written file: the spread of N runs over the
predicted 1σ per coefficient and pooled (√ of the mean of squares, its own 1σ √(1/(2k(N-1)))).

    python benchmarks/design_temperature.py [--runs 24] [--out DIR] [--config station.yaml]

With ``--config`` a station.yaml with a temperature chamber (fourteenth session: ``chamber:``
kind manual, range_c [20, 60], ramp_c_per_min 3, soak_s 300): the design places segments at the
chamber's setpoint, the built-ins run at the room's temperature and its warm-up, and the Monte
Carlo runs the chamber (``station montecarlo --config``).

With ``--quadratic`` (fifteenth session: several setpoints) the model is temperature_bias and
temperature_bias_quadratic and the criterion the worst 1σ of the T² coefficients
(``worst:*_tempco2_*``): with a chamber the design is offered the middle of its span as well.

Heavy (a design and N dry runs: ~2 minutes of CPU); not a test."""
from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def run(*args) -> tuple[subprocess.CompletedProcess, float, float]:
    """(the process, its CPU seconds with its children, wall seconds)."""
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "station.cli", *map(str, args)], capture_output=True,
                          text=True, env=env)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return done, cpu, wall


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=24)
    ap.add_argument("--out", default=None)
    ap.add_argument("--config", default=None, help="station.yaml (a chamber: the fourteenth session's goal)")
    ap.add_argument("--quadratic", action="store_true",
                    help="add temperature_bias_quadratic, criterion worst:*_tempco2_* (fifteenth session)")
    a = ap.parse_args()
    config = ("--config", a.config) if a.config else ()
    effects = ("--add", "temperature_bias") + (("--add", "temperature_bias_quadratic") if a.quadratic else ())
    pattern = "_tempco2_" if a.quadratic else "_tempco_"
    out = Path(a.out or tempfile.mkdtemp(prefix="design-temperature-"))
    out.mkdir(parents=True, exist_ok=True)
    scheme = out / "temp.yaml"
    done, cpu, wall = run("design", "--duration", 3715, *effects, "--criterion",
                          f"worst:*{pattern}*", "--centred", "--verify-runs", 0, "-o", scheme, "--json", *config)
    if done.returncode != 0:
        sys.exit(done.stderr[-3000:])
    report = json.loads(done.stdout)
    print(f"design: {cpu:.1f} s of CPU (children included), {wall:.0f} s wall; load {os.getloadavg()[0]:.1f}")
    for line in done.stderr.splitlines():
        if "criterion" in line:
            print("  " + line)
    value = report["designed"]["criterion"]
    best = min((b for b in report["builtins"] if b.get("criterion") is not None), key=lambda b: b["criterion"])
    print(f"worst 1σ {value:.4g} µg/°C{'²' if a.quadratic else ''} ({report['duration_s']:.0f} s, statics of {report['static_attitudes']} "
          f"attitude); best built-in {best['scheme']} {best['criterion']:.4g}: {100 * (1 - value / best['criterion']):.1f} % lower")
    done, cpu, wall = run("montecarlo", "--scheme", scheme, "--runs", a.runs, *effects, "--json", *config)
    if done.returncode != 0:
        sys.exit(done.stderr[-3000:])
    pred = {p["name"]: p["sigma"] for p in report["designed"]["parameters"]}
    rows = [r for r in json.loads(done.stdout)["parameters"] if pattern in r["name"]]
    ratios = np.array([r["std"] / pred[r["name"]] for r in rows])
    for r, q in zip(rows, ratios):
        print(f"  {r['name']:22s} spread {r['std']:.4g}  predicted {pred[r['name']]:.4g}  ratio {q:.3f}  "
              f"Cramér-Rao/predicted {r['crlb'] / pred[r['name']]:.4f}")
    k = len(ratios)
    print(f"Monte Carlo N = {a.runs}: pooled {np.sqrt(np.mean(ratios ** 2)):.3f} "
          f"(its 1σ {np.sqrt(1 / (2 * k * (a.runs - 1))):.3f}); {cpu:.0f} s of CPU")


if __name__ == "__main__":
    main()
