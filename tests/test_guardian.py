"""The table's guardian (station/bench/guardian.py) in process: the run released it (nothing
opened), or the run died (the pipe closed without 'done'): the table braked and held, what was
done logged, in the capture or, when the run died before making it, in the user's own
directory."""
from __future__ import annotations

import io
import os
import tempfile

import pytest

from drivers.base import TableSettings
from drivers.registry import open_table
from sim_devices.truth import default_truth
from sim_devices.twins.serve import BenchOptions, BenchServer
from station.bench import guardian


@pytest.fixture
def bench():
    with BenchServer(default_truth(3), BenchOptions(speed=50, axes=2)) as server:
        yield server


def _spec(server, log):
    import dataclasses

    return {"url": server.table_path, "protocol": "acutrol",
            "settings": dataclasses.asdict(TableSettings()), "log": str(log), "run_pid": 4242}


def _turning(server):
    with open_table(server.table_path) as table:
        table.close_interlocks()
        table.set_rate(2, 40.0)


def test_a_released_guardian_never_opens_the_port(bench, tmp_path):
    _turning(bench)
    assert guardian.guard(_spec(bench, tmp_path / "guardian.log"), io.BytesIO(guardian.DONE)) == 0
    assert not (tmp_path / "guardian.log").exists()
    assert bench.table.read_rate(2) == pytest.approx(40.0)          # untouched: the run's own business


def test_a_run_that_died_has_its_table_stopped_and_the_log_says_so(bench, tmp_path):
    _turning(bench)
    assert guardian.guard(_spec(bench, tmp_path / "guardian.log"), io.BytesIO(b"")) == 0
    assert abs(bench.table.read_rate(2)) < 0.05 and bench.table.axes[1].mode == "position"
    log = (tmp_path / "guardian.log").read_text()
    assert "(pid 4242) ended without stopping the table" in log
    assert "axis 2 was turning at 40 deg/s" in log and "braked to rest and held" in log


def test_without_the_capture_directory_the_log_goes_to_the_users_own(bench, tmp_path, monkeypatch):
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    _turning(bench)
    assert guardian.guard(_spec(bench, tmp_path / "no-capture-yet" / "guardian.log"), io.BytesIO(b"")) == 0
    fallback = tmp_path / f"station-{os.getuid()}" / "guardian.log"
    assert "axis 2 was turning at 40 deg/s" in fallback.read_text()
