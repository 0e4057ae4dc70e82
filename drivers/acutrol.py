"""Driver for Acutronic ACUTROL3000 controllers (the Acutrol Command Language, TM-8004), 1-3 axes.

The transport and the reply framing are chosen by the port URL (docs/protocols.md):

* any pyserial URL (``/dev/ttyUSB0`` through the DE-311 converter of TM-9411,
  ``socket://192.168.53.1:9878`` as in TM-9384C): framing ``tcp``: every message is answered,
  an error code and a length first;
* ``visa://GPIB0::1::INSTR`` (pyvisa, backend pyvisa-py): framing ``gpib``: only queries are
  answered; the driver ends each message with ``*STB?`` so that every message gets an answer
  and an error (bit 7 of the status byte: the error queue is not empty) is seen at once; the
  queue is emptied at connect (``*CLS``) and by reading it after each refusal;
  ``visa://TCPIP0::host::9878::SOCKET`` uses the ``tcp`` framing;
* ``#gpib`` or ``#tcp`` at the end of any URL chooses the framing explicitly.
"""
from __future__ import annotations

import time

from .errors import DeviceTimeout, ProtocolError, TableFault
from .protocols import acutrol as P
from .table import RateTable, TableStatus
from .transport import Port
from .visa_port import SCHEME as VISA, VisaPort

#: how long a line is left to go quiet when a stale reply was found at connect (s): a reply in
#: flight when its program died arrives within the controller's reply time
STALE_REPLY_S = 0.5
_MODE_CMD = {"position": "mode_position", "rate": "mode_rate"}
_LIMIT_MODE = {"position": "P", "rate": "R"}
_MODE_NAME = {"P": "position", "R": "rate", "A": "rate", "O": "off"}


def split_url(url: str) -> tuple[str, str]:
    """(transport URL, framing) of a port URL with an optional ``#tcp``/``#gpib``."""
    base, sep, frag = url.rpartition("#")
    if sep and frag.lower() in P.FRAMINGS:
        return base, frag.lower()
    if url.startswith(VISA) and url[len(VISA):].upper().startswith("GPIB"):
        return url, "gpib"
    return url, "tcp"


