"""Each injected fault gives its documented driver behaviour (docs/twins.md)."""
from __future__ import annotations

import time

import numpy as np
import pytest

from drivers.base import AxisLimits, ImuSettings, TableSettings
from drivers.errors import DeviceDisconnected, DeviceTimeout, TableFault
from drivers.registry import open_imu, open_table
from drivers.samples import ImuSamples
from drivers.transport import SerialSettings
from sim_devices.truth import default_truth
from sim_devices.twins.faults import Faults, ImuFaults, faults_from_dict, load_faults
from sim_devices.twins.serve import BenchOptions, BenchServer
from sim_devices.twins.table import TableConfig, TableFaults
from station.core.errors import UserError

SPEED = 50.0


def _bench(imu_protocol="vectornav", table_protocol="acutrol", axes=2, config=TableConfig(),
           speed=SPEED, **faults):
    f = Faults(imu=faults.pop("imu", ImuFaults()), table=faults.pop("table", TableFaults()))
    return BenchServer(default_truth(8), BenchOptions(speed=speed, axes=axes, faults=f, record=True,
                                                      imu_protocol=imu_protocol, table_config=config,
                                                      table_protocol=table_protocol))


def _read_all(imu, n):
    s = imu.read(n)
    return ImuSamples.concat([s, imu.read(imu.counters.frames - n)])


# ------------------------------------------------------------------------------ IMU

@pytest.mark.parametrize("protocol", ["vectornav", "csv"])
def test_dropped_frames_are_counted_as_gaps(protocol):
    with _bench(protocol, imu=ImuFaults(drop_probability=0.03)) as server:
        with open_imu(server.imu_path, protocol) as imu:
            s = _read_all(imu, 2000)
            c = imu.counters
        sent = np.concatenate(server.faulter.intact_times)
    sent = sent[(sent >= s.t_s[0] - 1e-9) & (sent <= s.t_s[-1] + 1e-9)]
    np.testing.assert_allclose(s.t_s, sent, atol=1e-9)
    expected_missing = int(round((s.t_s[-1] - s.t_s[0]) * 100)) + 1 - len(s)
    steps = np.diff(s.t_s)
    assert c.missing_frames == expected_missing > 20
    assert c.gaps == int((steps > 0.015).sum()) > 20
    assert c.checksum_errors == 0


@pytest.mark.parametrize("protocol", ["vectornav", "csv"])
def test_corrupted_frames_are_checksum_errors_and_gaps(protocol):
    with _bench(protocol, imu=ImuFaults(corrupt_probability=0.03)) as server:
        with open_imu(server.imu_path, protocol) as imu:
            s = _read_all(imu, 2000)
            c = imu.counters
        corrupted = server.faulter.frames_corrupted
    missing = int(round((s.t_s[-1] - s.t_s[0]) * 100)) + 1 - len(s)
    # every frame missing inside the window was corrupted; a corrupted sync/header byte
    # (vectornav) is a resync rather than a checksum error
    assert c.missing_frames == missing > 20
    assert missing - c.resyncs <= c.checksum_errors <= corrupted
    if protocol == "csv":
        assert c.checksum_errors == missing


@pytest.mark.parametrize("protocol", ["vectornav", "csv"])
def test_a_stalled_stream_ends_in_a_timeout_naming_the_device(protocol):
    with _bench(protocol, imu=ImuFaults(stall_at_s=5.0)) as server:
        with open_imu(server.imu_path, protocol, ImuSettings(frame_timeout_s=0.3)) as imu:
            t0 = time.monotonic()
            with pytest.raises(DeviceTimeout) as e:
                imu.read(5000)
            assert 0.3 <= time.monotonic() - t0 < 3.0
            assert str(e.value).startswith(f"imu {server.imu_path} ({protocol}): no valid frame for 0.3 s")
            assert imu.counters.frames > 0


def test_a_stall_that_ends_is_a_gap():
    with _bench(imu=ImuFaults(stall_at_s=4.0, stall_duration_s=2.0)) as server:
        with open_imu(server.imu_path, "vectornav", ImuSettings(frame_timeout_s=2.0)) as imu:
            s = imu.read(800)
            c = imu.counters
    assert c.gaps == 1 and c.missing_frames == 200
    assert np.max(np.diff(s.t_s)) == pytest.approx(2.01, abs=1e-6)


@pytest.mark.parametrize("protocol", ["vectornav", "csv"])
def test_a_disconnect_is_reported_naming_the_device(protocol):
    with _bench(protocol, imu=ImuFaults(disconnect_at_s=10.0)) as server:
        with open_imu(server.imu_path, protocol) as imu:
            with pytest.raises(DeviceDisconnected) as e:
                imu.read(100000)
            assert str(e.value).startswith(f"imu {server.imu_path} ({protocol}): disconnected")


