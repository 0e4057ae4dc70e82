"""The table driver's stop paths (drivers/table.py RateTable.stop, _stop_leftover_motion,
_after_halt; the Acutrol and Aerosmith _halt) on an in-process table whose axes brake at a
known deceleration on a simulated clock (issue 30 item 6: what mutation testing of the stop
needs; no port, no sleep: each test takes milliseconds).

The clock: ``time.monotonic`` and ``time.sleep`` of drivers.table are replaced by a counter that
``sleep`` advances, so deadlines are checked to the poll interval (0.01 s), whatever the load.
"""
from __future__ import annotations

import logging

import numpy as np
import pytest

from drivers import table as T
from drivers.acutrol import AcutrolTable
from drivers.aerosmith import AerosmithTable
from drivers.errors import DeviceTimeout, ProtocolError


class Clock:
    def __init__(self):
        self.now = 1000.0

    def monotonic(self):
        return self.now

    def sleep(self, s):
        self.now += s


@pytest.fixture
def clock(monkeypatch):
    c = Clock()
    monkeypatch.setattr(T.time, "monotonic", c.monotonic)
    monkeypatch.setattr(T.time, "sleep", c.sleep)
    return c


class FakeTable(T.RateTable):
    """Axes that brake at ``decel`` deg/s^2 once halted (rates read on the simulated clock);
    ``rates_script``: the rates read, one list per read, instead (then the clock is not used)."""
    protocol = "fake"

    def __init__(self, clock, rates, positions, closed=None, modes=None, decel=50.0, settings=None,
                 rates_script=None):
        super().__init__("fake://table", settings or T.TableSettings(poll_interval_s=0.01, settle_polls=5,
                                                                     wait_margin_s=10.0))
        self.clock = clock
        self.n_axes = len(rates)
        self.limits = self.settings.axis_limits(self.n_axes)
        self._modes = list(modes or ["rate"] * self.n_axes)
        self._rate_accel = [lim.max_accel_dps2 for lim in self.limits]
        self.rate0 = np.array(rates, float)
        self.pos0 = np.array(positions, float)
        self.closed = list(closed or [True] * self.n_axes)
        self.decel = decel
        self.halted_at = {a: clock.now for a in self.axes if not self.closed[a - 1]}   # unpowered: brakes itself
        self.calls = []
        self.script = list(rates_script) if rates_script is not None else None
        self.rate_reads = 0

    def _rate(self, axis):
        t0 = self.halted_at.get(axis)
        r = self.rate0[axis - 1]
        if t0 is None:
            return r
        left = max(0.0, abs(r) - self.decel * (self.clock.now - t0))
        return np.sign(r) * left

    def _read_rates(self):
        self.rate_reads += 1
        if self.script is not None:
            return self.script.pop(0) if len(self.script) > 1 else self.script[0]
        return [self._rate(a) for a in self.axes]

    def _read_positions(self):
        self.calls.append(("positions",))
        return list(self.pos0 + 0.5 * np.array([a in self.halted_at and self.closed[a - 1] for a in self.axes]))

    def _status(self):
        return list(self.closed), [False] * self.n_axes, 0

    def _halt(self, axis, mode):
        self.calls.append(("halt", axis, mode))
        self.halted_at[axis] = self.clock.now

    def _set_mode(self, axis, mode, demand):
        self.calls.append(("mode", axis, mode, demand))

    # not used by the stop
    def _identify(self): return "fake"
    def _count_axes(self): return self.n_axes
    def _set_move_limits(self, *a): pass
    def _set_limits(self, *a): pass
    def _reset(self): pass
    def _interlock(self, *a): pass
    def _demand_position(self, *a): pass
    def _demand_rate(self, *a): pass


def test_stop_halts_every_closed_axis_in_its_mode_then_holds_where_it_rested(clock):
    t = FakeTable(clock, rates=[20.0, -10.0, 0.0], positions=[10.0, 359.9, 200.0],
                  closed=[True, False, True], modes=["rate", "position", "position"])
    rest = t.stop()
    halts = [c for c in t.calls if c[0] == "halt"]
    assert halts == [("halt", 1, "rate"), ("halt", 3, "position")]       # axis 2: interlock open
    holds = [c for c in t.calls if c[0] == "mode"]
    # the rest positions read once at rest (+0.5 deg for a halted axis here), wrapped to [0, 360)
    assert holds == [("mode", 1, "position", 10.5), ("mode", 3, "position", 200.5)]
    assert t._modes == ["position", "off", "position"]
    np.testing.assert_array_equal(rest, [10.5, 359.9, 200.5])
    assert t.calls[-1] == ("positions",) and t.calls.index(holds[0]) > t.calls.index(("positions",))


def test_stop_wraps_the_hold_position(clock):
    t = FakeTable(clock, rates=[5.0], positions=[359.8])
    t.stop()
    assert [c for c in t.calls if c[0] == "mode"] == [("mode", 1, "position", pytest.approx(0.3))]


def test_a_halt_mode_is_the_mode_until_the_hold(clock):
    class Halting(FakeTable):
        _halt_mode = "rate"
        def _after_halt(self, axis, position_deg):
            self.calls.append(("after", axis, self._modes[axis - 1], position_deg))
    t = Halting(clock, rates=[5.0, 3.0], positions=[1.0, 2.0], modes=["position", "position"])
    t.stop()
    assert [c for c in t.calls if c[0] == "after"] == [("after", 1, "rate", 1.5), ("after", 2, "rate", 2.5)]


