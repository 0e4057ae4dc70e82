"""Xsens MTi over XBus (MTData2): the message format, the decoder under corruption, and the
driver against the twin over a real pseudo-terminal."""
from __future__ import annotations

import math
import struct

import numpy as np
import pytest
import serial
from hypothesis import given, settings
from hypothesis import strategies as st

from drivers.base import ImuSettings
from drivers.errors import LimitError, ProtocolError
from drivers.protocols import xbus as X
from drivers.registry import open_imu
from sim_devices import world
from sim_devices.truth import default_truth
from sim_devices.twins.faults import Faults, ImuFaults
from sim_devices.twins.serve import BenchOptions, BenchServer
from station.cli import main

SPEED = 50.0


def test_message_checksum_and_examples():
    # GoToConfig as every client sends it: FA FF 30 00 D1 (0xFF + 0x30 + 0x00 + 0xD1 = 0x200)
    assert X.message(X.MID.GoToConfig) == bytes.fromhex("faff3000d1")
    assert X.message(X.MID.GoToMeasurement) == bytes.fromhex("faff1000f1")
    m = X.message(X.MID.SetOutputConfiguration, X.output_configuration(X.station_configuration(100)))
    assert sum(m[1:]) % 256 == 0 and m[3] == 16
    assert m.hex(" ") == "fa ff c0 10 10 60 ff ff 40 20 00 64 80 20 00 64 08 10 00 64 7f"
    long = X.message(0x99, bytes(300))
    assert long[3] == 0xFF and long[4:6] == struct.pack(">H", 300) and sum(long[1:]) % 256 == 0
    assert X.XbusParser().feed(long) == [(0x99, bytes(300))]


def test_mtdata2_round_trip():
    items = X.station_configuration(100)
    blob = X.encode_mtdata2(items, [10000, 10100], [[0.01, -0.02, 9.81]] * 2, [[0.001, 0, -0.0005]] * 2, [25.0, 25.5])
    assert len(blob) == 2 * X.mtdata2_length(items) == 2 * 49
    d = X.XsensDecoder()
    s = d.feed(blob[:30])
    s = d.feed(blob[30:])
    assert len(s) == 2 and d.frames == 2
    np.testing.assert_allclose(s.t_s, [1.0, 1.01])
    np.testing.assert_allclose(s.accel_mps2[0], [0.01, -0.02, 9.81], rtol=1e-6)
    np.testing.assert_allclose(s.gyro_dps[0], np.degrees([0.001, 0, -0.0005]), rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(s.temp_c, [25.0, 25.5])


def test_sample_time_wraps_are_unwrapped():
    items = X.station_configuration(100)
    ticks = [X.SAMPLE_TIME_WRAP - 100, X.SAMPLE_TIME_WRAP, X.SAMPLE_TIME_WRAP + 100]
    blob = X.encode_mtdata2(items, ticks, np.zeros((3, 3)), np.zeros((3, 3)), np.zeros(3))
    s = X.XsensDecoder().feed(blob)
    np.testing.assert_allclose(np.diff(s.t_s), 0.01, atol=1e-9)


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=400), st.integers(0, 97))
def test_decoder_never_raises_and_keeps_intact_messages(junk, cut):
    items = X.station_configuration(100)
    good = X.encode_mtdata2(items, [1, 2], np.ones((2, 3)), np.ones((2, 3)), np.ones(2))
    d = X.XsensDecoder()
    out = d.feed(junk[:cut] + good + junk[cut:])
    assert d.frames >= 0 and len(out) >= 0
    d2 = X.XsensDecoder()
    assert len(d2.feed(good + junk + good)) >= 2


def test_a_checksum_of_0xfa_at_the_end_of_a_read_is_not_taken_for_a_preamble():
    """A read that ends exactly after a message whose checksum byte is 0xFA (1 message in 256;
    reads end on message boundaries whenever the reader keeps up): that byte was kept as the
    possible start of the next preamble, and the next read, starting with FA FF, then skipped
    one byte (the resync seen after GoToMeasurement in a loaded CI run)."""
    items = X.station_configuration(100)
    msgs = [X.encode_mtdata2(items, [k], np.full((1, 3), 0.1 * k), np.ones((1, 3)), np.ones(1))
            for k in range(2000)]
    ending_fa = [m for m in msgs if m[-1] == 0xFA]
    assert ending_fa                                     # about 2000 / 256 of them
    d = X.XsensDecoder()
    got = 0
    for m in ending_fa:
        got += len(d.feed(m))                            # one read per message
        got += len(d.feed(m[:1]))                        # the next read: 0xFA alone, ...
        got += len(d.feed(m[1:]))                        # ... then the rest
    assert got == 2 * len(ending_fa)
    assert (d.resyncs, d.bytes_discarded, d.checksum_errors) == (0, 0, 0)
    p = X.XbusParser()                                   # the parser alone, a bare 0xFA too
    assert p.feed(X.message(0x11, b"")) == [(0x11, b"")] and p.feed(b"\xfa") == []
    assert p.feed(b"\xff\x11\x00\xf0") == [(0x11, b"")] and p.resyncs == 0


