"""The Acutrol Command Language (ACL) of Acutronic ACUTROL3000 controllers: the subset used here.

Source: Acutronic TM-8004-C "ACUTROL3000 Command Language (ACL) Programming Manual" (§ numbers
below), TM-9384C (TCP/IP, port 9878) and TM-9411 (RS-232 through a MOXA DE-311 to that
port), and two public drivers (IEAv-EFO/acutrol3000 over pyvisa/GPIB, AcutronicRobotics/acutrol
over a TCP socket).  docs/protocols.md has the table, command by command, with its source.

Syntax (TM-8004 §2.1-2.4), written down once here and used by the driver to format and by the
twin to parse:

* a command is a colon path of mnemonics then, after white space, arguments separated by
  ``,``: ``:Demand:Position 3,10.5``; case-insensitive; a mnemonic may be shortened to any
  prefix of its long form (``:Dem:Pos``, ``:D:P``); where a prefix fits several mnemonics the
  first in :data:`COMMANDS` order wins (§2.1 warns about one-letter forms);
* several commands are chained with ``;``; one starting with ``:`` starts again from the root,
  one starting with ``*`` is a common command, any other continues under the subsystem of the
  previous command (``:Mode:Position 1;Rate 2``, ``:READ:POS? 1;POS 2;POS 3``) (§2.2.2, §2.3);
  the leading colon of the first command is optional (§2.3);
* a query ends its header with ``?``; the reads (``:Read:...``) answer without it too (§4.10,
  "for ACT2000 compatibility the ? is not required");
* ``ALL`` in place of the axis applies a command to every axis; a query with ``ALL`` is an
  error (§2.4);
* the answers of a message's queries are joined by ``;`` (§4.3.5 examples).
"""
from __future__ import annotations

import math
import struct
from dataclasses import dataclass

# ------------------------------------------------------------------------------ the commands


@dataclass(frozen=True)
class AclCommand:
    """One ACL command.  ``path``: long-form mnemonics (``("Read", "Position")``, or
    ``("*STB",)``); ``query``: ``"no"`` (a setting), ``"yes"`` (a query: ``?`` required) or
    ``"optional"`` (a read: ``?`` optional); ``args``: kinds of the arguments (``axis``,
    ``axis_all`` (an axis or ALL), ``float``, ``mode`` (a servo mode, §4.7), ``word``);
    ``optional_args``: how many trailing arguments may be left out."""

    key: str
    path: tuple[str, ...]
    query: str = "no"
    args: tuple[str, ...] = ()
    optional_args: int = 0
    source: str = ""
    doc: str = ""

    @property
    def text(self) -> str:
        """The long form of the header, ``:Read:Position?``."""
        head = self.path[0] if self.path[0].startswith("*") else ":" + ":".join(self.path)
        return head + ("?" if self.query != "no" else "")


