"""The batch worker's per-task path (issue 29; docs/fleet.md, Fifteenth session): the task
writes the calibration `station.api.estimate` writes, with the effects built once per worker
process (and again when the configuration they come from changes), and every BLAS library of a
worker limited to one thread once, even in a worker started without the nanny's
OPENBLAS_NUM_THREADS=1 (a cluster of the user's)."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from station import api
from station.batch import tasks
from station.io.calfile import read_calfile

ROOT = Path(__file__).resolve().parents[1]
SHORT = {"dwell_s": 5.0, "rotation_s": 5.0}      # 21 segments: ~0.3 s of CPU to estimate


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    return api.simulate("optimal9", tmp_path_factory.mktemp("worker-path") / "cap", seed=3, **SHORT)


def test_the_task_writes_what_api_estimate_writes(capture, tmp_path, monkeypatch):
    monkeypatch.setenv("STATION_READ_IN_PROCESS", "1")
    options = {"method": "auto", "add": ["bias_drift"], "plugins": [], "max_missing_fraction": 0.01,
               "max_gap_s": 1.0, "turn_sigma_deg": None}
    out = tasks.run(tasks.Job("estimate", str(capture), str(tmp_path / "task.yaml"), options))
    assert out.status in (tasks.DONE, tasks.POOR_FIT), out.message
    api.estimate(capture, add=["bias_drift"]).save(tmp_path / "api.yaml")
    task, single = read_calfile(tmp_path / "task.yaml"), read_calfile(tmp_path / "api.yaml")
    assert task["effects"] == single["effects"] and "bias_drift" in task["effects"]
    assert task["parameters"] == single["parameters"] and task["verdict"] == single["verdict"]
    assert out.verdict == single["verdict"]["result"]


def test_the_effects_are_built_once_per_worker_and_again_when_the_configuration_changes(tmp_path, monkeypatch):
    from station.cli import main

    config = tmp_path / "station.yaml"
    assert main(["init", str(config)]) == 0
    monkeypatch.setenv("STATION_CONFIG", str(config))
    monkeypatch.setattr(tasks, "_EFFECTS", {})
    options = {"add": [], "plugins": []}
    first = tasks._effects(options)
    assert tasks._effects(dict(options)) is first                       # the next capture: kept
    assert tasks._effects({**options, "add": ["bias_drift"]})[1] == ["bias_drift"]   # other options: their own
    config.write_text(config.read_text() + "\n# edited\n")               # the configuration edited: built again
    again = tasks._effects(options)
    assert again is not first and again[0] is not first[0]
    assert tasks._effects(options) is again
    monkeypatch.setenv("STATION_CONFIG", str(tmp_path / "missing.yaml"))  # a bad one: said each time, not kept
    for _ in range(2):
        with pytest.raises(Exception):
            tasks._effects(options)
    assert all(key[-1] is None or key[-1][1] is not None for key in tasks._EFFECTS)


_BLAS_PROBE = """
import json, sys
from station.batch import tasks
out = tasks.run(tasks.Job("estimate", sys.argv[1], sys.argv[2], {}))
from threadpoolctl import threadpool_info
print(json.dumps([out.status, sorted({(i["internal_api"], i["num_threads"]) for i in threadpool_info()
                                      if i["user_api"] == "blas"})]))
"""


@pytest.mark.skipif(len(os.sched_getaffinity(0)) < 2, reason="one core: one BLAS thread either way")
def test_a_worker_without_the_nannys_variables_runs_one_blas_thread(capture, tmp_path):
    env = {k: v for k, v in os.environ.items() if k not in ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
                                                               "OMP_NUM_THREADS", "STATION_BLAS_THREADS")}
    env["PYTHONPATH"] = str(ROOT)
    done = subprocess.run([sys.executable, "-c", _BLAS_PROBE, str(capture), str(tmp_path / "c.yaml")], env=env,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    status, libraries = json.loads(done.stdout.strip().splitlines()[-1])
    assert status in ("done", "poor fit") and libraries
    assert all(threads == 1 for _, threads in libraries), libraries


def test_the_filer_files_by_the_serial_the_worker_reports_as_by_the_file(capture, tmp_path, monkeypatch):
    """The command files each calibration by the serial its task reports (Outcome.imu_serial),
    without reading the file a second time: the same store, rows and files as reading it."""
    from station.batch.filing import Filer
    from station.io.history import Store, simulation_store

    monkeypatch.setenv("STATION_READ_IN_PROCESS", "1")
    out = tasks.run(tasks.Job("estimate", str(capture), str(tmp_path / "cal.yaml"), {}))
    assert out.imu_serial and out.imu_serial == read_calfile(tmp_path / "cal.yaml")["provenance"]["imu_serial"]
    listings = []
    for name, serial in (("read", None), ("given", out.imu_serial)):
        filer = Filer(str(tmp_path / name))
        assert filer.file(tmp_path / "cal.yaml", serial).startswith("filed as #")
        assert filer.file(tmp_path / "cal.yaml", serial).startswith("already filed as #")
        store = Store(simulation_store(str(tmp_path / name)))
        entries = [e for serial_, _ in store.serials() for e in store.list(serial_)]
        listings.append([(e.serial, e.verdict, e.sha256, e.path.name, e.problem) for e in entries])
    assert listings[0] == listings[1] and len(listings[0]) == 1
    # a serial that names no IMU: not filed, either way
    assert Filer(str(tmp_path / "none")).file(tmp_path / "cal.yaml", "") == "not filed: no IMU serial"
