"""Driver for single-axis tables speaking the three-letter dialect (protocol ``aerosmith``).

Interlock = the servo (``SRV1``/``SRV0``); the rate-mode acceleration is ``ACL``; the dialect
has no fault-reset or rate-limit command: NotSupported (use the controller's front panel), and
the driver enforces its own rate limits.  9600 baud unless the settings say otherwise; the
command strings come from ``TableSettings.dialect`` over the defaults (docs/protocols.md says
which are public and which unverified).
"""
from __future__ import annotations

from .errors import LimitError, NotSupported, ProtocolError, TableFault
from .protocols import aerosmith as P
from .table import RateTable, TableSettings, TableStatus
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

    def _exchange(self, name: str, *values) -> str:
        """Send one command, return its reply line ('' if none); ProtocolError on ``?``."""
        C = self.commands
        text = C.format(name, *values)
        if self._rx:
            self._rx.clear()
        self.port.write(text.encode("ascii") + C.terminator.encode("ascii"))
        raw = self.port.read_until(P.PROMPT, None, repr(text), self._rx)
        reply = raw[:-len(P.PROMPT)].decode("ascii", "replace").strip()
        if reply == P.ERROR_REPLY:
            if name != "status":
                closed, fault, sta = self._status()
                if fault[0] or not closed[0]:       # refused because of the table's state
                    st = TableStatus((closed[0],), (fault[0],), tuple(self._modes), sta)
                    raise TableFault(self.name, f"{text!r} refused: {st.describe()}")
            raise ProtocolError(self.name, f"{text!r} refused ('?')")
        cmd = C.command(name)
        if cmd.is_query:
            try:
                return cmd.reply.parse(reply)
            except ValueError as e:
                raise ProtocolError(self.name, f"bad answer to {text!r}: {e}") from None
        if reply:
            raise ProtocolError(self.name, f"unexpected answer to {text!r}: {reply[:80]!r}")
        return ""

    # ---------------------------------------------------------------- protocol part
    def _identify(self) -> str:
        sta = self._exchange("status")
        return f"three-letter single-axis controller (STA {sta})"

    def _count_axes(self) -> int:
        return 1

    def _set_move_limits(self, axis, rate_dps, accel_dps2):
        pass        # set on the controller; the driver checks its own limits

    def _set_limits(self, axis, mode, rate_dps, accel_dps2):
        if mode != "rate":
            raise NotSupported(self.name, "the three-letter dialect has no position-mode limit "
                                          "commands: set them on the controller")
        self._exchange("acceleration", accel_dps2)      # the rate limit is the driver's own

    def _read_positions(self):
        return [self._exchange("position")]

    def _read_rates(self):
        return [self._exchange("velocity")]

    def _status(self):
        sta = self._exchange("status")
        return [bool(sta & P.STA_DRIVE_ENABLED)], [bool(sta & P.STA_FAULT)], sta

    def _reset(self):
        raise NotSupported(self.name, "the three-letter dialect cannot reset faults: reset them "
                                      "on the controller's front panel")

    def _interlock(self, axis, close):
        self._exchange("servo", 1 if close else 0)

    _halt_mode = "position"         # STO brakes to rest and holds there

    def _set_mode(self, axis, mode, demand):
        # the dialect's motion commands carry their demand: JOG<rate>, MOV<position>
        if mode == "rate":
            self._exchange("jog", demand)
        else:
            self._exchange("move", demand)

    def _demand_position(self, axis, position_deg):
        self._exchange("move", position_deg)

    def _demand_rate(self, axis, rate_dps):
        self._exchange("jog", rate_dps)

    def _halt(self, axis, mode):
        self._exchange("stop")

    def _after_halt(self, axis, position_deg):
        pass            # STO holds where the axis came to rest