COMMANDS: tuple[AclCommand, ...] = (
    AclCommand("idn", ("*IDN",), "yes", source="TM-8004 §3.4", doc="identification"),
    AclCommand("stb", ("*STB",), "yes", source="TM-8004 §3.10",
               doc="status byte; reading it clears it"),
    AclCommand("esr", ("*ESR",), "yes", source="TM-8004 §3.3",
               doc="standard event status register; reading it clears it"),
    AclCommand("ese", ("*ESE",), "no", ("float",), source="TM-8004 §3.2",
               doc="standard event status enable register"),
    AclCommand("ese_query", ("*ESE",), "yes", source="TM-8004 §3.2"),
    AclCommand("cls", ("*CLS",), "no", source="TM-8004 §3.1",
               doc="clear the status byte, the event register and the error queue"),
    AclCommand("sre", ("*SRE",), "no", ("float",), source="TM-8004 §3.9",
               doc="service request enable register: the status bits that set MSS (bit 6)"),
    AclCommand("sre_query", ("*SRE",), "yes", source="TM-8004 §3.9"),
    # Configure (§4.2): the oscillator settings, kept and reported (synthesis is not simulated)
    AclCommand("configure_oscillator", ("Configure", "Oscillator"), "no",
               ("axis", "word", "float", "float", "word", "word"), source="TM-8004 §4.2.19",
               doc="<axis>,<Enable|Disable>,<amp_slew>,<freq_slew>,<Pos|Rate|Accel>,<Log|Lin>"),
    AclCommand("configure_oscillator_query", ("Configure", "Oscillator"), "optional", ("axis",),
               source="TM-8004 §4.2.19 (the example reads without ?); IEAv-EFO (:con:osc? 1)",
               doc="Enable|Disable, amp_slew, freq_slew, amp_mode, freq_mode"),
    # Demand (§4.3)
    AclCommand("demand_position", ("Demand", "Position"), "no", ("axis", "float"),
               source="TM-8004 §4.3.5", doc="position demand, deg (position mode)"),
    AclCommand("demand_position_query", ("Demand", "Position"), "yes", ("axis",),
               source="TM-8004 §4.3.5"),
    AclCommand("demand_rate", ("Demand", "Rate"), "no", ("axis", "float"),
               source="TM-8004 §4.3.6", doc="rate demand, deg/s (rate mode)"),
    AclCommand("demand_rate_query", ("Demand", "Rate"), "yes", ("axis",), source="TM-8004 §4.3.6"),
    AclCommand("demand_delta", ("Demand", "DeltaPosition"), "no", ("axis", "float"),
               source="TM-8004 §4.3.2; IEAv-EFO driver (:dem:delta)",
               doc="change the position demand by a step, deg"),
    AclCommand("demand_delta_query", ("Demand", "DeltaPosition"), "yes", ("axis",),
               source="TM-8004 §4.3.2", doc="the last step received, deg"),
    AclCommand("demand_oscillator", ("Demand", "Oscillator"), "no", ("axis", "float", "float", "float"),
               source="TM-8004 §4.3.4; IEAv-EFO driver (:dem:osc)",
               doc="synthesis demand: magnitude, frequency Hz, phase deg (kept; synthesis not simulated)"),
    AclCommand("demand_oscillator_query", ("Demand", "Oscillator"), "yes", ("axis",),
               source="TM-8004 §4.3.4", doc="magnitude;frequency;phase"),
    # Interlock (§4.5): Close before Configure/Control so that :I:C is Close (§4.5.1 example)
    AclCommand("interlock_close", ("Interlock", "Close"), "no", ("axis_all",),
               source="TM-8004 §4.5.1", doc="close the interlock and servo the axis"),
    AclCommand("interlock_open", ("Interlock", "Open"), "no", ("axis_all",),
               source="TM-8004 §4.5.5", doc="shut the axis down in an orderly fashion"),
    AclCommand("interlock_reset", ("Interlock", "Reset"), "no", ("axis_all",), optional_args=1,
               source="TM-8004 §4.5.6 (no argument); AcutronicRobotics driver sends an axis",
               doc="clear the frozen (latched) interlock faults of all axes"),
    AclCommand("interlock_state", ("Interlock",), "yes", ("axis",),
               source="IEAv-EFO driver (:interlock? 1 -> Fault); answers as §4.5.3",
               doc="Close, Open or Fault"),
    AclCommand("interlock_control_query", ("Interlock", "Control"), "yes", ("axis",),
               source="TM-8004 §4.5.3", doc="Close, Open or Fault"),
    # Limit (§4.6): <axis|ALL>,<mode>,<rate>,<acc>,<jerk> on the subsystem node itself
    AclCommand("limit_set", ("Limit",), "no", ("axis_all", "mode", "float", "float", "float"),
               source="TM-8004 §4.6; IEAv-EFO routine_example.cfg (:limit ALL,P,100,100,1)",
               doc="rate, acceleration and jerk limits of a mode"),
    # Acceleration before Absolute (:LIM:H P,4,180.0;...;A P,4,2000.0, §4.6.2)
    AclCommand("limit_acceleration", ("Limit", "Acceleration"), "no", ("mode", "axis_all", "float"),
               source="TM-8004 §4.6.2", doc="acceleration limit of a mode, deg/s²"),
    AclCommand("limit_acceleration_query", ("Limit", "Acceleration"), "yes", ("mode", "axis"),
               source="TM-8004 §4.6.2"),
    AclCommand("limit_rate", ("Limit", "Rate"), "no", ("mode", "axis_all", "float"),
               source="TM-8004 §4.6.8", doc="rate limit of a mode, deg/s"),
    AclCommand("limit_rate_query", ("Limit", "Rate"), "yes", ("mode", "axis"), source="TM-8004 §4.6.8"),
    AclCommand("limit_absolute_query", ("Limit", "Absolute"), "yes", ("axis",),
               source="TM-8004 §4.6.1; IEAv-EFO driver (:limit:absolute? 1)",
               doc="factory limits: rate, acceleration, jerk, low and high position, velocity trip"),
    # High/LowPosition after Absolute/Acceleration (:L:A stays Acceleration); the manual's
    # forms: <mode>,<axis>,<limit> and <axis>,<limit> (:L:H 1,-180), queries <mode>,<axis>
    # (:LIM:HPOS? P,3) and <axis> (:L:H? 2); HPOS/LPOS are the short forms (SHORT_FORMS)
    AclCommand("limit_high", ("Limit", "HighPosition"), "no", ("mode", "axis_all", "float"),
               source="TM-8004 §4.6.6", doc="high position limit of a mode, deg"),
    AclCommand("limit_high_axis", ("Limit", "HighPosition"), "no", ("axis_all", "float"),
               source="TM-8004 §4.6.6 (:L:H 1,-180)", doc="high position limit, position mode"),
    AclCommand("limit_high_query", ("Limit", "HighPosition"), "yes", ("mode", "axis"),
               source="TM-8004 §4.6.6 (:LIM:HPOS? P,3)"),
    AclCommand("limit_high_axis_query", ("Limit", "HighPosition"), "yes", ("axis",),
               source="TM-8004 §4.6.6 (:L:H? 2)", doc="position mode's"),
    AclCommand("limit_low", ("Limit", "LowPosition"), "no", ("mode", "axis_all", "float"),
               source="TM-8004 §4.6.7", doc="low position limit of a mode, deg"),
    AclCommand("limit_low_axis", ("Limit", "LowPosition"), "no", ("axis_all", "float"),
               source="TM-8004 §4.6.7 (as §4.6.6)", doc="low position limit, position mode"),
    AclCommand("limit_low_query", ("Limit", "LowPosition"), "yes", ("mode", "axis"),
               source="TM-8004 §4.6.7 (:LIM:LPOS? P,3)"),
    AclCommand("limit_low_axis_query", ("Limit", "LowPosition"), "yes", ("axis",),
               source="TM-8004 §4.6.7 (:L:L? 2)", doc="position mode's"),
    # Mode (§4.7)
    AclCommand("mode_position", ("Mode", "Position"), "no", ("axis_all",), source="TM-8004 §4.7.4"),
    AclCommand("mode_rate", ("Mode", "Rate"), "no", ("axis_all",), source="TM-8004 §4.7.5"),
    AclCommand("mode_off", ("Mode", "Off"), "no", ("axis_all",), source="TM-8004 §4.7.3",
               doc="rate mode with demand 0: a controlled stop, held at zero rate"),
    AclCommand("mode_arate", ("Mode", "Arate"), "no", ("axis_all",), source="TM-8004 §4.7.1",
               doc="absolute rate mode: refused by the twin (not simulated)"),
    AclCommand("mode_synthesis", ("Mode", "Synthesis"), "no", ("axis_all",),
               source="TM-8004 §4.7.6; IEAv-EFO (:mode:synt 1)",
               doc="synthesis mode: refused by the twin (not simulated)"),
    AclCommand("mode_track", ("Mode", "Track"), "no", ("axis_all",), source="TM-8004 §4.7.7",
               doc="track mode: refused by the twin (not simulated)"),
    AclCommand("mode_set", ("Mode",), "no", ("axis_all", "mode"), source="TM-8004 §4.7",
               doc=":Mode <axis|ALL>,<mode>"),
    AclCommand("mode_query", ("Mode",), "yes", ("axis",), source="TM-8004 §4.7",
               doc="the servo mode of an axis"),
    # Query (§4.9)
    AclCommand("query_system", ("Query", "System"), "yes", source="TM-8004 §4.9.2",
               doc="number of axes, first axis, ..., last axis"),
    AclCommand("query_error", ("Query", "Error"), "yes", ("word",), source="TM-8004 §4.9.1",
               doc="the description of an error code"),
    # Read (§4.10): the ? is optional
    AclCommand("read_acceleration", ("Read", "Acceleration"), "optional", ("axis",),
               source="TM-8004 §4.10.1", doc="acceleration, deg/s²"),
    AclCommand("read_position", ("Read", "Position"), "optional", ("axis",),
               source="TM-8004 §4.10.4", doc="position, deg"),
    AclCommand("read_rate", ("Read", "Rate"), "optional", ("axis",), source="TM-8004 §4.10.5",
               doc="rate, deg/s"),
    AclCommand("read_variable", ("Read", "Variable"), "optional", ("word",) * 8, optional_args=7,
               source="TM-8004 §4.10.3 (:R:V 3100, :R:V? 1021;V? 2083); numbers TM-9374A",
               doc="system variables x000, x001, x082, x083, x163, x176 (x = axis); up to 8"),
    # Status (§4.11)
    AclCommand("status_stb", ("Status", "STB"), "yes", source="TM-8004 §4.11.6",
               doc="the status byte without clearing it"),
    AclCommand("status_msg", ("Status", "MSG"), "yes", ("word", "word"), optional_args=1,
               source="TM-8004 §4.11.4 (answer format: twin's, unverified)",
               doc="messages of a queue (QERROR: the error queue), read and removed"),
    AclCommand("status_msgclr", ("Status", "MSGCLr"), "no", ("word",), source="TM-8004 §4.11.5"),
    # Utility (§4.14)
    AclCommand("utility_format", ("Utility", "Format"), "no", ("word",),
               source="TM-8004 §4.14.1; williamsea/Acutrol (:u:f f)",
               doc="response format: FLOat only here (BINary is not implemented)"),
    AclCommand("utility_format_query", ("Utility", "Format"), "yes", source="TM-8004 §4.14.1 (:U:F? -> FLOAT)"),
    AclCommand("utility_lockout", ("Utility", "Lockoutmode"), "no", ("word",),
               source="TM-8004 §4.14.2; AcutronicRobotics driver (:utility:lockout on)",
               doc="front-panel lockout ON|OFF: kept, no other effect in the twin"),
    AclCommand("utility_lockout_query", ("Utility", "Lockoutmode"), "yes",
               source="TM-8004 §4.14.2 (:U:L? -> OFF)"),
)

