"""Batch throughput (docs/fleet.md, "Batches"): `station batch estimate` over N simulated
captures on a local Dask cluster and on a scheduler + workers started as separate processes,
against the ceiling "single-process estimate rate x cores".

    python benchmarks/batch_throughput.py make DIR [--n 1000]      # the captures (simulator)
    python benchmarks/batch_throughput.py run DIR [--single 100]   # the measurements
    python benchmarks/batch_throughput.py pairs DIR [--n 40] [--rounds 3]   # worker vs single CPU, side by side

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


def load() -> str:
    one, five, fifteen = os.getloadavg()
    return f"load average {one:.1f} / {five:.1f} / {fifteen:.1f} (1/5/15 min) on {os.cpu_count()} cores"


def spread(captures: list[Path], n: int) -> list[Path]:
    """``n`` of the captures, evenly spread over the sorted list (the first and the last among
    them): the single-process ceiling is measured on the same mix of captures as the batch runs.
    A capture's estimate costs from 0.2 s to 4.5 s of CPU (27 Nov 2026, 200 of these captures:
    median 0.34 s, mean 0.50 s; 7 of the 200 take 2.5-4.5 s, their fits a thousand Jacobians),
    so the first n or the last n of a folder (what single and single-stream timed before) measure
    different mixes: 0.31 s against 0.52 s of CPU per capture in the thirteenth session."""
    if n >= len(captures):
        return list(captures)
    step = (len(captures) - 1) / max(1, n - 1)
    return [captures[round(i * step)] for i in range(n)]


def single(captures: list[Path]) -> dict:
    """The single-process estimate rate: station.estimate.estimate_capture and the calibration
    file written, one capture after the other in this process (warmed up on one first), reading
    in process, one BLAS thread -- what one worker does per capture, without the cluster.  CPU:
    this process's (user + system of every thread: RUSAGE_SELF, which is time.process_time; it
    starts no child, so RUSAGE_CHILDREN stays 0, checked)."""
    os.environ["STATION_READ_IN_PROCESS"] = "1"
    from threadpoolctl import threadpool_limits

    from station.estimate import estimate_capture
    from station.io.calfile import write_calfile

    out = Path(os.environ.get("TMPDIR", "/tmp")) / f"batch-single-{os.getpid()}"
    out.mkdir(exist_ok=True)
    each = []
    with threadpool_limits(limits=1, user_api="blas"):
        estimate_capture(captures[0])
        children = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu, wall = time.process_time(), time.perf_counter()
        for i, c in enumerate(captures):
            before = time.process_time()
            cal, _, prov = estimate_capture(c)
            write_calfile(out / f"{i}.yaml", cal, prov)
            each.append((c.name, time.process_time() - before))
        cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
    shutil.rmtree(out)
    costs = sorted(x for _, x in each)
    return {"captures": len(captures), "first": captures[0].name, "last": captures[-1].name,
            "wall_s": wall, "cpu_s": cpu, "rate_per_s": len(captures) / wall,
            "cpu_per_capture_s": cpu / len(captures), "cpu_median_s": costs[len(costs) // 2], "cpu_max_s": costs[-1],
            "per_capture_cpu_s": dict(each),
            "children_cpu_s": (after.ru_utime - children.ru_utime) + (after.ru_stime - children.ru_stime),
            "load": load()}


def _batch(args, env) -> tuple[float, float, str]:
    """(wall s, CPU s of the command and every process it started and waited for, stdout)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    started = time.perf_counter()
    r = subprocess.run([sys.executable, "-m", "station.cli", "batch", *map(str, args)], env=env,
                       capture_output=True, text=True)
    wall = time.perf_counter() - started
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if r.returncode != 0:
        raise SystemExit(f"batch failed ({r.returncode}): {r.stderr[-2000:]}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu, r.stdout


def _tree_cpu(procs) -> float:
    import psutil

    total = 0.0
    for p in procs:
        try:
            ps = psutil.Process(p.pid)
            for q in [ps, *ps.children(recursive=True)]:
                t = q.cpu_times()
                total += t.user + t.system
        except psutil.NoSuchProcess:
            pass
    return total


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


PHASES = ("single", "local", "scheduler")


def run(directory: Path, n_single: int, workers: int, phases=PHASES) -> dict:
    """The phases in order: single (before), local, scheduler, single (after); ``phases``
    leaves some out (on a loaded machine the two cluster runs may be run at once, in two
    invocations: their CPU time per capture stays comparable, their wall time does not)."""
    captures = sorted(p for p in directory.iterdir() if (p / "manifest.yaml").exists())
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1]))
    results = {"captures": len(captures), "workers": workers}
    if "single" in phases:
        results["single_before"] = single(spread(captures, n_single))
        print(json.dumps({k: v for k, v in results["single_before"].items() if k != "per_capture_cpu_s"}), flush=True)
    out = directory.parent / f"batch-out-{os.getpid()}"
    shutil.rmtree(out, ignore_errors=True)
    if "local" in phases:
        results["local"] = _local(directory, captures, out, workers, env)
    if "scheduler" in phases:
        results["scheduler"] = _scheduler(directory, captures, out, workers, env)
    if "single" in phases:
        results["single_after"] = single(spread(captures, n_single))
        print(json.dumps({k: v for k, v in results["single_after"].items() if k != "per_capture_cpu_s"}), flush=True)
        rate = (results["single_before"]["rate_per_s"] + results["single_after"]["rate_per_s"]) / 2
        cpu_each = (results["single_before"]["cpu_per_capture_s"] + results["single_after"]["cpu_per_capture_s"]) / 2
        for name in ("local", "scheduler"):
            if name in results:
                r = results[name]
                r["of_ceiling_wall"] = r["rate_per_s"] / (rate * workers)
                r["of_ceiling_cpu"] = cpu_each / r["cpu_per_capture_s"]
                # the same captures, one by one: each task's CPU in the workers against the single
                # process's CPU for that capture (the mean of before and after), whatever the mix
                tasks = r.get("tasks_by_capture", {})
                both = [c for c in results["single_before"]["per_capture_cpu_s"] if c in tasks]
                if both:
                    single_cpu = sum((results["single_before"]["per_capture_cpu_s"][c]
                                      + results["single_after"]["per_capture_cpu_s"][c]) / 2 for c in both)
                    r["same_captures"] = {"captures": len(both), "single_cpu_s": single_cpu,
                                          "tasks_cpu_s": sum(tasks[c] for c in both),
                                          "tasks_over_single": sum(tasks[c] for c in both) / single_cpu}
                    # the CPU ceiling for the batch's own mix of captures: what the single process
                    # would take for all of them (their tasks' CPU over the same-capture ratio)
                    # against what the batch took in all
                    r["of_ceiling_cpu_same_mix"] = (r["tasks_cpu_per_capture_s"] / r["same_captures"]["tasks_over_single"]
                                                    / r["cpu_per_capture_s"])
    shutil.rmtree(out, ignore_errors=True)
    return results


