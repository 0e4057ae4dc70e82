"""Contract of the RateTable interface, for every protocol, against the table twin over
real pseudo-terminals (pyserial on the slave side, the twin on the master side)."""
from __future__ import annotations

import time

import numpy as np
import pytest

from drivers.base import AxisLimits, TableSettings, angle_diff_deg
from drivers.errors import DeviceError, LimitError, NotSupported, ProtocolError, TableFault
from drivers.registry import open_table, table_driver
from sim_devices.truth import default_truth
from sim_devices.twins.serve import BenchOptions, BenchServer
from station.core.errors import UserError

# (protocol, axes, transport): acutrol over a pseudo-terminal with the TCP reply framing (RS-232
# through the DE-311, TM-9411), with the GPIB framing (replies to queries only), and over TCP
# on 127.0.0.1 (TM-9384C)
TABLES = [("acutrol", 1, "pty"), ("acutrol", 2, "gpib"), ("acutrol", 3, "tcp"), ("aerosmith", 1, "pty")]
SPEED = 50.0
# the tables a test applies to, by what it needs (parametrised indirectly: no test is generated
# for a table it does not apply to, instead of one that skips)
MULTI_AXIS = [t for t in TABLES if t[1] > 1]
WITH_LIMIT_COMMANDS = [t for t in TABLES if t[0] != "aerosmith"]     # the three-letter dialect has none


def _ids(tables):
    return [f"{p}-{n}ax-{t}" for p, n, t in tables]


@pytest.fixture(params=TABLES, ids=_ids(TABLES))
def bench(request):
    protocol, axes, transport = request.param
    server = BenchServer(default_truth(3), BenchOptions(
        speed=SPEED, axes=axes, table_protocol=protocol,
        table_framing="gpib" if transport == "gpib" else "tcp",
        table_tcp_port=0 if transport == "tcp" else None))
    server.url = server.table_path + ("#gpib" if transport == "gpib" else "")
    with server:
        yield server, protocol, axes


def _open(server, protocol, **kw):
    return open_table(server.url, protocol, TableSettings(**kw))


def test_connect_identifies_and_counts_axes(bench):
    server, protocol, axes = bench
    with _open(server, protocol) as table:
        assert table.identity
        assert table.n_axes == axes
        assert table.axes == tuple(range(1, axes + 1))
        assert len(table.limits) == axes
        np.testing.assert_array_equal(table.read_positions_deg(), np.zeros(axes))
        np.testing.assert_array_equal(table.read_rates_dps(), np.zeros(axes))
        st = table.status()
        assert len(st.interlock_closed) == len(st.fault) == axes
        assert not any(st.fault)


def test_interlocks_close_and_status_reports_them(bench):
    server, protocol, axes = bench
    with _open(server, protocol) as table:
        st = table.close_interlocks()
        assert st.interlock_closed == (True,) * axes and st.ok
        assert table.check_ok().ok
        assert [ax.interlock_closed for ax in server.table.axes] == [True] * axes


def test_move_to_reaches_every_axis_and_the_twin_agrees(bench):
    server, protocol, axes = bench
    targets = [123.25, -40.0, 359.5][:axes]
    with _open(server, protocol) as table:
        table.close_interlocks()
        final = table.move_to(targets)
        tol = table.settings.position_tolerance_deg
        assert np.all(np.abs(angle_diff_deg(final, targets)) <= tol)
        assert np.all(final >= 0) and np.all(final < 360)
        # the twin's true angles (unwrapped) are there too, and at rest
        th, thd, _ = server.table.axis_states(server.clock.now())
        assert np.all(np.abs(angle_diff_deg(th[0], targets)) <= tol)
        assert np.all(np.abs(thd[0]) < table.settings.rate_tolerance_dps)
        assert table.status().mode == ("position",) * axes


@pytest.mark.parametrize("bench", MULTI_AXIS, ids=_ids(MULTI_AXIS), indirect=True)
def test_move_to_leaves_axes_given_none_alone(bench):
    server, protocol, axes = bench
    with _open(server, protocol) as table:
        table.close_interlocks()
        table.move_to([10.0] + [None] * (axes - 1))
        np.testing.assert_allclose(table.read_positions_deg(), [10.0] + [0.0] * (axes - 1), atol=0.002)


