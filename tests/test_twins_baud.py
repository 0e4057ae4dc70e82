"""A serial line between a device at one baud rate and a driver at another, over the twins'
pseudo-terminals: what a UART at the wrong rate receives is garbage, fewer or more bytes by
the ratio of the rates (sim_devices/twins/uart.py, from first principles)."""
from __future__ import annotations

import math
import os
import time

import pytest
import serial
from hypothesis import given, settings, strategies as st

from drivers.protocols import vectornav as V
from sim_devices.truth import default_truth
from sim_devices.twins.serve import BenchOptions, BenchServer
from sim_devices.twins.uart import line_bits, reframe


def test_line_bits_are_8n1_lsb_first():
    assert list(line_bits(b"\x01\x80")) == [0, 1, 0, 0, 0, 0, 0, 0, 0, 1,
                                            0, 0, 0, 0, 0, 0, 0, 0, 1, 1]


@pytest.mark.parametrize("error", [-0.02, 0.0, 0.02])
def test_a_receiver_within_a_few_percent_gets_every_byte(error):
    data = os.urandom(5000)
    assert reframe(data, 115200, 115200 * (1 + error)) == data


@pytest.mark.parametrize("read_baud", [9600, 38400, 57600, 230400, 921600])
def test_a_receiver_at_another_rate_gets_garbage_in_proportion(read_baud):
    data = V.format_message("VNRRG,01,VN-100T") * 300            # 7,500 bytes of replies
    got = reframe(data, 115200, read_baud)
    assert V.find_message(got) is None
    ratio = len(got) / len(data)
    if read_baud < 115200:                    # one received character spans several sent ones
        assert ratio == pytest.approx(read_baud / 115200, rel=0.5)
    else:                                     # a new start bit at (nearly) every falling edge
        assert 1.0 < ratio <= 10 * 0.5 * read_baud / 115200 + 1


def test_the_pty_twin_answers_only_a_driver_at_its_baud_rate():
    with BenchServer(default_truth(2), BenchOptions(speed=20)) as server:
        assert server.imu_port.line_baud() == 115200
        for baud, answered in ((9600, False), (230400, False), (115200, True)):
            with serial.Serial(server.imu_path, baud, timeout=0.05) as port:
                assert server.imu_port.line_baud() == baud
                time.sleep(0.05)
                port.reset_input_buffer()
                port.write(V.format_message("VNRRG,01"))
                # at the wrong rates 0.5 s of garbage; at the right one, until the reply and the
                # stream have come (within 5 s: a twin starved on a busy machine)
                raw, end = bytearray(), time.monotonic() + (5.0 if answered else 0.5)
                while time.monotonic() < end and not (
                        answered and b"$VNRRG,01,VN-100T-SIM*" in raw and b"$VNYMR," in raw):
                    raw += port.read(65536)
            assert raw                                           # bytes arrive either way ...
            assert (b"$VNRRG,01,VN-100T-SIM*" in raw) == answered   # ... valid only at the rate
            assert (b"$VNYMR," in raw) == answered
        # register 05: the reply at the old rate, then the twin runs at the new one
        with serial.Serial(server.imu_path, 115200, timeout=0.05) as port:
            port.write(V.format_message("VNWRG,05,57600"))
            raw, end = bytearray(), time.monotonic() + 1.0
            while b"$VNWRG,05,57600*" not in raw and time.monotonic() < end:
                raw += port.read(65536)
            assert b"$VNWRG,05,57600*" in raw
            assert server.imu_frontend.line_baud == 57600
            port.baudrate = 57600
            time.sleep(0.05)
            port.reset_input_buffer()
            raw, end = bytearray(), time.monotonic() + 5.0
            while time.monotonic() < end and b"$VNYMR," not in raw:
                raw += port.read(65536)
            assert b"$VNYMR," in raw


def _reframe_byte_by_byte(data: bytes, sent_baud: float, read_baud: float) -> bytes:
    """A reference sharing no code with uart.reframe: the receiver of its docstring, one start
    bit at a time over the line's levels (a Python loop)."""
    line = [1]
    for b in data:
        line += [0] + [(b >> k) & 1 for k in range(8)] + [1]
    line = line[1:]
    r, out, i = sent_baud / read_baud, bytearray(), 0
    level = lambda x: line[int(x)] if x < len(line) else 1     # noqa: E731 (idle past the end)
    while True:
        while i < len(line) and not (line[i] == 0 and (i == 0 or line[i - 1] == 1)):
            i += 1                                              # the next falling edge
        if i >= len(line):
            return bytes(out)
        if level(i + 0.5 * r) != 0:                             # a glitch: look on from the next edge
            i += 1
            continue
        out.append(sum(level(i + (k + 0.5) * r) << (k - 1) for k in range(1, 9)))
        i = math.ceil(i + 9.5 * r)                              # after the stop-bit sample


@settings(max_examples=80, deadline=None)
@given(st.binary(max_size=200), st.sampled_from([9600, 19200, 38400, 57600, 115200, 128000,
                                                 230400, 460800, 921600]),
       st.floats(0.05, 20.0))
def test_reframe_gives_the_bytes_of_a_receiver_walking_one_start_bit_at_a_time(data, sent, ratio):
    read = sent * ratio
    if read == sent:
        return
    assert reframe(data, sent, read) == _reframe_byte_by_byte(data, sent, read)