BY_KEY = {c.key: c for c in COMMANDS}

#: short forms that are not prefixes of the long form: the capitals of the manual's headings
#: ("High POSition", "Low POSition", TM-8004 §4.6.6/§4.6.7), used in its examples
#: (:LIM:HPOS P,2,179.0, :LIM:LPOS? P,3)
SHORT_FORMS = {"HIGHPOSITION": ("HPOS",), "LOWPOSITION": ("LPOS",)}

#: servo modes (TM-8004 §4.7), in the order one-letter forms resolve ("A" is Arate)
MODES = ("Position", "Rate", "Arate", "Synthesis", "Track", "Abort", "Off")
#: the limit-mode letter of each servo mode (TM-8004 §4.6)
MODE_LETTER = {"Position": "P", "Rate": "R", "Arate": "R", "Synthesis": "S", "Track": "T",
               "Abort": "A", "Off": "O"}
#: :Interlock? answers (TM-8004 §4.5.3)
INTERLOCK_STATES = ("Close", "Open", "Fault")

# --- status byte (*STB?, TM-8004 §3.10): reading it with *STB? clears it --------------------------
STB_SI = 0x01     # bit 0: summary of the system interlocks (an axis interlock fault)
STB_ACP = 0x02    # bit 1: summary of the ACP processes
STB_SUP = 0x04    # bit 2: summary of the supervisor processes
STB_RI = 0x08     # bit 3: summary of the remote interfaces
STB_MAV = 0x10    # bit 4: message available in the output queue
STB_ESB = 0x20    # bit 5: an enabled standard event (*ESR & *ESE)
STB_MSS = 0x40    # bit 6: master summary status (any of the others)
STB_EQ = 0x80     # bit 7: the error message queue is not empty
STB_BITS = {0: "SI system interlock", 1: "ACP", 2: "SUP", 3: "RI", 4: "MAV", 5: "ESB",
            6: "MSS", 7: "EQ error queue"}

