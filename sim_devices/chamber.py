"""A simulated temperature chamber, from first principles.

The chamber's air follows each new setpoint at a constant ramp rate (its heater and cooler at
full power until it arrives, then held there); a setpoint given while it is still ramping turns
the ramp towards the new one.  The IMU sits in that air as one thermal mass: its case
temperature T follows the air temperature A as a first-order lag,

    dT/dt = (A(t) - T) / tau            (Newton's law of cooling, tau = m c / (h S))

and on top of that the IMU's self-heating (its warm-up) and any slow drift add, as without a
chamber (sim_devices/truth.py TemperatureTruth).  With A piecewise linear the lag is exact in
closed form: over a piece A(t) = A0 + s (t - t0),

    T(t) = A(t) - s tau + (T0 - A0 + s tau) exp(-(t - t0) / tau).

Before the first setpoint the air is the room's (TemperatureTruth.start_c) and the IMU with it,
so a run that never sets the chamber has exactly the temperatures it had without one.
Independent of the station's own chamber code (station/core/chamber.py): this is the world.
"""
from __future__ import annotations

import numpy as np


class ChamberAir:
    """The chamber's air temperature over bench time, from the setpoints given to it."""

    def __init__(self, room_c: float):
        self.room_c = float(room_c)
        # pieces: (start time s, air degC at the start, slope degC/s); the last one runs forever
        self._pieces: list = [(-np.inf, self.room_c, 0.0)]

    @property
    def commanded(self) -> bool:
        return len(self._pieces) > 1

    def air(self, t) -> np.ndarray:
        t = np.asarray(t, dtype=float)
        starts = np.array([p[0] for p in self._pieces])
        k = np.searchsorted(starts, t, side="right") - 1
        t0 = starts[k]
        a0 = np.array([p[1] for p in self._pieces])[k]
        s = np.array([p[2] for p in self._pieces])[k]
        return a0 + s * np.where(np.isfinite(t0), t - t0, 0.0)

    def set(self, t: float, setpoint_c: float, ramp_c_per_min: float) -> None:
        """At bench time ``t`` the chamber is set to ``setpoint_c``; its air ramps there at
        ``ramp_c_per_min`` and holds.  Setpoints must come in time order."""
        t = float(t)
        if t < self._pieces[-1][0]:
            # a later piece (the arrival of an earlier ramp) is after t: cut it away
            self._pieces = [p for p in self._pieces if p[0] <= t]
        a = float(self.air(t))
        rate = float(ramp_c_per_min) / 60.0
        d = float(setpoint_c) - a
        if abs(d) < 1e-12 or rate <= 0.0:
            self._pieces.append((t, float(setpoint_c), 0.0))
            return
        self._pieces.append((t, a, np.sign(d) * rate))
        self._pieces.append((t + abs(d) / rate, float(setpoint_c), 0.0))

    def lagged(self, t, tau_s: float) -> np.ndarray:
        """The temperature of a body following this air as a first-order lag of ``tau_s``,
        starting with the air (the room) before the first setpoint."""
        t = np.asarray(t, dtype=float)
        pieces = self._pieces
        # the body's temperature at each piece's start, forward
        body = [self.room_c]
        for (t0, a0, s), (t1, _, _) in zip(pieces[:-1], pieces[1:]):
            if not np.isfinite(t0):
                body.append(a0)              # the room, steady
                continue
            d = t1 - t0
            a1 = a0 + s * d
            body.append(a1 - s * tau_s + (body[-1] - a0 + s * tau_s) * np.exp(-d / tau_s))
        starts = np.array([p[0] for p in pieces])
        k = np.searchsorted(starts, t, side="right") - 1
        t0 = starts[k]
        a0 = np.array([p[1] for p in pieces])[k]
        s = np.array([p[2] for p in pieces])[k]
        y0 = np.array(body)[k]
        dt = np.where(np.isfinite(t0), t - t0, 0.0)
        a = a0 + s * dt
        return a - s * tau_s + (y0 - a0 + s * tau_s) * np.exp(-dt / tau_s)

    def lagged_rate(self, t, tau_s: float) -> np.ndarray:
        """d/dt of :meth:`lagged`, degC/s."""
        return (self.air(t) - self.lagged(t, tau_s)) / tau_s
