"""The abstract rate-table interface :class:`RateTable`, its settings and status.

As in python-can, each public method does the common work (argument and limit checks,
waiting for arrival, timeouts, logging) and calls one small protocol-specific method
(``_name``) that a driver implements.
"""
from __future__ import annotations

import abc
import errno
import fcntl
import hashlib
import math
import os
import stat
import tempfile
import time
from dataclasses import dataclass, field

import numpy as np

from .device import Device
from .errors import DeviceError, DeviceTimeout, LimitError, TableFault
from .transport import SerialSettings


@dataclass(frozen=True)
class AxisLimits:
    """What the driver allows on one axis (the controller may allow less).

    ``max_rate_dps``/``max_accel_dps2``: refused beyond (rate demands, limits);
    ``move_rate_dps``/``move_accel_dps2``: the position-mode limits set at connect.
    """

    max_rate_dps: float = 300.0
    max_accel_dps2: float = 300.0
    move_rate_dps: float = 60.0
    move_accel_dps2: float = 60.0


@dataclass(frozen=True)
class TableSettings:
    """Settings of a rate-table driver.

    ``axes``: number of axes (None: ask the controller).  ``limits``: one :class:`AxisLimits`
    for every axis, or one per axis (outer first).  A move has arrived when the position is
    within ``position_tolerance_deg`` and the rate within ``rate_tolerance_dps`` for
    ``settle_polls`` polls in a row, polled every ``poll_interval_s``.  A wait gives up
    after its expected duration (from the limits) plus ``wait_margin_s``, and earlier when
    the axis has stayed at rest away from its demand for ``stall_polls`` polls.
    """

    serial: SerialSettings = field(default_factory=SerialSettings)
    axes: int | None = None
    limits: tuple[AxisLimits, ...] = (AxisLimits(),)
    position_tolerance_deg: float = 0.002
    rate_tolerance_dps: float = 0.01
    settle_polls: int = 5
    poll_interval_s: float = 0.01
    wait_margin_s: float = 10.0
    stall_polls: int = 50
    dialect: tuple[tuple[str, str], ...] = ()     # aerosmith: (command name, string) overrides

    def axis_limits(self, n_axes: int) -> tuple[AxisLimits, ...]:
        if len(self.limits) == 1:
            return self.limits * n_axes
        if len(self.limits) != n_axes:
            raise ValueError(f"limits for {len(self.limits)} axes given, the table has {n_axes}")
        return tuple(self.limits)


@dataclass(frozen=True)
class TableStatus:
    """Per axis (outer first): interlock closed, fault latched, mode as last commanded
    (``off``, ``position``, ``rate``, or ``unknown`` before any command); ``raw`` the
    controller's status word."""

    interlock_closed: tuple[bool, ...]
    fault: tuple[bool, ...]
    mode: tuple[str, ...]
    raw: int

    @property
    def ok(self) -> bool:
        return all(self.interlock_closed) and not any(self.fault)

    def describe(self) -> str:
        parts = []
        for i, (closed, fault) in enumerate(zip(self.interlock_closed, self.fault)):
            s = f"axis {i + 1}: interlock {'closed' if closed else 'OPEN'}"
            parts.append(s + (", FAULT" if fault else ""))
        return "; ".join(parts) + f" (status {self.raw:#04x})"


@dataclass(frozen=True)
class LeftoverMotion:
    """An axis found moving when the port was opened: its rate then (deg/s) and where it was
    braked to rest and held (deg)."""

    axis: int
    rate_dps: float
    rest_deg: float


#: how long opening a table waits for another station process (a guardian stopping the table of
#: a run that died) to let go of it: braking from 300 deg/s at 100 deg/s^2 and settling
LOCK_WAIT_S = 20.0


