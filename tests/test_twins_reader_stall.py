"""Issue 28, seventeenth session (item 4): the twins judge an IMU reader absent (serve.READER_STALL_S:
it took nothing for 0.25 s of wall time while device time was held for it and the table's client
asked) and drop its queue: frames lost.  The judgement must be the reader's, not the twins' own
loop's: a loop descheduled for longer than that (a loaded host, the GIL of an in-process run) found
on its return that 0.3 s had passed since it last saw the reader take bytes, and dropped the queue
of a reader that had been reading all along -- frames lost in a run that otherwise passes.  Wall
time is simulated (tests/test_twins_speed.py's line without the kernel); nothing depends on the
machine.  Both sides: the loop's stall costs no frame; a reader that really stops reading while
the table is asked is still taken for absent."""
from __future__ import annotations

import os

from sim_devices.truth import default_truth
from sim_devices.twins.serve import BenchOptions, BenchServer
from test_twins_speed import _Line, simulated_wall


def _bench(monkeypatch):
    wall = simulated_wall(monkeypatch)
    server = BenchServer(default_truth(2), BenchOptions(speed=50.0, imu_protocol="csv"))
    server.imu_port.close()
    server.imu_port = line = _Line()
    client = os.open(server.table_path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)

    def run(seconds, take_per_step=0, ask=True, step_s=0.01):
        for _ in range(round(seconds / step_s)):
            wall[0] += step_s
            line.reader_takes(take_per_step)
            if ask:                      # the table's client asks something every step
                os.write(client, b"?\n")
            server.step(0.0)
            try:
                os.read(client, 4096)
            except BlockingIOError:
                pass
    return server, line, run, client


def test_the_twins_own_stall_does_not_drop_a_reading_readers_frames(monkeypatch):
    server, line, run, client = _bench(monkeypatch)
    try:
        run(0.5, ask=False)                       # the stream's queue grows: nobody reads yet
        made = line.accepted + line.backlog
        run(1.0, made // 100)                     # a reader taking half of the stream, the table asked
        assert server.clock.held_wall_s > 0 and server.readers_given_up == 0
        run(0.3, made // 100 * 30, step_s=0.3)    # the loop away 0.3 s; the reader read meanwhile
        run(0.5, made // 100)
        assert server.readers_given_up == 0, "a reading reader was judged absent"
        assert server.faulter.frames_overflowed == 0, server.faulter.frames_overflowed
    finally:
        os.close(client)
        server.close_ports()


def test_a_reader_that_stops_while_the_table_is_asked_is_still_judged_absent(monkeypatch):
    server, line, run, client = _bench(monkeypatch)
    try:
        run(0.5, ask=False)
        made = line.accepted + line.backlog
        run(1.0, made // 100)
        run(0.3)                                  # the reader takes nothing, the loop looks every 10 ms
        assert server.readers_given_up == 1
    finally:
        os.close(client)
        server.close_ports()