def _tasks_cpu(state: Path) -> float:
    """CPU time the tasks themselves took in the workers (each Outcome's cpu_s: the worker
    process's CPU from the task's start to its end), from the batch's state file."""
    return sum(_tasks_by_capture(state).values())


def _tasks_by_capture(state: Path) -> dict:
    """{capture folder name: its task's CPU s} from the batch's state file."""
    out = {}
    for line in state.read_text().splitlines():
        rec = json.loads(line)
        out[Path(rec.get("source", "")).name] = rec.get("cpu_s", 0.0)
    return out


def _breakdown(r: dict, tasks_cpu: float, startup: dict | None, n: int) -> dict:
    """Where the CPU beyond the tasks' own went: the cluster's start-up and shutdown (a batch of
    one capture, less its task), and the rest per task (scheduler, client, nannies, transfer)."""
    r["tasks_cpu_s"] = tasks_cpu
    r["tasks_cpu_per_capture_s"] = tasks_cpu / n
    if startup is not None:
        r["startup_cpu_s"] = startup["cpu_s"] - startup["tasks_cpu_s"]
        r["per_task_overhead_cpu_s"] = (r["cpu_s"] - tasks_cpu - r["startup_cpu_s"]) / n
    return r


def _local(directory, captures, out, workers, env) -> dict:
    """A local cluster, started and stopped by the command; and the same on one capture (what
    starting and stopping the cluster costs)."""
    one = out / "one"
    one.mkdir(parents=True, exist_ok=True)
    (one / captures[0].name).symlink_to(captures[0].resolve())
    wall1, cpu1, _ = _batch(["estimate", one, "-o", out / "local-one", "--workers", workers, "--restart",
                             "--no-history"], env)
    startup = {"wall_s": wall1, "cpu_s": cpu1, "tasks_cpu_s": _tasks_cpu(out / "local-one" / ".station-batch-estimate.jsonl")}
    print(json.dumps({"local_one_capture": startup}), flush=True)
    load_before = load()
    wall, cpu, _ = _batch(["estimate", directory, "-o", out / "local", "--workers", workers, "--restart",
                           "--no-history"], env)
    r = {"wall_s": wall, "cpu_s": cpu, "rate_per_s": len(captures) / wall,
         "cpu_per_capture_s": cpu / len(captures), "load_before": load_before, "load_after": load()}
    _breakdown(r, _tasks_cpu(out / "local" / ".station-batch-estimate.jsonl"), startup, len(captures))
    r["tasks_by_capture"] = _tasks_by_capture(out / "local" / ".station-batch-estimate.jsonl")
    print(json.dumps({"local": {k: v for k, v in r.items() if k != "tasks_by_capture"}}), flush=True)
    return r


