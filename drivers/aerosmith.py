"""Driver for single-axis tables speaking the three-letter dialect (protocol ``aerosmith``).

Framing as the public client shows it (``drivers/protocols/aerosmith.py``): every command is
sent terminated (``\\r``; never a bare ``STO``), its answer is a reply line then a prompt line,
each ended by ``\\r``.  ``JOG`` and ``STO`` may not be answered at all (the client never reads
their answer): the driver sends ``STA`` right after each and reads until ``STA``'s number, so
it works either way.

No stale demand (docs/protocols.md): rate mode is entered by ``JOG0`` (its own demand), position
mode by ``MOV`` to the measured position, and the stop is ``JOG0`` (brake at the ``ACL``
acceleration), then, at rest, ``MOV`` to the measured position; ``STO`` only if ``JOG0`` is
refused.  Interlock = the servo (``SRV1``/``SRV0``, unverified); the rate-mode acceleration is
``ACL``, the position-mode velocity ``VEL`` (set at connect); the dialect has no fault-reset,
position-mode acceleration or rate-limit command: NotSupported (use the controller's front
panel), and the driver enforces its own rate limits.  9600 baud unless the settings say
otherwise; the command strings come from ``TableSettings.dialect`` over the defaults.
"""
from __future__ import annotations

from .errors import LimitError, NotSupported, ProtocolError, TableFault
from .protocols import aerosmith as P
from .table import RateTable, TableSettings, TableStatus, wrap_deg
from .transport import SerialSettings


