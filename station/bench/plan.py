"""A run's plan: small typed steps, compiled from a scheme (station/bench/compile.py) and executed
by the sequencer (station/bench/sequencer.py), the only code that touches hardware.

Every step says what it is for (``purpose``), which segment it serves (``segment``: the
steps of a segment that is already complete are skipped on ``--resume``; ``None`` for steps
that are run every time, e.g. the warm-up), and how long it should take in device time
(``estimate_s``), so that dry runs and duration estimates walk the plan without hardware.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

from station.io.scheme import RotationSpec, StaticSpec


@dataclass(frozen=True)
class Step:
    purpose: str
    segment: str | None
    estimate_s: float

    def describe(self) -> str:
        return self.purpose


@dataclass(frozen=True)
class WarmUp(Step):
    """Stream the IMU for at least ``min_s``; with ``slope_c_per_h``, until the temperature
    changes more slowly than that over ``window_s`` (at most ``max_s``).  ``resumed``: the warm-up
    of a resumed or extended run (``resumed_warmup``); ``restart_min_s``: its minimum when the
    IMU's clock shows that the IMU was restarted (switched off) while the run was stopped."""

    min_s: float = 0.0
    max_s: float | None = None
    slope_c_per_h: float | None = None
    window_s: float = 300.0
    resumed: bool = False
    restart_min_s: float = 0.0

    def describe(self) -> str:
        text = f"warm up{' again' if self.resumed else ''}: at least {self.min_s:g} s"
        if self.slope_c_per_h is not None:
            text += (f", until |dT/dt| < {self.slope_c_per_h:g} C/h over {self.window_s:g} s "
                     f"(at most {self.max_s:g} s)")
        return text


def resumed_warmup(step: WarmUp) -> WarmUp:
    """The warm-up a resumed or extended run waits before its first segment (issue 28): the IMU
    may have cooled while the run was stopped (switched off, unplugged), or be as warm as it was,
    so the temperature decides -- with a slope rule (``slope_c_per_h``) the same rule without the
    minimum ``min_s`` (a minimum counted from power-on): a warm IMU passes after one window of
    readings (``window_s``), a cooled one warms up again until the slope is below the limit (at
    most ``max_s``).  Without a slope rule the station cannot tell a warm IMU from a cold one: the
    whole ``min_s`` again.  An IMU switched off meanwhile has been on for less than ``min_s``: when
    its clock went back below the capture's warm-up records (``restart_min_s``: the sequencer's
    ``_clock_restarted``; the clock of a VectorNav or of the twins is the time since startup) the
    minimum applies again, counted from the resumed warm-up's first sample -- the slope alone
    cannot tell an IMU whose temperature has not started rising (a sensor lagging the heat
    source, a coarse temperature LSB) from a warm one.  station.simulate.dryrun.warmup_seconds
    (``resumed``) is this rule on the simulated IMU (never switched off on a dry run's append)."""
    least = 0.0 if step.slope_c_per_h is not None else step.min_s
    estimate = max(step.window_s, step.max_s or 0.0) if step.slope_c_per_h is not None else step.min_s
    return replace(step, purpose="let the IMU reach a steady temperature again after the pause", min_s=least,
                   estimate_s=estimate, resumed=True, restart_min_s=step.min_s)


@dataclass(frozen=True)
class MoveTo(Step):
    """Position moves of the axes to ``positions_deg`` (None: leave that axis alone)."""

    positions_deg: tuple = ()

    def describe(self) -> str:
        angles = ", ".join("-" if p is None else f"{p:.4f}" for p in self.positions_deg)
        return f"move table to ({angles}) deg: {self.purpose}"


@dataclass(frozen=True)
class Settle(Step):
    """Discard ``duration_s`` of IMU samples (after a move, before recording)."""

    duration_s: float = 0.0

    def describe(self) -> str:
        return f"settle {self.duration_s:g} s"


@dataclass(frozen=True)
class Dwell(Step):
    """Record a static segment: ``spec.dwell_s`` of IMU samples, the table held."""

    spec: StaticSpec = None
    table_deg: tuple | None = None      # the commanded angles (recorded), None without a table

    def describe(self) -> str:
        return f"record {self.spec.name}: static {self.spec.dwell_s:g} s, {self.purpose}"


@dataclass(frozen=True)
class Rotate(Step):
    """Record a rotation segment: ramp ``axis`` to ``table_rate_dps``, settle, record
    ``revolutions`` whole turns, ramp down.  With ``record_ramp`` (issue 28 item 3) one ramp is
    recorded: "start": the recording opens with the axis at rest (``rest_s``), then the ramp up at
    ``accel_dps2`` and the whole turns at the rate; "end": the whole turns at the rate, then the
    brake at ``accel_dps2`` and ``rest_s`` at rest.  The window then holds a change of rate, which
    shows a time offset between the IMU's stamps and the table's encoder."""

    spec: RotationSpec = None
    axis: int = 1                       # table axis, 1 = outer
    table_rate_dps: float = 0.0         # signed, of the table axis (= sign x spec.rate_dps)
    revolutions: int = 1
    accel_dps2: float = 50.0
    settle_s: float = 0.0
    elevation_deg: float = 0.0          # the rotation axis above the horizontal, as compiled
    table_deg: tuple = ()               # start angles
    record_ramp: str | None = None      # "start" | "end": that ramp is inside the recorded window
    rest_s: float = 0.0                 # with record_ramp: the axis at rest in the window, s

    @property
    def steady_s(self) -> float:
        """The whole turns at the rate, s."""
        return self.revolutions * 360.0 / abs(self.table_rate_dps)

    @property
    def ramp_s(self) -> float:
        """The recorded ramp (0 without one), s."""
        return abs(self.table_rate_dps) / self.accel_dps2 if self.record_ramp else 0.0

    @property
    def capture_s(self) -> float:
        """The recorded window, s."""
        return self.steady_s + (self.ramp_s + self.rest_s if self.record_ramp else 0.0)

    def describe(self) -> str:
        ramp = ""
        if self.record_ramp == "start":
            ramp = f" after {self.rest_s:g} s at rest and the ramp up ({self.ramp_s:.3g} s at {self.accel_dps2:g} deg/s^2)"
        elif self.record_ramp == "end":
            ramp = f" then the brake ({self.ramp_s:.3g} s at {self.accel_dps2:g} deg/s^2) and {self.rest_s:g} s at rest"
        return (f"record {self.spec.name}: axis {self.axis} at {self.table_rate_dps:+g} deg/s, "
                f"{self.revolutions} rev{ramp} ({self.capture_s:g} s), {self.purpose}")