def _scheduler(directory, captures, out, workers, env) -> dict:
    """A scheduler and workers started as separate processes (as on a cluster), on loopback;
    their CPU time counted from /proc (psutil) before and after the batch."""
    port = _free_port()
    # the workers started as docs/fleet.md tells a user to start their own ("start the workers
    # with that variable set"): the statistical profiler off, as the local cluster's are
    # (station/batch/cluster.py), unless the environment says otherwise
    env = dict(env)
    env.setdefault("DASK_DISTRIBUTED__WORKER__PROFILE__ENABLED", "False")
    # and with the cluster's clockwork slowed as the local cluster's is (cluster.CLOCKWORK)
    from station.batch.cluster import CLOCKWORK

    for _, variable, value in CLOCKWORK:
        env.setdefault(variable, value)
    logs = open(directory.parent / f"dask-bench-{os.getpid()}.log", "w")
    procs = [subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1",
                               "--port", str(port), "--no-dashboard"], env=env, stdout=logs, stderr=logs)]
    address = f"tcp://127.0.0.1:{port}"
    try:
        for k in range(workers):
            procs.append(subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker", address,
                                           "--nthreads", "1", "--nworkers", "1", "--no-dashboard"],
                                          env=env, stdout=logs, stderr=logs))
        from distributed import Client

        with Client(address, timeout=120) as client:
            client.wait_for_workers(workers, timeout=300)
        load_before = load()
        cluster_cpu = _tree_cpu(procs)
        wall, cpu, _ = _batch(["estimate", directory, "-o", out / "scheduler", "--scheduler", address,
                               "--restart", "--no-history"], env)
        cluster_cpu = _tree_cpu(procs) - cluster_cpu
        r = {"wall_s": wall, "cpu_s": cpu + cluster_cpu, "command_cpu_s": cpu, "cluster_cpu_s": cluster_cpu,
             "rate_per_s": len(captures) / wall, "cpu_per_capture_s": (cpu + cluster_cpu) / len(captures),
             "load_before": load_before, "load_after": load()}
        _breakdown(r, _tasks_cpu(out / "scheduler" / ".station-batch-estimate.jsonl"), None, len(captures))
        r["tasks_by_capture"] = _tasks_by_capture(out / "scheduler" / ".station-batch-estimate.jsonl")
        print(json.dumps({"scheduler": {k: v for k, v in r.items() if k != "tasks_by_capture"}}), flush=True)
    finally:
        for p in reversed(procs):
            p.terminate()
        for p in procs:
            try:
                p.wait(timeout=30)
            except subprocess.TimeoutExpired:
                p.kill()
        logs.close()
    return r


