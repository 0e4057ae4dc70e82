"""Issue 28 item 3 (fifteenth session): `station run` records turns whose ramp is in the window on
the device twins over pseudo-terminals (the sequencer commands the rate inside the window and
places the table's reads on the IMU's clock: station/bench/ramp_angle.py)."""
import subprocess
import sys
from pathlib import Path

import numpy as np
import yaml

from sim_devices.truth import default_truth
from sim_devices.twins.serve import BenchOptions, BenchServer
from station.io.capture import read_capture

SPEED = 8.0
RATE, ACCEL = 300.0, 300.0
CONFIG = f"""\
version: 1
table:
  axes: 3
  limits: [{{max_rate_dps: 300, max_accel_dps2: 300, move_rate_dps: 60, move_accel_dps2: 60, rate_accel_dps2: {ACCEL:g}}}]
run: {{operator: false, settle_s: 0.5, max_missing_fraction: 0.02, max_gap_s: 2.0, rerecord_attempts: 5}}
"""
SCHEME = f"""\
name: ramps
defaults: {{dwell_s: 1, rate_dps: {RATE:g}, rotation_s: 1.2}}
segments:
  - {{static: s0, up_body: [0, 0, 1]}}
  - {{rotation: up, axis_body: [0, 0, 1], record_ramp: start, pair: false}}
  - {{rotation: down, axis_body: [1, 0, 0], record_ramp: end, pair: false}}
"""


def test_the_twins_record_a_ramp_up_and_a_brake_with_their_rates_and_angles(tmp_path):
    """The manifest says which ramp each window keeps, the table's rates at its edges and the angle;
    the gyro's own integral over the window agrees with that angle within what the twins' scale
    error, a 20 ms clock offset and the placement of the reads allow: per read, its bracket (the IMU
    stamps before and after it, recorded in table_reads) times the rate; the mean of the reads
    is within the widest bracket of the truth, so |integral - angle - dt dw| <= |w| (widest
    bracket + one period) + 2000 ppm of the angle (the twin's gyro scale errors are ~1000 ppm)."""
    (tmp_path / "station.yaml").write_text(CONFIG)
    (tmp_path / "s.yaml").write_text(SCHEME)
    truth = default_truth(11)
    truth.bench.time_offset_s = 0.02
    with BenchServer(truth, BenchOptions(speed=SPEED, seed=11, axes=3, lossless=True)) as bench:
        proc = subprocess.run([sys.executable, "-m", "station.cli", "run", "--config", "station.yaml",
                               "--port", bench.imu_path, "--table-port", bench.table_path, "--scheme", "s.yaml",
                               "--out", "cap", "--no-history"], cwd=tmp_path, capture_output=True, text=True,
                              timeout=300)
    assert proc.returncode in (0, 2, 3), proc.stderr[-2000:]       # one static: the estimate may refuse
    capture = read_capture(tmp_path / "cap", load_data=True)
    ramps = {s.name: s for s in capture.segments if s.kind == "rotation"}
    assert set(ramps) == {"up", "down"} and all(s.status == "complete" for s in ramps.values())
    for name, s in ramps.items():
        kind = "start" if name.startswith("up") else "end"
        sign = np.sign(s.rate_dps)
        assert s.extra["record_ramp"] == kind and s.extra["ramp_accel_dps2"] == ACCEL
        edges = (s.extra["rate_start_dps"], s.extra["rate_end_dps"])
        assert (edges[0] == 0.0) == (kind == "start") and (edges[1] == 0.0) == (kind == "end")
        moving = edges[1] if kind == "start" else edges[0]
        assert abs(moving - sign * RATE) < 0.01
        g = s.data.gyro @ np.asarray(s.axis_body, float)
        rest, turning = (g[:3], g[-3:]) if kind == "start" else (g[-3:], g[:3])
        assert abs(rest.mean()) < 1.0 and abs(turning.mean() - sign * RATE) < 1.0
        integral = float(np.gradient(s.data.t) @ g)
        reads = np.array(s.extra["table_reads"], float)
        widest = float(np.max(reads[:, 3] - reads[:, 2]))
        dw = edges[1] - edges[0]
        bound = RATE * (widest + 1.0 / capture.imu.sample_rate_hz) + 2e-3 * abs(s.angle_deg)
        assert abs(integral - s.angle_deg - 0.02 * dw) < bound, (name, integral, s.angle_deg, bound)
    # the window holds the turn at the rate and the ramp (r^2 / 2a = 150 deg), the rest more or less
    assert all(abs(s.angle_deg) > 360.0 for s in ramps.values())
    assert Path(tmp_path / "cap" / "manifest.yaml").read_text().count("record_ramp") == 2
    assert yaml.safe_load((tmp_path / "cap" / "manifest.yaml").read_text())["format"] == "station-capture/1"
