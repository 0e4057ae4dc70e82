"""Driver for single-axis tables speaking the three-letter dialect (protocol ``aerosmith``).

The dialect has no interlock, fault-reset or limit commands: the driver reports the
interlock and fault bits of ``STA``, refuses to change them (NotSupported: use the
controller's front panel) and enforces its own rate limits; the controller's move profile
limits are set on the controller.
"""
from __future__ import annotations

from .errors import NotSupported, ProtocolError, TableFault
from .protocols import aerosmith as P
from .table import RateTable, TableStatus

C = P.COMMANDS


class AerosmithTable(RateTable):
    protocol = "aerosmith"

    def __init__(self, url, settings=None):
        super().__init__(url, settings)
        self._rx = bytearray()

    def _exchange(self, name: str, *values) -> str:
        """Send one command, return its reply line ('' if none); ProtocolError on ``?``."""
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
        raise NotSupported(self.name, "the three-letter dialect has no limit commands: set the "
                                      "limits on the controller")

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
        closed, fault, _ = self._status()
        if close and closed[0] and not fault[0]:
            return
        raise NotSupported(self.name, f"the three-letter dialect cannot {'close' if close else 'open'} "
                                      "the interlock: use the controller's front panel")

    def _set_mode(self, axis, mode):
        if mode == "rate":
            self._exchange("jog", 0.0)
        elif mode == "position":
            self._exchange("stop")
        else:
            raise NotSupported(self.name, "the three-letter dialect has no servo-off command")

    def _demand_position(self, axis, position_deg):
        self._exchange("move", position_deg)

    def _demand_rate(self, axis, rate_dps):
        self._exchange("jog", rate_dps)

    def _halt(self, axis, mode):
        self._exchange("stop")