@pytest.fixture
def bench():
    truth = default_truth(4)
    with BenchServer(truth, BenchOptions(speed=SPEED, imu_protocol="xsens", axes=2)) as server:
        yield server, truth


def test_driver_starts_up_and_reads_the_truth_at_rest(bench):
    server, truth = bench
    with open_imu(server.imu_path, "xsens") as imu:
        assert imu.identity == "MTi-3-SIM device id 03700001 firmware 1.8.2"
        assert server.imu_frontend.state == "config"
        assert imu.configure(100.0) == 100.0
        s = imu.read(2000)
        assert server.imu_frontend.state == "measurement"
        c = imu.counters
    # not a sample lost or corrupted, not a byte skipped (a read ending on a message whose
    # checksum is 0xFA used to cost one resync: test_a_checksum_of_0xfa_at_the_end_of_a_read...)
    assert c.missing_frames == 0 and c.checksum_errors == 0
    assert c.resyncs == 0 and c.bytes_discarded == 0, c
    np.testing.assert_allclose(np.diff(s.t_s), 0.01, atol=1e-9)
    site = world.Site(truth.bench.latitude_deg, truth.bench.height_m)
    accel, gyro = truth.measure(np.array([[0.0, 0.0, site.g]]), np.degrees(site.earth_rate_enu)[None, :],
                                s.temp_c.mean(), None)
    sa, sg = truth.accel_noise_sigma / math.sqrt(len(s)), truth.gyro_noise_sigma / math.sqrt(len(s))
    np.testing.assert_allclose(s.accel_mps2.mean(axis=0), accel[0], atol=5 * sa + 1e-5)
    np.testing.assert_allclose(s.gyro_dps.mean(axis=0), gyro[0], atol=5 * sg + 1e-6)
    assert server.imu_frontend.state == "config"          # stopped on close


def test_output_rate_and_refusals(bench):
    server, _ = bench
    with open_imu(server.imu_path, "xsens") as imu:
        assert imu.configure(200.0) == 200.0
        s = imu.read(400)
        np.testing.assert_allclose(np.diff(s.t_s), 0.005, atol=1e-9)
        with pytest.raises(LimitError, match="not 400 Hz / N"):
            imu.configure(300.0)
        with pytest.raises(LimitError, match=r"400 Hz of 49-byte messages needs 196000 baud"):
            imu.configure(400.0)
    with serial.Serial(server.imu_path, 115200, timeout=0.5) as port:      # outputs the twin refuses
        port.write(X.message(X.MID.GoToConfig))
        port.write(X.message(X.MID.SetOutputConfiguration, X.output_configuration([(0x2010, 100)])))
        got = X.XbusParser().feed(port.read(200))
    assert (X.MID.GoToConfig + 1, b"") in got and (X.MID.Error, bytes([0x21])) in got


def test_corruption_counts_and_every_intact_message_decoded():
    faults = Faults(imu=ImuFaults(garbage_every_s=0.25, garbage_bytes=48, corrupt_probability=0.02))
    opts = BenchOptions(speed=SPEED, imu_protocol="xsens", faults=faults, record=True)
    with BenchServer(default_truth(2), opts) as server:
        with open_imu(server.imu_path, "xsens") as imu:
            s = imu.read(3000)
            c = imu.counters
        sent = np.concatenate(server.faulter.intact_times)
    window = sent[(sent >= s.t_s[0] - 1e-9) & (sent <= s.t_s[-1] + 1e-9)]
    np.testing.assert_allclose(s.t_s, window, rtol=0, atol=1e-9)
    assert c.checksum_errors > 0 and c.resyncs > 0


def test_probe_xsens(capsys):
    with BenchServer(default_truth(2), BenchOptions(speed=SPEED, imu_protocol="xsens")) as server:
        assert main(["probe", "--port", server.imu_path, "--imu-protocol", "xsens", "--seconds", "20",
                     "--json"]) == 0
    import json
    r = json.loads(capsys.readouterr().out)
    assert r["frames"] == 2000 and r["missing_frames"] == 0 and abs(r["rate_hz"] - 100.0) < 1e-6
    assert r["identity"].startswith("MTi-3-SIM")


def test_the_docs_show_the_messages_as_sent():
    from pathlib import Path
    doc = (Path(__file__).resolve().parents[1] / "docs" / "protocols.md").read_text()
    for mid, data in [(X.MID.GoToConfig, b""), (X.MID.GoToConfig + 1, b""), (X.MID.ReqDID, b""),
                      (X.MID.DeviceID, struct.pack(">I", 0x03700001)), (X.MID.ReqFWRev, b""),
                      (X.MID.FirmwareRev, bytes([1, 8, 2])), (X.MID.GoToMeasurement, b""),
                      (X.MID.SetOutputConfiguration, X.output_configuration(X.station_configuration(100)))]:
        assert X.message(mid, data).hex(" ") in doc
