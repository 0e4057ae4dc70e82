"""Twins at any speed: a reader that keeps up loses no frame up to --speed 500; frames lost
with device time far ahead of wall time are reported as a twin that cannot keep up (a whole run
at --speed 500: tests/test_sequencer.py).

Everything is judged on device time (the frames' own time stamps), not on wall time.
"""
from __future__ import annotations

import time

import numpy as np
import pytest

from drivers.base import ImuSettings
from drivers.registry import open_imu
from drivers.samples import ImuSamples
from sim_devices.truth import default_truth
from sim_devices.twins.serve import BenchOptions, BenchServer
from station.bench.imu_stream import lost_frames_note


@pytest.mark.parametrize("protocol", ["vectornav", "csv"])
@pytest.mark.parametrize("speed", [200.0, 500.0])
def test_no_frame_lost_at_high_speed_when_the_reader_keeps_up(protocol, speed):
    n = 20000                              # 200 s of device time at 100 Hz
    with BenchServer(default_truth(2), BenchOptions(speed=speed, imu_protocol=protocol)) as server:
        with open_imu(server.imu_path, protocol, ImuSettings(frame_timeout_s=2.0)) as imu:
            first = imu.read(2000)
            overflowed = server.faulter.frames_overflowed      # (csv streams from power-up)
            s = ImuSamples.concat([first] + [imu.read(2000) for _ in range(n // 2000 - 1)])
            c = imu.counters
            assert server.faulter.frames_overflowed == overflowed
    assert len(s) == n
    assert c.missing_frames == 0 and c.gaps == 0 and c.checksum_errors == 0
    np.testing.assert_allclose(np.diff(s.t_s), 0.01, atol=1e-6)      # every sample, in order


def test_a_reader_that_falls_behind_a_fast_twin_is_told_so():
    speed = 300.0                       # a twin that drops what is not read, as a real IMU's UART
    with BenchServer(default_truth(2), BenchOptions(speed=speed, lossless=False)) as server:
        with open_imu(server.imu_path, "vectornav", ImuSettings(frame_timeout_s=2.0)) as imu:
            first = imu.read(100)
            wall0 = time.monotonic()
            time.sleep(3.0)             # the reader pauses: 900 s of device time, more than the
                                        #   twin's send buffer holds (2 s of wall time)
            blocks = []
            while imu.counters.missing_frames == 0 and sum(map(len, blocks)) < 100000:
                blocks.append(imu.read(5000))
            wall = time.monotonic() - wall0
            lost = imu.counters.missing_frames
        last = blocks[-1]
    assert server.faulter.frames_overflowed > 0 and lost > 0
    note = lost_frames_note("static-1", lost, float(last.t_s[-1] - first.t_s[0]), wall)
    assert "cannot keep up" in note and "lower --speed" in note


def test_lost_frames_at_the_pace_of_hardware_are_not_blamed_on_a_twin():
    note = lost_frames_note("static-1", 3, device_s=20.0, wall_s=20.1)
    assert "cannot keep up" not in note and "3 frames lost while recording" in note
