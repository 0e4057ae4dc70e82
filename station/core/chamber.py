"""A temperature chamber around the table: its settings (station.yaml ``chamber:``), the time a
setpoint change costs, and the rule that says when the IMU's own temperature has settled.

Shared by the compiler and the sequencer (station.bench), the dry runs (station.simulate) and the
designer's time model (station.design), which may not import one another: plain numbers only.

A chamber's step, as the station runs it (docs/configuration.md "chamber"):

1. the chamber is set to the setpoint (``kind: manual``: the operator is asked to set it and
   confirms; the chamber's air then ramps at about ``ramp_c_per_min``);
2. the station waits at least the ramp's time, ``|setpoint - previous setpoint| / ramp``, then
   until the IMU's *own* temperature settles: for ``soak_s`` (a fixed soak), or until the
   least-squares slope of the IMU's temperature over the last ``settle_window_s`` is below
   ``settle_slope_c_per_min`` (at most ``settle_max_s`` after the ramp);
3. the IMU's temperature is compared with the setpoint: a difference beyond ``agree_c`` is a
   finding written into the capture (the segment's ``chamber`` entry), not absorbed.

Units: degrees Celsius (°C), seconds, °C/min.
"""
from __future__ import annotations

import collections
import math
from dataclasses import dataclass

import numpy as np

KINDS = ("manual",)


@dataclass(frozen=True)
class ChamberConfig:
    kind: str = "manual"                      # manual: the operator sets it when asked
    range_c: tuple = (-40.0, 85.0)            # the setpoints it can hold, °C
    ramp_c_per_min: float = 2.0               # how fast its air follows a new setpoint, °C/min
    ambient_c: float = 25.0                   # the room: the chamber's air before the first setpoint, °C
    soak_s: float | None = None               # a fixed soak after the ramp, s; or the slope rule:
    settle_slope_c_per_min: float | None = 0.02   # the IMU's temperature slope below this...
    settle_window_s: float = 120.0            # ...over this window (s)
    settle_max_s: float = 3600.0              # never longer than this after the ramp, s
    imu_time_constant_s: float = 600.0        # the IMU's lag behind the air, for time estimates (plan, design)
    agree_c: float = 5.0                      # |IMU temperature - setpoint| beyond this: a finding, °C

    def in_range(self, setpoint_c: float) -> bool:
        lo, hi = self.range_c
        return lo <= setpoint_c <= hi

    def ramp_s(self, from_c: float, to_c: float) -> float:
        """The chamber air's ramp from ``from_c`` to ``to_c``, s."""
        return abs(float(to_c) - float(from_c)) / self.ramp_c_per_min * 60.0

    def settle_estimate_s(self, from_c: float, to_c: float) -> float:
        """The wait after the ramp until the settle rule holds, estimated (plan, design): the
        fixed soak; or, for the slope rule, the time a first-order lag of ``imu_time_constant_s``
        behind the air takes for its slope to fall below the threshold, plus the window it must
        hold over.  The lag after a linear ramp at rate r of length L: slope(t) = r (1 -
        e^{-L/tau}) e^{-t/tau} after the ramp ends, below X from t = tau ln(r (1 - e^{-L/tau}) / X)."""
        if self.soak_s is not None:
            return float(self.soak_s)
        tau = self.imu_time_constant_s
        r = self.ramp_c_per_min
        L = self.ramp_s(from_c, to_c)
        if L <= 0.0:
            return 0.0
        peak = r * -math.expm1(-L / tau)                 # °C/min when the ramp ends
        wait = tau * math.log(peak / self.settle_slope_c_per_min) if peak > self.settle_slope_c_per_min else 0.0
        return min(wait + self.settle_window_s, self.settle_max_s)

    def step_s(self, from_c: float, to_c: float) -> float:
        """Ramp and settling of one setpoint change, estimated, s (the operator's time not included)."""
        if abs(float(to_c) - float(from_c)) < 1e-9:
            return 0.0
        return self.ramp_s(from_c, to_c) + self.settle_estimate_s(from_c, to_c)

    def describe(self) -> str:
        rule = settle_rule(self.soak_s, self.settle_slope_c_per_min, self.settle_window_s, self.settle_max_s)
        return (f"{self.kind} chamber {self.range_c[0]:g}..{self.range_c[1]:g} °C, ramp "
                f"{self.ramp_c_per_min:g} °C/min, {rule}")


def settle_rule(soak_s, slope_c_per_min, window_s, max_s, degree: str = "°C") -> str:
    """The settling rule in words: a fixed soak, or the slope rule on the IMU's own temperature
    (the configuration's and a compiled chamber step's description)."""
    if soak_s is not None:
        return f"soak {soak_s:g} s"
    return (f"until the IMU's temperature slope < {slope_c_per_min:g} {degree}/min over {window_s:g} s "
            f"(at most {max_s:g} s)")


def order_levels(levels, ambient_c: float) -> list:
    """The order a scheme visits chamber setpoints in (the design writes it so): from the room,
    the nearer end of the setpoints first, then across to the other end -- the least ramping."""
    levels = sorted(set(float(x) for x in levels))
    if not levels:
        return []
    lo, hi = levels[0], levels[-1]
    return levels if abs(lo - ambient_c) <= abs(hi - ambient_c) else levels[::-1]


class SlopeSettle:
    """Feeds on the IMU's temperature readings (t s, T °C) and says when the settle rule holds:
    the least-squares slope over the last ``window_s`` below ``slope_c_per_min`` (a full window
    needed).  The window's sums are kept as readings come and go (a reading a second for an
    hour's settling: a fit over the window at every reading was most of a dry run's time)."""

    def __init__(self, slope_c_per_min: float, window_s: float):
        self.limit = float(slope_c_per_min)
        self.window_s = float(window_s)
        self._window: collections.deque = collections.deque()
        self._sums = np.zeros(5)              # n, sum t, sum T, sum t^2, sum t T (t from the first reading)
        self._t0 = self._last = None

    def feed(self, t: float, temp_c: float) -> None:
        if not math.isfinite(temp_c):
            return
        if self._t0 is None:
            self._t0 = float(t)
        x, y = float(t) - self._t0, float(temp_c)
        self._window.append((x, y))
        self._sums += (1.0, x, y, x * x, x * y)
        self._last = x
        while self._window and self._window[0][0] < x - self.window_s:
            a, b = self._window.popleft()
            self._sums -= (1.0, a, b, a * a, a * b)

    def slope_c_per_min(self) -> float | None:
        if self._last is None or self._last < self.window_s or self._sums[0] < 3:
            return None
        n, st, sy, stt, sty = self._sums
        d = n * stt - st * st
        return float((n * sty - st * sy) / d * 60.0) if d > 0 else None

    @property
    def settled(self) -> bool:
        s = self.slope_c_per_min()
        return s is not None and abs(s) < self.limit


def finding(setpoint_c: float, imu_c: float, agree_c: float) -> str | None:
    """The cross-check after a chamber step: a sentence when the IMU's temperature and the
    setpoint disagree beyond ``agree_c``, else None."""
    d = float(imu_c) - float(setpoint_c)
    if not math.isfinite(d):
        return "the IMU reported no temperature: the chamber's setpoint could not be checked"
    if abs(d) <= agree_c:
        return None
    return (f"the IMU's temperature {imu_c:.2f} °C is {d:+.2f} °C from the chamber's setpoint "
            f"{setpoint_c:g} °C (beyond the {agree_c:g} °C agreed): the chamber, its setting or the "
            "IMU's sensor is off, or the IMU heats itself more than expected")