def sample(pid: int, state: Path, extra_pids=()) -> dict:
    """A batch still running (a machine too loaded for 1,000 captures to finish in the time one
    has): the captures it has finished (its state file), the CPU time of the command and every
    process under it (and of ``extra_pids``: a scheduler and workers started apart), and the
    wall time since the command started."""
    import psutil

    class P:
        def __init__(self, pid):
            self.pid = pid

    done = len([line for line in state.read_text().splitlines() if '"status": "done"' in line])
    cpu = _tree_cpu([P(pid), *map(P, extra_pids)])
    wall = time.time() - psutil.Process(pid).create_time()
    return {"captures_done": done, "wall_s": wall, "cpu_s": cpu, "rate_per_s": done / wall,
            "cpu_per_capture_s": cpu / done, "load": load()}


def single_stream(directory: Path, n: int) -> None:
    """single() one capture at a time, a JSON line (captures, wall, CPU so far) after each ten:
    run beside a batch on a loaded machine, both see the same load, and it can be read at any
    moment.  The captures: ``n`` spread over the folder (spread(), as single() takes them)."""
    os.environ["STATION_READ_IN_PROCESS"] = "1"
    from threadpoolctl import threadpool_limits

    from station.estimate import estimate_capture
    from station.io.calfile import write_calfile

    captures = spread(sorted(p for p in directory.iterdir() if (p / "manifest.yaml").exists()), n)
    out = Path(os.environ.get("TMPDIR", "/tmp")) / f"batch-single-{os.getpid()}"
    out.mkdir(exist_ok=True)
    with threadpool_limits(limits=1, user_api="blas"):
        estimate_capture(captures[0])
        cpu, wall = time.process_time(), time.perf_counter()
        for i, c in enumerate(captures, 1):
            cal, _, prov = estimate_capture(c)
            write_calfile(out / f"{i}.yaml", cal, prov)
            if i % 10 == 0:
                w, u = time.perf_counter() - wall, time.process_time() - cpu
                print(json.dumps({"captures": i, "wall_s": w, "cpu_s": u, "rate_per_s": i / w,
                                  "cpu_per_capture_s": u / i, "load": load()}), flush=True)
    shutil.rmtree(out)


def pairs(directory: Path, n: int, rounds: int, workers: int = 2) -> dict:
    """CPU per capture of the batch's workers against single processes **run at the same
    time**, on the same ``n`` captures (spread over the folder), in interleaved rounds: each
    round runs ``workers`` single processes at once (`single-of`: capture k to process k mod
    workers, each process's CPU from inside it, its start-up not counted), then `station batch
    estimate --workers N` on the same captures (the command's CPU and every process it waited
    for: RUSAGE_CHILDREN; the tasks' own CPU from the state file).  Both fill the same cores,
    so what the machine does to two busy processes (shared caches, the host's scheduling, the
    other sessions' load) is on both sides of the ratio; what is left is the batch's own: the
    cluster's start-up, its clockwork over the batch's wall time, and what each task does
    beyond the estimate (the fingerprint, the state, the result's round trip)."""
    captures = spread(sorted(p for p in directory.iterdir() if (p / "manifest.yaml").exists()), n)
    work = directory.parent / f"batch-pairs-{os.getpid()}"
    shutil.rmtree(work, ignore_errors=True)
    linked = work / "captures"
    linked.mkdir(parents=True)
    for c in captures:
        (linked / c.name).symlink_to(c.resolve())
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1]))
    out = {"captures": len(captures), "workers": workers, "rounds": []}
    try:
        for r in range(rounds):
            load_before = load()
            started = time.perf_counter()
            procs = [subprocess.Popen([sys.executable, __file__, "single-of", *map(str, captures[k::workers])],
                                      env=env, stdout=subprocess.PIPE, text=True) for k in range(workers)]
            singles = [json.loads(p.communicate()[0].strip().splitlines()[-1]) for p in procs]
            single_wall = time.perf_counter() - started
            per_capture = {name: c for s in singles for name, c in s["per_capture_cpu_s"].items()}
            state = work / "out" / ".station-batch-estimate.jsonl"
            wall, cpu, _ = _batch(["estimate", linked, "-o", work / "out", "--workers", workers, "--restart",
                                   "--no-history"], env)
            tasks = _tasks_by_capture(state)
            single_cpu = sum(per_capture.values())
            row = {"load_before": load_before, "load_after": load(),
                   "singles_wall_s": single_wall, "singles_cpu_per_capture_s": single_cpu / len(captures),
                   "batch_wall_s": wall, "batch_cpu_per_capture_s": cpu / len(captures),
                   "tasks_cpu_per_capture_s": sum(tasks.values()) / len(captures),
                   "tasks_over_singles": sum(tasks.values()) / single_cpu,
                   "batch_over_singles": cpu / single_cpu}
            out["rounds"].append(row)
            print(json.dumps(row), flush=True)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    rows = out["rounds"]
    for key in ("tasks_over_singles", "batch_over_singles"):
        out[key] = sum(r[key] for r in rows) / len(rows)
    return out


