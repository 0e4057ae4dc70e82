"""No driver path lets the controller execute a stale demand (issue 23, docs/protocols.md
"Demands before modes").

A real ACUTROL3000 executes the demand loaded for a mode when the mode is entered (IEAv-EFO's
notes from one: ``:d:p 1,0`` then ``:m:p ALL`` "send all axis to demanded position"; "if new
demand is loaded when mode is activated the axis will go to new demand as fast as possible"),
and so does the twin.  Each test below first leaves a stale demand on the controller, as
another program or an earlier run would (a ±250 deg/s rate, a far position), then runs one
driver path and reads the twin's own motion over the whole interval: the axis must never have
moved toward the stale demand.  Each fails on a driver that sends a mode before its demand
(the driver before issue 23: ``:Mode:Rate n`` to brake a moving axis, ``:Mode:Position n`` to
hold it, ``:mode 1,pos`` before the target).
"""
from __future__ import annotations

import numpy as np
import pytest

from drivers.base import TableSettings
from drivers.registry import open_table
from sim_devices.truth import default_truth
from sim_devices.twins.serve import BenchOptions, BenchServer

SPEED = 50.0
STALE_RATE = 250.0          # deg/s: the last rotation of an earlier run
TRANSPORTS = ["pty", "gpib", "tcp"]


@pytest.fixture(params=TRANSPORTS)
def bench(request):
    transport = request.param
    server = BenchServer(default_truth(3), BenchOptions(
        speed=SPEED, axes=1, table_protocol="acutrol",
        table_framing="gpib" if transport == "gpib" else "tcp",
        table_tcp_port=0 if transport == "tcp" else None))
    server.url = server.table_path + ("#gpib" if transport == "gpib" else "")
    server.opened = []
    with server:
        yield server
        for table in server.opened:          # (the table lock too: another process may want it)
            table.close()


def _connect(server):
    table = open_table(server.url, "acutrol", TableSettings())
    server.opened.append(table)
    table.close_interlocks()
    return table


def _raw(table, *commands):
    """What another program sends: raw ACL commands, no driver logic."""
    table._exchange(*commands)


def _motion(server, t0, t1, n=4000):
    """The twin's own axis-1 positions (unwrapped deg) and rates (deg/s) over [t0, t1], as its
    controller drives them: the encoder's (the axis itself differs by the encoder's error, whose
    ripple on the rate, up to ~0.05 deg/s at 250 deg/s, is no part of the braking profile)."""
    t = np.linspace(t0, t1, n)
    th, thd, _ = server.table.axes[0].motion.eval(t)
    return th, thd


#: the hold at the rest position as read (the twin's encoder resolution, 1e-5 deg) may correct
#: by half a count: a profiled move of 5e-6 deg at the 60 deg/s^2 position-mode limit peaks at
#: sqrt(60 * 5e-6) = 0.017 deg/s; stale demands are hundreds of deg/s and degrees away
HOLD_RATE_DPS = 2 * (60.0 * 5e-6) ** 0.5


def _braked_and_held(pos, rate, rest_deg):
    """Braking only (never faster than at the start, never reversing but for the hold's
    correction), then held where it came to rest (within the encoder's resolution)."""
    assert np.max(np.abs(rate)) <= abs(rate[0]) + HOLD_RATE_DPS
    assert np.all(rate * np.sign(rate[0]) >= -HOLD_RATE_DPS)
    assert abs(rate[-1]) < 1e-3
    assert abs(((pos[-1] - rest_deg) + 180) % 360 - 180) < 0.002


def _now(server):
    return server.table.clock.now()


def test_rate_mode_enters_at_zero_rate(bench):
    table = _connect(bench)
    _raw(table, ("demand_rate", 1, STALE_RATE))            # loaded in off mode: not executed
    t0 = _now(bench)
    table.rate_mode(1)
    table.stop()
    _, rate = _motion(bench, t0, _now(bench))
    assert np.max(np.abs(rate)) < HOLD_RATE_DPS


def test_position_mode_holds_where_the_axis_is(bench):
    table = _connect(bench)
    _raw(table, ("demand_position", 1, 150.0))
    t0 = _now(bench)
    table.position_mode(1)
    table.stop()
    pos, rate = _motion(bench, t0, _now(bench))
    assert np.max(np.abs(pos)) < 0.01 and np.max(np.abs(rate)) < HOLD_RATE_DPS


def test_move_from_rate_mode_goes_straight_to_its_target(bench):
    table = _connect(bench)
    table.rate_mode(1)
    _raw(table, ("demand_position", 1, 200.0))             # the short way to 200 is through -160
    t0 = _now(bench)
    table.move_to([30.0])
    pos, _ = _motion(bench, t0, _now(bench))
    assert pos.min() > -0.02 and pos.max() < 30.0 + 0.02   # the overshoot is at most 0.01 deg


def test_set_rate_from_position_mode_never_exceeds_its_rate(bench):
    table = _connect(bench)
    table.move_to([10.0])
    _raw(table, ("demand_rate", 1, STALE_RATE))            # loaded in position mode: stored
    t0 = _now(bench)
    table.set_rate(1, 20.0)
    table.stop()
    _, rate = _motion(bench, t0, _now(bench))
    assert rate.max() < 20.0 + HOLD_RATE_DPS and rate.min() > -HOLD_RATE_DPS


