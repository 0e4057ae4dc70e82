"""The simulated clock shared by the twins: device time runs ``speed`` times wall time."""
from __future__ import annotations

import threading
import time


class SimClock:
    """Device time in s, 0 when created (or ``start_s``), advancing ``speed`` x wall time."""

    def __init__(self, speed: float = 1.0, start_s: float = 0.0):
        if not speed > 0:
            raise ValueError(f"speed must be > 0, got {speed!r}")
        self.speed = float(speed)
        self._start = float(start_s)
        self._wall0 = time.monotonic()
        self.held_wall_s = 0.0       # wall time during which device time stood at its cap
        self._cap: float | None = None
        self._lock = threading.Lock()        # read by the drivers' and tests' threads too

    def _free(self) -> float:
        return self._start + self.speed * (time.monotonic() - self._wall0)

    def now(self) -> float:
        with self._lock:
            v = self._free()
            return v if self._cap is None or v < self._cap else self._cap

    def set_speed(self, speed: float) -> None:
        """From now on device time runs ``speed`` x wall time; it stays continuous (tests slow
        the world down around a moment they must hit)."""
        if not speed > 0:
            raise ValueError(f"speed must be > 0, got {speed!r}")
        with self._lock:
            v = self._free()
            self._start, self._wall0, self.speed = v, time.monotonic(), float(speed)

    def wall_until(self, device_t: float) -> float:
        """Wall seconds until device time ``device_t`` (<= 0 if past)."""
        return (device_t - self.now()) / self.speed

    @property
    def capped(self) -> bool:
        """Device time stands at its cap (the world waits)."""
        with self._lock:
            return self._cap is not None and self._free() >= self._cap

    def limit(self, cap_s: float | None) -> None:
        """Device time runs on from where it is now, but not beyond ``cap_s`` (None: no cap;
        ``now()``: it stands still).  Wall time spent at a cap adds no device time: device time
        stays continuous and never goes back."""
        with self._lock:
            v = self._free()
            cur = v if self._cap is None or v < self._cap else self._cap
            if v > cur:               # the wall time spent at the old cap
                self._wall0 += (v - cur) / self.speed
                self.held_wall_s += (v - cur) / self.speed
            self._cap = None if cap_s is None else max(float(cap_s), cur)


class StepClock:
    """Device time as the commands of one loop step see it: the time of the step, set by the
    serve loop, so that every command answered in a step happens at the instant up to which
    the IMU frames were already sent (``serve.BenchServer.step``)."""

    def __init__(self, clock):
        self.clock = clock
        self.t = clock.now()

    @property
    def speed(self) -> float:
        return self.clock.speed

    def set(self, t: float) -> None:
        self.t = float(t)

    def now(self) -> float:
        return self.t

    def wall_until(self, device_t: float) -> float:
        return self.clock.wall_until(device_t)


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
