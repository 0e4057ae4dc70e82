"""The simulated clock shared by the twins: device time runs ``speed`` times wall time."""
from __future__ import annotations

import time


class SimClock:
    """Device time in s, 0 when created (or ``start_s``), advancing ``speed`` x wall time."""

    def __init__(self, speed: float = 1.0, start_s: float = 0.0):
        if not speed > 0:
            raise ValueError(f"speed must be > 0, got {speed!r}")
        self.speed = float(speed)
        self._start = float(start_s)
        self._wall0 = time.monotonic()

    def now(self) -> float:
        return self._start + self.speed * (time.monotonic() - self._wall0)

    def wall_until(self, device_t: float) -> float:
        """Wall seconds until device time ``device_t`` (<= 0 if past)."""
        return (device_t - self.now()) / self.speed

    def hold(self, wall_s: float) -> None:
        """Let ``wall_s`` wall seconds (already passed) add no device time: the world waits."""
        if wall_s > 0:
            self._wall0 += wall_s


class ManualClock:
    """A clock that moves only when told (deterministic tests of the twins)."""

    def __init__(self, start_s: float = 0.0):
        self.t = float(start_s)
        self.speed = 1.0

    def now(self) -> float:
        return self.t

    def advance(self, dt_s: float) -> float:
        self.t += float(dt_s)
        return self.t

    def wall_until(self, device_t: float) -> float:
        return 0.0
