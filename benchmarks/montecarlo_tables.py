"""The 2010 paper's Monte Carlo tables 3, 4 and 5 with the least-squares estimator, against the
Cramér-Rao bound, as markdown (docs/method-lsq.md).

Runs `station montecarlo --json` for each table (500 runs each by default; about 10 minutes a
table on 2 idle cores), or formats JSON files already made with --from DIR (t3.json, t4.json,
t5.json).  Usage:
    python benchmarks/montecarlo_tables.py [--runs 500] [--from DIR]
"""
import argparse
import json
import subprocess
import sys
from pathlib import Path

TABLES = {
    "t4": ("Table 4: optimal9, 100 µg/√Hz, 0.03 °/h/√Hz", ["--scheme", "optimal9", "--accel-noise-ug", "100",
                                                          "--gyro-noise-dph", "0.03"]),
    "t3": ("Table 3: optimal9, 500 µg/√Hz, 0.1 °/h/√Hz", ["--scheme", "optimal9", "--accel-noise-ug", "500",
                                                         "--gyro-noise-dph", "0.1"]),
    "t5": ("Table 5: chatfield18, 500 µg/√Hz, 0.1 °/h/√Hz", ["--scheme", "chatfield18", "--accel-noise-ug", "500",
                                                            "--gyro-noise-dph", "0.1"]),
}


def table(doc) -> str:
    lines = [f"| parameter | unit | std of error | Cramér–Rao bound | std / bound | mean reported 1σ | 1σ / std |",
             "|---|---|---:|---:|---:|---:|---:|"]
    worst_bound, worst_sigma = 0.0, 0.0
    for p in doc["parameters"]:
        r1, r2 = p["std"] / p["crlb"], p["mean_sigma"] / p["std"]
        worst_bound, worst_sigma = max(worst_bound, r1), max(worst_sigma, abs(r2 - 1))
        lines.append(f"| {p['name']} | {p['unit']} | {p['std']:.4g} | {p['crlb']:.4g} | {r1:.3f} | "
                     f"{p['mean_sigma']:.4g} | {r2:.3f} |")
    lines.append(f"\nLargest std/bound {worst_bound:.3f} (required ≤ 1.1); largest |1σ/std − 1| "
                 f"{worst_sigma:.3f} (required ≤ 0.15); {doc['runs']} runs.")
    return "\n".join(lines)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=500)
    ap.add_argument("--from", dest="source")
    a = ap.parse_args()
    for key, (title, args) in TABLES.items():
        if a.source:
            doc = json.loads((Path(a.source) / f"{key}.json").read_text())
        else:
            out = subprocess.run([sys.executable, "-m", "station.cli", "montecarlo", "--runs", str(a.runs),
                                  "--json", *args], check=True, capture_output=True, text=True).stdout
            doc = json.loads(out)
        print(f"**{title}** (settings {doc['settings']})\n\n{table(doc)}\n")


if __name__ == "__main__":
    main()
