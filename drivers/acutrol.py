"""Driver for Acutronic Acutrol controllers (SCPI-style, protocol ``acutrol``), 1-3 axes."""
from __future__ import annotations

from .errors import ProtocolError, TableFault
from .protocols import acutrol as P
from .table import RateTable, TableStatus

C = P.COMMANDS
_MODE_CMD = {"position": "mode_position", "rate": "mode_rate", "off": "mode_off"}
_LIMIT_MODE = {"position": "P", "rate": "R"}


class AcutrolTable(RateTable):
    protocol = "acutrol"

    def __init__(self, url, settings=None):
        super().__init__(url, settings)
        self._rx = bytearray()
        self.last_status = 0

    # ---------------------------------------------------------------- the exchange
    def _exchange(self, *commands: tuple) -> list[str]:
        """Send ``commands`` ((name, *values) each) on one line ended by ``*STB?``; return
        the answers of the queries.  ProtocolError when the command-error bit comes back."""
        texts = [C.format(name, *values) for name, *values in commands]
        line = C.chain.join(texts + [C.format("status_byte")])
        if self._rx:
            self._rx.clear()
        self.port.write(line.encode("ascii") + C.terminator.encode("ascii"))
        reply = self.port.read_until(b"\n", None, repr(line), self._rx)
        fields = reply.decode("ascii", "replace").strip().split(C.chain)
        try:
            stb = int(fields[-1])
        except ValueError:
            raise ProtocolError(self.name, f"status byte expected at the end of the reply to "
                                           f"{line!r}, got {reply[:80]!r}") from None
        self.last_status = stb
        if stb & P.STB_COMMAND_ERROR:
            closed, fault, _ = self._decode_status(stb) if self.n_axes else ([True], [False], stb)
            if any(fault) or not all(closed):       # refused because of the table's state
                st = TableStatus(tuple(closed), tuple(fault), tuple(self._modes), stb)
                raise TableFault(self.name, f"{line!r} refused: {st.describe()}")
            raise ProtocolError(self.name, f"{line!r} refused (command error, status {stb:#04x})")
        n_queries = sum(C.command(name).is_query for name, *_ in commands)
        if len(fields) - 1 != n_queries:
            raise ProtocolError(self.name, f"{n_queries} answers expected to {line!r}, got {reply[:80]!r}")
        return fields[:-1]

    def _floats(self, name: str) -> list[float]:
        answers = self._exchange(*[(name, axis) for axis in self.axes])
        reply = C.command(name).reply
        try:
            return [reply.parse(a) for a in answers]
        except ValueError as e:
            raise ProtocolError(self.name, f"bad answer to {name}: {e}") from None

    # ---------------------------------------------------------------- protocol part
    def _identify(self) -> str:
        return self._exchange(("identify",))[0]

    def _count_axes(self) -> int:
        n = 0
        for axis in range(1, P.MAX_AXES + 1):
            try:
                self._exchange(("read_position", axis))
            except ProtocolError:
                break
            n = axis
        if n == 0:
            raise ProtocolError(self.name, "the controller has no axis 1")
        return n

    def _set_move_limits(self, axis, rate_dps, accel_dps2):
        self._exchange(("limit_rate", "P", axis, rate_dps), ("limit_acceleration", "P", axis, accel_dps2))

    def _set_limits(self, axis, mode, rate_dps, accel_dps2):
        m = _LIMIT_MODE[mode]
        self._exchange(("limit_rate", m, axis, rate_dps), ("limit_acceleration", m, axis, accel_dps2))

    def _read_positions(self):
        return self._floats("read_position")

    def _read_rates(self):
        return self._floats("read_rate")

    def _status(self):
        self._exchange()
        return self._decode_status(self.last_status)

    def _decode_status(self, stb: int):
        closed = [bool(stb & P.STB_INTERLOCK_CLOSED[i]) for i in range(self.n_axes)]
        fault = [bool(stb & P.STB_FAULT[i]) for i in range(self.n_axes)]
        return closed, fault, stb

    def _read_state(self):
        answers = self._exchange(*[("read_position", a) for a in self.axes],
                                 *[("read_rate", a) for a in self.axes])
        try:
            pos = [C.command("read_position").reply.parse(x) for x in answers[:self.n_axes]]
            rates = [C.command("read_rate").reply.parse(x) for x in answers[self.n_axes:]]
        except ValueError as e:
            raise ProtocolError(self.name, f"bad answer to the position and rate queries: {e}") from None
        return (pos, rates, *self._decode_status(self.last_status))

    def _reset(self):
        self._exchange(("interlock_reset",))

    def _interlock(self, axis, close):
        self._exchange(("interlock_close" if close else "interlock_open", axis))

    def _set_mode(self, axis, mode):
        self._exchange((_MODE_CMD[mode], axis))

    def _demand_position(self, axis, position_deg):
        self._exchange(("demand_position", axis, position_deg))

    def _demand_rate(self, axis, rate_dps):
        self._exchange(("demand_rate", axis, rate_dps))

    def _halt(self, axis, mode):
        # rate mode with a zero demand: brakes at the rate-mode acceleration limit
        if mode == "rate":
            self._exchange(("demand_rate", axis, 0.0))
        elif mode != "off":
            self._exchange(("mode_rate", axis))

    def _after_halt(self, axis):
        self._exchange(("mode_position", axis))