def test_set_rate_turns_the_axis_and_stop_brings_it_to_rest(bench):
    server, protocol, axes = bench
    with _open(server, protocol) as table:
        table.close_interlocks()
        rate = table.set_rate(axes, -25.0)
        assert abs(rate + 25.0) <= table.settings.rate_tolerance_dps
        a0 = server.clock.now()
        p0 = table.read_positions_deg()[axes - 1]
        b0 = server.clock.now()
        time.sleep(0.05)
        a1 = server.clock.now()
        p1 = table.read_positions_deg()[axes - 1]
        b1 = server.clock.now()
        swept = -angle_diff_deg(p1, p0)
        # each position was read at a device time between the clock readings around it
        # (at speed 50, 50 ms wall = 2.5 s device: about 62.5 deg)
        assert 25.0 * (a1 - b0) - 1e-3 < swept < 25.0 * (b1 - a0) + 1e-3
        assert table.status().mode[axes - 1] == "rate"
        rest = table.stop()
        assert np.all(np.abs(table.read_rates_dps()) <= table.settings.rate_tolerance_dps)
        time.sleep(0.05)
        np.testing.assert_allclose(table.read_positions_deg(), rest, atol=1e-4)
        assert table.status().mode == ("position",) * axes


def test_limits_are_checked_before_anything_is_sent(bench):
    server, protocol, axes = bench
    limits = AxisLimits(max_rate_dps=100.0)
    with _open(server, protocol, limits=(limits,)) as table:
        table.close_interlocks()
        with pytest.raises(LimitError, match=r"axis 1: rate 150.0 deg/s beyond the limit 100"):
            table.set_rate(1, 150.0)
        with pytest.raises(LimitError, match="no axis 4"):
            table.set_rate(4, 1.0)
        with pytest.raises(LimitError, match="positions given"):
            table.move_to([1.0] * (axes + 1))
        with pytest.raises(LimitError, match="not finite"):
            table.move_to([float("nan")] * axes)
        assert server.table.axes[0].mode == "off"          # nothing reached the twin
        assert str(table.name) in str(LimitError(table.name, "x"))


def test_a_refusal_by_the_controller_is_a_protocol_error_naming_the_command(bench):
    server, protocol, axes = bench
    # the driver allows 5000 deg/s, the controller (twin) 1000 deg/s
    with _open(server, protocol, limits=(AxisLimits(max_rate_dps=5000.0),)) as table:
        table.close_interlocks()
        with pytest.raises(ProtocolError) as e:
            table.set_rate(1, 1500.0)
        assert table.name in str(e.value) and "1500" in str(e.value)
        # and the line is usable afterwards
        assert table.read_rates_dps().shape == (axes,)


def test_rate_limits_of_a_mode(bench):
    server, protocol, axes = bench
    with _open(server, protocol) as table:
        if protocol == "aerosmith":
            with pytest.raises(NotSupported):
                table.set_rate_limits(1, "position", 10.0, 10.0)
            return
        table.set_rate_limits(1, "rate", 20.0, 40.0)
        assert server.table.axes[0].limits["R"] == [20.0, 40.0]
        with pytest.raises(LimitError):
            table.set_rate_limits(1, "rate", 0.0, 40.0)


@pytest.mark.parametrize("bench", WITH_LIMIT_COMMANDS, ids=_ids(WITH_LIMIT_COMMANDS), indirect=True)
def test_rate_waits_follow_a_lower_rate_mode_acceleration(bench):
    """With the rate-mode ramp lowered by set_rate_limits, reaching a rate and braking take
    longer than the axis' maximum acceleration says: the waits must expect that, not time out."""
    server, protocol, axes = bench
    # 20 deg/s at 1 deg/s^2: 20 s of device time, 0.4 s of wall time at speed 50 (each way); the
    # margin and the axis' maximum acceleration (300 deg/s^2) would allow 2 x 20/300 + 0.05 =
    # 0.18 s (40 deg/s with a 0.2 s margin before: 0.8 s against 0.47 s, twice the wall time)
    with _open(server, protocol, wait_margin_s=0.05) as table:
        table.close_interlocks()
        table.set_rate_limits(1, "rate", 60.0, 1.0)
        assert abs(table.set_rate(1, 20.0) - 20.0) <= table.settings.rate_tolerance_dps
        table.stop()
        assert abs(table.read_rates_dps()[0]) <= table.settings.rate_tolerance_dps


@pytest.mark.parametrize("bench", WITH_LIMIT_COMMANDS, ids=_ids(WITH_LIMIT_COMMANDS), indirect=True)
def test_connect_sets_the_position_mode_limits(bench):
    server, protocol, axes = bench
    lim = AxisLimits(move_rate_dps=12.5, move_accel_dps2=25.0)
    with _open(server, protocol, limits=(lim,)):
        assert [ax.limits["P"] for ax in server.table.axes] == [[12.5, 25.0]] * axes


