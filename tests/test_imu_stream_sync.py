"""A settle with several IMUs asks every IMU's reader at once, then waits for each (issue 29,
the 4-IMU run's wall time): one block read by each reader answers all of them, where asking one
after the other needed each reader to finish a block begun after the previous one had answered.

A fake driver whose every read blocks until the test releases it (no clock, no sleep): which
reads an answer needs is then a fact of the code, not of timing.  At the end each fake is
closed first (its pending read fails, as a real port's does when closed), so that
``ImuStream.stop`` finds the reader thread ended instead of waiting out its join ceiling
(3 x frame_timeout_s = 3 s per stream: 12 of this file's 15 s before)."""
from __future__ import annotations

import threading
import types

import numpy as np

from drivers.samples import ImuSamples
from station.bench.imu_stream import ImuStream


class GatedImu:
    """read(n) returns n samples, each read waiting for one release; read_available() nothing."""

    def __init__(self):
        self.settings = types.SimpleNamespace(frame_timeout_s=1.0)
        self.gate = threading.Semaphore(0)
        self.reads = 0
        self.t = 0.0
        self.closed = False

    def start(self):
        pass

    def stop(self):
        self.close()

    def close(self):
        """Close the port: the pending read (and every later one) fails at once."""
        self.closed = True
        self.gate.release(100)

    def read(self, n):
        self.gate.acquire()
        if self.closed:
            raise ConnectionError("GatedImu closed")
        self.reads += 1
        t = self.t + np.arange(1, n + 1) * 0.01
        self.t = float(t[-1])
        return ImuSamples(t, np.zeros((n, 3)), np.zeros((n, 3)), np.full(n, np.nan))

    def read_available(self):
        return ImuSamples.empty()


def test_every_reader_asked_first_is_answered_by_one_block_each():
    imus = [GatedImu() for _ in range(4)]
    streams = [ImuStream(imu, 100.0) for imu in imus]
    for s in streams:
        s.start()
    try:
        tickets = [s.ask_sync() for s in streams]       # as Sequencer._discard now does
        for imu in imus:
            imu.gate.release()                          # each reader finishes one block
        answers = [s.sync(ticket=k, wait_s=10.0) for s, k in zip(streams, tickets)]
        assert answers == [0.1] * 4                     # 10 samples of 0.01 s: the first block each
        assert [imu.reads for imu in imus] == [1] * 4
    finally:
        for imu in imus:
            imu.close()
        for s in streams:
            s.stop()


def test_a_sync_asked_after_the_block_began_waits_for_the_next_one():
    """The property a settle rests on: an answer covers every sample that had reached the
    computer when it was asked (so asking the second IMU only after the first had answered
    needed a second block of the second reader: the wait the settle no longer makes)."""
    imu = GatedImu()
    stream = ImuStream(imu, 100.0)
    stream.start()
    try:
        ticket = stream.ask_sync()                   # asked while the first read is pending
        imu.gate.release()
        assert stream.sync(ticket=ticket, wait_s=10.0) == 0.1
        ticket = stream.ask_sync()                   # asked after it: the next block answers
        assert stream.sync(ticket=ticket, wait_s=0.05) is None
        imu.gate.release()
        assert stream.sync(ticket=ticket, wait_s=10.0) == 0.2
    finally:
        imu.close()
        stream.stop()
