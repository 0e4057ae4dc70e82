"""Issue 28 review item 2: a recorded-ramp window that lost data is recorded again from its initial
state (a ramp up from rest, a brake from the rate) on the device twins over pseudo-terminals.
Before, the second attempt found the table turning ("start") or at rest ("end") and the run
stopped with "its angle is unknown", exit 2."""
import subprocess
import sys

import numpy as np
import pytest
import yaml

from sim_devices.truth import default_truth
from sim_devices.twins.faults import faults_from_dict
from sim_devices.twins.serve import BenchOptions, BenchServer
from station.io.capture import read_capture

CONFIG = """\
version: 1
table:
  axes: 3
  limits: [{max_rate_dps: 300, max_accel_dps2: 300, move_rate_dps: 60, move_accel_dps2: 60, rate_accel_dps2: 300}]
run: {operator: false, settle_s: 0.5, max_missing_fraction: 0.02, max_gap_s: 0.3, rerecord_attempts: 2}
"""
# at speed 8 the window (4.8 s of device time) lies at ~8.6-13.4 s ("start") and ~9.6-14.5 s
# ("end") of the twins' clock, measured on a loaded machine; the IMU's 0.6 s stall is put in its
# middle, over a second from either edge (the test checks that it fell inside: a kept-aside copy)
STALL_AT_S = {"start": 11.0, "end": 12.0}


@pytest.mark.parametrize("kind", ["start", "end"])
def test_a_ramp_window_that_lost_data_is_recorded_again(tmp_path, kind):
    (tmp_path / "station.yaml").write_text(CONFIG)
    (tmp_path / "s.yaml").write_text(f"""name: r
defaults: {{dwell_s: 1, rate_dps: 100, rotation_s: 3.6}}
segments:
  - {{static: s0, up_body: [0, 0, 1]}}
  - {{rotation: r, axis_body: [0, 0, 1], record_ramp: {kind}, pair: false}}
""")
    faults = faults_from_dict({"version": 1, "imu": {"stall": {"at_s": STALL_AT_S[kind], "duration_s": 0.6}}})
    with BenchServer(default_truth(11), BenchOptions(speed=8.0, seed=11, axes=3, lossless=True,
                                                     faults=faults)) as bench:
        proc = subprocess.run([sys.executable, "-m", "station.cli", "run", "--config", "station.yaml",
                               "--port", bench.imu_path, "--table-port", bench.table_path, "--scheme", "s.yaml",
                               "--out", "cap", "--no-history"], cwd=tmp_path, capture_output=True, text=True,
                              timeout=300)
    # one static: the run's own estimate refuses (exit 2, the accelerometers undetermined); the
    # recording itself must have completed
    assert "angle is unknown" not in proc.stderr, proc.stderr[-2000:]
    assert "does not determine" in proc.stderr, proc.stderr[-2000:]
    assert (tmp_path / "cap" / "r.csv.incomplete").is_file(), "the stall missed the window"
    capture = read_capture(tmp_path / "cap", load_data=True)
    r = next(s for s in capture.segments if s.name == "r")
    assert r.status == "complete"
    assert r.extra["record_ramp"] == kind
    # the angle agrees with the gyro's integral over the window (as tests/test_ramp_twins.py's
    # bound: the widest read bracket and a period at the rate, 2000 ppm for the twin's scale
    # errors, and the twin's clock offset, at most 20 ms, times the rate's change)
    g = r.data.gyro @ np.asarray(r.axis_body, float)
    integral = float(np.gradient(r.data.t) @ g)
    reads = np.array(r.extra["table_reads"], float)
    bound = 100.0 * (float(np.max(reads[:, 3] - reads[:, 2])) + 0.01) + 2e-3 * abs(r.angle_deg) + 0.02 * 100.0
    assert abs(integral - r.angle_deg) < bound, (integral, r.angle_deg, bound)
    edges = (r.extra["rate_start_dps"], r.extra["rate_end_dps"])
    assert edges == ((0.0, edges[1]) if kind == "start" else (edges[0], 0.0)) and abs(sum(edges)) > 99.0
    manifest = yaml.safe_load((tmp_path / "cap" / "manifest.yaml").read_text())
    assert manifest["format"] == "station-capture/1"
