"""Acutrol (ACL, TM-8004) front-end of the table twin.

Parsing comes from ``drivers.protocols.acutrol`` (long and short forms, chaining, ``ALL``,
optional ``?`` of the reads); this module executes the commands on the :class:`TableTwin`
and keeps the controller's status: the status byte (``*STB?`` reads and clears it,
``:Status:STB?`` does not), the standard event status register (``*ESR?``, ``*ESE``), the
error queue (``:Status:MSG? QERROR``).  Answers are framed as chosen: ``tcp`` (TCP port 9878,
RS-232 through the DE-311: every message answered, error code and length first) or ``gpib``
(only queries answered, one line ended by ``\\n``).
"""
from __future__ import annotations

from collections import deque

from drivers.protocols import acutrol as P

from .lines import take_lines
from .table import CommandRefused, TableTwin

MAX_ERRORS = 32


class AcutrolFrontEnd:
    def __init__(self, table: TableTwin, framing: str = "tcp"):
        if table.n_axes > P.MAX_AXES:
            raise ValueError("acutrol tables have 1 to 3 axes")
        if framing not in P.FRAMINGS:
            raise ValueError(f"framing must be one of {P.FRAMINGS}")
        self.table = table
        self.framing = framing
        self._rx = bytearray()
        self.errors: deque = deque(maxlen=MAX_ERRORS)      # (code, text)
        self._eq_event = False
        self._si_event = False
        self.esr = 0
        self.ese = 0
        self._faults_seen = [False] * table.n_axes
        self.other_limits: dict = {}        # (letter, axis) -> [rate, accel] for modes not simulated
        t = table
        self.handlers = {
            "idn": t.identity, "stb": self._read_stb, "esr": self._read_esr, "ese": self._set_ese,
            "ese_query": lambda: self.ese, "cls": self._cls,
            "demand_position": self._axes(t.demand_position),
            "demand_position_query": self._demand_position_query,
            "demand_rate": self._axes(t.demand_rate),
            "demand_rate_query": self._demand_rate_query,
            "demand_delta": self._axes(self._demand_delta),
            "interlock_close": self._axes(t.interlock_close),
            "interlock_open": self._axes(t.interlock_open),
            "interlock_reset": lambda *axis: t.interlock_reset(),
            "interlock_state": self._interlock_state,
            "interlock_control_query": self._interlock_state,
            "limit_acceleration": lambda m, a, v: self._set_limit(m, a, accel_dps2=v),
            "limit_acceleration_query": lambda m, a: self._limit(m, a)[1],
            "limit_rate": lambda m, a, v: self._set_limit(m, a, rate_dps=v),
            "limit_rate_query": lambda m, a: self._limit(m, a)[0],
            "limit_absolute_query": self._absolute,
            "mode_position": self._axes(lambda a: self._mode(a, "Position")),
            "mode_rate": self._axes(lambda a: self._mode(a, "Rate")),
            "mode_off": self._axes(lambda a: self._mode(a, "Off")),
            "mode_set": lambda axis, mode: self._axes(lambda a: self._mode(a, mode))(axis),
            "mode_query": self._mode_query,
            "query_system": self._system, "query_error": self._error_text,
            "read_acceleration": self._checked(t.read_acceleration),
            "read_position": self._checked(t.read_position),
            "read_rate": self._checked(t.read_rate),
            "status_stb": lambda: self._stb(clear=False), "status_msg": self._messages,
            "status_msgclr": lambda q: self.errors.clear(),
            "utility_format": self._format, "utility_lockout": lambda v: None,
        }
        missing = set(P.BY_KEY) - set(self.handlers)
        assert not missing, f"no twin handler for {missing}"

    # ------------------------------------------------------------------ bytes in, bytes out
    def receive(self, data: bytes) -> bytes:
        """Execute the complete messages in ``data`` (ended by ``\\n``, ``\\r\\n``); the answers."""
        self._rx += data
        out = [self.execute(line) for line in take_lines(self._rx)]
        if len(self._rx) > P.MAX_MESSAGE:
            self._rx.clear()
            self._push(P.ERR_SYNTAX, "message longer than 32768 characters")
        return b"".join(out)

    def execute(self, line: bytes) -> bytes:
        text = line.decode("ascii", "replace").strip()
        answers, first_error = [], None
        if not text and self.framing == "gpib":
            return b""
        base: tuple = ()
        for part in P.split_message(text):
            try:
                parsed = P.parse_command(part, base)
                base = parsed.base
                value = self.handlers[parsed.command.key](*parsed.args)
            except P.AclError as e:
                self._push(e.code, str(e))
                first_error = first_error or (e.code, str(e))
                continue
            except CommandRefused as e:
                self._push(P.ERR_ILLEGAL, str(e))
                first_error = first_error or (P.ERR_ILLEGAL, str(e))
                continue
            if parsed.command.query != "no":
                answers.append(_format(value))
        if self.framing == "gpib":
            return (";".join(answers) + "\n").encode("ascii") if answers else b""
        code, data = (first_error if first_error else (P.ERR_NONE, P.OK))
        return P.pack_response(code, ";".join(answers) if answers else data)

    # ------------------------------------------------------------------ status
    def _push(self, code: int, text: str) -> None:
        self.errors.append((code, text.replace(";", ",")))
        self._eq_event = True
        self.esr |= P.ERROR_ESR.get(code, P.ESR_DDE)

    def _note_faults(self) -> None:
        for i, ax in enumerate(self.table.axes):
            if ax.fault and not self._faults_seen[i]:
                self._si_event = True
            self._faults_seen[i] = ax.fault

    def _stb(self, clear: bool) -> int:
        self._note_faults()
        stb = 0
        if self._si_event or any(ax.fault for ax in self.table.axes):
            stb |= P.STB_SI
        if self.esr & self.ese:
            stb |= P.STB_ESB
        if self._eq_event:
            stb |= P.STB_EQ
        if stb:
            stb |= P.STB_MSS
        if clear:
            self._si_event = self._eq_event = False
        return stb

    def _read_stb(self) -> int:
        return self._stb(clear=True)

    def _read_esr(self) -> int:
        v, self.esr = self.esr, 0
        return v

    def _set_ese(self, value: float) -> None:
        v = round(value)
        if not 0 <= v <= 255:
            raise P.AclError(P.ERR_RANGE)
        self.ese = v

    def _cls(self) -> None:
        self.errors.clear()
        self.esr = 0
        self._eq_event = self._si_event = False

    def _messages(self, qid: str, count: str = "ALL"):
        if qid.upper() not in ("QERROR", "QALL"):
            raise P.AclError(P.ERR_RANGE, f"queue {qid!r} not kept by the twin")
        n = len(self.errors) if count.upper() == "ALL" else _int(count)
        out = [f"{c},{t}" for c, t in (self.errors.popleft() for _ in range(min(n, len(self.errors))))]
        return P.QueryText(";".join(out))

    def _error_text(self, code: str):
        return P.QueryText(P.ERROR_TEXT.get(_int(code), "no error" if _int(code) == 0 else "unknown error"))

    # ------------------------------------------------------------------ axes
    def _axes(self, fn):
        """Apply ``fn(axis, *rest)`` to one axis or to ALL."""
        def run(axis, *rest):
            targets = range(1, self.table.n_axes + 1) if axis == "ALL" else [self._check(axis)]
            for a in targets:
                fn(a, *rest)
        return run

    def _checked(self, fn):
        return lambda axis: fn(self._check(axis))

    def _check(self, axis) -> int:
        if not isinstance(axis, int) or not 1 <= axis <= self.table.n_axes:
            raise P.AclError(P.ERR_RANGE, f"no axis {axis!r}")
        return axis

    def _mode(self, axis: int, mode: str) -> None:
        simulated = {"Position": "position", "Rate": "rate", "Off": "off"}
        if mode not in simulated:
            raise CommandRefused(f"{mode} mode is not simulated by the twin")
        self.table.set_mode(axis, simulated[mode])

    def _mode_query(self, axis):
        mode = self.table.axes[self._check(axis) - 1].mode
        return P.QueryText({"position": "Position", "rate": "Rate", "off": "Off"}[mode])

    def _interlock_state(self, axis):
        ax = self.table.axes[self._check(axis) - 1]
        return P.QueryText("Fault" if ax.fault else "Close" if ax.interlock_closed else "Open")

    def _demand_delta(self, axis: int, delta_deg: float) -> None:
        ax = self.table.axes[axis - 1]
        self.table.demand_position(axis, ax.demand_deg + delta_deg)

    def _demand_position_query(self, axis):
        return self.table.axes[self._check(axis) - 1].demand_deg

    def _demand_rate_query(self, axis):
        return self.table.axes[self._check(axis) - 1].rate_demand_dps

    def _letter(self, mode: str) -> str:
        return P.MODE_LETTER[mode]

    def _set_limit(self, mode: str, axis, **kw) -> None:
        letter = self._letter(mode)
        targets = range(1, self.table.n_axes + 1) if axis == "ALL" else [self._check(axis)]
        for a in targets:
            if letter in ("P", "R"):
                try:
                    self.table.set_limit(letter, a, **kw)
                except CommandRefused as e:
                    raise P.AclError(P.ERR_RANGE, str(e)) from None
                continue
            max_rate, max_acc = self.table.axes[a - 1].hardware
            lim = self.other_limits.setdefault((letter, a), [max_rate, max_acc])
            rate, acc = kw.get("rate_dps"), kw.get("accel_dps2")
            if (rate is not None and not 0 < rate <= max_rate) or (acc is not None and not 0 < acc <= max_acc):
                raise P.AclError(P.ERR_RANGE, "limit beyond the axis' absolute limit")
            lim[0] = lim[0] if rate is None else rate
            lim[1] = lim[1] if acc is None else acc

    def _limit(self, mode: str, axis) -> tuple[float, float]:
        letter, a = self._letter(mode), self._check(axis)
        if letter in ("P", "R"):
            return tuple(self.table.axes[a - 1].limits[letter])
        return tuple(self.other_limits.get((letter, a), self.table.axes[a - 1].hardware))

    def _absolute(self, axis):
        rate, acc = self.table.axes[self._check(axis) - 1].hardware
        # rate, acceleration, jerk, low and high position, velocity trip (TM-8004 §4.6.1)
        return P.QueryText(",".join(P.format_float(v) for v in (rate, acc, 10 * acc, -180.0, 180.0, 1.1 * rate)))

    def _system(self):
        n = self.table.n_axes
        return P.QueryText(",".join(str(v) for v in (n, *range(1, n + 1))))

    def _format(self, word: str) -> None:
        if not "FLOAT".startswith(word.strip().upper()):
            raise CommandRefused("only the FLOat response format is simulated")


def _format(value) -> str:
    if isinstance(value, P.QueryText):
        return str(value)
    if isinstance(value, bool):
        return "1" if value else "0"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return P.format_float(value)
    return str(value)


def _int(text: str) -> int:
    t = str(text).strip()
    if not t.lstrip("+-").isdigit() or len(t) > 9:
        raise P.AclError(P.ERR_RANGE, f"not an integer: {t[:20]!r}")
    return int(t)
