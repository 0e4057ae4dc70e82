"""The rate-table twin: axes with modes, limits, interlocks, faults and encoder readback.

Protocol-independent: the front-ends (``table_acutrol``, ``table_aerosmith``) turn bytes into
calls of these methods.  A call that the controller would refuse raises
:class:`CommandRefused`.  Power-up state: every axis at 0 deg, at rest, interlock open, servo
off, no fault (``interlocks_closed=True`` for controllers without interlock commands).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .geometry import TableGeometry
from .motion import AxisMotion



#: device seconds of motion kept (the IMU twin evaluates recent instants; tests look back over
#: a whole sequence of moves, which at --speed 100 on a loaded machine can exceed a minute)
MOTION_MEMORY_S = 600.0

class CommandRefused(Exception):
    """The controller cannot execute the command (unknown, bad argument, wrong state)."""


@dataclass(frozen=True)
class TableConfig:
    """Hardware of the twin: the axes' limits (one number for every axis, or one per axis,
    outer first), encoder and rate readback resolution, settling time after a move, the
    limits in force at power-up."""

    # absolute (factory) limits: 1000 deg/s is the BD125 rate range (its datasheet, public in
    # IEAv-EFO/acutrol3000 doc/) and IEAv-EFO's set_limits(lim_rate=1000); 8300 deg/s² is
    # IEAv-EFO's set_limits(lim_acc=8300) (the BD125 datasheet: 4200 deg/s² without load, the
    # figure of IEAv-EFO's routine.py), above the manual's 1500 and 2000 (TM-8004 §4.6.2)
    max_rate_dps: float | tuple[float, ...] = 1000.0
    max_accel_dps2: float | tuple[float, ...] = 8300.0
    move_rate_dps: float = 60.0          # position-mode limits at power-up
    move_accel_dps2: float = 60.0
    rate_accel_dps2: float = 100.0       # rate-mode acceleration limit at power-up
    encoder_resolution_deg: float = 1e-5
    rate_resolution_dps: float = 1e-5
    settle_s: float = 1.0
    #: 1-sigma (arcsec) of an angle the table turns between two unrelated angles, read by its
    #: encoder (station.yaml's ``table.angle_error_arcsec``; None: the truth's
    #: ``bench.table_angle_error_arcsec``, BenchServer); see EncoderError
    angle_error_arcsec: float | None = 0.0
    identity: str = "Acutronic,ACUTROL3000-SIM,{axes}AX-0001,3.1.0"

    def hardware(self, axis: int) -> tuple[float, float]:
        """(max rate deg/s, max acceleration deg/s²) of ``axis`` (1 = outer)."""
        def pick(v):
            return float(v if isinstance(v, (int, float)) else v[axis - 1])
        return pick(self.max_rate_dps), pick(self.max_accel_dps2)


class EncoderError:
    """What an axis's encoder reads wrong: e(p) (deg) at encoder angle p, the graduation and
    mounting errors of a real angle encoder, a function of the angle alone (the same at every
    visit, periodic over a revolution):

        e(p) = sum_{h=1..H} c_h cos(h p) + d_h sin(h p),     c_h, d_h ~ N(0, s^2 / H)

    (rms s over the angle; H = HARMONICS, correlated over about 360/H deg).  The controller closes
    its loops on the encoder, so the axis truly stands (and turns) at p - e(p): a position move
    ends where the encoder reads the demand, the axis off by -e(demand); in rate mode the encoder
    angle follows the demanded ramp, the readback rate is the demand, and the angle truly turned
    between encoder angles p0 and p1 is (p1 - p0) - (e(p1) - e(p0)).  With s = sigma / sqrt 2 the
    angle turned between two unrelated angles errs by sigma (the configured figure, the 1-sigma
    the estimator states for a rotation's angle); over whole revolutions the periodic error
    cancels (e(p0 + 360) = e(p0)), as on a real table.  The readbacks are quantised besides
    (TableConfig.encoder_resolution_deg)."""

    HARMONICS = 16

    def __init__(self, sigma_arcsec: float, rng):
        s = float(sigma_arcsec) / 3600.0 / math.sqrt(2.0)
        self.h = np.arange(1, self.HARMONICS + 1, dtype=float)
        self.c = rng.normal(0.0, s / math.sqrt(self.HARMONICS), self.HARMONICS)
        self.d = rng.normal(0.0, s / math.sqrt(self.HARMONICS), self.HARMONICS)
        # (2H, 3): the columns giving e, de/dp (deg/deg) and d2e/dp2 (per deg) from [cos(h p) | sin(h p)]
        h, c, d, k = self.h, self.c, self.d, math.pi / 180.0
        self._weights = np.column_stack([np.concatenate([c, d]), np.concatenate([h * d, -h * c]) * k,
                                         -np.concatenate([h * h * c, h * h * d]) * k * k])

    def true_states(self, p, v, a):
        """The axis's true (angle deg, rate deg/s, acceleration deg/s²) from the encoder's."""
        x = np.radians(np.asarray(p, dtype=float))[..., None] * self.h
        # e, de/dp and d2e/dp2 as one product of [cos | sin] with the harmonics' coefficients
        # (they were sums of (N, H) temporaries: ~13 us a sample)
        e, de, d2e = np.moveaxis(np.concatenate([np.cos(x), np.sin(x)], axis=-1) @ self._weights, -1, 0)
        return p - e, v * (1.0 - de), a * (1.0 - de) - v * v * d2e


@dataclass
class TableFaults:
    """Faults of the table (docs/twins.md): an interlock trip of ``trip_axis`` at device time
    ``trip_at_s``; ``stuck_axis`` stopping ``shortfall_deg`` short of every position demand;
    no replies from ``stall_at_s`` (for ``stall_duration_s``, None = for ever); the port
    hung up at ``disconnect_at_s``."""

    trip_axis: int | None = None
    trip_at_s: float | None = None
    stuck_axis: int | None = None
    shortfall_deg: float = 0.0
    stall_at_s: float | None = None
    stall_duration_s: float | None = None
    disconnect_at_s: float | None = None


@dataclass
class AxisState:
    motion: AxisMotion
    limits: dict = field(default_factory=dict)       # "P"/"R" -> [rate_dps, accel_dps2]
    interlock_closed: bool = False
    fault: bool = False
    mode: str = "off"
    hardware: tuple[float, float] = (1000.0, 1000.0)     # max rate deg/s, max accel deg/s²
    demand_deg: float = 0.0            # last position demand, deg
    rate_demand_dps: float = 0.0       # last rate demand, deg/s


class TableTwin:
    def __init__(self, geometry: TableGeometry, clock, *, config: TableConfig = TableConfig(),
                 ripple_fraction: float = 0.0, ripple_hz: float = 1.0, rng=None,
                 faults: TableFaults | None = None, interlocks_closed: bool = False):
        self.geometry = geometry
        self.clock = clock
        self.config = config
        self.faults = faults or TableFaults()
        rng = rng if rng is not None else np.random.default_rng(0)
        self.axes = []
        for axis in range(1, geometry.n_axes + 1):
            rate, acc = config.hardware(axis)
            self.axes.append(AxisState(
                AxisMotion(ripple_fraction=ripple_fraction, ripple_hz=ripple_hz,
                           settle_s=config.settle_s, rng=rng),
                {"P": [min(config.move_rate_dps, rate), min(config.move_accel_dps2, acc)],
                 "R": [rate, min(config.rate_accel_dps2, acc)]},
                interlock_closed=interlocks_closed, hardware=(rate, acc)))
        self._tripped = False
        # each axis's encoder error (none at 0 arcsec: the rng untouched, the motion exact)
        sigma = config.angle_error_arcsec or 0.0
        self.encoder_errors = ([EncoderError(sigma, np.random.default_rng(rng.integers(2**63)))
                                for _ in self.axes] if sigma > 0 else None)

    @property
    def n_axes(self) -> int:
        return len(self.axes)

    # ------------------------------------------------------------------ time and faults
    def update(self, now: float) -> None:
        """Fire the faults due by ``now``; forget motion older than MOTION_MEMORY_S."""
        f = self.faults
        if not self._tripped and f.trip_at_s is not None and now >= f.trip_at_s:
            self._tripped = True
            ax = self._axis(f.trip_axis)
            ax.fault = True
            ax.interlock_closed = False         # the mode stays selected (interlock_open)
            ax.motion.plan_stop(f.trip_at_s, ax.hardware[1])
        for ax in self.axes:
            ax.motion.prune(now - MOTION_MEMORY_S)

    def stalled(self, now: float) -> bool:
        f = self.faults
        if f.stall_at_s is None or now < f.stall_at_s:
            return False
        return f.stall_duration_s is None or now < f.stall_at_s + f.stall_duration_s

    # ------------------------------------------------------------------ commands
    def identity(self) -> str:
        return self.config.identity.format(axes=self.n_axes)

    def interlock_reset(self) -> None:
        for ax in self.axes:
            ax.fault = False

    def interlock_close(self, axis: int) -> None:
        """Close the interlock and servo the axis in its selected mode, executing that mode's
        demand (TM-8004 §4.5.6's example selects the mode before closing: ``:D:P 2,0.0;:I:R;
        :M:P 2;:I C 2``, "Change axis 2 to Position mode; Close axis 2 interlocks and servo"):
        whatever demand the mode holds, however old.  Off holds zero rate."""
        ax = self._axis(axis)
        if ax.fault:
            raise CommandRefused(f"axis {axis}: fault latched (reset first)")
        if ax.interlock_closed:
            return                              # "no effect on an axis that is already servoed"
        ax.interlock_closed = True
        self._servo(axis, ax, self.clock.now())

    def interlock_open(self, axis: int, keep_mode: bool = True) -> None:
        """Open the interlock: the axis brakes to rest unpowered.  Its mode stays selected (with
        its demand) unless ``keep_mode`` is False: nothing public says a controller forgets
        it, and closing the interlock again servoes the axis in it (the pessimistic reading)."""
        ax = self._axis(axis)
        ax.interlock_closed = False
        mode = ax.mode
        self._brake(ax, "off")
        if keep_mode:
            ax.mode = mode

    def set_mode(self, axis: int, mode: str) -> None:
        """Enter ``mode``: it executes the demand loaded for it (docs/protocols.md, "Demands
        before modes": the IEAv-EFO notes from a real ACUTROL3000, ``:d:p 1,0`` then ``:m:p ALL``
        "send all axis to demanded position").  Position mode drives to the position demand,
        rate mode ramps to the rate demand, whatever they were set to and whenever; off mode
        brakes to zero rate whatever the demands (TM-8004 §4.7.3: "No demands affect Off Mode")."""
        ax = self._axis(axis)
        if mode not in ("position", "rate", "off"):
            raise CommandRefused(f"unknown mode {mode!r}")
        ax.mode = mode
        if ax.interlock_closed:        # with the interlock open the mode is selected, for its close
            self._servo(axis, ax, self.clock.now())

    def _servo(self, axis: int, ax: AxisState, now: float) -> None:
        """Execute the selected mode: its demand, or zero rate in off mode."""
        if ax.mode == "position":
            self._plan_position(axis, ax, now)
        elif ax.mode == "rate":
            ax.motion.plan_rate(now, ax.rate_demand_dps, ax.limits["R"][1])
        else:
            self._brake(ax, "off")

    def demand_position(self, axis: int, position_deg: float) -> None:
        """Load a position demand (any mode, interlock open or closed); executed at once in
        position mode, else when position mode is entered."""
        ax = self._axis(axis)
        ax.demand_deg = float(position_deg)
        if ax.mode == "position" and ax.interlock_closed:
            self._plan_position(axis, ax, self.clock.now())

    def demand_rate(self, axis: int, rate_dps: float) -> None:
        """Load a rate demand (any mode); executed at once in rate mode, else when rate mode
        is entered.  Refused beyond the rate-mode rate limit."""
        ax = self._axis(axis)
        rate, acc = ax.limits["R"]
        if abs(rate_dps) > rate:
            raise CommandRefused(f"axis {axis}: {rate_dps} deg/s beyond the rate limit {rate}")
        ax.rate_demand_dps = float(rate_dps)
        if ax.mode == "rate" and ax.interlock_closed:
            ax.motion.plan_rate(self.clock.now(), rate_dps, acc)

    def _plan_position(self, axis: int, ax: AxisState, now: float) -> None:
        """Move to the position demand the shortest way round (a stuck axis stops short)."""
        p, _, _ = ax.motion.state(now)
        delta = (ax.demand_deg - p + 180.0) % 360.0 - 180.0
        if self.faults.stuck_axis == axis:
            delta = math.copysign(max(0.0, abs(delta) - self.faults.shortfall_deg), delta)
        rate, acc = ax.limits["P"]
        ax.motion.plan_position(now, p + delta, rate, acc)

    def set_limit(self, mode: str, axis: int, *, rate_dps=None, accel_dps2=None) -> None:
        ax = self._axis(axis)
        max_rate, max_acc = ax.hardware
        if rate_dps is not None:
            if not 0.0 < rate_dps <= max_rate:
                raise CommandRefused(f"axis {axis}: rate limit {rate_dps} outside (0, {max_rate}]")
            ax.limits[mode][0] = float(rate_dps)
        if accel_dps2 is not None:
            if not 0.0 < accel_dps2 <= max_acc:
                raise CommandRefused(f"axis {axis}: acceleration limit {accel_dps2} outside (0, {max_acc}]")
            ax.limits[mode][1] = float(accel_dps2)

    def stop(self, axis: int) -> None:
        """Brake to rest and hold there (position mode; the position demand becomes the
        position where the axis comes to rest, the rate demand 0)."""
        ax = self._axis(axis)
        if not ax.interlock_closed:
            raise CommandRefused(f"axis {axis}: interlock open")
        self._brake(ax, "position")
        ax.demand_deg = float(ax.motion.segments[-1].p0 % 360.0)      # the rest position
        ax.rate_demand_dps = 0.0

    def read_position(self, axis: int) -> float:
        p, _, _ = self._axis(axis).motion.state(self.clock.now())
        res = self.config.encoder_resolution_deg
        return float(np.round(p / res) * res % 360.0)

    def read_rate(self, axis: int) -> float:
        _, v, _ = self._axis(axis).motion.state(self.clock.now())
        res = self.config.rate_resolution_dps
        return float(np.round(v / res) * res) + 0.0

    def read_acceleration(self, axis: int) -> float:
        """Angular acceleration, deg/s²."""
        _, _, a = self._axis(axis).motion.state(self.clock.now())
        return float(a) + 0.0

    def in_motion(self, axis: int) -> bool:
        _, v, _ = self._axis(axis).motion.state(self.clock.now())
        return abs(v) > self.config.rate_resolution_dps

    # ------------------------------------------------------------------ for the IMU twin
    def axis_states(self, t):
        """(theta, theta_dot, theta_ddot), each (N, k) in deg, deg/s, deg/s²: the axes' true
        angles (the encoder's, less its error: EncoderError)."""
        t = np.atleast_1d(np.asarray(t, dtype=float))
        cols = [ax.motion.eval(t) for ax in self.axes]
        if self.encoder_errors is not None:         # the motion is the encoder's: the axis's own
            cols = [err.true_states(*c) for err, c in zip(self.encoder_errors, cols)]
        return tuple(np.column_stack([c[i] for c in cols]) for i in range(3))

    def kinematics_at(self, t):
        """(C_bn, w_eb_b rad/s, wdot_eb_b rad/s²) of the platform at device times ``t``."""
        th, thd, thdd = self.axis_states(t)
        return self.geometry.kinematics(np.radians(th), np.radians(thd), np.radians(thdd))

    # ------------------------------------------------------------------ helpers
    def _axis(self, axis) -> AxisState:
        if not isinstance(axis, int) or not 1 <= axis <= len(self.axes):
            raise CommandRefused(f"no axis {axis!r}")
        return self.axes[axis - 1]

    def _brake(self, ax: AxisState, mode: str) -> None:
        acc = ax.hardware[1] if mode == "off" else ax.limits["P"][1]
        ax.motion.plan_stop(self.clock.now(), acc)
        ax.mode = mode