@dataclass(frozen=True)
class Operator(Step):
    """Ask the operator to do something and wait for the confirmation.  ``remount``: the
    table is brought to rest (interlocks opened where the protocol can) before asking."""

    instruction: str = ""
    remount: bool = False
    mounting: tuple | None = None       # the mounting afterwards (case axes on the platform)

    def describe(self) -> str:
        return f"OPERATOR: {self.instruction}"


@dataclass(frozen=True)
class Chamber(Step):
    """Set the temperature chamber to ``setpoint_c`` (a manual chamber: the operator sets it and
    confirms), then wait for the ramp (``ramp_s``) and until the IMU's own temperature settles
    (station.core.chamber: a fixed soak or the slope rule); then the IMU's temperature is checked
    against the setpoint (beyond ``agree_c``: a finding in the capture)."""

    setpoint_c: float = 0.0
    from_c: float = 0.0                 # the setpoint before (the room's for the first)
    ramp_s: float = 0.0
    soak_s: float | None = None         # a fixed soak after the ramp, or the slope rule:
    slope_c_per_min: float | None = None
    window_s: float = 120.0
    max_s: float = 3600.0               # the slope rule's longest wait after the ramp
    agree_c: float = 5.0
    instruction: str = ""

    def describe(self) -> str:
        from station.core.chamber import settle_rule

        rule = settle_rule(self.soak_s, self.slope_c_per_min, self.window_s, self.max_s, degree="C")
        return (f"CHAMBER {self.from_c:g} -> {self.setpoint_c:g} C: OPERATOR: {self.instruction}; "
                f"ramp {self.ramp_s:.0f} s, {rule} (about {self.estimate_s:.0f} s in all)")


@dataclass(frozen=True)
class HandStatic(Step):
    """Without a table: the operator puts the IMU on a face and keeps it still; the recording
    continues until the data show ``spec.dwell_s`` of stillness."""

    spec: StaticSpec = None
    instruction: str = ""

    def describe(self) -> str:
        return f"OPERATOR (by hand): {self.instruction}"


@dataclass(frozen=True)
class HandRotation(Step):
    """Without a table: the operator turns the IMU; the recording continues until the data
    show a turn followed by stillness."""

    spec: RotationSpec = None
    instruction: str = ""

    def describe(self) -> str:
        return f"OPERATOR (by hand): {self.instruction}"


@dataclass(frozen=True)
class Checkpoint(Step):
    """The segment is on disk and in the manifest: a run resumes after it."""

    def describe(self) -> str:
        return f"checkpoint: {self.segment} saved"


@dataclass
class Plan:
    scheme: str
    steps: list = field(default_factory=list)
    notes: list = field(default_factory=list)     # e.g. what the compiler had to change
    manual: bool = False                          # performed by hand, no table
    mounting_of: dict = field(default_factory=dict)   # segment -> mounting while it records

    def __iter__(self):
        return iter(self.steps)

    @property
    def duration_s(self) -> float:
        return sum(s.estimate_s for s in self.steps)

    @property
    def segments(self) -> list[str]:
        return [s.segment for s in self.steps if isinstance(s, Checkpoint)]

    def recording(self) -> list:
        """The steps that record a segment (Dwell, Rotate, HandStatic, HandRotation)."""
        return [s for s in self.steps if isinstance(s, (Dwell, Rotate, HandStatic, HandRotation))]

    def remaining(self, done: set[str]) -> list:
        """The steps still to run when the segments ``done`` are complete (``--resume``):
        steps of no segment (the warm-up: once a segment is done, the resumed rule,
        resumed_warmup) and those of the segments not done.  A chamber step belongs
        to the first segment of its setpoint: when that segment is done but a later one of the
        same setpoint is not, the step is run again before that one (bound to it), so that a
        resumed run sets the chamber and waits as the first run did -- the chamber may have been
        switched off or changed in between (the review's finding: the rest of the level was
        recorded at whatever temperature the room had, with no trace in the capture)."""
        out, pending = [], None
        for s in self.steps:
            if isinstance(s, WarmUp) and done:      # a segment was recorded after the first warm-up
                s = resumed_warmup(s)
            if isinstance(s, Chamber):
                if s.segment is None or s.segment not in done:
                    out.append(s)
                    pending = None
                else:
                    pending = s
                continue
            if s.segment is None or s.segment not in done:
                if pending is not None and s.segment is not None:
                    out.append(replace(pending, segment=s.segment))
                    pending = None
                out.append(s)
        return out
