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
from drivers.errors import LimitError, ProtocolError
from drivers.protocols import vectornav as V
from drivers.registry import open_imu
from sim_devices.truth import default_truth
from sim_devices.twins.clock import ManualClock
from sim_devices.twins.faults import ImuFaults, StreamFaulter
from sim_devices.twins.geometry import TableGeometry
from sim_devices.twins.imu import ImuTwin
from sim_devices.twins.imu_vectornav import VectorNavFrontEnd
from sim_devices.twins.serve import BenchOptions, BenchServer
from sim_devices.twins.table import TableTwin

from processes import quiet_after, read_until

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
    with serial.Serial(server.imu_path, 115200, timeout=0.05) as raw:     # the lines are there ...
        assert b"$VNIMU," in read_until(raw, lambda b: b"$VNIMU," in b)
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
    with serial.Serial(server.imu_path, 115200, timeout=0.05) as port:
        msg, raw = _ask(port, "VNASY,0", crc)
        assert msg == "VNASY,0" and (b"*" + V.crc16(b"VNASY,0") + b"\r\n" in raw) == crc
        assert _ask(port, "VNRRG,01", crc)[0] == "VNRRG,01,VN-100T-SIM"
        assert _ask(port, "VNRRG,02", crc)[0] == "VNRRG,02,2"
        assert _ask(port, "VNRRG,04", crc)[0] == "VNRRG,04,2.1.0.0"
        assert _ask(port, "VNRRG,05,1", crc)[0] == "VNRRG,05,115200"
        assert _ask(port, "VNWRG,05,230400,1", crc)[0] == "VNWRG,05,230400,1"     # at the old rate
        port.baudrate = 230400
        assert _ask(port, "VNWRG,05,12345", crc)[0] == "VNERR,07"
        assert _ask(port, "VNRRG,06", crc)[0] == "VNRRG,06,14"          # factory default: $VNYMR
        assert _ask(port, "VNWRG,06,0", crc)[0] == "VNWRG,06,0"
        assert _ask(port, "VNWRG,06,19,1", crc)[0] == "VNWRG,06,19,1"
        assert _ask(port, "VNWRG,07,50", crc)[0] == "VNWRG,07,50"
        assert _ask(port, "VNRRG,07", crc)[0] == "VNRRG,07,50"
        values = [float(v) for v in _ask(port, "VNRRG,54", crc)[0].split(",")[2:]]
        assert len(values) == 11
        assert np.linalg.norm(values[3:6]) == pytest.approx(9.8, abs=0.05)        # m/s^2, at rest
        assert np.linalg.norm(values[6:9]) < 1e-3                                 # rad/s
        assert _ask(port, "VNRRG,75", crc)[0] == "VNRRG,75,0,0,00"       # binary output off
        assert _ask(port, "VNWRG,75,1,8,05,0001,001C", crc)[0] == "VNWRG,75,1,8,05,0001,001C"
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


# ------------------------------------------------------------------ factory default, error codes

def _lines(raw: bytes, header: bytes) -> list[bytes]:
    """The checked ASCII messages with ``header`` in ``raw``."""
    out, pos = [], 0
    while (found := V.find_message(raw, pos)) is not None:
        body, pos = found
        if body.encode().startswith(header):
            out.append(body.encode())
    return out