if __name__ == "__main__" and len(sys.argv) > 1 and sys.argv[1] == "single-of":
    res = single([Path(a) for a in sys.argv[2:]])
    print(json.dumps({k: v for k, v in res.items() if k in ("captures", "cpu_s", "wall_s", "per_capture_cpu_s")}))
    sys.exit(0)


if __name__ == "__main__" and len(sys.argv) > 1 and sys.argv[1] == "pairs":
    p = argparse.ArgumentParser()
    p.add_argument("what")
    p.add_argument("directory", type=Path)
    p.add_argument("--n", type=int, default=40, help="captures (spread over the folder)")
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--workers", type=int, default=2)
    a = p.parse_args()
    res = pairs(a.directory, a.n, a.rounds, a.workers)
    print(json.dumps(res, indent=1))
    print(f"{res['captures']} captures, {a.rounds} rounds: the tasks took {res['tasks_over_singles']:.3f} x and the "
          f"batch in all {res['batch_over_singles']:.3f} x the CPU of {a.workers} single processes run at once")
    sys.exit(0)


if __name__ == "__main__" and len(sys.argv) > 1 and sys.argv[1] == "single-stream":
    single_stream(Path(sys.argv[2]), int(sys.argv[3]) if len(sys.argv) > 3 else 200)
    sys.exit(0)


if __name__ == "__main__" and len(sys.argv) > 1 and sys.argv[1] == "sample":
    p = argparse.ArgumentParser()
    p.add_argument("what")
    p.add_argument("pid", type=int, help="the station batch command's process")
    p.add_argument("state", type=Path, help="its state file")
    p.add_argument("--also", type=int, action="append", default=[], help="scheduler and worker processes")
    a = p.parse_args()
    print(json.dumps(sample(a.pid, a.state, a.also)))
    sys.exit(0)


if __name__ == "__main__":
    p = argparse.ArgumentParser()
    p.add_argument("what", choices=("make", "run"))
    p.add_argument("directory", type=Path)
    p.add_argument("--single", type=int, default=100, help="captures timed in one process (the ceiling)")
    p.add_argument("--workers", type=int, default=len(os.sched_getaffinity(0)))
    p.add_argument("--json", type=Path, help="write the results here too")
    p.add_argument("--only", action="append", choices=PHASES, help="run only these phases (repeatable)")
    a = p.parse_args()
    res = run(a.directory, a.single, a.workers, tuple(a.only or PHASES))
    print(json.dumps(res, indent=1))
    if a.json:
        a.json.write_text(json.dumps(res, indent=1))
    for name in ("local", "scheduler"):
        r = res.get(name)
        if not r or "of_ceiling_cpu" not in r:
            continue
        print(f"{name}: {res['captures']} captures in {r['wall_s']:.0f} s wall ({r['rate_per_s']:.2f}/s), "
              f"{r['cpu_per_capture_s']:.3f} s CPU per capture; {r['of_ceiling_wall']:.2f} of the wall-time "
              f"ceiling, {r['of_ceiling_cpu']:.2f} of the CPU ceiling"
              + (f"; on the {r['same_captures']['captures']} captures timed alone too, the tasks took "
                 f"{r['same_captures']['tasks_over_single']:.2f} x their single-process CPU, "
                 f"{r['of_ceiling_cpu_same_mix']:.2f} of the CPU ceiling for the batch's own captures"
                 if "same_captures" in r else ""))
