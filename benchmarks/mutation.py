"""Mutation testing of the modules behind honesty and safety (issue 30 item 6), with mutmut.

One module at a time (mutation runs are CPU-heavy and the machine is shared): the tracked files
of this clone are copied into a scratch directory, the tests kept there are the ones named for
that module below, the [tool.mutmut] configuration is written for that module alone (every other
.py file of its package left unmutated), and `mutmut run` is started there with --children
processes.  Then every surviving mutant is printed with its diff, and the counts and the score
(killed / (killed + survived + no tests + timeouts)) as one JSON line per module.

Usage:
    python benchmarks/mutation.py [MODULE ...] [--children 1] [--keep DIR] [--list]

MODULE is a key of MODULES (default: all, one after the other).  Survivors are read and either
killed by a test or explained in docs/testing.md.
"""
import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: module -> the tests that guard it (kept in the scratch copy; helpers and data always kept)
MODULES = {
    "station/estimate/verdict.py": ["tests/test_verdicts.py", "tests/test_verdict_rules.py"],
    "station/model/compensate.py": ["tests/test_effects_raw_counts.py", "tests/test_effect_plugins.py",
                                    "tests/test_cli.py"],
    "drivers/vectornav.py": ["tests/test_drivers_decoders.py", "tests/test_decoders_long_reads.py",
                             "tests/test_drivers_damage_counts.py", "tests/test_fuzz_readers.py"],
    "station/io/capture.py": ["tests/test_capture.py", "tests/test_capture_kill.py",
                              "tests/test_capture_streaming.py"],
}


# mutmut's own timeout is 4 x (the mutant's tests' time in the statistics run + 1 s); on a shared
# machine whose load swings by 10x between that run and a mutant's, sound mutants were killed as
# timeouts (32 of the first 55 of verdict.py at a load average of 25 on 2 cores).  The same check,
# with the factor given (--timeout-factor, default 20).
RUNNER = """
import os, signal, sys
from datetime import datetime
from time import sleep
import mutmut.__main__ as m

FACTOR = float(os.environ["MUTATION_TIMEOUT_FACTOR"])


def timeout_checker(mutants):
    def inner():
        while True:
            sleep(1)
            now = datetime.now()
            for mm, name, _ in mutants:
                for pid, start in list(mm.start_time_by_pid.items()):
                    if (now - start).total_seconds() > (mm.estimated_time_of_tests_by_mutant[name] + 1) * FACTOR:
                        try:
                            os.kill(pid, signal.SIGXCPU)
                        except ProcessLookupError:
                            pass
    return inner


m.timeout_checker = timeout_checker
sys.argv = ["mutmut"] + sys.argv[1:]
m.cli()
"""


def tracked_files() -> list:
    out = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=True).stdout
    return [p for p in out.splitlines() if p]


def scratch_copy(module: str, dest: Path) -> None:
    keep = set(MODULES[module])
    for rel in tracked_files():
        name = Path(rel).name
        if rel.startswith("tests/") and name.startswith("test_") and name.endswith(".py") and rel not in keep:
            continue
        if rel.startswith(("benchmarks/", "docs/", "examples/")) or rel.endswith(".whl"):
            continue
        src, dst = ROOT / rel, dest / rel
        if src.is_file():
            dst.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, dst)
    package = module.split("/")[0] + "/"
    others = sorted(str(p.relative_to(dest)) for p in (dest / package).rglob("*.py") if str(p.relative_to(dest)) != module)
    copied = [d for d in ("station/", "drivers/", "sim_devices/", "schemes/") if d != package]
    text = (dest / "pyproject.toml").read_text()
    text = re.sub(r'addopts = "[^"]*"', 'addopts = "-q -p no:xdist -p no:cacheprovider"', text)
    text += ("\n[tool.mutmut]\n"
             f"paths_to_mutate = [{json.dumps(package)}]\n"
             f"do_not_mutate = {json.dumps(others)}\n"
             f"also_copy = {json.dumps(copied)}\n")      # not the package: copied after the mutants, it would overwrite them
    (dest / "pyproject.toml").write_text(text)


def run_module(module: str, children: int, keep: Path | None, timeout_factor: float = 20.0) -> dict:
    work = Path(tempfile.mkdtemp(prefix="station-mutation-")) if keep is None else keep
    if keep is not None and keep.exists():
        shutil.rmtree(keep)
    work.mkdir(parents=True, exist_ok=True)
    scratch_copy(module, work)
    # the mutants' directory exists before Python starts: a PYTHONPATH entry missing at start-up
    # is cached as absent, and the tests would import the unmutated copy beside it
    (work / "mutants").mkdir(exist_ok=True)
    env = {**os.environ, "PYTHONPATH": str(work / "mutants"), "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
    env.pop("PYTEST_ADDOPTS", None)
    env["MUTATION_TIMEOUT_FACTOR"] = str(timeout_factor)
    t0 = time.perf_counter()
    run = subprocess.run([sys.executable, "-c", RUNNER, "run", "--max-children", str(children)], cwd=work, env=env,
                         capture_output=True, text=True)
    elapsed = time.perf_counter() - t0
    results = subprocess.run([sys.executable, "-m", "mutmut", "results", "--all", "true"], cwd=work, env=env,
                             capture_output=True, text=True)
    status: dict = {}
    for line in results.stdout.splitlines():
        m = re.match(r"\s*(\S+): (.+)$", line)
        if m:
            status.setdefault(m.group(2).strip(), []).append(m.group(1))
    counts = {k: len(v) for k, v in status.items()}
    survivors = status.get("survived", [])
    # names only: `mutmut show NAME` costs seconds each (run it in --keep's directory)
    for name in survivors:
        print(f"survived: {name}")
    killed = counts.get("killed", 0)
    judged = sum(v for k, v in counts.items() if k not in ("skipped", "not checked"))
    summary = {"module": module, "seconds": round(elapsed, 1), "counts": counts,
               "score": round(killed / judged, 4) if judged else None, "exit": run.returncode, "work": str(work)}
    if run.returncode != 0:
        summary["tail"] = (run.stdout + run.stderr)[-3000:]
    print(json.dumps(summary, ensure_ascii=False))
    if keep is None:
        shutil.rmtree(work, ignore_errors=True)
    return summary


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("modules", nargs="*", help=f"default: all of {', '.join(MODULES)}")
    ap.add_argument("--children", type=int, default=1, help="mutmut's worker processes (default 1: a shared machine)")
    ap.add_argument("--timeout-factor", type=float, default=20.0,
                    help="a mutant's tests may take this many times their time in mutmut's statistics run (+1 s)")
    ap.add_argument("--keep", type=Path, help="work in this directory and keep it (mutmut browse there)")
    ap.add_argument("--list", action="store_true", help="the modules and their tests")
    args = ap.parse_args(argv)
    if args.list:
        for m, tests in MODULES.items():
            print(m, " ".join(tests))
        return 0
    unknown = [m for m in args.modules if m not in MODULES]
    if unknown:
        ap.error(f"unknown module {', '.join(unknown)}: one of {', '.join(MODULES)}")
    for module in args.modules or list(MODULES):
        run_module(module, args.children, args.keep, args.timeout_factor)
    return 0


if __name__ == "__main__":
    sys.exit(main())
