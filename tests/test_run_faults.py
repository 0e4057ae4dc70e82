"""station run against the device twins with a fault injected: the user sees one line (exit
status 2), the table is left at rest where it can be, and what was recorded can be resumed."""
import pytest
import yaml

from sim_devices.truth import default_truth
from sim_devices.twins.faults import Faults, ImuFaults
from sim_devices.twins.serve import BenchOptions, BenchServer
from sim_devices.twins.table import TableFaults
from station.cli import main
from station.io.capture import read_capture

SCHEME = """\
name: tiny
defaults: {dwell_s: 3.0, rate_dps: 30.0, rotation_s: 12.0}
segments:
  - {static: zup, up_body: [0, 0, 1]}
  - {static: xup, up_body: [1, 0, 0]}
  - {rotation: rotz, axis_body: [0, 0, 1]}
"""
CONFIG = """\
version: 1
table:
  axes: 3
  limits: [{max_rate_dps: 300, max_accel_dps2: 300, move_rate_dps: 60, move_accel_dps2: 60, rate_accel_dps2: 100}]
run:
  operator: false
  settle_s: 1
"""


@pytest.mark.parametrize("fault", ["table", "imu"])
def test_a_device_that_disconnects_mid_run_is_one_line_and_resumable(tmp_path, capsys, monkeypatch, fault):
    (tmp_path / "s.yaml").write_text(SCHEME)
    (tmp_path / "station.yaml").write_text(CONFIG)
    monkeypatch.chdir(tmp_path)
    faults = Faults(table=TableFaults(disconnect_at_s=25.0)) if fault == "table" else \
        Faults(imu=ImuFaults(disconnect_at_s=25.0))
    with BenchServer(default_truth(4), BenchOptions(speed=20.0, seed=4, axes=3, faults=faults)) as bench:
        status = main(["run", "--scheme", "s.yaml", "--config", "station.yaml", "--port", bench.imu_path,
                       "--table-port", bench.table_path, "--out", str(tmp_path / "cap")])
    err = capsys.readouterr().err
    assert status == 2, err
    last = [line for line in err.splitlines() if line.startswith("station run:")]
    assert len(last) == 1 and "Traceback" not in err and "disconnect" in last[0], err
    capture = read_capture(tmp_path / "cap")           # readable; resumable from what is kept
    assert all(s.status in ("complete", "incomplete") for s in capture.segments)
    assert "--resume" in last[0] or not capture.segments
    assert yaml.safe_load((tmp_path / "cap" / "manifest.yaml").read_text())["imu"]["serial"]


def test_frames_lost_beyond_the_limit_are_recorded_again_then_the_run_stops(tmp_path, capsys, monkeypatch):
    """5 % of the frames dropped (limit 1 %, station.yaml run.max_missing_fraction): every
    recording of the first segment is bad; each is kept aside and recorded again, and after
    run.rerecord_attempts the run stops with one line that says why."""
    (tmp_path / "s.yaml").write_text(SCHEME)
    (tmp_path / "station.yaml").write_text(CONFIG + "  rerecord_attempts: 1\n")
    monkeypatch.chdir(tmp_path)
    faults = Faults(imu=ImuFaults(drop_probability=0.05))
    with BenchServer(default_truth(4), BenchOptions(speed=20.0, seed=4, axes=3, faults=faults)) as bench:
        status = main(["run", "--scheme", "s.yaml", "--config", "station.yaml", "--port", bench.imu_path,
                       "--table-port", bench.table_path, "--out", str(tmp_path / "cap")])
        rates = [bench.table.read_rate(axis) for axis in (1, 2, 3)]
    err = capsys.readouterr().err
    assert status == 2, err
    assert "zup: every recording lost too much data" in err and "limit 1 %" in err and "--resume" in err
    assert rates == [0.0, 0.0, 0.0]
    cap = tmp_path / "cap"
    assert (cap / "zup.csv.incomplete").stat().st_size > 0 and (cap / "zup.csv.incomplete2").stat().st_size > 0
    assert read_capture(cap).complete() == []
