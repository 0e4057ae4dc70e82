"""Three-letter (aerosmith) front-end of a single-axis table twin, driven by the command
table ``drivers.protocols.aerosmith.COMMANDS``."""
from __future__ import annotations

from drivers.protocols import aerosmith as P

from .lines import take_lines
from .table import CommandRefused, TableTwin

C = P.COMMANDS
MAX_LINE = 256


class AerosmithFrontEnd:
    def __init__(self, table: TableTwin):
        if table.n_axes != 1:
            raise ValueError("the three-letter dialect drives single-axis tables")
        self.table = table
        self._rx = bytearray()
        self.handlers = {
            "home": lambda: self._move(0.0),
            "move": self._move,
            "jog": self._jog,
            "stop": lambda: table.stop(1),
            "servo": self._servo,
            "acceleration": lambda v: table.set_limit("R", 1, accel_dps2=v),
            "position": lambda: table.read_position(1),
            "velocity": lambda: table.read_rate(1),
            "status": self._status,
        }
        missing = {c.name for c in C.commands} - set(self.handlers)
        assert not missing, f"no twin handler for {missing}"

    def receive(self, data: bytes) -> bytes:
        self._rx += data
        out = [self.execute(line) for line in take_lines(self._rx, b"\r\n") if line.strip()]
        if len(self._rx) > MAX_LINE:
            self._rx.clear()
            out.append((P.ERROR_REPLY + P.REPLY_END).encode() + P.PROMPT)
        return b"".join(out)

    def execute(self, line: bytes) -> bytes:
        try:
            cmd, args = C.parse(line.decode("ascii", "replace"))
            value = self.handlers[cmd.name](*args)
        except (ValueError, CommandRefused):
            return (P.ERROR_REPLY + P.REPLY_END).encode("ascii") + P.PROMPT
        text = cmd.reply.format(value) + P.REPLY_END if cmd.is_query else ""
        return text.encode("ascii") + P.PROMPT

    def _servo(self, on: int) -> None:
        if on not in (0, 1):
            raise CommandRefused("SRV takes 0 or 1")
        if on:
            self.table.interlock_close(1)
        else:
            self.table.interlock_open(1)

    def _move(self, position_deg: float) -> None:
        t = self.table              # the new demand first: entering the mode executes it
        t.demand_position(1, position_deg)
        if t.axes[0].mode != "position":
            t.set_mode(1, "position")

    def _jog(self, rate_dps: float) -> None:
        t = self.table
        t.demand_rate(1, rate_dps)
        if t.axes[0].mode != "rate":
            t.set_mode(1, "rate")

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