# --- standard event status register (*ESR?): bit assignment of IEEE 488.2, which TM-8004 §3.2
# and §4.11.2 refer to (the manual's own table is the Act2000 one) ----------------------------
ESR_QYE = 0x04    # query error
ESR_DDE = 0x08    # device-dependent error
ESR_EXE = 0x10    # execution error: parameter out of range, not possible in this state
ESR_CME = 0x20    # command error: not recognized, syntax

# --- error codes: TM-8004 §6.1 leaves the error queue "TBD"; these are the twin's (unverified)
ERR_NONE = 0
ERR_UNKNOWN = 1          # "command not recognized" (the wording the IEAv-EFO notes report)
ERR_SYNTAX = 2
ERR_RANGE = 3            # PARAMETER OUT OF RANGE (TM-8004, in every command's Errors)
ERR_ILLEGAL = 4          # ILLEGAL CMD (TM-8004 §4.1.3, .5): not possible in this state
ERR_QUERY_ALL = 5        # ALL in a query (TM-8004 §2.4)
ERROR_TEXT = {ERR_UNKNOWN: "command not recognized", ERR_SYNTAX: "syntax error",
              ERR_RANGE: "parameter out of range", ERR_ILLEGAL: "illegal command",
              ERR_QUERY_ALL: "ALL not allowed in a query"}
