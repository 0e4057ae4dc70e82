"""No stale demand on the three-letter dialect (issue 23, item 1): every path by which the driver
changes mode or motion, against the twin's pessimistic reading (the controller keeps the last
position demand, and STO holds it: docs/protocols.md, ``aerosmith``).  Each test fails on a
driver that stops, or enters position mode, by STO; the last one shows that the twin catches
such a driver."""
from __future__ import annotations

import time

import pytest

from drivers.registry import open_table
from drivers.aerosmith import AerosmithTable
from drivers.table import AxisLimits, TableSettings, angle_diff_deg
from sim_devices.truth import default_truth
from sim_devices.twins.serve import BenchOptions, BenchServer

SPEED = 50.0


@pytest.fixture(params=[False, True], ids=["answered", "silent-motion"])
def bench(request):
    with BenchServer(default_truth(3), BenchOptions(
            speed=SPEED, axes=1, table_protocol="aerosmith",
            table_silent_motion=request.param)) as server:
        yield server


def _open(server, cls=None, **settings):
    if cls is None:
        return open_table(server.table_path, "aerosmith", TableSettings(**settings))
    table = cls(server.table_path, TableSettings())
    table.connect()
    return table


def _demands_since(server, n):
    return [(kind, round(v, 3)) for _, kind, v in server.table_frontend.demands[n:]]


def _turning(table, rate=30.0, seconds=0.02):
    table.set_rate(1, rate)
    time.sleep(seconds)          # 1 s of device time at SPEED 50


def _at_rest(table, polls=10):
    still = 0
    while still < polls:
        still = still + 1 if abs(table.read_rates_dps()[0]) <= 0.01 else 0
        time.sleep(0.01)
    return float(table.read_positions_deg()[0])


def test_stop_after_a_rotation_stays_where_it_braked(bench):
    """stop() while turning (rate mode): JOG0, then MOV to the measured position, never a
    return to the last MOV target."""
    with _open(bench) as table:
        table.move_to([90.0])
        _turning(table)
        before = float(table.read_positions_deg()[0])
        n = len(bench.table_frontend.demands)
        end = float(table.stop()[0])
        kinds = [k for k, _ in _demands_since(bench, n)]
        assert kinds == ["JOG", "MOV"] and _demands_since(bench, n)[0] == ("JOG", 0.0)
        # braking from 30 deg/s at 100 deg/s^2 takes 4.5 deg, but the exchanges before JOG0 take
        # device time too (0.5 s per 10 ms at SPEED 50): onwards, never back towards 90 deg
        assert 0.0 < float(angle_diff_deg(end, before)) < 60.0
        assert _at_rest(table) == pytest.approx(end, abs=0.01)
        assert abs(float(angle_diff_deg(end, 90.0))) > 20.0


def test_stop_during_a_move_stops_short_of_its_target(bench):
    # moves at 10 deg/s (VEL10 at connect): the exchanges of stop() before JOG0 cost little
    with _open(bench, limits=(AxisLimits(move_rate_dps=10.0),)) as table:
        table.move_to([150.0], wait=False)
        while float(table.read_positions_deg()[0]) < 40.0:
            time.sleep(0.002)
        end = float(table.stop()[0])
        assert 40.0 < end < 120.0                   # 10 deg/s braked at 100 deg/s^2: 0.5 deg
        assert _at_rest(table) == pytest.approx(end, abs=0.01)
        assert bench.table_frontend.demands[-1][1] == "MOV"


def test_position_mode_is_entered_by_a_move_to_the_measured_position(bench):
    with _open(bench) as table:
        table.move_to([90.0])
        _turning(table, 20.0)
        t_before = bench.clock.now()            # the twin's device time, at or before the read
        before = float(table.read_positions_deg()[0])
        n = len(bench.table_frontend.demands)
        table.position_mode(1)
        (kind, held), = _demands_since(bench, n)
        t_demand = bench.table_frontend.demands[n][0]
        # while turning at 20 deg/s: the demand is a position measured after `before` and no later
        # than the demand itself -- however long the host took between them (a loaded CI took
        # 20 deg, 1 s of device time, where a fixed 10 deg bound had been set)
        ahead = float(angle_diff_deg(held, before))
        assert kind == "MOV" and 0.0 <= ahead <= 20.0 * (t_demand - t_before) + 0.01, (ahead, t_demand - t_before)
        assert _at_rest(table) == pytest.approx(held, abs=0.01)   # braked and came back


def test_move_after_a_rotation_never_heads_for_the_old_target(bench):
    with _open(bench) as table:
        table.move_to([90.0])
        _turning(table)
        n = len(bench.table_frontend.demands)
        table.move_to([200.0])
        assert _demands_since(bench, n) == [("MOV", 200.0)]          # the target is the entry


def test_rate_mode_is_entered_by_its_own_demand(bench):
    with _open(bench) as table:
        table.move_to([90.0])
        n = len(bench.table_frontend.demands)
        table.rate_mode(1)
        assert _demands_since(bench, n) == [("JOG", 0.0)]
        table.move_to([90.0])
        n = len(bench.table_frontend.demands)
        table.set_rate(1, 10.0)
        assert _demands_since(bench, n) == [("JOG", 10.0)]
        table.stop()


class _StopsBySTO(AerosmithTable):
    """The pattern of the old driver: position mode and the stop by STO."""

    _halt_mode = "position"

    def _set_mode(self, axis, mode, demand):
        if mode == "position":
            self._motion("stop")
            self._exchange("move", demand)
        else:
            super()._set_mode(axis, mode, demand)

    def _halt(self, axis, mode):
        self._motion("stop")

    def _after_halt(self, axis, position_deg):
        self._motion("stop")


def test_the_twin_catches_a_driver_that_stops_by_sto(bench):
    """The pessimistic reading is what makes the tests above fail on such a driver: its stop
    drives back to the last move target."""
    table = _open(bench, _StopsBySTO)
    try:
        table.move_to([90.0])
        _turning(table)
        end = float(table.stop()[0])
        assert end == pytest.approx(90.0, abs=0.01)
        assert ("HOLD", 90.0) in _demands_since(bench, 0)
    finally:
        table.close()


def test_closing_the_servo_is_followed_by_a_zero_rate(bench):
    """close_interlocks(): SRV1, then JOG0 at once (what SRV1 servoes to is unverified: a
    controller that kept the last JOG or MOV could resume it); an axis already enabled is left
    alone."""
    with _open(bench) as table:
        table.move_to([45.0])
        n = len(bench.table_frontend.demands)
        table.close_interlocks()                       # enabled since power-up: nothing sent
        assert _demands_since(bench, n) == []
        table.open_interlocks()
        table.close_interlocks()
        assert _demands_since(bench, n) == [("JOG", 0.0)]
        assert table.status().interlock_closed == (True,)
        assert abs(angle_diff_deg(_at_rest(table), 45.0)) < 0.01