def test_closed_port_and_unknown_protocol():
    with pytest.raises(DeviceError, match="cannot open /dev/does-not-exist"):
        open_table("/dev/does-not-exist", "acutrol")
    with pytest.raises(UserError, match="unknown rate-table protocol 'nope'"):
        table_driver("nope")


def test_a_demand_refused_for_an_open_interlock_is_a_table_fault(bench):
    server, protocol, axes = bench
    with _open(server, protocol) as table:
        if protocol == "aerosmith":             # enabled from power-up; SRV0 opens it
            table.open_interlocks([1])
            with pytest.raises(TableFault, match=r"'JOG10' refused: axis 1: interlock OPEN \(status 0x00\) "
                                                 r"\(unverified: STA bit assignment\)"):
                table.set_rate(1, 10.0)
        else:
            # the controller selects the mode with the interlock open (TM-8004 §4.5.6's order):
            # the wait sees the open interlock and says so; nothing moved
            with pytest.raises(TableFault, match=r"axis 1: interlock OPEN"):
                table.set_rate(1, 10.0)
            assert server.table.read_rate(1) == 0.0
        table.close_interlocks([1])
        table.set_rate(1, 10.0)
        table.open_interlocks([1])
        assert table.status().mode[0] == "off"
        deadline = time.monotonic() + 10.0             # braked to rest: waited on, not slept for
        while table.read_rates_dps()[0] != 0.0 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert table.read_rates_dps()[0] == 0.0


def test_aerosmith_dialect_strings_are_data_and_9600_baud_is_the_default():
    from drivers.aerosmith import AerosmithTable
    from drivers.protocols import aerosmith as A
    assert AerosmithTable("/dev/null").settings.serial.baudrate == 9600
    cs = A.dialect((("move", "mpa"), ("position", "PPS")))
    assert cs.format("move", 12.5) == "MPA12.5000" and cs.parse("pps")[0].name == "position"
    assert cs.format("move", 90.0) == "MPA90"          # whole numbers as the public client writes them
    with pytest.raises(ValueError, match="unknown aerosmith commands"):
        A.dialect((("fly", "FLY"),))
    with pytest.raises(ValueError, match="not three letters"):
        A.dialect((("move", "MOVE"),))
    with pytest.raises(LimitError, match="same string"):
        AerosmithTable("/dev/null", TableSettings(dialect=(("move", "JOG"),)))


def test_any_pyserial_url_spy_logs_the_exchange(tmp_path):
    log = tmp_path / "spy.txt"
    with BenchServer(default_truth(3), BenchOptions(speed=SPEED, axes=2)) as server:
        with open_table(f"spy://{server.table_path}?file={log}") as table:
            assert table.n_axes == 2
    assert "*IDN?" in log.read_text() and ":Query:System?" in log.read_text()


def test_a_socket_port_reads_what_came_at_once_and_closes_without_a_pause(monkeypatch):
    """``socket://`` (acutrol over TCP, TM-9384C): ``in_waiting`` counts the bytes received, so a
    reply is taken in one read (pyserial's port says 1, and a reply went one byte per select and
    recv); ``close()`` does not sleep (pyserial's sleeps 0.3 s "in case of quick reconnects"), and
    the pause is taken by the next open of the same address within 0.3 s, for the rest of it."""
    import logging
    import socket

    from drivers import transport

    slept = []
    monkeypatch.setattr(transport.time, "sleep", lambda s: slept.append(s))
    with socket.create_server(("127.0.0.1", 0)) as server:
        url = "socket://127.0.0.1:%d" % server.getsockname()[1]
        port = transport.Port(url, transport.SerialSettings(), "table test", logging.getLogger("test"))
        peer, _ = server.accept()
        with peer:
            peer.sendall(b"x" * 100)
            deadline = time.monotonic() + 10.0
            while port._ser.in_waiting < 100 and time.monotonic() < deadline:
                pass
            assert port._ser.in_waiting == 100
            assert port.read_some() == b"x" * 100
        port.close()
        assert slept == []                                 # closed without a pause
        again = transport.Port(url, transport.SerialSettings(), "table test", logging.getLogger("test"))
        again.close()
    assert len(slept) == 1 and 0 < slept[0] <= transport.SOCKET_RECONNECT_S     # the rest, on reopening
