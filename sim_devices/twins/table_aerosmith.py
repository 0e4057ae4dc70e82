"""Three-letter (aerosmith) front-end of a single-axis table twin, driven by the command
table ``drivers.protocols.aerosmith.COMMANDS``.

Framing (docs/protocols.md, ``aerosmith``): a command with a number is executed at its line's
terminator (``\\r`` or ``\\n``; the other byte of ``\\r\\n`` and empty lines are ignored); a
command without one as soon as its three letters have arrived, so the bare ``STO`` of the
public client stops the table at once.  Each command is answered by a reply line and the
prompt line (``P.answer``); with ``silent_motion`` the commands the client writes without
reading (``JOG``, ``STO``, ``SGO``) are not answered at all.

Motion, where public material is silent, takes the pessimistic reading: the controller keeps
the last position demand (``MOV``, ``HOM``; 0 deg at power-up) and ``STO`` enters position
mode holding it, so a ``STO`` after a ``JOG`` drives back to the old target.  ``demands``
records every demand the axis was sent to execute (tests look for stale ones).
"""
from __future__ import annotations

import math

from drivers.protocols import aerosmith as P

from .table import CommandRefused, TableTwin

C = P.COMMANDS
MAX_LINE = 256
_ENDS = b"\r\n"
_NO_ARGS = {c.header for c in C.commands if not c.args}


class AerosmithFrontEnd:
    def __init__(self, table: TableTwin, *, silent_motion: bool = False):
        if table.n_axes != 1:
            raise ValueError("the three-letter dialect drives single-axis tables")
        self.table = table
        self.silent_motion = silent_motion
        self._rx = bytearray()
        self.target_deg = 0.0            # the position demand the controller keeps
        self.demands: list[tuple[float, str, float]] = []   # (device time, "MOV"/"JOG"/"HOLD", value)
        self.handlers = {
            "home": lambda: self._move(0.0),
            "move": self._move,
            "jog": self._jog,
            "stop": self._stop,
            "servo": self._servo,
            "acceleration": lambda v: table.set_limit("R", 1, accel_dps2=v),
            "velocity_limit": lambda v: table.set_limit("P", 1, rate_dps=v),
            "motion_complete": self._motion_complete,
            "position": lambda: table.read_position(1),
            "velocity": lambda: table.read_rate(1),
            "status": self._status,
        }
        missing = {c.name for c in C.commands} - set(self.handlers)
        assert not missing, f"no twin handler for {missing}"

    # ------------------------------------------------------------------ bytes
    def receive(self, data: bytes) -> bytes:
        self._rx += data
        out = []
        while self._rx:
            if self._rx[0] in _ENDS:                       # \n of \r\n, empty lines
                del self._rx[0]
                continue
            head = bytes(self._rx[:3]).decode("ascii", "replace").upper()
            if head in _NO_ARGS:                           # complete with its three letters
                del self._rx[:3]
                out.append(self.execute(head.encode()))
                continue
            ends = [i for i in (self._rx.find(b"\r"), self._rx.find(b"\n")) if i >= 0]
            if not ends:
                break
            end = min(ends)
            line = bytes(self._rx[:end])
            del self._rx[:end + 1]
            out.append(self.execute(line))
        if len(self._rx) > MAX_LINE:
            self._rx.clear()
            out.append(P.answer(P.ERROR_REPLY))
        return b"".join(out)

    def execute(self, line: bytes) -> bytes:
        text = line.decode("ascii", "replace")
        silent = self.silent_motion and text.strip()[:3].upper() in P.SILENT_COMMANDS
        try:
            cmd, args = C.parse(text)
            value = self.handlers[cmd.name](*args)
        except (ValueError, CommandRefused):
            return b"" if silent else P.answer(P.ERROR_REPLY)
        if silent:
            return b""
        return P.answer(cmd.reply.format(value) if cmd.is_query else "")

    # ------------------------------------------------------------------ commands
    def _servo(self, on: int) -> None:
        if on not in (0, 1):
            raise CommandRefused("SRV takes 0 or 1")
        if on:
            self.table.interlock_close(1)
        else:       # SRV0: servo off; SRV1 then holds where the axis is (unverified either way)
            self.table.interlock_open(1, keep_mode=False)

    def _powered(self):
        ax = self.table.axes[0]
        if not ax.interlock_closed:
            raise CommandRefused("servo off")
        return ax

    def _go(self, position_deg: float, what: str) -> None:
        """Position mode, driving the shortest way round to ``position_deg``."""
        t = self.table
        ax = self._powered()
        now = t.clock.now()
        p, _, _ = ax.motion.state(now)
        delta = (position_deg - p + 180.0) % 360.0 - 180.0
        if t.faults.stuck_axis == 1:
            delta = math.copysign(max(0.0, abs(delta) - t.faults.shortfall_deg), delta)
        rate, acc = ax.limits["P"]
        ax.motion.plan_position(now, p + delta, rate, acc)
        ax.mode = "position"
        ax.demand_deg = float(position_deg % 360.0)
        self.demands.append((now, what, float(position_deg % 360.0)))

    def _move(self, position_deg: float) -> None:
        self._go(position_deg, "MOV")
        self.target_deg = float(position_deg % 360.0)

    def _stop(self) -> None:
        """Pessimistic: position mode, holding the last position demand."""
        self._go(self.target_deg, "HOLD")

    def _jog(self, rate_dps: float) -> None:
        t = self.table
        ax = self._powered()
        rate, acc = ax.limits["R"]
        if abs(rate_dps) > rate:
            raise CommandRefused(f"{rate_dps} deg/s beyond the rate limit {rate}")
        now = t.clock.now()
        ax.motion.plan_rate(now, rate_dps, acc)
        ax.mode = "rate"
        ax.rate_demand_dps = float(rate_dps)
        self.demands.append((now, "JOG", float(rate_dps)))

    def _motion_complete(self, tolerance: int) -> int:
        if tolerance < 0:
            raise CommandRefused("MCO takes a tolerance >= 0")
        t = self.table
        ax = t.axes[0]
        if t.in_motion(1):
            return 0
        if ax.mode == "position":
            err = (t.read_position(1) - self.target_deg + 180.0) % 360.0 - 180.0
            return int(abs(err) <= tolerance)
        return 1

    def _status(self) -> int:
        ax = self.table.axes[0]
        sta = 0
        if ax.interlock_closed:
            sta |= P.STA_DRIVE_ENABLED
        if ax.fault:
            sta |= P.STA_FAULT
        if self.table.in_motion(1):
            sta |= P.STA_IN_MOTION
        if ax.mode == "rate":
            sta |= P.STA_RATE_MODE
        return sta