class AcutrolTable(RateTable):
    protocol = "acutrol"

    def __init__(self, url, settings=None):
        super().__init__(url, settings)
        self.transport_url, self.framing = split_url(url)
        self._rx = bytearray()
        self.last_status = 0

    def _open_port(self):
        if self.transport_url.startswith(VISA):
            return VisaPort(self.transport_url[len(VISA):], self.settings.serial, self.name, self.log)
        return Port(self.transport_url, self.settings.serial, self.name, self.log)

    # ---------------------------------------------------------------- the exchange
    def _exchange(self, *commands: tuple) -> list[str]:
        """Send ``commands`` ((key, *values) each) as one message; the answers of its queries.

        A refused command is a TableFault when an interlock is open or a fault latched (the
        controller's state explains it), a ProtocolError otherwise."""
        texts = [P.format_command(key, *values) for key, *values in commands]
        n_queries = sum(P.BY_KEY[key].query != "no" for key, *_ in commands)
        if self.framing == "gpib":
            if not commands or commands[-1][0] != "stb":
                texts.append(P.BY_KEY["stb"].text)
                n_queries += 1
            line = ";".join(texts)
            answers, error = self._exchange_gpib(line)
        else:
            line = ";".join(texts)
            answers, error = self._exchange_tcp(line, n_queries)
        if error is not None:
            self._refused(line, error)
        if len(answers) != n_queries:
            raise ProtocolError(self.name, f"{n_queries} answers expected to {line!r}, got {len(answers)}: "
                                           f"{';'.join(answers)[:80]!r}")
        if self.framing == "gpib" and commands and commands[-1][0] != "stb":
            answers = answers[:-1]
        return answers

    def _exchange_gpib(self, line: str):
        self._rx.clear()
        self.port.write(line.encode("ascii") + b"\n")
        reply = self.port.read_until(b"\n", None, repr(line), self._rx)
        answers = reply.decode("ascii", "replace").strip().split(";")
        try:
            stb = int(answers[-1])
        except ValueError:
            raise ProtocolError(self.name, f"status byte expected at the end of the reply to "
                                           f"{line!r}, got {reply[:80]!r}") from None
        self.last_status = stb
        if stb & P.STB_EQ:
            self._rx.clear()
            ask = P.format_command("status_msg", "QERROR", "ALL")
            self.port.write(ask.encode("ascii") + b"\n")
            text = self.port.read_until(b"\n", None, ask, self._rx).decode("ascii", "replace").strip()
            errors = [m.partition(",") for m in text.split(";") if m]
            return answers, "; ".join(f"error {c}: {t}" for c, _, t in errors) or "error queue empty"
        return answers, None

    def _exchange_tcp(self, line: str, n_queries: int):
        self._rx.clear()
        self.port.write(line.encode("ascii") + b"\r\n")
        head = self.port.read_exact(P.RESPONSE_HEADER.size, None, repr(line), self._rx)
        code, length = P.RESPONSE_HEADER.unpack(head)
        if length > P.MAX_MESSAGE:
            raise ProtocolError(self.name, f"reply to {line!r} announces {length} bytes (error code {code})")
        data = self.port.read_exact(length, None, repr(line), self._rx).decode("ascii", "replace").strip()
        if code != P.ERR_NONE:
            return [], f"error {code}: {data}"
        if n_queries == 0:
            if data != P.OK:
                raise ProtocolError(self.name, f"'OK' expected in reply to {line!r}, got {data[:80]!r}")
            return [], None
        return data.split(";"), None

    def _refused(self, line: str, error: str):
        if self.n_axes and not line.startswith(":Interlock?"):
            try:
                closed, fault, stb = self._status()
            except ProtocolError:
                closed, fault, stb = [True], [False], self.last_status
            if any(fault) or not all(closed):     # refused because of the table's state
                st = TableStatus(tuple(closed), tuple(fault), tuple(self._modes), stb)
                raise TableFault(self.name, f"{line!r} refused ({error}): {st.describe()}")
        raise ProtocolError(self.name, f"{line!r} refused ({error})")

    def _floats(self, key: str) -> list[float]:
        return self._parse_floats(self._exchange(*[(key, axis) for axis in self.axes]), key)

    def _parse_floats(self, answers, what: str) -> list[float]:
        try:
            return [float(a) for a in answers]
        except ValueError:
            raise ProtocolError(self.name, f"bad answer to {what}: {';'.join(answers)[:80]!r}") from None

    # ---------------------------------------------------------------- protocol part
    def _identify(self) -> str:
        """``*IDN?`` twice: the same answer both times, or the line held a reply that an earlier
        program never read (it died mid-exchange, e.g. a run killed while its guardian
        connects): then the line is left to go quiet, cleared, and asked again."""
        try:
            first, second = (self._ask_identity() for _ in range(2))
        except (ProtocolError, DeviceTimeout):
            first, second = None, ""
        if first != second:
            self.log.warning("%s: a stale reply on the line at connect: resynchronising", self.name)
            time.sleep(STALE_REPLY_S)
            self._rx.clear()
            self.port.discard_input()
            first, second = (self._ask_identity() for _ in range(2))
            if first != second:
                raise ProtocolError(self.name, f"*IDN? answered {first[:40]!r}, then {second[:40]!r}")
        return second

    def _ask_identity(self) -> str:
        if self.framing == "gpib":
            # bit 7 of the status byte stays set while the error queue holds messages
            # (TM-8004 §4.11.4), so messages left by an earlier session would read as a refusal
            # of every message: *CLS empties the queue first (§3.1)
            return self._exchange(("cls",), ("idn",))[0]
        return self._exchange(("idn",))[0]

    def _count_axes(self) -> int:
        answer = self._exchange(("query_system",))[0]
        try:
            n = int(answer.split(",")[0])
        except ValueError:
            raise ProtocolError(self.name, f"bad answer to :Query:System?: {answer[:80]!r}") from None
        if n < 1:
            raise ProtocolError(self.name, "the controller has no axis")
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

    def read_accelerations_dps2(self) -> list[float]:
        """Measured angular accelerations of all axes, deg/s² (``:Read:Acceleration?``)."""
        return self._floats("read_acceleration")

    def read_modes(self) -> list[str]:
        """The controller's servo mode of every axis (``:Mode? n``): position, rate, off, ..."""
        answers = self._exchange(*[("mode_query", a) for a in self.axes])
        return [_MODE_NAME.get(a.strip()[:1].upper(), a.strip().lower()) for a in answers]

    def _interlocks(self, answers):
        states = [a.strip().capitalize() for a in answers]
        if any(s not in P.INTERLOCK_STATES for s in states):
            raise ProtocolError(self.name, f"bad answer to :Interlock?: {';'.join(answers)[:80]!r}")
        return [s == "Close" for s in states], [s == "Fault" for s in states]

    def _status(self):
        answers = self._exchange(*[("interlock_state", a) for a in self.axes], ("stb",))
        closed, fault = self._interlocks(answers[:-1])
        try:
            self.last_status = int(answers[-1])
        except ValueError:
            raise ProtocolError(self.name, f"bad status byte {answers[-1][:20]!r}") from None
        return closed, fault, self.last_status

    def _read_state(self):
        n = self.n_axes
        answers = self._exchange(*[("read_position", a) for a in self.axes],
                                 *[("read_rate", a) for a in self.axes],
                                 *[("interlock_state", a) for a in self.axes])
        pos = self._parse_floats(answers[:n], "the position queries")
        rates = self._parse_floats(answers[n:2 * n], "the rate queries")
        closed, fault = self._interlocks(answers[2 * n:])
        return pos, rates, closed, fault, self.last_status

    def _reset(self):
        self._exchange(("interlock_reset",))

    def _interlock(self, axis, close, hold_deg):
        if not close:
            self._exchange(("interlock_open", axis))
            return
        # one message: harmless demands for every mode, Off selected ("no demands affect Off
        # Mode", §4.7.3), then the close that servoes the axis in it (§4.5.6's order)
        self._exchange(("demand_rate", axis, 0.0), ("demand_position", axis, hold_deg),
                       ("mode_off", axis), ("interlock_close", axis))

    _DEMAND = {"position": "demand_position", "rate": "demand_rate"}
    _halt_mode = "rate"

    def _set_mode(self, axis, mode, demand):
        # one message, the demand first: ":Demand:Rate 1,0.000000;:Mode:Rate 1" (the controller
        # executes the loaded demand on entering the mode; docs/protocols.md)
        self._exchange((self._DEMAND[mode], axis, demand), (_MODE_CMD[mode], axis))

    def _demand_position(self, axis, position_deg):
        self._exchange(("demand_position", axis, position_deg))

    def _demand_rate(self, axis, rate_dps):
        self._exchange(("demand_rate", axis, rate_dps))

    def _halt(self, axis, mode):
        # a zero rate demand, then rate mode, whatever mode the axis is in: it brakes at the
        # rate-mode acceleration limit and cannot resume an earlier rate demand
        self._set_mode(axis, "rate", 0.0)