class TableLock:
    """One station process at a time talks to a table: an advisory lock (``flock``) on a file
    named after the table's port (``$TMPDIR/station-<uid>/table-<hash>.lock``), whatever the
    transport.  Two processes on one line would read each other's replies; the case that
    matters is a run started again at once after one was killed, while the killed run's
    guardian (station/bench/guardian.py) is still stopping the table.  Within one process the
    lock is shared (counted): drivers of one program are that program's business."""

    _held: dict[str, list] = {}          # lock path -> [fd, count] held by this process

    def __init__(self, url: str, name: str):
        key = url.rpartition("#")[0] if "#" in url else url
        if os.path.exists(key):
            key = os.path.realpath(key)          # /dev/serial/by-id/... and /dev/ttyUSB0 alike
        digest = hashlib.sha256(key.encode("utf-8", "replace")).hexdigest()[:20]
        self.dir = os.path.join(tempfile.gettempdir(), f"station-{os.getuid()}")
        self.path = os.path.join(self.dir, f"table-{digest}.lock")
        self.name = name
        self._mine = False

    def _open(self) -> int:
        """The lock file, in a directory of this user's only (0700, never a link: a file another
        user planted in the shared temporary directory is never opened, let alone written)."""
        try:
            os.makedirs(self.dir, mode=0o700, exist_ok=True)
            st = os.lstat(self.dir)
            if not stat.S_ISDIR(st.st_mode) or st.st_uid != os.getuid() or st.st_mode & 0o077:
                raise DeviceError(self.name, f"{self.dir} is not a private directory of this user: "
                                             "remove it (the table lock lives there)")
            return os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW, 0o600)
        except OSError as e:
            raise DeviceError(self.name, f"cannot open the table lock {self.path} ({e.strerror})") from None

    def acquire(self, wait_s: float = LOCK_WAIT_S) -> None:
        if self._mine:
            return
        held = self._held.get(self.path)
        if held is not None:                     # this process holds it already: counted
            held[1] += 1
            self._mine = True
            return
        fd = self._open()
        deadline = time.monotonic() + wait_s
        while True:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                break
            except OSError as e:
                if e.errno not in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                    os.close(fd)
                    raise DeviceError(self.name, f"cannot lock {self.path} ({e})") from None
                if time.monotonic() > deadline:
                    holder = os.pread(fd, 32, 0).decode("ascii", "replace").strip()
                    os.close(fd)
                    raise DeviceError(self.name, f"in use by another station process (pid {holder or '?'}) "
                                                 f"for over {wait_s:g} s") from None
                time.sleep(0.05)
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        self._held[self.path] = [fd, 1]
        self._mine = True

    def release(self) -> None:
        if not self._mine:
            return
        self._mine = False
        held = self._held.get(self.path)
        if held is None:
            return
        held[1] -= 1
        if held[1] <= 0:
            del self._held[self.path]
            os.close(held[0])                    # closing the file releases the lock


def wrap_deg(x):
    """Angle in [0, 360)."""
    return np.mod(x, 360.0)


def angle_diff_deg(a, b):
    """a - b wrapped to [-180, 180)."""
    return (np.asarray(a, dtype=float) - b + 180.0) % 360.0 - 180.0


