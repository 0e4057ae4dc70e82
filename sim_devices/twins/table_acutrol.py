"""Acutrol (ACL, TM-8004) front-end of the table twin.

Parsing comes from ``drivers.protocols.acutrol`` (long and short forms, chaining, ``ALL``,
optional ``?`` of the reads); this module executes the commands on the :class:`TableTwin`
and keeps the controller's status: the status byte (``*STB?`` reads and clears its event
bits, ``:Status:STB?`` does not; bit 7 stays set while the error queue holds messages, bit 6
(MSS) summarises the bits enabled by ``*SRE``), the standard event status register
(``*ESR?``, ``*ESE``), the error queue (``:Status:MSG? QERROR``).  Answers are framed as chosen: ``tcp`` (TCP port 9878,
RS-232 through the DE-311: every message answered, error code and length first) or ``gpib``
(only queries answered, one line ended by ``\\n``).
"""
from __future__ import annotations

from collections import deque

from drivers.protocols import acutrol as P

from .lines import take_lines
from .table import CommandRefused, TableTwin

MAX_ERRORS = 32
#: power-up service request enable register: the system-interlock summary (bit 0) only.  The
#: manual gives no power-up value (unverified); this one makes both of its *STB? examples hold
#: (65: SI with MSS, 2: ACP without MSS, TM-8004 §3.10) and IEAv-EFO's check *stb? == 65.
SRE_POWER_UP = P.STB_SI
#: absolute (factory) position limits the twin reports (:Limit:Absolute?, TM-8004 §4.6.1)
ABS_LOW_DEG, ABS_HIGH_DEG = -180.0, 180.0
#: system variables (TM-8004 §4.10.3: axis * 1000 + number) the twin backs, with their source
VARIABLES = {0: "position demand (V_POSN_DMD x000, TM-9374A table 3-1)",
             1: "rate demand (V_RATE_DMD x001, TM-9374A table 3-1)",
             82: "estimated position (x082, TM-9374A fig. 2-2; TM-8004 §4.2.30 example 1082)",
             83: "estimated rate (x083, TM-9374A fig. 2-2)",
             163: "composite estimated position (V1163, TM-8004 §4.2.5 example)",
             176: "estimated acceleration (x176, TM-9374A fig. 2-2)"}