def test_the_twin_powers_up_as_a_factory_default_vn100(server):
    """A factory VN-100 streams $VNYMR at 40 Hz (register 06 = 14, 07 = 40), binary output off,
    at 115200 baud; the fields as the manual's register 27 (UM001 7.2.3): yaw, pitch, roll (deg),
    mag (gauss), accel (m/s^2), gyro (rad/s), in its fixed widths."""
    with serial.Serial(server.imu_path, 115200, timeout=0.05) as port:
        raw = read_until(port, lambda b: len(_lines(b, b"VNYMR,")) > 11)
        assert 0xFA not in raw                        # no binary frame
        ymr = _lines(bytes(raw), b"VNYMR,")
        assert len(ymr) > 10
        fields = ymr[-1].split(b",")[1:]
        assert len(fields) == 12
        assert [len(f) for f in fields] == [8] * 3 + [7] * 3 + [7] * 3 + [9] * 3
        v = np.array([float(f) for f in fields])
        assert np.linalg.norm(v[6:9]) == pytest.approx(9.8, abs=0.05)    # m/s^2, at rest
        assert np.linalg.norm(v[9:12]) < 1e-3                            # rad/s
        assert 0.3 < np.linalg.norm(v[3:6]) < 0.7                        # gauss
        assert _ask(port, "VNRRG,06")[0] == "VNRRG,06,14"
        assert _ask(port, "VNRRG,07")[0] == "VNRRG,07,40"
        assert _ask(port, "VNRRG,75")[0] == "VNRRG,75,0,0,00"
        assert _ask(port, "VNWRG,06,14")[0] == "VNWRG,06,14"              # refused before
        assert _ask(port, "VNRRG,27")[0].count(",") == 13
    # 40 a second of device time, from power-up (the front end alone, on a manual clock)
    clock = ManualClock()
    truth = default_truth(3)
    fe = VectorNavFrontEnd(ImuTwin(TableTwin(TableGeometry.default(1), clock), truth),
                           StreamFaulter(ImuFaults(), None))
    out = fe.produce(clock.now()) + b"".join(fe.produce(clock.advance(0.25)) for _ in range(40))
    assert len(_lines(out, b"VNYMR,")) == 400 and out.count(b"$") == 400
    assert len(out) == 400 * V.ASCII_MESSAGE_BYTES[V.ADOR_VNYMR]             # fixed widths


def test_the_driver_starts_a_factory_default_sensor_cleanly(server):
    """pause, ASCII off, binary output 75, resume: after start, clean frames only."""
    with serial.Serial(server.imu_path, 115200, timeout=0.05) as raw:
        assert b"$VNYMR," in read_until(raw, lambda b: b"$VNYMR," in b)          # the factory stream is there
    with open_imu(server.imu_path, "vectornav") as imu:
        s = imu.read(3000)
        c = imu.counters
    assert len(s) == 3000 and c.frames >= 3000
    assert (c.resyncs, c.bytes_discarded, c.checksum_errors, c.missing_frames) == (0, 0, 0, 0)
    np.testing.assert_allclose(np.diff(s.t_s), 0.01, atol=2e-6)
    fe = server.imu_frontend
    assert (fe.ador, fe.async_mode, fe.divisor) == (V.ADOR_OFF, V.ASYNC_MODE_PORT1, 8)


def test_error_codes_are_hex_as_the_sensor_sends_them(server):
    """Bytes from a public VN-100 transcript (115200 baud, $VNYMR on): ``$VNWRG,07,100*6C`` is
    answered ``$VNERR,0C*02`` (error 12, insufficient baud rate), 50 and 40 Hz are accepted."""
    assert V.format_message("VNERR,0C") == b"$VNERR,0C*02\r\n"
    assert V.parse_error_code("0C") == 12 and V.parse_error_code("0A") == 10
    assert V.parse_error_code("FF") == 255 and V.parse_error_code("1G") is None
    assert V.error_body(12) == "VNERR,0C" and V.error_body(8) == "VNERR,08"
    with serial.Serial(server.imu_path, 115200, timeout=0.05) as port:
        port.write(b"$VNWRG,07,100*6C\r\n")
        buf, end = bytearray(), time.monotonic() + 2
        while b"$VNERR" not in buf and time.monotonic() < end:
            buf += port.read(4096)
        assert b"$VNERR,0C*02\r\n" in buf
        assert _ask(port, "VNWRG,07,50")[0] == "VNWRG,07,50"
        assert _ask(port, "VNWRG,07,40")[0] == "VNWRG,07,40"
    with open_imu(server.imu_path, "vectornav") as imu:
        with pytest.raises(ProtocolError, match=r"\$VNWRG,99,100 refused: VNERR 08 \(error 8: invalid register"):
            imu._ask("VNWRG,99,100")
        assert imu._ask("VNWRG,06,14") == ["14"]          # $VNYMR at 40 Hz: fits 115200 baud
        with pytest.raises(ProtocolError) as e:
            imu._ask("VNWRG,07,100")
    msg = str(e.value)
    assert "$VNWRG,07,100 refused: VNERR 0C (error 12: insufficient baud rate" in msg
    assert "115200 baud" in msg and "set a higher baud rate (register 05" in msg