def test_stop_during_a_move_brakes_without_a_stale_rate(bench):
    table = _connect(bench)
    table.move_to([0.5])
    _raw(table, ("demand_rate", 1, STALE_RATE))
    t0 = _now(bench)
    table.move_to([180.0], wait=False)                     # at the position-mode limit, 60 deg/s
    for _ in range(200):
        if abs(table.read_rates_dps()[0]) > 10.0:
            break
    table.stop()
    _, rate = _motion(bench, t0, _now(bench))
    move_rate = table.limits[0].move_rate_dps
    assert np.max(np.abs(rate)) <= move_rate + HOLD_RATE_DPS
    assert abs(table.read_rates_dps()[0]) < 0.01


def test_stop_while_turning_holds_where_the_axis_came_to_rest(bench):
    table = _connect(bench)
    table.set_rate(1, 40.0)
    _raw(table, ("demand_position", 1, 300.0))             # a far position demand, left in rate mode
    t0 = _now(bench)
    rest = table.stop()
    t1 = _now(bench)
    pos, rate = _motion(bench, t0, t1 + 5.0)              # and 5 device s of what is planned after
    _braked_and_held(pos, rate, rest[0])
    assert table.read_modes() == ["position"]
    assert float(table._exchange(("demand_position_query", 1))[0]) == pytest.approx(rest[0], abs=0.002)


def test_a_new_connection_stops_an_axis_left_turning(bench):
    """An earlier run killed during a rotation: the axis turns at 250 deg/s, a position demand
    far away.  A new connection knows nothing of its mode: it finds the axis moving, brakes it
    (zero rate demand, then rate mode), holds it where it came to rest and says so."""
    table = _connect(bench)
    table.set_rate(1, STALE_RATE)
    _raw(table, ("demand_position", 1, 123.0))
    table.close()
    t0 = _now(bench)
    with open_table(bench.url, "acutrol", TableSettings()) as fresh:
        (found,) = fresh.found_moving
        assert found.axis == 1 and found.rate_dps == pytest.approx(STALE_RATE, abs=0.01)
        note = fresh.describe_leftover()
        assert "axis 1 was turning at 250 deg/s when the port was opened" in note
        assert f"held (axis 1 at {found.rest_deg:.6f} deg)" in note
        pos, rate = _motion(bench, t0, _now(bench) + 5.0)
        _braked_and_held(pos, rate, found.rest_deg)
        assert fresh.read_modes() == ["position"]
        np.testing.assert_allclose(fresh.read_rates_dps(), 0.0, atol=1e-3)


def test_a_connection_to_a_table_at_rest_moves_nothing(bench):
    with open_table(bench.url, "acutrol", TableSettings()) as table:
        assert table.found_moving == [] and table.describe_leftover() == ""
        assert table.read_modes() == ["off"]            # no command was sent to the axis


@pytest.mark.parametrize("framing", ["tcp", "gpib"])
def test_a_reply_left_on_the_line_is_not_taken_for_the_identity(framing, monkeypatch):
    """A program killed mid-exchange leaves its reply in flight; the next to connect (the run's
    guardian, a run started again at once) must not read it as its own answer: after the
    connect's discard a stale reply arrives, and the driver still reads the axes right."""
    from drivers.protocols import acutrol as P
    from drivers.transport import Port

    with BenchServer(default_truth(3), BenchOptions(speed=SPEED, axes=2, table_framing=framing)) as server:
        stale = (P.pack_response(0, "250.000000;0.000000") if framing == "tcp" else b"250.000000;0.000000;0\n")
        discard = Port.discard_input
        injected = []

        def discard_then_stale(self):
            discard(self)
            if not injected:                      # the killed program's reply, arriving late
                injected.append(True)
                server.table_port.write(stale)

        monkeypatch.setattr(Port, "discard_input", discard_then_stale)
        url = server.table_path + ("#gpib" if framing == "gpib" else "")
        with open_table(url, "acutrol", TableSettings()) as table:
            assert injected and "ACUTROL3000" in table.identity
            assert table.n_axes == 2
            np.testing.assert_array_equal(table.read_rates_dps(), [0.0, 0.0])
            assert table.found_moving == []


def _turning_then_unpowered(bench):
    """A table turning at 250 deg/s whose interlock was then opened, once it has coasted to rest."""
    table = _connect(bench)
    table.set_rate(1, STALE_RATE)
    table.open_interlocks()
    for _ in range(2000):
        if abs(table.read_rates_dps()[0]) < 1e-3:
            break
    return table


def test_closing_the_interlock_never_resumes_the_mode_left_selected(bench):
    """An earlier run turning at 250 deg/s had its interlock opened (an operator's remount, a
    trip): the axis braked unpowered but rate mode stays selected with its 250 deg/s demand, and
    closing the interlock servoes the axis in it (TM-8004 §4.5.6).  close_interlocks() sends
    harmless demands and Off before the close: the axis holds still where it is."""
    table = _turning_then_unpowered(bench)
    assert bench.table.axes[0].mode == "rate" and bench.table.axes[0].rate_demand_dps == STALE_RATE
    t0 = _now(bench)
    table.close_interlocks()
    pos, rate = _motion(bench, t0, _now(bench) + 5.0)
    assert np.max(np.abs(rate)) < HOLD_RATE_DPS and np.ptp(pos) < 0.002
    assert table.read_modes() == ["off"] and table.status().interlock_closed == (True,)


def test_the_twin_catches_a_close_that_resumes_the_selected_mode(bench):
    """The same with a bare ':Interlock:Close 1' (the driver before issue 23): the twin spins
    the axis back up toward 250 deg/s, so the test above can fail."""
    table = _turning_then_unpowered(bench)
    t0 = _now(bench)
    _raw(table, ("interlock_close", 1))
    _, rate = _motion(bench, t0, _now(bench) + 5.0)
    assert np.max(np.abs(rate)) > 100.0
    table.stop()