class RateTable(Device):
    """A rate table of 1-3 axes (axis 1 = outermost).  Angles in deg, rates in deg/s.

    Continuous axes: positions read back in [0, 360); a position demand is reached the
    shortest way round.
    """

    kind = "table"

    def __init__(self, url: str, settings: TableSettings | None = None):
        super().__init__(url, settings or TableSettings())
        self.n_axes = 0
        self.limits: tuple[AxisLimits, ...] = ()
        self._modes: list[str] = []
        self.found_moving: list[LeftoverMotion] = []
        self._lock = TableLock(url, self.name)

    def connect(self) -> str:
        """Take the table's lock (another station process may be stopping it), then open the
        port and bring the table up; the lock is held until :meth:`close`."""
        self._lock.acquire()
        try:
            return super().connect()
        except BaseException:
            self._lock.release()
            raise

    def close(self) -> None:
        try:
            super().close()
        finally:
            self._lock.release()

    def __del__(self):
        # a driver dropped without close(): its port goes with it, and so does the table's lock
        lock = getattr(self, "_lock", None)
        if lock is not None:
            lock.release()

    # ------------------------------------------------------------------ connection
    def _on_connect(self) -> str:
        """Identify the controller, find its axes, set the move limits."""
        self.port.discard_input()
        self.identity = self._identify()
        n = self.settings.axes or self._count_axes()
        if not 1 <= n <= 3:
            raise LimitError(self.name, f"{n} axes: tables of 1 to 3 axes are supported")
        self.n_axes = n
        try:
            self.limits = self.settings.axis_limits(n)
        except ValueError as e:
            raise LimitError(self.name, str(e)) from None
        self._modes = ["unknown"] * n
        self._rate_accel = [lim.max_accel_dps2 for lim in self.limits]   # rate-mode ramps, deg/s^2
        for axis, lim in enumerate(self.limits, 1):
            self._set_move_limits(axis, lim.move_rate_dps, lim.move_accel_dps2)
        self.found_moving = self._stop_leftover_motion()
        return f"{self.identity}, {self.n_axes} axes"

    def _stop_leftover_motion(self) -> list[LeftoverMotion]:
        """At connect: an axis still moving was left so by an earlier run, program or operator
        (a run killed during a rotation keeps turning): brake every axis to rest and hold it
        there (:meth:`stop`, which cannot resume an old demand).  What was found and done is
        kept in ``found_moving`` for the command to say (``describe_leftover``)."""
        rates = self.read_rates_dps()
        moving = [axis for axis in self.axes
                  if abs(rates[axis - 1]) > max(self.settings.rate_tolerance_dps, 1e-3)]
        if not moving:
            return []
        self.log.warning("%s: axes %s moving at connect (%s deg/s): stopping them", self.name, moving,
                         [round(float(rates[a - 1]), 6) for a in moving])
        rest = self.stop()
        return [LeftoverMotion(axis, float(rates[axis - 1]), float(rest[axis - 1])) for axis in moving]

    def describe_leftover(self) -> str:
        """One sentence on the motion found at connect and what was done ('' when none)."""
        if not self.found_moving:
            return ""
        parts = [f"axis {m.axis} was turning at {m.rate_dps:.6g} deg/s" for m in self.found_moving]
        held = ", ".join(f"axis {m.axis} at {m.rest_deg:.6f} deg" for m in self.found_moving)
        return (f"{self.name}: {'; '.join(parts)} when the port was opened (left by an earlier run or "
                f"another program): braked to rest and held ({held})")

    @property
    def axes(self) -> tuple[int, ...]:
        return tuple(range(1, self.n_axes + 1))

    # ------------------------------------------------------------------ reading
    def read_positions_deg(self) -> np.ndarray:
        """Encoder positions of all axes, deg in [0, 360)."""
        return np.asarray(self._read_positions(), dtype=float)

    def read_rates_dps(self) -> np.ndarray:
        return np.asarray(self._read_rates(), dtype=float)

    def status(self) -> TableStatus:
        closed, fault, raw = self._status()
        self._note_open(closed)
        return TableStatus(tuple(closed), tuple(fault), tuple(self._modes), raw)

    def _note_open(self, closed) -> None:
        """An axis whose interlock is open is unpowered: its mode is off."""
        for i, c in enumerate(closed):
            if not c:
                self._modes[i] = "off"

    def check_ok(self) -> TableStatus:
        """The status; TableFault naming the axes when an interlock is open or a fault latched."""
        st = self.status()
        if not st.ok:
            raise TableFault(self.name, st.describe())
        return st

    # ------------------------------------------------------------------ interlocks
    def reset_interlocks(self) -> None:
        """Clear latched faults (tripped interlocks stay open until closed)."""
        self._reset()

    def close_interlocks(self, axes=None) -> TableStatus:
        """Close the interlocks of ``axes`` (all) that are open and servo them holding still.

        Closing an interlock servoes the axis in its selected mode, executing that mode's demand
        (TM-8004 §4.5.6: ``:D:P 2,0.0;:I:R;:M:P 2;:I C 2``), and the mode selected before the
        interlock opened may still be selected with its old demand (a rotation of an earlier
        run).  So each driver sends, before the close and in the same message where it can,
        what makes the axis hold still where it is (``_interlock(axis, True, hold_deg)``).  An
        axis whose interlock is already closed is left alone ("no effect on an axis that is
        already servoed", §4.5.6)."""
        axes = self._axes_arg(axes)
        closed, _, _ = self._status()
        to_close = [a for a in axes if not closed[a - 1]]
        if to_close:
            pos = self.read_positions_deg()
            for axis in to_close:
                self._interlock(axis, True, float(pos[axis - 1]))
                self._modes[axis - 1] = self._closed_mode
        return self.status()

    def open_interlocks(self, axes=None) -> None:
        for axis in self._axes_arg(axes):
            self._interlock(axis, False, None)
            self._modes[axis - 1] = "off"

    # ------------------------------------------------------------------ motion
    # A controller executes the demand loaded for a mode when the mode is entered (IEAv-EFO's
    # notes from a real ACUTROL3000: "if new demand is loaded when mode is activated the axis
    # will go to new demand as fast as possible"; docs/protocols.md, "Demands before modes").
    # So every mode change here sends the demand the mode must execute first, in the same
    # message where the protocol allows (``_set_mode``): no path enters a mode with whatever
    # demand an earlier run, program or operator left.

    def position_mode(self, axis: int, hold_deg: float | None = None) -> None:
        """Position mode holding ``hold_deg`` (default: the position measured now; call it at
        rest, as :meth:`stop` does)."""
        self._check_axis(axis)
        if hold_deg is None:
            hold_deg = float(self.read_positions_deg()[axis - 1])
        self._enter_mode(axis, "position", float(wrap_deg(float(hold_deg))))

    def rate_mode(self, axis: int) -> None:
        """Rate mode at a zero rate demand (the demand is sent first)."""
        self._check_axis(axis)
        self._enter_mode(axis, "rate", 0.0)

    def _enter_mode(self, axis: int, mode: str, demand: float) -> None:
        if not math.isfinite(demand):
            raise LimitError(self.name, f"axis {axis}: demand {demand!r} is not finite")
        self._set_mode(axis, mode, demand)
        self._modes[axis - 1] = mode

    def move_to(self, positions_deg, *, wait: bool = True) -> np.ndarray:
        """Move the axes to ``positions_deg`` (one per axis; None leaves an axis alone).

        Switches those axes to position mode; with ``wait`` returns the settled positions,
        or raises TableFault (fault, open interlock, axis at rest short of its demand) or
        DeviceTimeout.
        """
        targets = list(positions_deg)
        if len(targets) != self.n_axes:
            raise LimitError(self.name, f"{len(targets)} positions given for {self.n_axes} axes")
        start = self.read_positions_deg()
        expected = 0.0
        for axis, target in enumerate(targets, 1):
            if target is None:
                continue
            if not math.isfinite(float(target)):
                raise LimitError(self.name, f"axis {axis}: position {target!r} is not finite")
            lim = self.limits[axis - 1]
            dist = abs(float(angle_diff_deg(target, start[axis - 1])))
            expected = max(expected, dist / lim.move_rate_dps + lim.move_rate_dps / lim.move_accel_dps2)
        for axis, target in enumerate(targets, 1):
            if target is None:
                continue
            demand = float(wrap_deg(float(target)))
            self.log.info("%s: axis %d -> %.6f deg", self.name, axis, demand)
            if self._modes[axis - 1] != "position":
                self._enter_mode(axis, "position", demand)      # the target, then the mode
            else:
                self._demand_position(axis, demand)
        if not wait:
            return start
        return self._wait_positions(targets, expected)

    def set_rate(self, axis: int, rate_dps: float, *, wait: bool = True) -> float:
        """Turn ``axis`` at ``rate_dps`` (rate mode); with ``wait`` returns once the measured
        rate has settled on the demand."""
        self._check_axis(axis)
        lim = self.limits[axis - 1]
        rate = float(rate_dps)
        if not math.isfinite(rate) or abs(rate) > lim.max_rate_dps:
            raise LimitError(self.name, f"axis {axis}: rate {rate_dps!r} deg/s beyond the limit "
                                        f"{lim.max_rate_dps:g} deg/s")
        before = float(self.read_rates_dps()[axis - 1])
        self.log.info("%s: axis %d at %.6f deg/s", self.name, axis, rate)
        if self._modes[axis - 1] != "rate":
            self._enter_mode(axis, "rate", rate)               # the demand, then the mode
        else:
            self._demand_rate(axis, rate)
        if not wait:
            return before
        expected = abs(rate - before) / self._rate_accel[axis - 1]
        return self._wait_rate(axis, rate, expected)

    def set_rate_limits(self, axis: int, mode: str, rate_dps: float, accel_dps2: float) -> None:
        """Rate and acceleration limits of ``mode`` (``position`` or ``rate``) on ``axis``."""
        self._check_axis(axis)
        lim = self.limits[axis - 1]
        if not (0 < rate_dps <= lim.max_rate_dps and 0 < accel_dps2 <= lim.max_accel_dps2):
            raise LimitError(self.name, f"axis {axis}: limits {rate_dps:g} deg/s, {accel_dps2:g} "
                                        f"deg/s^2 outside (0, {lim.max_rate_dps:g}], "
                                        f"(0, {lim.max_accel_dps2:g}]")
        self._set_limits(axis, mode, rate_dps, accel_dps2)
        if mode == "rate":          # the waits expect ramps at this acceleration
            self._rate_accel[axis - 1] = accel_dps2

    def stop(self) -> np.ndarray:
        """Controlled stop: every axis brakes to rest and holds there.  Returns the positions.

        Whatever mode the driver believes an axis is in (a previous run may have left it
        turning, the front panel may have changed it), each axis with its interlock closed is
        braked by a zero rate demand sent before (or with) the mode that executes it; once all
        are at rest each holds the position measured there, sent before position mode."""
        closed, _, _ = self._status()
        active = [axis for axis in self.axes if closed[axis - 1]]   # open interlock: brakes itself
        rates = self.read_rates_dps()
        for axis in active:
            self._halt(axis, self._modes[axis - 1])
            if self._halt_mode is not None:
                self._modes[axis - 1] = self._halt_mode
        # each axis brakes at the acceleration of its braking mode (the slower, when unsure)
        expected = max((abs(rates[axis - 1]) / min(self._rate_accel[axis - 1],
                                                   self.limits[axis - 1].move_accel_dps2)
                        for axis in self.axes), default=0.0)
        deadline = time.monotonic() + expected + self.settings.wait_margin_s
        still = 0
        while still < self.settings.settle_polls:
            rates = self.read_rates_dps()
            still = still + 1 if np.all(np.abs(rates) <= self.settings.rate_tolerance_dps) else 0
            if time.monotonic() > deadline:
                raise DeviceTimeout(self.name, f"did not come to rest (rates {np.round(rates, 4).tolist()} "
                                               f"deg/s)")
            time.sleep(self.settings.poll_interval_s)
        rest = self.read_positions_deg()
        for axis in self.axes:
            if axis in active:
                self._after_halt(axis, float(rest[axis - 1]))
            else:
                self._modes[axis - 1] = "off"
        return self.read_positions_deg()

    # ------------------------------------------------------------------ waits
    def _poll(self, axes):
        """(positions, rates) of all axes; TableFault when a fault is latched on any axis or
        an interlock of ``axes`` is open (one exchange where the protocol allows)."""
        pos, rates, closed, fault, raw = self._read_state()
        self._note_open(closed)
        if any(fault) or not all(closed[a - 1] for a in axes):
            st = TableStatus(tuple(closed), tuple(fault), tuple(self._modes), raw)
            raise TableFault(self.name, st.describe())
        return np.asarray(pos, dtype=float), np.asarray(rates, dtype=float)

    def _wait_positions(self, targets, expected_s: float) -> np.ndarray:
        s = self.settings
        idx = [i for i, t in enumerate(targets) if t is not None]
        goal = np.array([float(targets[i]) for i in idx])
        deadline = time.monotonic() + 2.0 * expected_s + s.wait_margin_s
        settled = at_rest = 0
        last = None
        while True:
            pos, rates = self._poll([i + 1 for i in idx])
            err = angle_diff_deg(pos[idx], goal)
            still = np.all(np.abs(rates[idx]) <= s.rate_tolerance_dps)
            if np.all(np.abs(err) <= s.position_tolerance_deg) and still:
                settled += 1
                if settled >= s.settle_polls:
                    return pos
            else:
                settled = 0
            moved = last is not None and np.any(
                np.abs(angle_diff_deg(pos[idx], last)) > s.position_tolerance_deg / 10)
            at_rest = at_rest + 1 if (still and not moved and last is not None and not settled) else 0
            last = pos[idx]
            worst = int(np.argmax(np.abs(err)))
            axis = idx[worst] + 1
            if at_rest >= s.stall_polls:
                raise TableFault(self.name, f"axis {axis} came to rest at {pos[axis - 1]:.6f} deg, "
                                            f"{abs(err[worst]):.6f} deg from its demand "
                                            f"{wrap_deg(goal[worst]):.6f} deg")
            if time.monotonic() > deadline:
                raise DeviceTimeout(self.name, f"axis {axis} did not reach {wrap_deg(goal[worst]):.6f} "
                                               f"deg in time (at {pos[axis - 1]:.6f} deg)")
            time.sleep(s.poll_interval_s)

    def _wait_rate(self, axis: int, rate: float, expected_s: float) -> float:
        s = self.settings
        deadline = time.monotonic() + 2.0 * expected_s + s.wait_margin_s
        settled = 0
        while True:
            r = float(self._poll([axis])[1][axis - 1])
            if abs(r - rate) <= s.rate_tolerance_dps:
                settled += 1
                if settled >= s.settle_polls:
                    return r
            else:
                settled = 0
            if time.monotonic() > deadline:
                raise DeviceTimeout(self.name, f"axis {axis} did not reach {rate:g} deg/s in time "
                                               f"(at {r:.6f} deg/s)")
            time.sleep(s.poll_interval_s)

    # ------------------------------------------------------------------ helpers
    def _check_axis(self, axis: int) -> None:
        if axis not in self.axes:
            raise LimitError(self.name, f"no axis {axis!r} (the table has axes 1..{self.n_axes})")

    def _axes_arg(self, axes):
        axes = self.axes if axes is None else tuple(axes)
        for a in axes:
            self._check_axis(a)
        return axes

    # ------------------------------------------------------------------ protocol part
    @abc.abstractmethod
    def _identify(self) -> str: ...

    @abc.abstractmethod
    def _count_axes(self) -> int: ...

    @abc.abstractmethod
    def _set_move_limits(self, axis: int, rate_dps: float, accel_dps2: float) -> None: ...

    @abc.abstractmethod
    def _set_limits(self, axis: int, mode: str, rate_dps: float, accel_dps2: float) -> None: ...

    @abc.abstractmethod
    def _read_positions(self) -> list[float]: ...

    @abc.abstractmethod
    def _read_rates(self) -> list[float]: ...

    @abc.abstractmethod
    def _status(self) -> tuple[list[bool], list[bool], int]: ...

    def _read_state(self):
        """(positions, rates, interlock closed, fault, raw status) of all axes.  Override to
        do it in one exchange."""
        closed, fault, raw = self._status()
        return self._read_positions(), self._read_rates(), closed, fault, raw

    @abc.abstractmethod
    def _reset(self) -> None: ...

    #: the mode an axis is in once ``_interlock(axis, True, ...)`` has closed it
    _closed_mode: str = "off"

    @abc.abstractmethod
    def _interlock(self, axis: int, close: bool, hold_deg: float | None) -> None:
        """Open, or close (then the axis must hold still at ``hold_deg``, its measured position,
        whatever mode and demand it had: see :meth:`close_interlocks`)."""

    @abc.abstractmethod
    def _set_mode(self, axis: int, mode: str, demand: float) -> None:
        """Enter ``mode`` (``position``/``rate``) executing ``demand`` (deg, deg/s): the demand
        reaches the controller before the mode, in one message where the protocol allows."""

    @abc.abstractmethod
    def _demand_position(self, axis: int, position_deg: float) -> None: ...

    @abc.abstractmethod
    def _demand_rate(self, axis: int, rate_dps: float) -> None: ...

    #: the mode an axis is in once ``_halt`` was sent (None: unchanged)
    _halt_mode: str | None = None

    @abc.abstractmethod
    def _halt(self, axis: int, mode: str) -> None:
        """Start braking ``axis`` (believed to be in ``mode``) to rest, by commands that cannot
        execute an older demand."""

    def _after_halt(self, axis: int, position_deg: float) -> None:
        """Once every axis is at rest: hold ``axis`` at ``position_deg``, where it came to rest
        (position mode, the demand sent first)."""
        self._enter_mode(axis, "position", float(wrap_deg(position_deg)))