def test_the_twin_refuses_outputs_the_baud_rate_cannot_carry(server):
    """Error 12 when the async outputs (ASCII message x frequency + binary output 1) need more
    than the baud rate carries at 10 bits a byte: 800 Hz of 44-byte frames at 9600 baud."""
    with serial.Serial(server.imu_path, 115200, timeout=0.05) as port:
        assert _ask(port, "VNASY,0")[0] == "VNASY,0"
        assert _ask(port, "VNWRG,06,0")[0] == "VNWRG,06,0"
        assert _ask(port, "VNWRG,05,9600")[0] == "VNWRG,05,9600"
        port.baudrate = 9600
        assert _ask(port, "VNWRG,75,1,1,05,0001,001C")[0] == "VNERR,0C"       # 352,000 baud needed
        assert _ask(port, "VNWRG,75,1,16,05,0001,001C")[0] == "VNERR,0C"      # 50 Hz: 22,000
        assert _ask(port, "VNWRG,75,1,80,05,0001,001C")[0] == "VNWRG,75,1,80,05,0001,001C"   # 10 Hz: 4400
        assert _ask(port, "VNWRG,06,14")[0] == "VNERR,0C"                     # + 40 x 116 bytes
        assert _ask(port, "VNWRG,07,1")[0] == "VNWRG,07,1"
        assert _ask(port, "VNWRG,06,14")[0] == "VNWRG,06,14"                  # + 1 x 116 bytes
        assert _ask(port, "VNWRG,07,10")[0] == "VNERR,0C"
        assert _ask(port, "VNRRG,75")[0] == "VNRRG,75,1,80,05,0001,001C"       # refused: unchanged


def test_the_twin_writes_vnymr_as_the_manual_does():
    """VN-100 UM001 7.2.3, register 27's example response, byte for byte (its checksum too);
    VN-200 UM004 5.6, register 05's."""
    example = (b"$VNRRG,27,+006.380,+000.023,-001.953,+1.0640,-0.2531,+3.0614,+00.005,+00.344,"
               b"-09.758,-0.001222,-0.000450,-0.001218*4F\r\n")
    body, end = V.find_message(example)
    assert end == len(example)
    v = [float(x) for x in body.split(",")[2:]]
    assert V.format_message("VNRRG,27," + V.ymr_values(v[0:3], v[3:6], v[6:9], v[9:12])) == example
    assert len(example) - len(b"$VNRRG,27,") + len(b"$VNYMR,") == V.ASCII_MESSAGE_BYTES[V.ADOR_VNYMR]
    assert V.format_message("VNRRG,05,115200") == b"$VNRRG,05,115200*5D\r\n"


def test_binary_output_off_as_vectornavs_library_writes_it(server):
    """VectorNav's own library turns binary output off with its default register value,
    `$VNWRG,75,0,0,0` (async mode 0, no group, no field mask): accepted, the stream stops, the
    register reads back as at power-up (the twin answered error 7 to it)."""
    with serial.Serial(server.imu_path, 115200, timeout=0.05) as port:
        assert _ask(port, "VNWRG,06,0")[0] == "VNWRG,06,0"
        assert _ask(port, "VNWRG,75,1,8,05,0001,001C")[0] == "VNWRG,75,1,8,05,0001,001C"
        assert 0xFA in read_until(port, lambda b: 0xFA in b)    # binary frames flow
        assert _ask(port, "VNWRG,75,0,0,0")[0] == "VNWRG,75,0,0,0"
        # and stop: 0.3 s (6 s of the twin's time at SPEED 20) without a frame, once what was
        # under way when the register was written has come
        assert quiet_after(port, lambda chunk: 0xFA in chunk, 0.3)
        assert _ask(port, "VNRRG,75")[0] == "VNRRG,75,0,0,00"