# ------------------------------------------------------------------------------ table

@pytest.mark.parametrize("protocol,axes", [("acutrol", 2), ("aerosmith", 1)])
def test_an_interlock_trip_during_a_move_is_a_table_fault(protocol, axes):
    # 180 deg at 10 deg/s: the trip at 10 s of device time (1 s of wall time at speed 10: the
    # opening and the interlocks' closing come before it also on a loaded machine, which at
    # speed 50 they did not) comes during the move
    slow = TableConfig(move_rate_dps=10.0)
    with _bench(table_protocol=protocol, axes=axes, config=slow, speed=10.0,
                table=TableFaults(trip_axis=1, trip_at_s=10.0)) as server:
        settings = TableSettings(limits=(AxisLimits(move_rate_dps=10.0),))
        with open_table(server.table_path, protocol, settings) as table:
            table.close_interlocks()
            with pytest.raises(TableFault) as e:
                table.move_to([180.0] + [0.0] * (axes - 1))
            assert str(e.value).startswith(f"table {server.table_path} ({protocol}): axis 1: interlock OPEN, FAULT")
            st = table.status()
            assert st.fault[0] and not st.interlock_closed[0] and not st.ok
            # braked to rest (within 10 s of wall time: a loaded machine may hold the twin up)
            deadline = time.monotonic() + 10.0
            while abs(table.read_rates_dps()[0]) != 0.0 and time.monotonic() < deadline:
                time.sleep(0.01)
            assert abs(table.read_rates_dps()[0]) == 0.0
            if protocol == "acutrol":                              # recover
                table.reset_interlocks()
                assert table.close_interlocks().ok
                table.move_to([20.0, 0.0])


def test_an_interlock_trip_while_turning_is_a_table_fault_on_the_next_wait():
    # at speed 10 the trip comes 0.6 s after the start, in the 20 s (2 s wall) ramp to 200 deg/s
    with _bench(table=TableFaults(trip_axis=2, trip_at_s=6.0), speed=10.0) as server:
        with open_table(server.table_path) as table:
            table.close_interlocks()
            table.set_rate_limits(2, "rate", 300.0, 10.0)
            with pytest.raises(TableFault, match="axis 2: interlock OPEN, FAULT"):
                table.set_rate(2, 200.0)
            with pytest.raises(TableFault, match="axis 2: interlock OPEN, FAULT"):
                table.check_ok()
            table.stop()                                           # the other axis still stops


@pytest.mark.parametrize("protocol,axes", [("acutrol", 2), ("aerosmith", 1)])
def test_an_axis_that_does_not_reach_its_demand(protocol, axes):
    stuck = TableFaults(stuck_axis=1, shortfall_deg=0.5)
    with _bench(table_protocol=protocol, axes=axes, table=stuck) as server:
        settings = TableSettings(stall_polls=20)
        with open_table(server.table_path, protocol, settings) as table:
            table.close_interlocks()
            with pytest.raises(TableFault) as e:
                table.move_to([30.0] + [10.0] * (axes - 1))
            assert str(e.value) == (f"table {server.table_path} ({protocol}): axis 1 came to rest at "
                                    "29.500000 deg, 0.500000 deg from its demand 30.000000 deg")


@pytest.mark.parametrize("protocol,axes", [("acutrol", 2), ("aerosmith", 1)])
def test_a_stalled_table_ends_in_a_timeout_naming_it(protocol, axes):
    with _bench(table_protocol=protocol, axes=axes, table=TableFaults(stall_at_s=5.0)) as server:
        # the stall comes at 5 s of the twin's time (0.1 s of wall time): on a loaded machine
        # that can be while the driver still opens the port (its first query then times out,
        # the same report); else the table is asked from 7.5 s of device time on
        settings = TableSettings(serial=SerialSettings(timeout_s=0.2))
        deadline = time.monotonic() + 10.0
        with pytest.raises(DeviceTimeout) as e:
            with open_table(server.table_path, protocol, settings) as table:
                while server.clock.now() < 7.5 and time.monotonic() < deadline:
                    time.sleep(0.01)
                table.read_positions_deg()
        assert server.clock.now() >= 5.0                        # after the stall, not before
        assert str(e.value).startswith(f"table {server.table_path} ({protocol}): no reply to ")
        assert "within 0.2 s" in str(e.value)