_OSC_SWITCH = ("Enable", "Disable")
_OSC_AMP = ("Position", "Rate", "Acceleration")
_OSC_FREQ = ("Logarithmic", "Linear")


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
        self._si_event = False
        self.esr = 0
        self.ese = 0
        self._faults_seen = [False] * table.n_axes
        self.other_limits: dict = {}        # (letter, axis) -> [rate, accel] for modes not simulated
        self.sre = SRE_POWER_UP
        self.position_limits: dict = {}     # (letter, axis) -> [low, high] deg (kept, see _pos_limits)
        self.jerk: dict = {}                # (letter, axis) -> jerk limit deg/s³ (kept, not simulated)
        self.last_delta = [0.0] * table.n_axes
        self.oscillator = [["Disable", 5.0, 0.1, "Position", "Logarithmic"] for _ in range(table.n_axes)]
        self.oscillator_demand = [[0.0, 0.0, 0.0] for _ in range(table.n_axes)]
        self.lockout = "OFF"
        t = table
        self.handlers = {
            "idn": t.identity, "stb": self._read_stb, "esr": self._read_esr, "ese": self._set_ese,
            "ese_query": lambda: self.ese, "cls": self._cls,
            "sre": self._set_sre, "sre_query": lambda: self.sre,
            "configure_oscillator": self._configure_oscillator,
            "configure_oscillator_query": self._oscillator_query,
            "demand_delta_query": lambda axis: self.last_delta[self._check(axis) - 1],
            "demand_oscillator": self._demand_oscillator,
            "demand_oscillator_query": self._demand_oscillator_query,
            "limit_set": self._limit_set,
            "limit_high": lambda m, a, v: self._set_pos_limit(m, a, high=v),
            "limit_high_axis": lambda a, v: self._set_pos_limit("Position", a, high=v),
            "limit_high_query": lambda m, a: self._pos_limits(m, a)[1],
            "limit_high_axis_query": lambda a: self._pos_limits("Position", a)[1],
            "limit_low": lambda m, a, v: self._set_pos_limit(m, a, low=v),
            "limit_low_axis": lambda a, v: self._set_pos_limit("Position", a, low=v),
            "limit_low_query": lambda m, a: self._pos_limits(m, a)[0],
            "limit_low_axis_query": lambda a: self._pos_limits("Position", a)[0],
            "read_variable": self._read_variables,
            "utility_format_query": lambda: P.QueryText("FLOAT"),
            "utility_lockout_query": lambda: P.QueryText(self.lockout),
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
            "mode_arate": self._axes(lambda a: self._mode(a, "Arate")),
            "mode_synthesis": self._axes(lambda a: self._mode(a, "Synthesis")),
            "mode_track": self._axes(lambda a: self._mode(a, "Track")),
            "mode_set": lambda axis, mode: self._axes(lambda a: self._mode(a, mode))(axis),
            "mode_query": self._mode_query,
            "query_system": self._system, "query_error": self._error_text,
            "read_acceleration": self._checked(t.read_acceleration),
            "read_position": self._checked(t.read_position),
            "read_rate": self._checked(t.read_rate),
            "status_stb": lambda: self._stb(clear=False), "status_msg": self._messages,
            "status_msgclr": lambda q: self.errors.clear(),
            "utility_format": self._format, "utility_lockout": self._set_lockout,
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
            except P.AclError as e:
                # the parser stays where the refused header put it (TM-8004 §2.3)
                base = e.base if e.base is not None else ()
                self._push(e.code, str(e))
                first_error = first_error or (e.code, str(e))
                continue
            base = parsed.base
            try:
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
        self.esr |= P.ERROR_ESR.get(code, P.ESR_DDE)

    def _note_faults(self) -> None:
        for i, ax in enumerate(self.table.axes):
            if ax.fault and not self._faults_seen[i]:
                self._si_event = True
            self._faults_seen[i] = ax.fault

    def _stb(self, clear: bool) -> int:
        """The status byte (TM-8004 §3.10, §4.11): SI while a fault is latched or since one
        occurred (cleared by reading); ESB for an enabled standard event; EQ while the error
        queue is not empty ("the status bit remains true as long as the queue is not empty",
        §4.11.4: reading the byte does not empty the queue); MSS when a bit enabled by *SRE
        is set ("at least one enabled event has occurred", §3.10)."""
        self._note_faults()
        stb = 0
        if self._si_event or any(ax.fault for ax in self.table.axes):
            stb |= P.STB_SI
        if self.esr & self.ese:
            stb |= P.STB_ESB
        if self.errors:
            stb |= P.STB_EQ
        if stb & self.sre & ~P.STB_MSS:
            stb |= P.STB_MSS
        if clear:
            self._si_event = False
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

    def _set_sre(self, value: float) -> None:
        v = round(value)
        if not 0 <= v <= 255:
            raise P.AclError(P.ERR_RANGE)
        self.sre = v & ~P.STB_MSS          # "bit 6 (RQS) cannot be set" (§3.9)

    def _cls(self) -> None:
        self.errors.clear()
        self.esr = 0
        self._si_event = False

    def _messages(self, qid: str, count: str = "ALL"):
        if qid.upper() not in ("QERROR", "QALL"):
            raise P.AclError(P.ERR_RANGE, f"queue {qid!r} not kept by the twin")
        n = len(self.errors) if "ALL".startswith(count.upper()) else _int(count)
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
        """The mode's letter, as the manual's examples answer (:MODE? 2 -> P, :M? 1;:M? 2;:M? 3
        -> P;R;P, TM-8004 §4.7); Off is O, its limit-mode letter (§4.6)."""
        mode = self.table.axes[self._check(axis) - 1].mode
        return P.QueryText({"position": "P", "rate": "R", "off": "O"}[mode])

    def _interlock_state(self, axis):
        ax = self.table.axes[self._check(axis) - 1]
        return P.QueryText("Fault" if ax.fault else "Close" if ax.interlock_closed else "Open")

    def _demand_delta(self, axis: int, delta_deg: float) -> None:
        ax = self.table.axes[axis - 1]
        self.table.demand_position(axis, ax.demand_deg + delta_deg)
        self.last_delta[axis - 1] = float(delta_deg)

    def _demand_oscillator(self, axis, magnitude: float, frequency_hz: float, phase_deg: float) -> None:
        a = self._check(axis)
        if magnitude < 0.0:
            raise P.AclError(P.ERR_RANGE, "negative oscillator magnitude")
        if frequency_hz < 0.0:
            raise P.AclError(P.ERR_RANGE, "negative oscillator frequency")
        self.oscillator_demand[a - 1] = [float(magnitude), float(frequency_hz), float(phase_deg)]

    def _demand_oscillator_query(self, axis):
        # "<magnitude><frequency><phase>", the example answers 10.000;2.5000;90.00000 (§4.3.4)
        return P.QueryText(";".join(P.format_float(v) for v in self.oscillator_demand[self._check(axis) - 1]))

    def _configure_oscillator(self, axis, switch, amp_slew, freq_slew, amp_mode, freq_mode) -> None:
        a = self._check(axis)
        values = [_word(switch, _OSC_SWITCH), float(amp_slew), float(freq_slew),
                  _word(amp_mode, _OSC_AMP), _word(freq_mode, _OSC_FREQ)]
        if amp_slew < 0.0 or freq_slew < 0.0:
            raise P.AclError(P.ERR_RANGE, "negative oscillator slew")
        self.oscillator[a - 1] = values

    def _oscillator_query(self, axis):
        # the §4.2.19 example answer: "Enable, 5.000000, 0.100000, Acceleration, Logarithmic"
        on, amp_slew, freq_slew, amp_mode, freq_mode = self.oscillator[self._check(axis) - 1]
        return P.QueryText(", ".join((on, P.format_float(amp_slew), P.format_float(freq_slew), amp_mode, freq_mode)))

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

    def _limit_set(self, axis, mode: str, rate: float, acc: float, jerk: float) -> None:
        """:Limit <axis|ALL>,<mode>,<rate>,<acc>,<jerk> (§4.6): all checked before any is set."""
        letter = self._letter(mode)
        targets = range(1, self.table.n_axes + 1) if axis == "ALL" else [self._check(axis)]
        for a in targets:
            max_rate, max_acc = self.table.axes[a - 1].hardware
            if not (0 < rate <= max_rate and 0 < acc <= max_acc and 0 < jerk <= 10 * max_acc):
                raise P.AclError(P.ERR_RANGE, "limit beyond the axis' absolute limit")
        for a in targets:
            self._set_limit(mode, a, rate_dps=rate, accel_dps2=acc)
            self.jerk[(letter, a)] = float(jerk)

    def _pos_limits(self, mode: str, axis) -> list:
        """[low, high] position limits of a mode, deg.  Kept and reported only: the twin's axes
        are continuous (moves take the shortest way round), and "this limit is used only if the
        ACP is set for LIMITED motion" (TM-8004 §4.6.6, §4.7.4)."""
        key = (self._letter(mode), self._check(axis))
        return self.position_limits.setdefault(key, [ABS_LOW_DEG, ABS_HIGH_DEG])

    def _set_pos_limit(self, mode: str, axis, low=None, high=None) -> None:
        targets = range(1, self.table.n_axes + 1) if axis == "ALL" else [self._check(axis)]
        value = low if high is None else high
        if not ABS_LOW_DEG <= value <= ABS_HIGH_DEG:     # limits on the limits (§4.6.1)
            raise P.AclError(P.ERR_RANGE, f"position limit {value} outside the absolute "
                                          f"[{ABS_LOW_DEG}, {ABS_HIGH_DEG}]")
        for a in targets:
            self._pos_limits(mode, a)[0 if high is None else 1] = float(value)

    def _read_variables(self, *numbers):
        out = []
        for text in numbers:
            v = _int(text)
            axis, number = divmod(v, 1000)
            if not 1 <= axis <= self.table.n_axes or number not in VARIABLES:
                raise P.AclError(P.ERR_RANGE, f"variable {v} not kept by the twin")
            t, ax = self.table, self.table.axes[axis - 1]
            value = {0: lambda: ax.demand_deg, 1: lambda: ax.rate_demand_dps,
                     82: lambda: t.read_position(axis), 163: lambda: t.read_position(axis),
                     83: lambda: t.read_rate(axis), 176: lambda: t.read_acceleration(axis)}[number]()
            out.append(P.format_float(value))
        return P.QueryText(",".join(out))

    def _set_lockout(self, word: str) -> None:
        if word.upper() not in ("ON", "OFF"):
            raise P.AclError(P.ERR_RANGE, "lockout is ON or OFF")
        self.lockout = word.upper()

    def _absolute(self, axis):
        rate, acc = self.table.axes[self._check(axis) - 1].hardware
        # rate, acceleration, jerk, low and high position, velocity trip (TM-8004 §4.6.1)
        return P.QueryText(",".join(P.format_float(v) for v in (rate, acc, 10 * acc, ABS_LOW_DEG, ABS_HIGH_DEG, 1.1 * rate)))

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


def _word(text: str, words) -> str:
    """The word of ``words`` that ``text`` abbreviates (``Disab`` is Disable, §4.2.19)."""
    t = str(text).strip().upper()
    for w in words:
        if t and w.upper().startswith(t):
            return w
    raise P.AclError(P.ERR_RANGE, f"{str(text)[:20]!r} is not one of {', '.join(words)}")


def _int(text: str) -> int:
    t = str(text).strip()
    if not t.lstrip("+-").isdigit() or len(t) > 9:
        raise P.AclError(P.ERR_RANGE, f"not an integer: {t[:20]!r}")
    return int(t)
