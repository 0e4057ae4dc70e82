"""Acutrol (SCPI-style) front-end of the table twin, driven by the command table
``drivers.protocols.acutrol.COMMANDS``."""
from __future__ import annotations

from drivers.protocols import acutrol as P

from .lines import take_lines
from .table import CommandRefused, TableTwin

C = P.COMMANDS
MAX_LINE = 4096
_LIMIT_KEY = {"P": "P", "R": "R"}


class AcutrolFrontEnd:
    def __init__(self, table: TableTwin):
        if table.n_axes > P.MAX_AXES:
            raise ValueError("acutrol tables have 1 to 3 axes")
        self.table = table
        self._rx = bytearray()
        self._error = False
        self.handlers = {
            "identify": table.identity,
            "status_byte": self._status_byte,
            "interlock_reset": table.interlock_reset,
            "interlock_close": table.interlock_close,
            "interlock_open": table.interlock_open,
            "mode_position": lambda axis: table.set_mode(axis, "position"),
            "mode_rate": lambda axis: table.set_mode(axis, "rate"),
            "mode_off": lambda axis: table.set_mode(axis, "off"),
            "demand_position": table.demand_position,
            "demand_rate": table.demand_rate,
            "limit_rate": lambda mode, axis, v: table.set_limit(_LIMIT_KEY[mode], axis, rate_dps=v),
            "limit_acceleration": lambda mode, axis, v: table.set_limit(_LIMIT_KEY[mode], axis, accel_dps2=v),
            "read_position": table.read_position,
            "read_rate": table.read_rate,
        }
        missing = {c.name for c in C.commands} - set(self.handlers)
        assert not missing, f"no twin handler for {missing}"

    def receive(self, data: bytes) -> bytes:
        """Execute the complete lines in ``data``; the replies."""
        self._rx += data
        out = [self.execute(line) for line in take_lines(self._rx)]
        if len(self._rx) > MAX_LINE:
            self._rx.clear()
            self._error = True
        return b"".join(out)

    def execute(self, line: bytes) -> bytes:
        replies = []
        text = line.decode("ascii", "replace").strip()
        for part in C.split_line(text):
            try:
                cmd, args = C.parse(part)
                value = self.handlers[cmd.name](*args)
            except (ValueError, CommandRefused):
                self._error = True
                continue
            if cmd.is_query:
                replies.append(cmd.reply.format(value))
        return (C.chain.join(replies) + "\n").encode("ascii") if replies else b""

    def _status_byte(self) -> int:
        stb = 0
        for i, ax in enumerate(self.table.axes):
            if ax.interlock_closed:
                stb |= P.STB_INTERLOCK_CLOSED[i]
            if ax.fault:
                stb |= P.STB_FAULT[i]
        if self._error:
            stb |= P.STB_COMMAND_ERROR
            self._error = False
        return stb
