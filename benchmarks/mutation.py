"""Mutation testing of the modules behind honesty and safety (issue 30 item 6), with mutmut.

One target at a time (mutation runs are CPU-heavy and the machine is shared): the tracked files
of this clone are copied into a scratch directory, the tests kept there are the ones named for
that target below, the [tool.mutmut] configuration is written so that only the target's files
are mutated (every other .py file of their package copied unmutated), and `mutmut run` is
started there with --children processes, restricted to the target's functions (mutmut's mutant
names are globbed: ``module.x_function*``, ``module.xǁClassǁmethod*``) when the target is a part
of a large module (the least-squares covariance, the table driver's stop, the capture writer).
Then every surviving mutant is printed by name (``--diff``: with its diff), and the counts and the
score (killed / (killed + survived + no tests + timeouts)) as one JSON line per target.

A per-mutant timeout replaces mutmut 3.2's: its checker compares every running mutant with the
estimated test time of *every* mutant of the same file, so a mutant whose tests take 30 s is
killed as soon as any other mutant of the file has tests of under a second (and the kill,
SIGXCPU, is then counted as "killed": mutmut maps exit -24 to killed).  Here each mutant is
measured against its own tests' time (x ``--timeout-factor``, at least ``--timeout-min`` s), the
whole process group (the tests' subprocesses too) is killed, and the mutant is counted as a
timeout, not a kill.

Usage:
    python benchmarks/mutation.py [TARGET ...] [--children 1] [--keep DIR] [--list] [--diff]

TARGET is a key of TARGETS (default: all, one after the other).  Survivors are read and either
killed by a test or explained in docs/testing.md.
"""
from __future__ import annotations

import argparse
import fnmatch
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
SEP = "\u01c1"       # mutmut's class separator in mutant names (ǁ)


def _functions(module: str, names: list) -> list:
    """mutmut mutant-name globs for functions ("name") and methods ("Class.method", "Class.*")."""
    out = []
    for n in names:
        if "." in n:
            cls, meth = n.split(".", 1)
            out.append(f"{module}.x{SEP}{cls}{SEP}{meth}__mutmut_*")
        else:
            out.append(f"{module}.x_{n}__mutmut_*")
    return out


#: target -> (the files mutated, the mutant-name globs (None: every function of the files), the
#: tests that guard it: fast unit tests in the pytest process, so that mutmut's statistics run
#: maps each function to the tests that call it)
TARGETS = {
    "verdict": (["station/estimate/verdict.py"], None,
                ["tests/test_verdict_rules.py", "tests/test_verdict_units.py", "tests/test_verdicts.py"]),
    "lsq-covariance": (
        ["station/estimate/lsq.py"],
        _functions("station.estimate.lsq", [
            "_ScaledSVD.*", "covariance", "_null_columns", "FitResult.covariance_of", "reported",
            "_reported_index", "_reported_columns", "_held_by_weak_priors", "_gauss_newton_step"]),
        ["tests/test_lsq_covariance.py"]),
    "compensate": (["station/model/compensate.py"], None,
                   ["tests/test_compensate_units.py"]),
    "decoders": (
        ["drivers/protocols/vectornav_binary.py", "drivers/protocols/crc.py", "drivers/protocols/xbus.py",
         "drivers/protocols/csvlines.py"],
        _functions("drivers.protocols.vectornav_binary", ["VectorNavDecoder.*"])
        + _functions("drivers.protocols.crc", ["crc16_rows", "_table"])
        + _functions("drivers.protocols.xbus", ["XbusParser.*", "XsensDecoder.*", "parse_mtdata2"])
        + _functions("drivers.protocols.csvlines", ["CsvDecoder.*", "_skippable"]),
        ["tests/test_decoders_long_reads.py", "tests/test_drivers_damage_counts.py", "tests/test_drivers_decoders.py",
         "tests/test_decoder_units.py"]),
    "table-stop": (
        ["drivers/table.py", "drivers/acutrol.py", "drivers/aerosmith.py"],
        _functions("drivers.table", ["RateTable.stop", "RateTable._stop_leftover_motion",
                                     "RateTable._after_halt"])
        + _functions("drivers.acutrol", ["AcutrolTable._halt"])
        + _functions("drivers.aerosmith", ["AerosmithTable._halt"]),
        ["tests/test_table_stop_units.py"]),
    "capture-writer": (
        ["station/io/capture.py"],
        _functions("station.io.capture", ["CaptureWriter.*", "SegmentWriter.*", "FormattedRows.*",
                                          "_atomic_write", "_aside_name", "remove_stray_temporaries"]),
        ["tests/test_capture.py", "tests/test_capture_formatted_rows.py", "tests/test_capture_writer_units.py"]),
}


