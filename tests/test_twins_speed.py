"""Twins at any speed: a reader that keeps up loses no frame up to --speed 500; frames lost
with device time far ahead of wall time are reported as a twin that cannot keep up (a whole run
at --speed 500: tests/test_sequencer.py).

Everything is judged on device time (the frames' own time stamps), not on wall time.
"""
from __future__ import annotations

import os
import time
import types

import numpy as np
import pytest

from drivers.base import ImuSettings
from drivers.registry import open_imu
from drivers.samples import ImuSamples
from sim_devices.truth import default_truth
from sim_devices.twins import clock as clock_module
from sim_devices.twins import serve
from sim_devices.twins.endpoint import QueuedEndpoint
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
            # the reader pauses until the twin's send buffer (STREAM_BUFFER_WALL_S = 2 s of wall
            # time of the stream) has overflowed: waited for, not slept over (3 s before); the
            # ceiling only bounds a twin that never overflows, which the assertion below names
            deadline = time.monotonic() + 30.0
            while server.faulter.frames_overflowed == 0 and time.monotonic() < deadline:
                time.sleep(0.01)
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


class _Line(QueuedEndpoint):
    """A pseudo-terminal's line as the kernel keeps it, without the kernel: the read buffer
    (n_tty, 4095 bytes in raw mode; what FIONREAD counts) and the flip buffers behind it, which
    refill the read buffer as soon as a reader has read (the kernel's worker does it within
    microseconds).  Never readable or writable for ``select`` (an idle pipe's read end)."""

    def __init__(self, flip_bytes=16384):
        super().__init__(8192)
        self._rfd, self._wfd = os.pipe()
        self.n_tty = self.flip = self.taken = self.accepted = 0
        self.flip_bytes = flip_bytes

    def fileno(self):
        return self._rfd

    def read(self):
        return b""

    def unread(self):
        return self.n_tty

    def _send(self, data):
        n = min(len(data), self.flip_bytes - self.flip)
        if n == 0:
            return None
        self.flip += n
        self.accepted += n
        self._refill()
        return n

    def _refill(self):
        m = min(4095 - self.n_tty, self.flip)
        self.n_tty, self.flip = self.n_tty + m, self.flip - m

    def reader_takes(self, n):
        while n > 0 and self.n_tty > 0:
            m = min(n, self.n_tty)
            self.n_tty, self.taken, n = self.n_tty - m, self.taken + m, n - m
            self._refill()

    def close(self):
        if not self.closed:
            self.closed = True
            os.close(self._rfd)
            os.close(self._wfd)



def simulated_wall(monkeypatch, start_s: float = 1000.0) -> list:
    """The twins' wall time (their loop's and clock's time.monotonic) moved by hand: a list whose
    one element the test advances; nothing then depends on the machine's speed or load."""
    wall = [start_s]
    fake_time = types.SimpleNamespace(monotonic=lambda: wall[0])
    monkeypatch.setattr(serve, "time", fake_time)
    monkeypatch.setattr(clock_module, "time", fake_time)
    return wall

def test_a_reader_of_a_line_the_queue_keeps_full_is_seen_and_waited_for(monkeypatch):
    """The twins' clock waits for a reader that reads (lossless): it must see the reader
    although the unread count never falls.  A csv twin streams from power-up, nobody reads for
    0.5 s of wall time (its queue grows), then a reader takes half of what the twin makes
    (a reader slower than --speed asks).  The kernel refills the read buffer from the flip
    buffers, which the twin refills from its queue, before the twin looks: the unread count
    stays 4095.  Before, such a reader was taken for absent: the clock ran free and the twin
    dropped frames once its queue was half full (the flake of the test above at --speed 500,
    under load).  Wall time is simulated (steps of 10 ms); nothing depends on the machine."""
    wall = simulated_wall(monkeypatch)
    server = BenchServer(default_truth(2), BenchOptions(speed=50.0, imu_protocol="csv"))
    server.imu_port.close()
    server.imu_port = line = _Line()
    try:
        def run(seconds, take_per_step=0):
            for _ in range(round(seconds / 0.01)):
                wall[0] += 0.01
                server.step(0.0)
                line.reader_takes(take_per_step)
                assert line.unread() == 4095 or line.taken == 0      # the count never falls
        run(0.5)                        # nobody reads
        made = line.accepted + line.backlog                  # 0.5 s of the stream at speed 50
        assert line.taken == 0 and server.faulter.frames_overflowed == 0 and not server.clock.capped
        run(3.0, made // 100)           # a reader taking half of the stream's bytes per 10 ms
        assert line.taken > made        # it read the queue of the first 0.5 s and more
        assert server.faulter.frames_overflowed == 0          # no frame dropped
        # device time stood still while the reader took the 0.5 s of queue (1 s at half the
        # pace), then ran at half the speed
        assert server.clock.held_wall_s > 1.0
    finally:
        server.close_ports()
