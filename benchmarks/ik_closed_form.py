"""The closed-form inverse kinematics (station/bench/gimbal.py, issue 26) against the iterative
solve it replaced: the 7 built-in schemes compiled for 7 tables (the default configuration and
1-, 2- and 3-axis tables with and without an operator: 49 plans), once with the closed form and
once with the iterative solve only (gimbal.CLOSED_FORM = False), each in a fresh memory of
solves.  Every plan must have the same steps, segments, axes, operator instructions and notes;
the angles and durations may differ by round-off only.  Prints the largest differences, how many
plans are byte for byte identical, and the CPU seconds of each compilation.

Usage: python benchmarks/ik_closed_form.py      (exit status 1 if a plan differs beyond 1e-9)
"""
from __future__ import annotations

import dataclasses
import math
import pickle
import sys
import time

import numpy as np

import station.bench.gimbal as gimbal
from station.bench.compile import compile_scheme
from station.bench.config import Config, RunConfig, TableConfig
from station.core.errors import UserError
from station.io.scheme import builtin_names, load_scheme

TABLES = {"default": Config(), **{f"{k}-axis{' operator' if op else ''}": Config(table=TableConfig(axes=k),
                                                                                 run=RunConfig(operator=op))
                                  for k in (1, 2, 3) for op in (True, False)}}


def compile_all(closed: bool) -> tuple[dict, float]:
    gimbal.CLOSED_FORM = closed
    gimbal._SOLVED.clear()
    out, t0 = {}, time.process_time()
    for name in builtin_names():
        scheme = load_scheme(name)
        for table, config in TABLES.items():
            try:
                out[(name, table)] = compile_scheme(scheme, config)
            except UserError as e:                     # e.g. screwdriver's 720 deg/s: the same message
                out[(name, table)] = ("error", str(e))
    return out, time.process_time() - t0


def compare(a, b, path: str, worst: dict) -> None:
    """Same structure and text; floats within 1e-9 (deg, s); the largest difference per field."""
    if type(a) is not type(b):
        raise AssertionError(f"{path}: {type(a).__name__} against {type(b).__name__}")
    if dataclasses.is_dataclass(a):
        for f in dataclasses.fields(a):
            compare(getattr(a, f.name), getattr(b, f.name), f"{path}.{f.name}", worst)
    elif isinstance(a, dict):
        assert a.keys() == b.keys(), path
        for k in a:
            compare(a[k], b[k], f"{path}[{k!r}]", worst)
    elif isinstance(a, (list, tuple, np.ndarray)):
        assert len(a) == len(b), f"{path}: {len(a)} against {len(b)} items"
        for i, (u, v) in enumerate(zip(a, b)):
            compare(u, v, f"{path}[{i}]", worst)
    elif isinstance(a, (float, np.floating)):
        d = abs(float(a) - float(b))
        field = path.rsplit(".", 1)[-1].split("[")[0]
        worst[field] = max(worst.get(field, 0.0), d)
        assert d < 1e-9 * max(1.0, abs(float(a))) or (math.isnan(a) and math.isnan(b)), (path, a, b)
    elif hasattr(a, "__dict__") and not isinstance(a, (str, int)):
        compare(vars(a), vars(b), path, worst)
    else:
        assert a == b, (path, a, b)


def main() -> int:
    closed, t_closed = compile_all(True)
    iterative, t_iter = compile_all(False)
    gimbal.CLOSED_FORM = True
    worst: dict = {}
    failed = 0
    for key in iterative:
        try:
            compare(iterative[key], closed[key], f"{key[0]} on {key[1]}", worst)
        except AssertionError as e:
            failed += 1
            print("DIFFERS:", e)
    same = sum(pickle.dumps(closed[k]) == pickle.dumps(iterative[k]) for k in closed)
    print(f"{len(closed)} plans; {len(closed) - failed} the same to 1e-9, {same} byte for byte identical")
    print("largest differences:", ", ".join(f"{k} {v:.2g}" for k, v in sorted(worst.items()) if v) or "none")
    print(f"CPU to compile the {len(closed)}: closed form {t_closed:.2f} s, iterative {t_iter:.2f} s")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