# The runner: mutmut's CLI with its timeout checker replaced (see the module's docstring), and
# each mutant's tests in their own process group (so that a timeout kills their subprocesses).
RUNNER = r"""
import os, signal, sys
from datetime import datetime
from time import sleep
import mutmut.__main__ as m

import time
FACTOR = float(os.environ["MUTATION_TIMEOUT_FACTOR"])
MINIMUM = float(os.environ["MUTATION_TIMEOUT_MIN"])
timed_out = set()
clean = [0.0]       # the wall time of mutmut's clean run of the target's tests (all of them)


def timeout_checker(mutants):
    files = {id(mm): mm for mm, _, _ in mutants}.values()

    def inner():
        while True:
            sleep(0.5)
            now = datetime.now()
            for mm in files:
                for pid, start in list(mm.start_time_by_pid.items()):
                    # mutmut's estimate is the tests' last phase (teardown, ~0 s: pytest's
                    # report hook overwrites call with teardown), so the floor is the clean run
                    # of all the target's tests, three times over: a mutant runs a subset of them
                    limit = max(MINIMUM, 3.0 * clean[0], (mm.estimated_time_of_tests_by_pid.get(pid, 0.0) + 1) * FACTOR)
                    if (now - start).total_seconds() > limit and pid not in timed_out:
                        timed_out.add(pid)
                        try:
                            os.killpg(pid, signal.SIGKILL)
                        except (ProcessLookupError, PermissionError):
                            try:
                                os.kill(pid, signal.SIGKILL)
                            except ProcessLookupError:
                                pass
    return inner


_register_result = m.SourceFileMutationData.register_result


def register_result(self, *, pid, exit_code):
    if pid in timed_out:
        exit_code = 36          # mutmut's "timeout"
        timed_out.discard(pid)
    return _register_result(self, pid=pid, exit_code=exit_code)


_run_tests = m.PytestRunner.run_tests


def run_tests(self, *, mutant_name, tests):
    if mutant_name is not None:         # a mutant's child: its own process group
        try:
            os.setpgid(0, 0)
        except OSError:
            pass
        return _run_tests(self, mutant_name=mutant_name, tests=tests)
    start = time.monotonic()
    try:
        return _run_tests(self, mutant_name=mutant_name, tests=tests)
    finally:
        clean[0] = time.monotonic() - start


m.timeout_checker = timeout_checker
m.SourceFileMutationData.register_result = register_result
m.PytestRunner.run_tests = run_tests
sys.argv = ["mutmut"] + sys.argv[1:]
m.cli()
"""


def tracked_files() -> list:
    out = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=True).stdout
    return [p for p in out.splitlines() if p]


def scratch_copy(target: str, dest: Path, tests=None) -> None:
    files, _, default_tests = TARGETS[target]
    tests = tests or default_tests
    keep = set(tests)
    for rel in tracked_files():
        name = Path(rel).name
        if rel.startswith("tests/") and name.startswith("test_") and name.endswith(".py") and rel not in keep:
            continue
        if rel.startswith(("benchmarks/", "examples/")) or rel.endswith(".whl"):     # docs/: tests read them
            continue
        src, dst = ROOT / rel, dest / rel
        if src.is_file():
            dst.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, dst)
    package = files[0].split("/")[0] + "/"
    others = sorted(str(p.relative_to(dest)) for p in (dest / package).rglob("*.py")
                    if str(p.relative_to(dest)) not in files)
    copied = [d for d in ("station/", "drivers/", "sim_devices/", "schemes/", "docs/") if d != package]
    text = (dest / "pyproject.toml").read_text()
    # --tb=line: a mutant that raises deep in a command (estimate -> judge) had pytest render the
    # source of every frame (an AST parse of each file: the mutants' files are large), which on a
    # loaded machine took longer than the timeout: such mutants were counted as timeouts
    text = re.sub(r'addopts = "[^"]*"', 'addopts = "-q -p no:xdist -p no:cacheprovider --tb=line"', text)
    text += ("\n[tool.mutmut]\n"
             f"paths_to_mutate = [{json.dumps(package)}]\n"
             f"do_not_mutate = {json.dumps(others)}\n"
             f"also_copy = {json.dumps(copied)}\n")      # not the package: copied after the mutants, it would overwrite them
    (dest / "pyproject.toml").write_text(text)


def _selected(name: str, globs) -> bool:
    return globs is None or any(fnmatch.fnmatchcase(name, g) for g in globs)


