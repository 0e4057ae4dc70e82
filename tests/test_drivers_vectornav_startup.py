"""VectorNav start-up as a real client does it, and the twin's standard registers, over real
pseudo-terminals.  The command strings are those VectorNav's programming library (vnproglib
1.2, packet.cpp) generates: ``$VNWRG,05,<baud>,<port>``, ``$VNWRG,06,<ador>,<port>``,
``$VNRRG,54``, ``$VNWNV``, ``$VNRST``, with the 8-bit checksum or the 16-bit CRC."""
from __future__ import annotations

import time

import numpy as np
import pytest
import serial

from drivers.base import ImuSettings
from drivers.errors import LimitError
from drivers.protocols import vectornav as V
from drivers.registry import open_imu
from sim_devices.truth import default_truth
from sim_devices.twins.serve import BenchOptions, BenchServer

SPEED = 20.0


@pytest.fixture
def server():
    with BenchServer(default_truth(2), BenchOptions(speed=SPEED)) as s:
        yield s


def _ask(port, body, crc=False, timeout=2.0):
    """Send ``$body*..`` and return the first reply message (skipping binary frames)."""
    port.write(V.format_message(body, crc=crc))
    buf, end = bytearray(), time.monotonic() + timeout
    head = body.split(",")[0] if not body.startswith("VNRRG") and not body.startswith("VNWRG") else ",".join(body.split(",")[:2])
    while time.monotonic() < end:
        buf += port.read(max(1, port.in_waiting))
        pos = 0
        while (found := V.find_message(buf, pos)) is not None:
            msg, pos = found
            if msg.startswith(head) or msg.startswith("VNERR"):
                return msg, bytes(buf)
    raise AssertionError(f"no reply to {body}")


def test_a_sensor_sending_ascii_async_output_is_quietened_at_connect(server):
    server.imu_frontend.ador = V.ADOR_VNIMU           # as a sensor fresh from another program
    with serial.Serial(server.imu_path, timeout=0.05) as raw:     # the lines are there ...
        time.sleep(0.2)
        assert b"$VNIMU," in raw.read(65536)
    with open_imu(server.imu_path, "vectornav") as imu:
        assert "hardware 2" in imu.identity
        s = imu.read(2000)
        c = imu.counters
    assert server.imu_frontend.ador == V.ADOR_OFF     # ... the driver wrote register 06 = 0
    assert len(s) == 2000 and c.resyncs == 0 and c.bytes_discarded == 0 and c.missing_frames == 0


def test_rate_is_checked_against_the_baud_rate(server):
    with open_imu(server.imu_path, "vectornav", ImuSettings(rate_hz=400.0)) as imu:
        with pytest.raises(LimitError, match=r"400 Hz of 44-byte frames needs 176000 baud .* at most 261.8 Hz"):
            imu.configure()
        assert imu.configure(200.0) == 200.0
    with open_imu(server.imu_path, "vectornav", ImuSettings(rate_hz=800.0, device_baud=921600)) as imu:
        assert server.imu_frontend.baudrate == 921600
        assert imu.configure() == 800.0
        assert len(imu.read(800)) == 800
    with pytest.raises(LimitError, match="baud rate 1000 is not one of"):
        open_imu(server.imu_path, "vectornav", ImuSettings(device_baud=1000))


@pytest.mark.parametrize("crc", [False, True], ids=["checksum8", "crc16"])
def test_the_twin_answers_the_standard_registers(server, crc):
    with serial.Serial(server.imu_path, timeout=0.05) as port:
        msg, raw = _ask(port, "VNASY,0", crc)
        assert msg == "VNASY,0" and (b"*" + V.crc16(b"VNASY,0") + b"\r\n" in raw) == crc
        assert _ask(port, "VNRRG,01", crc)[0] == "VNRRG,01,VN-100T-SIM"
        assert _ask(port, "VNRRG,02", crc)[0] == "VNRRG,02,2"
        assert _ask(port, "VNRRG,04", crc)[0] == "VNRRG,04,2.1.0.0"
        assert _ask(port, "VNRRG,05,1", crc)[0] == "VNRRG,05,115200"
        assert _ask(port, "VNWRG,05,230400,1", crc)[0] == "VNWRG,05,230400,1"
        assert _ask(port, "VNWRG,05,12345", crc)[0] == "VNERR,07"
        assert _ask(port, "VNRRG,06", crc)[0] == "VNRRG,06,0"
        assert _ask(port, "VNWRG,06,19,1", crc)[0] == "VNWRG,06,19,1"
        assert _ask(port, "VNWRG,07,50", crc)[0] == "VNWRG,07,50"
        assert _ask(port, "VNRRG,07", crc)[0] == "VNRRG,07,50"
        values = [float(v) for v in _ask(port, "VNRRG,54", crc)[0].split(",")[2:]]
        assert len(values) == 11
        assert np.linalg.norm(values[3:6]) == pytest.approx(9.8, abs=0.05)        # m/s^2, at rest
        assert np.linalg.norm(values[6:9]) < 1e-3                                 # rad/s
        assert _ask(port, "VNRRG,75", crc)[0] == "VNRRG,75,1,8,05,0001,001C"
        assert _ask(port, "VNRRG,76", crc)[0] == "VNRRG,76,0,0,00"
        assert _ask(port, "VNRRG,77", crc)[0] == "VNRRG,77,0,0,00"
        assert _ask(port, "VNWRG,76,1,8,01,0001", crc)[0] == "VNERR,07"             # twin streams 75 only
        # saved settings come back after a reset; others are lost
        assert _ask(port, "VNWNV", crc)[0] == "VNWNV"
        assert _ask(port, "VNWRG,06,0", crc)[0] == "VNWRG,06,0"
        assert _ask(port, "VNRST", crc)[0] == "VNRST"
        assert _ask(port, "VNRRG,06", crc)[0] == "VNRRG,06,19"
        assert _ask(port, "VNRRG,05", crc)[0] == "VNRRG,05,230400"
        assert _ask(port, "VNRRG,99", crc)[0] == "VNERR,08"


def test_ascii_crc16_replies_are_understood():
    body = b"VNRRG,01,VN-100T"
    good = b"$" + body + b"*" + V.crc16(body) + b"\r\n"
    assert V.find_message(b"junk" + good) == (body.decode(), len(good) + 4)
    bad = b"$" + body + b"*" + b"%04X" % ((int(V.crc16(body), 16) ^ 1)) + b"\r\n"
    assert V.find_message(bad) is None
    assert V.crc16(b"123456789") == b"31C3"            # CRC-16/XMODEM check value
