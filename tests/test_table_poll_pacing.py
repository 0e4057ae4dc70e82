"""The rate-table driver's waits (drivers/table.py: a move's and a rate's settle, a stop) poll the
table every ``poll_interval_s``: polls *start* that far apart, the exchange counting toward the
interval.  Before (twenty-first session), a full interval was slept after every exchange: on the
twins, whose replies take 5-15 ms under load, about half of a wait's wall time was these sleeps,
and on a slow line (an exchange longer than the interval) every poll came an interval late.

A table of one axis at rest, on a virtual clock (drivers.table's ``time`` replaced: every exchange
advances it by EXCHANGE_S, every sleep by what was asked), so the checks are exact and take no
wall time.  Both sides of the rule: a slow exchange is not followed by a sleep, and a fast one is
still paced to the interval (a settle spans at least ``settle_polls`` intervals)."""
import numpy as np
import pytest

import drivers.table as table_module
from drivers.table import RateTable, TableSettings

INTERVAL_S = 0.02


class VirtualTime:
    """time.monotonic and time.sleep on a clock that moves only when told."""

    def __init__(self):
        self.t = 1000.0
        self.sleeps = []

    def monotonic(self):
        return self.t

    def sleep(self, s):
        self.sleeps.append(s)
        self.t += s


class _NoPort:
    def discard_input(self):
        pass

    def close(self):
        pass


class RestingTable(RateTable):
    """One axis at rest in position mode (the demands it is given are reached at once); every
    exchange takes ``exchange_s`` of the virtual clock; ``polls``, ``rate_reads``: when each read
    of the state (the settles' polls) and of the rates alone (a stop's) began."""

    protocol = "virtual"

    def __init__(self, clock, exchange_s):
        super().__init__("virtual-paced-table", TableSettings(axes=1, poll_interval_s=INTERVAL_S, settle_polls=5))
        self.clock, self.exchange_s = clock, exchange_s
        self.pos, self.rate, self.polls, self.rate_reads = 0.0, 0.0, [], []

    def _open_port(self):
        return _NoPort()

    def _x(self):
        self.clock.t += self.exchange_s

    def _identify(self):
        self._x()
        return "virtual"

    def _count_axes(self):
        return 1

    def _set_move_limits(self, axis, rate_dps, accel_dps2):
        self._x()

    def _set_limits(self, axis, mode, rate_dps, accel_dps2):
        self._x()

    def _read_positions(self):
        self._x()
        return [self.pos]

    def _read_rates(self):
        self.rate_reads.append(self.clock.t)
        self._x()
        return [self.rate]

    def _status(self):
        self._x()
        return [True], [False], 0

    def _read_state(self):
        self.polls.append(self.clock.t)
        self._x()
        return [self.pos], [self.rate], [True], [False], 0

    def _reset(self):
        self._x()

    def _interlock(self, axis, close, hold_deg):
        self._x()

    def _set_mode(self, axis, mode, demand):
        self._x()
        if mode == "position":
            self.pos = demand
        else:
            self.rate = demand

    def _demand_position(self, axis, position_deg):
        self._x()
        self.pos = position_deg

    def _demand_rate(self, axis, rate_dps):
        self._x()
        self.rate = rate_dps

    def _halt(self, axis, mode):
        self._x()
        self.rate = 0.0


def _table(monkeypatch, exchange_s):
    clock = VirtualTime()
    monkeypatch.setattr(table_module, "time", clock)
    table = RestingTable(clock, exchange_s)
    table.connect()
    return table, clock


def _waits(table):
    """Each wait of the driver, by what it runs: the settle of a move, of a rate, and a stop."""
    yield "move", lambda: table.move_to([10.0])
    yield "rate", lambda: table.set_rate(1, 0.0)
    yield "stop", table.stop


@pytest.mark.parametrize("exchange_s", [0.03, 0.005], ids=["slow-line", "fast-line"])
def test_the_table_is_polled_every_interval_counting_the_exchange(monkeypatch, exchange_s):
    table, clock = _table(monkeypatch, exchange_s)
    try:
        for what, wait in _waits(table):
            clock.sleeps.clear()
            wait()
            reads = table.rate_reads if what == "stop" else table.polls
            starts = np.diff(reads[-table.settings.settle_polls:])
            # a poll every interval, or every exchange when the line is slower than that: the
            # settle spans settle_polls intervals at least, and no more than the line needs
            assert starts == pytest.approx(np.full(len(starts), max(INTERVAL_S, exchange_s)), abs=1e-9), what
            # (between the settle's polls; a stop sleeps after its last too)
            assert len(clock.sleeps) == (0 if exchange_s >= INTERVAL_S else
                                         table.settings.settle_polls - (what != "stop")), what
            # what is slept is what is left of the interval (before: a full interval after each)
            assert all(s == pytest.approx(INTERVAL_S - exchange_s, abs=1e-9) for s in clock.sleeps), (what, clock.sleeps)
    finally:
        table.close()
