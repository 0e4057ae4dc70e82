"""A driver that opens an IMU twin's line nobody has read for a while is answered at once (issue
29: the resume of tests/test_multi_imu.py lost its replugged IMU at the start, "no reply to
$VNASY,0 within 10 s", at load 17).

The twin streams while nobody reads its line (an adapter plugged in again, the IMU still set to
stream; here a VectorNav twin streaming the station's binary output from power-up).  A real
IMU's bytes on a line nobody reads are lost but for what the line itself holds; the lossless
twin kept queueing them (up to half its transmit buffer, two seconds of wall time of the
stream: 1.2 MB before that resume), and the driver's first command was answered after all of
it.  Now a command from a line whose reader has taken nothing for READER_ACTIVE_S drops that
queue (counted as overflowed), and the reply follows only what the pseudo-terminal holds.  The
frames are judged by when they were made (while nobody read), not by the reader's state when its
command comes: pyserial flushes the input as it opens the port, so the twin may see the reader
before its first command (a simpler rule, "drop when the reader is not active", left the reply
behind the queue in one resume of two: 0.72 s at load 7).

Wall time is simulated (steps of 10 ms, as tests/test_twins_speed.py): nothing depends on the
machine's load.  0.5 s of wall time at --speed 100 queue ~150 kB of frames.
"""
from __future__ import annotations

import os
import termios

from drivers.protocols import vectornav as V
from sim_devices.truth import default_truth
from sim_devices.twins import serve
from sim_devices.twins.serve import BenchOptions, BenchServer
from test_twins_speed import simulated_wall


def test_a_command_on_a_line_nobody_read_is_answered_after_what_the_line_holds(monkeypatch):
    wall = simulated_wall(monkeypatch)
    server = BenchServer(default_truth(2), BenchOptions(speed=100.0, imu_startup="binary"))
    line = server.lines[0]
    try:
        def run(seconds):
            for _ in range(round(seconds / 0.01)):
                wall[0] += 0.01
                server.step(0.0)

        run(0.5)                                    # streaming, nobody reads
        queued = line.port.backlog
        assert queued > 100_000, queued             # the stream queued beyond the line
        overflowed = line.faulter.frames_overflowed
        fd = os.open(line.port.path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        try:
            def take():
                got = bytearray()
                while True:
                    try:
                        chunk = os.read(fd, 65536)
                    except BlockingIOError:
                        return got
                    if not chunk:
                        return got
                    got += chunk

            # the twin sees the reader before its command (pyserial's open flushes the input,
            # which the twin may or may not see fall: here the reader takes what waits, 50 ms)
            termios.tcflush(fd, termios.TCIFLUSH)
            for _ in range(5):
                run(0.01)
                take()
            assert wall[0] - line.last_taken_wall < serve.READER_ACTIVE_S      # the reader is seen
            assert line.port.backlog > 100_000                                # the queue still there
            os.write(fd, V.format_message("VNASY,0"))
            received = bytearray()
            for _ in range(20):                     # 0.2 s of wall time, reading all the while
                run(0.01)
                received += take()
                if b"$VNASY" in received:
                    break
        finally:
            os.close(fd)
        assert b"$VNASY" in received, (len(received), line.port.backlog)
        # before the reply: at most what the line held (the kernel's buffers), not the queue
        ahead = received.index(b"$VNASY")
        assert ahead <= serve.FLIP_MAX_BYTES + 4096 < queued, (ahead, queued)
        assert line.faulter.frames_overflowed > overflowed          # the queue's frames: lost, counted
    finally:
        server.close_ports()