def test_a_table_disconnect_is_reported():
    with _bench(table=TableFaults(disconnect_at_s=5.0)) as server:
        # the disconnect comes at 5 s of the twin's time: asked until it has (10 s of wall time
        # at most), never after a fixed sleep that a loaded machine can outlast (or while the
        # driver still opens the port, which a loaded machine can make last that long)
        deadline = time.monotonic() + 10.0
        with pytest.raises(DeviceDisconnected, match=f"table {server.table_path} \\(acutrol\\): disconnected"):
            with open_table(server.table_path) as table:
                while time.monotonic() < deadline:
                    table.read_positions_deg()
                    time.sleep(0.01)


def test_a_bench_whose_lines_all_hung_up_waits_instead_of_spinning():
    """Every line closed (the table's and the IMU's disconnect faults): the twins' loop has no
    port to select on, and waits its turn's timeout (<= 20 ms; 1 ms at the least) for a request
    or a stop, instead of turning as fast as it can: a core burnt until the bench is stopped
    (~40,000 turns a second before, on a loaded machine)."""
    with _bench(imu=ImuFaults(disconnect_at_s=1.0), table=TableFaults(disconnect_at_s=1.0)) as server:
        deadline = time.monotonic() + 10.0
        while not (server.table_port.closed and server.lines[0].port.closed):
            assert time.monotonic() < deadline, "the disconnect faults did not come within 10 s"
            time.sleep(0.01)
        s0, t0 = server.steps, time.monotonic()
        time.sleep(0.5)
        turns, wall = server.steps - s0, time.monotonic() - t0
    # a turn waits 1 ms at the least (a capped clock; 20 ms here): at most one a ms, and one more
    assert turns <= wall / 0.001 + 1, f"{turns} turns of the loop in {wall:.2f} s with every line closed"


# ------------------------------------------------------------------------------ the file

def test_faults_file_round_trip(tmp_path):
    p = tmp_path / "faults.yaml"
    p.write_text("""version: 1
imu:
  garbage: {every_s: 1.0, bytes: 17}
  corrupt: {probability: 0.01}
  drop: {probability: 0.02}
  stall: {at_s: 20, duration_s: 5}
  disconnect: {at_s: 30}
table:
  interlock_trip: {axis: 2, at_s: 10}
  stuck_axis: {axis: 1, shortfall_deg: 0.5}
  stall: {at_s: 20}
  disconnect: {at_s: 40}
""")
    f = load_faults(p, n_axes=2)
    assert (f.imu.garbage_every_s, f.imu.garbage_bytes, f.imu.corrupt_probability,
            f.imu.drop_probability, f.imu.stall_at_s, f.imu.stall_duration_s,
            f.imu.disconnect_at_s) == (1.0, 17, 0.01, 0.02, 20, 5, 30)
    assert (f.table.trip_axis, f.table.trip_at_s, f.table.stuck_axis, f.table.shortfall_deg,
            f.table.stall_at_s, f.table.stall_duration_s, f.table.disconnect_at_s) == (2, 10, 1, 0.5, 20, None, 40)
    assert faults_from_dict(None) == Faults()


@pytest.mark.parametrize("text,message", [
    ("[1, 2]", "field '(top level)': expected a mapping"),
    ("version: 2", "field 'version': unsupported version 2"),
    ("imu: {noise: 1}", "field 'imu.noise': unknown field"),
    ("imu: {drop: {probability: 1.5}}", "field 'imu.drop.probability': must be <= 1.0"),
    ("imu: {drop: {probability: yes}}", "field 'imu.drop.probability': expected a number"),
    ("imu: {garbage: {bytes: 3}}", "field 'imu.garbage.every_s': required, missing"),
    ("imu: {garbage: {every_s: 1, bytes: 2.5}}", "field 'imu.garbage.bytes': expected an integer"),
    ("imu: {stall: {at_s: .nan}}", "field 'imu.stall.at_s': must be finite"),
    ("table: {interlock_trip: {axis: 3, at_s: 1}}", "field 'table.interlock_trip.axis': must be <= 2"),
    ("table: {stuck_axis: {axis: 1}}", "field 'table.stuck_axis.shortfall_deg': required, missing"),
    ("imu: [", "not valid YAML"),
    ("!!python/object:os.system ls", "not valid YAML"),
])
def test_faults_file_errors_name_the_file_and_field(tmp_path, text, message):
    p = tmp_path / "f.yaml"
    p.write_text(text)
    with pytest.raises(UserError) as e:
        load_faults(p, n_axes=2)
    assert str(e.value).startswith(f"{p}: ") and message in str(e.value)