def run_target(target: str, children: int, keep: Path | None, timeout_factor: float = 20.0,
               timeout_min: float = 30.0, diff: bool = False, only=None, tests=None) -> dict:
    files, globs, _ = TARGETS[target]
    if only:
        globs = list(only)
    work = Path(tempfile.mkdtemp(prefix="station-mutation-")) if keep is None else keep
    if keep is not None and keep.exists():
        shutil.rmtree(keep)
    work.mkdir(parents=True, exist_ok=True)
    scratch_copy(target, work, tests)
    # the mutants' directory exists before Python starts: a PYTHONPATH entry missing at start-up
    # is cached as absent, and the tests would import the unmutated copy beside it
    (work / "mutants").mkdir(exist_ok=True)
    env = {**os.environ, "PYTHONPATH": str(work / "mutants"), "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
    env.pop("PYTEST_ADDOPTS", None)
    env["MUTATION_TIMEOUT_FACTOR"] = str(timeout_factor)
    env["MUTATION_TIMEOUT_MIN"] = str(timeout_min)
    t0 = time.perf_counter()
    cpu0 = os.times()
    run = subprocess.run([sys.executable, "-c", RUNNER, "run", "--max-children", str(children), *(globs or [])],
                         cwd=work, env=env, capture_output=True, text=True)
    elapsed = time.perf_counter() - t0
    cpu1 = os.times()
    results = subprocess.run([sys.executable, "-m", "mutmut", "results", "--all", "true"], cwd=work, env=env,
                             capture_output=True, text=True)
    status: dict = {}
    for line in results.stdout.splitlines():
        m = re.match(r"\s*(\S+): (.+)$", line)
        if m and _selected(m.group(1), globs):
            status.setdefault(m.group(2).strip(), []).append(m.group(1))
    counts = {k: len(v) for k, v in status.items()}
    survivors = status.get("survived", []) + status.get("no tests", []) + status.get("timeout", [])
    for name in sorted(survivors):
        kind = next(k for k, v in status.items() if name in v)
        print(f"{kind}: {name}")
        if diff:
            shown = subprocess.run([sys.executable, "-m", "mutmut", "show", name], cwd=work, env=env,
                                   capture_output=True, text=True).stdout
            print("\n".join(line for line in shown.splitlines() if line.startswith(("+", "-"))
                            and not line.startswith(("+++", "---"))))
    killed = counts.get("killed", 0)
    judged = sum(v for k, v in counts.items() if k not in ("skipped", "not checked"))
    summary = {"target": target, "files": files, "seconds": round(elapsed, 1),
               "cpu_seconds": round((cpu1.children_user + cpu1.children_system)
                                    - (cpu0.children_user + cpu0.children_system), 1),
               "counts": counts, "score": round(killed / judged, 4) if judged else None,
               "exit": run.returncode, "work": str(work)}
    if run.returncode != 0 or not judged:
        summary["tail"] = (run.stdout + run.stderr)[-3000:]
    print(json.dumps(summary, ensure_ascii=False), flush=True)
    if keep is None:
        shutil.rmtree(work, ignore_errors=True)
    return summary


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("targets", nargs="*", help=f"default: all of {', '.join(TARGETS)}")
    ap.add_argument("--children", type=int, default=1, help="mutmut's worker processes (default 1: a shared machine)")
    ap.add_argument("--timeout-factor", type=float, default=20.0,
                    help="a mutant's tests may take this many times their time in mutmut's statistics run (+1 s)")
    ap.add_argument("--timeout-min", type=float, default=30.0, help="and at least this many seconds")
    ap.add_argument("--keep", type=Path, help="work in this directory and keep it (mutmut browse there)")
    ap.add_argument("--diff", action="store_true", help="print each survivor's diff (mutmut show)")
    ap.add_argument("--only", action="append", metavar="GLOB",
                    help="only these mutants (mutmut's names, globs: station.estimate.verdict.x__bound__mutmut_6)")
    ap.add_argument("--tests", nargs="+", metavar="FILE", help="these test files instead of the target's")
    ap.add_argument("--list", action="store_true", help="the targets, their files and tests")
    args = ap.parse_args(argv)
    if args.list:
        for t, (files, globs, tests) in TARGETS.items():
            print(t, " ".join(files), "|", " ".join(tests), "|", "every function" if globs is None else " ".join(globs))
        return 0
    unknown = [t for t in args.targets if t not in TARGETS]
    if unknown:
        ap.error(f"unknown target {', '.join(unknown)}: one of {', '.join(TARGETS)}")
    for target in args.targets or list(TARGETS):
        run_target(target, args.children, args.keep, args.timeout_factor, args.timeout_min, args.diff, args.only, args.tests)
    return 0


if __name__ == "__main__":
    sys.exit(main())