def test_stop_waits_for_settle_polls_in_a_row_at_or_below_the_tolerance(clock):
    tol = 0.01
    s = T.TableSettings(poll_interval_s=0.01, settle_polls=5, rate_tolerance_dps=tol)
    still, moving = [tol, -tol], [0.02, 0.0]
    script = [[30.0, 0.0]] + [still] * 4 + [moving] + [still] * 5
    t = FakeTable(clock, rates=[30.0, 0.0], positions=[0.0, 0.0], settings=s, rates_script=script)
    t.stop()
    assert t.rate_reads == 1 + 4 + 1 + 5            # the bounce restarts the count
    assert clock.now == pytest.approx(1000.0 + 10 * 0.01)       # one sleep per poll


def test_stop_gives_up_after_the_braking_time_plus_the_margin(clock):
    """30 deg/s at the slower of the rate-mode (40) and move (60) accelerations: 0.75 s, plus
    the 10 s margin; the rates never fall."""
    s = T.TableSettings(poll_interval_s=0.01, wait_margin_s=10.0,
                        limits=(T.AxisLimits(max_accel_dps2=40.0, move_accel_dps2=60.0),
                                T.AxisLimits(max_accel_dps2=300.0, move_accel_dps2=20.0)))
    t = FakeTable(clock, rates=[30.0, -4.0], positions=[0.0, 0.0], settings=s, rates_script=[[30.0, -4.0]])
    with pytest.raises(DeviceTimeout, match=r"did not come to rest \(rates \[30\.0, -4\.0\] deg/s\)"):
        t.stop()
    assert 1000.0 + 10.75 < clock.now <= 1000.0 + 10.75 + 0.011
    # axis 2 decides when its braking is the longer: 4 / min(300, 20) = 0.2 s < 0.75 s; 40 deg/s
    t = FakeTable(clock, rates=[1.0, -40.0], positions=[0.0, 0.0], settings=s, rates_script=[[1.0, -40.0]])
    start = clock.now
    with pytest.raises(DeviceTimeout):
        t.stop()
    assert start + 12.0 < clock.now <= start + 12.0 + 0.011


def test_a_table_that_brakes_in_time_is_not_a_timeout(clock):
    """50 deg/s^2 braking from 100 deg/s takes 2 s; expected 100 / min(300, 60) = 1.67 s + 10 s."""
    t = FakeTable(clock, rates=[100.0], positions=[0.0], decel=50.0)
    t.stop()
    assert 1002.0 <= clock.now < 1002.2


def test_the_rounded_rates_are_in_the_timeout_message(clock):
    s = T.TableSettings(poll_interval_s=0.01, wait_margin_s=0.05)
    t = FakeTable(clock, rates=[0.123456789], positions=[0.0], settings=s, rates_script=[[0.123456789]])
    with pytest.raises(DeviceTimeout, match=r"rates \[0\.1235\] deg/s"):
        t.stop()


# ------------------------------------------------------------------ at connect


@pytest.mark.parametrize("tolerance, moving", [(0.01, [2, 3]), (0.0, [1, 2, 3]), (0.002, [1, 2, 3])])
def test_leftover_motion_is_found_above_the_tolerance_or_1e_3(clock, tolerance, moving, caplog):
    s = T.TableSettings(rate_tolerance_dps=tolerance)
    rates = [0.005, 0.02, -0.5]
    t = FakeTable(clock, rates=rates, positions=[1.0, 2.0, 3.0], settings=s)
    with caplog.at_level(logging.WARNING, logger="drivers.fake"):
        found = t._stop_leftover_motion()
    assert found == [T.LeftoverMotion(a, rates[a - 1], [1.5, 2.5, 3.5][a - 1]) for a in moving]
    assert f"axes {moving} moving at connect" in caplog.text
    assert [round(r, 6) for r in (rates[a - 1] for a in moving)] == eval(caplog.text.split("connect (")[1].split(" deg/s")[0])


def test_no_leftover_motion_no_stop(clock):
    t = FakeTable(clock, rates=[0.0, 0.0009, -0.0009], positions=[1.0, 2.0, 3.0],
                  settings=T.TableSettings(rate_tolerance_dps=0.0))
    assert t._stop_leftover_motion() == []
    assert not [c for c in t.calls if c[0] in ("halt", "mode")]
    t = FakeTable(clock, rates=[0.0, 0.01, -0.01], positions=[1.0, 2.0, 3.0],
                  settings=T.TableSettings(rate_tolerance_dps=0.01))
    assert t._stop_leftover_motion() == []


# ------------------------------------------------------------------ the protocols' halt


def test_acutrol_halts_by_a_zero_rate_demand_in_rate_mode():
    t = AcutrolTable.__new__(AcutrolTable)
    calls = []
    t._set_mode = lambda axis, mode, demand: calls.append((axis, mode, demand))
    t._halt(2, "position")
    assert calls == [(2, "rate", 0.0)]
    assert AcutrolTable._halt_mode is None or AcutrolTable._halt_mode == "rate"


def test_aerosmith_halts_by_jog_0_and_stops_when_jog_is_refused():
    t = AerosmithTable.__new__(AerosmithTable)
    calls = []
    t._motion = lambda name, *values: calls.append((name, *values))
    t._halt(1, "rate")
    assert calls == [("jog", 0)]
    assert AerosmithTable._halt_mode == "rate"

    calls.clear()

    def refuse_jog(name, *values):
        calls.append((name, *values))
        if name == "jog":
            raise ProtocolError("table", "JOG refused")
    t._motion = refuse_jog
    t._halt(1, "position")
    assert calls == [("jog", 0), ("stop",)]
