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
from sim_devices.twins.serve import BenchOptions, BenchServer
from station.io.capture import read_capture

CONFIG = """\
version: 1
table:
  axes: 3
  limits: [{max_rate_dps: 300, max_accel_dps2: 300, move_rate_dps: 60, move_accel_dps2: 60, rate_accel_dps2: 300}]
run: {operator: false, settle_s: 0.5, max_missing_fraction: 0.02, max_gap_s: 0.3, rerecord_attempts: 2}
"""
# The IMU's 0.6 s stall is put relative to the window's own command, by the twins' loop when the
# command reaches the table (StallAfterCommand), never at a fixed device time: where the window
# lies on the twins' clock depends on the host's load (their clock runs on at speed 8 while the
# station is between its reads: at load 13 the window began 4-6 s of device time later than at
# load 2, and a stall at a fixed 11 s missed it; docs/twins.md, "Recorded ramps under load").
# "start": 1.0 s after the ramp's command (the ramp ends 0.33 s after it; the window holds the
# ramp and 3.6 s of turns after the command's latest moment); "end": 0.1 s after the brake's (the
# window holds the 0.33 s brake and 0.5 s at rest after it, and the first read at rest): inside
# either way, whatever the load (the test checks that it fell inside: a kept-aside copy)
STALL_S = 0.6
STALL_AFTER_S = {"start": 1.0, "end": 0.1}


class StallAfterCommand:
    """The IMU twin's frames from ``STALL_AFTER_S[kind]`` after the window's command (device s),
    for STALL_S, are not sent: "start" the first rate demand other than 0 (the ramp up), "end" the
    first demand of 0 after one (the brake).  Put in the twins' loop as the command is executed
    (each axis's ``plan_rate``, at the loop step's device time): the stall's frames are not made
    yet then, so it lands where it is put; once, so that the recording again is clean."""

    def __init__(self, bench, kind):
        self.bench, self.kind, self.at, self.turned = bench, kind, None, False
        for ax in bench.table.axes:
            ax.motion.plan_rate = self._wrap(ax.motion.plan_rate)

    def _wrap(self, plan):
        def plan_rate(t, rate_dps, amax):
            if self.at is None and (rate_dps != 0.0 if self.kind == "start" else self.turned and rate_dps == 0.0):
                imu = self.bench.lines[0].faults
                imu.stall_at_s, imu.stall_duration_s = t + STALL_AFTER_S[self.kind], STALL_S
                self.at = t
            self.turned = self.turned or rate_dps != 0.0
            return plan(t, rate_dps, amax)
        return plan_rate


@pytest.mark.parametrize("kind", ["start", "end"])
def test_a_ramp_window_that_lost_data_is_recorded_again(tmp_path, kind):
    (tmp_path / "station.yaml").write_text(CONFIG)
    (tmp_path / "s.yaml").write_text(f"""name: r
defaults: {{dwell_s: 1, rate_dps: 100, rotation_s: 3.6}}
segments:
  - {{static: s0, up_body: [0, 0, 1]}}
  - {{rotation: r, axis_body: [0, 0, 1], record_ramp: {kind}, pair: false}}
""")
    with BenchServer(default_truth(11), BenchOptions(speed=8.0, seed=11, axes=3, lossless=True)) as bench:
        stall = StallAfterCommand(bench, kind)
        proc = subprocess.run([sys.executable, "-m", "station.cli", "run", "--config", "station.yaml",
                               "--port", bench.imu_path, "--table-port", bench.table_path, "--scheme", "s.yaml",
                               "--out", "cap", "--no-history"], cwd=tmp_path, capture_output=True, text=True,
                              timeout=300)
    # one static: the run's own estimate refuses (exit 2, the accelerometers undetermined); the
    # recording itself must have completed.  Which of the estimator's two refusals it is depends on
    # the window's length, which on a loaded host holds more rest than compiled (the reads' latency
    # on the twins' clock): "does not determine the accelerometers" (the rank) or, once in 12
    # loaded runs with an 8.9 s "start" window, "cannot determine the model: 34 measurements for
    # 35 unknowns" (the count, docs/twins.md "Recorded ramps under load")
    assert "angle is unknown" not in proc.stderr, proc.stderr[-2000:]
    assert proc.returncode == 2, proc.stderr[-2000:]
    assert ("does not determine the accelerometers" in proc.stderr
            or "cannot determine the model" in proc.stderr), proc.stderr[-2000:]
    assert stall.at is not None, "the window's command never reached the table"
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