ERROR_ESR = {ERR_UNKNOWN: ESR_CME, ERR_SYNTAX: ESR_CME, ERR_RANGE: ESR_EXE,
             ERR_ILLEGAL: ESR_EXE, ERR_QUERY_ALL: ESR_CME}
MAX_AXES = 3
MAX_MESSAGE = 32768          # TM-8004 §2.5: up to 32K characters a message

# ------------------------------------------------------------------------------ framing
#: TCP port of the ACL server (TM-9384C §1; RS-232 reaches it through a DE-311, TM-9411 §4)
TCP_PORT = 9878
#: "The response includes an error code and a message length; this is prefixed to data"
#: (TM-8004 §2).  The AcutronicRobotics TCP driver drops the first 8 bytes of every answer and
#: expects "OK" after them for a command.  Layout assumed here (unverified): int32 error code,
#: int32 length of the data that follow, both little-endian ("least significant byte first",
#: TM-8004 §2.4).
RESPONSE_HEADER = struct.Struct("<iI")
OK = "OK"
FRAMINGS = ("tcp", "gpib")


class QueryText(str):
    """An answer that is text already (not a number to format)."""


def pack_response(error: int, data: str) -> bytes:
    raw = data.encode("ascii", "replace")
    return RESPONSE_HEADER.pack(int(error), len(raw)) + raw