class AerosmithTable(RateTable):
    protocol = "aerosmith"

    def __init__(self, url, settings=None):
        super().__init__(url, settings or TableSettings(serial=SerialSettings(baudrate=P.DEFAULT_BAUD)))
        self._rx = bytearray()
        try:
            self.commands = P.dialect(self.settings.dialect)
        except ValueError as e:
            raise LimitError(self.name, str(e)) from None

    # ---------------------------------------------------------------- line
    def _send(self, text: str) -> None:
        self.port.write(text.encode("ascii") + self.commands.terminator.encode("ascii"))

    def _read_answer(self, what: str) -> str:
        """One answer: the reply line (returned, stripped), then the prompt line."""
        reply = self.port.read_until(b"\r", None, repr(what), self._rx)
        self.port.read_until(b"\r", None, repr(what), self._rx)        # the prompt
        return reply.decode("ascii", "replace").strip()

    def _exchange(self, name: str, *values):
        """Send one command, return its value ('' for a command without one)."""
        text = self.commands.format(name, *values)
        self._rx.clear()
        self._send(text)
        reply = self._read_answer(text)
        if reply == P.ERROR_REPLY:
            self._refused(text, name)
        return self._value(name, text, reply)

    def _motion(self, name: str, *values) -> None:
        """A command that may not be answered (JOG, STO), followed by ``STA``: reads its
        answer if there is one, then STA's; TableFault when STA says the drive is off."""
        C = self.commands
        text = C.format(name, *values)
        sta_text = C.format("status")
        self._rx.clear()
        self._send(text)
        self._send(sta_text)
        first = self._read_answer(text)
        refused = False
        try:
            sta = C.command("status").reply.parse(first)       # no answer to the command
        except ValueError:
            refused = first == P.ERROR_REPLY
            if first and not refused:
                raise ProtocolError(self.name, f"unexpected answer to {text!r}: {first[:80]!r}") from None
            sta = self._value("status", sta_text, self._read_answer(sta_text))
        closed, fault = bool(sta & P.STA_DRIVE_ENABLED), bool(sta & P.STA_FAULT)
        if fault or not closed:
            st = TableStatus((closed,), (fault,), tuple(self._modes), sta)
            how = "refused" if refused else "not executed"
            raise TableFault(self.name, f"{text!r} {how}: {st.describe()} {P.UNVERIFIED_STA}")
        if refused:
            raise ProtocolError(self.name, f"{text!r} refused ('?') {P.UNVERIFIED_REFUSAL}")

    def _refused(self, text: str, name: str):
        if name != "status":
            closed, fault, sta = self._status()
            if fault[0] or not closed[0]:       # refused because of the table's state
                st = TableStatus((closed[0],), (fault[0],), tuple(self._modes), sta)
                raise TableFault(self.name, f"{text!r} refused: {st.describe()} {P.UNVERIFIED_STA}")
        raise ProtocolError(self.name, f"{text!r} refused ('?') {P.UNVERIFIED_REFUSAL}")

    def _value(self, name: str, text: str, reply: str):
        cmd = self.commands.command(name)
        if cmd.is_query:
            try:
                return cmd.reply.parse(reply)
            except ValueError as e:
                raise ProtocolError(self.name, f"bad answer to {text!r}: {e}") from None
        if reply:
            raise ProtocolError(self.name, f"unexpected answer to {text!r}: {reply[:80]!r}")
        return ""

    # ---------------------------------------------------------------- messages
    def _poll(self, axes):
        try:
            return super()._poll(axes)
        except TableFault as e:            # read from the STA bits
            raise TableFault(self.name, f"{e.message} {P.UNVERIFIED_STA}") from None

    def check_ok(self) -> TableStatus:
        try:
            return super().check_ok()
        except TableFault as e:
            raise TableFault(self.name, f"{e.message} {P.UNVERIFIED_STA}") from None

    # ---------------------------------------------------------------- protocol part
    def _identify(self) -> str:
        sta = self._exchange("status")
        return f"three-letter single-axis controller (STA {sta})"

    def _count_axes(self) -> int:
        return 1

    def _set_move_limits(self, axis, rate_dps, accel_dps2):
        self._exchange("velocity_limit", rate_dps)      # no position-mode acceleration command

    def _set_limits(self, axis, mode, rate_dps, accel_dps2):
        if mode != "rate":
            raise NotSupported(self.name, "the three-letter dialect has no position-mode "
                                          "acceleration command (VEL, the move velocity, is set "
                                          "at connect from AxisLimits.move_rate_dps): set it on "
                                          "the controller")
        self._exchange("acceleration", accel_dps2)      # the rate limit is the driver's own

    def _read_positions(self):
        return [float(wrap_deg(self._exchange("position")))]    # range unverified: wrapped

    def _read_rates(self):
        return [self._exchange("velocity")]

    def _status(self):
        sta = self._exchange("status")
        return [bool(sta & P.STA_DRIVE_ENABLED)], [bool(sta & P.STA_FAULT)], sta

    def _reset(self):
        raise NotSupported(self.name, "the three-letter dialect cannot reset faults: reset them "
                                      "on the controller's front panel")

    _closed_mode = "rate"

    def _interlock(self, axis, close, hold_deg):
        self._exchange("servo", 1 if close else 0)
        if close:
            # what SRV1 servoes to is unverified (a stored JOG or MOV could resume): JOG0 at
            # once, so that the axis holds zero rate whatever the controller kept
            self._motion("jog", 0.0)

    def _set_mode(self, axis, mode, demand):
        # the dialect's motion commands carry their demand: JOG<rate>, MOV<position>
        if mode == "rate":
            self._motion("jog", demand)
        elif mode == "position":
            self._exchange("move", demand)
        else:
            raise NotSupported(self.name, "the three-letter dialect has no servo-off mode "
                                          "(SRV0 opens the interlock)")

    def _demand_position(self, axis, position_deg):
        self._exchange("move", position_deg)

    def _demand_rate(self, axis, rate_dps):
        self._motion("jog", rate_dps)

    _halt_mode = "rate"             # JOG0

    def _halt(self, axis, mode):
        try:
            self._motion("jog", 0)              # brake at ACL, whatever the mode
        except ProtocolError:
            self._motion("stop")                # last resort: what STO holds is unverified

    # _after_halt: the base's, MOV to the rest position (position mode entered by its demand)