# ------------------------------------------------------------------------------ parsing
class AclError(Exception):
    """A command of a message that cannot be executed: ``code`` is one of ``ERR_*``.
    ``base``: where the parser stands after it (the subsystem the next relative command of
    the message continues in, TM-8004 §2.3), when the header says; None when it does not."""

    def __init__(self, code: int, message: str = "", base: tuple[str, ...] | None = None):
        self.code = code
        self.base = base
        super().__init__(message or ERROR_TEXT.get(code, "error"))


@dataclass
class _Node:
    name: str
    children: dict          # upper-case long name -> _Node, in priority order
    commands: list          # AclCommands ending here


def _build_tree():
    root = _Node("", {}, [])
    for cmd in COMMANDS:
        if cmd.path[0].startswith("*"):
            continue
        node = root
        for name in cmd.path:
            node = node.children.setdefault(name.upper(), _Node(name, {}, []))
        node.commands.append(cmd)
    return root


_TREE = _build_tree()
_COMMON = {c.path[0]: [d for d in COMMANDS if d.path == c.path] for c in COMMANDS if c.path[0].startswith("*")}


def _resolve(node: _Node, mnemonic: str) -> _Node:
    m = mnemonic.upper()
    if not m or not m.isalnum():
        raise AclError(ERR_UNKNOWN, f"bad mnemonic {mnemonic[:20]!r}")
    for key, child in node.children.items():
        if key.startswith(m) or m in SHORT_FORMS.get(key, ()):
            return child
    raise AclError(ERR_UNKNOWN, f"{mnemonic[:20]!r} not recognized")


@dataclass(frozen=True)
class Parsed:
    command: AclCommand
    args: list
    is_query: bool
    base: tuple[str, ...]           # the subsystem the next relative command continues in


def split_message(text: str) -> list[str]:
    """The commands of one message (``;``-separated, blanks dropped)."""
    return [p.strip() for p in text.split(";") if p.strip()]


def parse_command(text: str, base: tuple[str, ...] = ()) -> Parsed:
    """One command of a message, relative to the subsystem ``base`` of the previous one.

    A refused command still moves the parser (TM-8004 §2.3: "the parser location can be found
    by finding the last colon before the last mnemonic in the compound header"): the
    :class:`AclError` carries in ``base`` the subsystem the next relative command continues in,
    so that one bad element of ``:LIM:H ...;L ...;R ...`` does not break the rest of the chain."""
    s = text.strip()
    head, _, rest = s.partition(" ")
    if "\t" in head:
        head, _, more = head.partition("\t")
        rest = more + " " + rest
    rest = rest.strip()
    is_query = head.endswith("?")
    if is_query:
        head = head[:-1]
    elif rest.startswith("?"):              # ":Read:Acceleration ?<axis>" (TM-8004 §4.10.1)
        is_query, rest = True, rest[1:].strip()
    if head.startswith("*"):
        candidates = _COMMON.get(head.upper())
        if not candidates:
            raise AclError(ERR_UNKNOWN, f"{head[:20]!r} not recognized", base)
        path, next_base = candidates[0].path, base
    else:
        absolute = head.startswith(":") or not base
        parts = head.lstrip(":").split(":") if head.strip(":") else []
        if not parts or any(not p for p in parts):
            raise AclError(ERR_SYNTAX, f"bad header {head[:40]!r}", None)
        start = () if absolute else tuple(base)
        node = _find_node(start)
        try:
            subsystem = [n.name for n in _path_nodes(node, parts[:-1])]
        except AclError as e:
            e.base = None                   # the subsystem itself is not known
            raise
        next_base = start + tuple(subsystem)
        try:
            last = _resolve(_find_node(next_base), parts[-1])
        except AclError as e:
            e.base = next_base
            raise
        candidates = last.commands
    try:
        cmd = _choose(candidates, is_query, head, rest)
        args = parse_args(cmd, rest)
    except AclError as e:
        e.base = next_base
        raise
    return Parsed(cmd, args, is_query, next_base)


def _path_nodes(node, parts):
    out = []
    for p in parts:
        node = _resolve(node, p)
        out.append(node)
    return out


def _find_node(path):
    node = _TREE
    for name in path:
        node = node.children[name.upper()]
    return node


def _choose(candidates, is_query: bool, head: str, rest: str = "") -> AclCommand:
    """The command a header stands for: query or not, then (where one header has several
    forms, :L:H P,1,90 and :L:H 1,-180) the first whose number of arguments fits."""
    fits = [c for c in candidates if c.query == "optional" or (c.query == "yes") == is_query]
    n = len(rest.split(",")) if rest else 0
    for c in fits:
        if len(c.args) - c.optional_args <= n <= len(c.args):
            return c
    if fits:
        return fits[0]
    raise AclError(ERR_UNKNOWN, f"{head[:40]!r}{'?' if is_query else ''} not recognized")


def parse_args(cmd: AclCommand, rest: str) -> list:
    parts = [p.strip() for p in rest.split(",")] if rest else []
    need = len(cmd.args)
    if not need - cmd.optional_args <= len(parts) <= need:
        raise AclError(ERR_SYNTAX, f"{cmd.text} takes {need} arguments, got {len(parts)}")
    return [_parse_arg(kind, p, cmd) for kind, p in zip(cmd.args, parts)]


def _parse_arg(kind: str, text: str, cmd: AclCommand):
    if not text or len(text) > 40:
        raise AclError(ERR_SYNTAX, f"{cmd.text}: empty or over-long argument")
    if kind in ("axis", "axis_all"):
        if text.upper() == "ALL":
            if kind == "axis" or cmd.query != "no":
                raise AclError(ERR_QUERY_ALL)
            return "ALL"
        if not text.isdigit():
            raise AclError(ERR_RANGE, f"{cmd.text}: bad axis {text!r}")
        return int(text)
    if kind == "float":
        try:
            v = float(text.replace(" ", ""))
        except ValueError:
            raise AclError(ERR_SYNTAX, f"{cmd.text}: not a number: {text!r}") from None
        if not math.isfinite(v):
            raise AclError(ERR_RANGE, f"{cmd.text}: not finite")
        return v
    if kind == "mode":
        return parse_mode(text)
    return text.upper()


def parse_mode(text: str) -> str:
    """The servo mode a word stands for (any prefix, case-insensitive, TM-8004 §2.7)."""
    t = text.strip().upper()
    for m in MODES:
        if t and m.upper().startswith(t):
            return m
    raise AclError(ERR_RANGE, f"unknown mode {text[:20]!r}")


def format_float(value: float) -> str:
    """<NR2> with 6 decimals (TM-8004 §2.6.1.4), never a leading + sign."""
    return f"{float(value):.6f}"


def format_command(key: str, *values) -> str:
    """The long form of a command with its arguments (the driver's side)."""
    cmd = BY_KEY[key]
    if not len(cmd.args) - cmd.optional_args <= len(values) <= len(cmd.args):
        raise TypeError(f"{key} takes {len(cmd.args)} values, got {len(values)}")
    vals = []
    for kind, v in zip(cmd.args, values):
        if kind == "float":
            x = float(v)
            if not math.isfinite(x):
                raise ValueError(f"{key}: not a finite number: {v!r}")
            vals.append(format_float(x))
        elif kind == "mode":
            parse_mode(str(v))              # checked; written as given (P, R, Position, ...)
            vals.append(str(v))
        else:
            vals.append(str(v))
    return cmd.text + (" " + ",".join(vals) if vals else "")
