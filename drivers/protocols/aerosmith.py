"""The three-letter ASCII dialect of single-axis rate tables (protocol ``aerosmith``).

Public source: ``IdealAerosmithTable`` in actigraph/RateTableSweepGUI (``RateSweepGUI.py``), a
Python client of an Ideal Aerosmith rate table (model not named in it).  What it shows:

* a command is three letters with its number written right after them (``%d`` for
  ``ACL JOG MOV RMO VEL ZER MCO PER CYC``, ``%f`` for ``HOF AMP FRQ``), sent as ``CMD\\r\\n``;
  pyserial's defaults, so 9600 baud 8N1;
* ``request()`` reads two lines, each ended by ``\\r`` (it strips what surrounds them): the
  reply (the value for ``PPO``, ``PVE``, ``STA``, ``MCO``), then the prompt;
* ``jog()`` (``JOG``) and ``start()`` (``SGO``) write without reading, and the next request
  first sends ``STA`` and reads two lines; ``stop()`` writes ``STO`` with no terminator at
  all, reads nothing and sleeps 1 s.

Framing here (the twin's, the driver reads both variants below): every command is answered by
one reply line (empty for a command without a value) and the prompt line ``>``, each ended by
``\\r\\n`` (the client needs the ``\\r``; the ``\\n`` after it is the twin's choice, the client
strips it): ``PPO`` → ``90.0001\\r\\n>\\r\\n``, ``ACL100`` → ``\\r\\n>\\r\\n``.  The client, if
it is right, also allows that ``JOG``, ``SGO`` and ``STO`` are not answered at all
(``SILENT_COMMANDS``): the twin can serve that variant, and the driver follows each motion
command by ``STA`` so that it reads either.  **Unverified**: the ``\\n``, the prompt's
character ``>`` (the client only counts the line), the ``?`` refusal, the ``STA`` bits, the
position range and decimals, ``SRV`` and what a command does beyond its name.  Every command
string is data: :func:`dialect` builds the command set with other strings
(``TableSettings.dialect``).
"""
from __future__ import annotations

from .commands import Arg, Command, CommandSet


def _num(name, unit):
    """A number the client writes with ``%d``: whole values go out the same way; a fraction
    is written with 4 decimals (**unverified**: the client never sends one)."""
    return Arg(name, "float", unit, decimals=4, compact=True)


COMMANDS = CommandSet(
    name="aerosmith", header_sep="", arg_sep="", chain="", terminator="\r", header_length=3,
    commands=(
        Command("home", "HOM", doc="home: move to 0 deg (position mode)", example=("HOM", "")),
        Command("move", "MOV", (_num("position_deg", "deg"),),
                doc="move to a position, deg (position mode), the shortest way round",
                example=("MOV90", "")),
        Command("jog", "JOG", (_num("rate_dps", "deg/s"),),
                doc="turn at a rate, deg/s (rate mode)", example=("JOG-10", "")),
        Command("stop", "STO", doc="stop", example=("STO", "")),
        Command("servo", "SRV", (Arg("on", "int"),), doc="servo (drive) on (1) or off (0)",
                example=("SRV1", "")),
        Command("acceleration", "ACL", (_num("accel_dps2", "deg/s^2"),),
                doc="acceleration of JOG, deg/s²", example=("ACL100", "")),
        Command("velocity_limit", "VEL", (_num("rate_dps", "deg/s"),),
                doc="velocity of moves (position mode), deg/s", example=("VEL60", "")),
        Command("motion_complete", "MCO", (Arg("tolerance", "int"),),
                reply=Arg("complete", "int"),
                doc="1 when the motion is complete (at rest; in position mode within the "
                    "tolerance of the target), else 0", example=("MCO1", "1")),
        Command("position", "PPO", reply=Arg("position_deg", "float", "deg", decimals=4),
                doc="print position, deg", example=("PPO", "90.0001")),
        Command("velocity", "PVE", reply=Arg("rate_dps", "float", "deg/s", decimals=4),
                doc="print velocity, deg/s", example=("PVE", "-10.0000")),
        Command("status", "STA", reply=Arg("status", "int"),
                doc="status word, decimal (bits below: unverified)", example=("STA", "9")),
    ),
)

#: where each command comes from: the client's method (actigraph/RateTableSweepGUI,
#: RateSweepGUI.py, class IdealAerosmithTable) and what it shows of the argument, or
#: "unverified" (no public source found)
CLIENT = "actigraph/RateTableSweepGUI RateSweepGUI.py IdealAerosmithTable"
SOURCES = {
    "home": "public: home() sends HOM (request)",
    "move": "public: move(position) sends MOV%d (request); units of position unverified (deg assumed)",
    "jog": "public: jog(degreesPerSecond) sends JOG%d, no reply read",
    "stop": "public: stop() sends STO with no terminator, no reply read",
    "servo": "unverified: SRV is in no public client found in this search; SRV as the interlock is unverified",
    "acceleration": "public: setAcceleration(degreesPerSecondSquared) sends ACL%d (request)",
    "velocity_limit": "public: setVelocity(degreesPerSecond) sends VEL%d (request); position-mode use unverified",
    "motion_complete": "public: isMoving(tolerance=1) sends MCO%d, '1' = not moving (request)",
    "position": "public: getPosition() = float(request('PPO')); range unverified",
    "velocity": "public: getVelocity() = float(request('PVE'))",
    "status": "public: getStatus() = int(request('STA')); the bits are unverified",
}
#: commands the client uses that are not in COMMANDS (the twin answers them ``?``)
CLIENT_ONLY = {"DIR": "setDirection(clockwise) DIR1/DIR0", "HOF": "setHomeOffset(degrees) HOF%f",
               "RMO": "relationalMove(position) RMO%d", "SAV": "saveSettings() SAV",
               "ZER": "setZero(degrees) ZER%d", "AMP": "setAmplitude(degrees) AMP%f",
               "FRQ": "setFrequency(hertz) FRQ%f", "PER": "setPeriod(seconds) PER%d",
               "CYC": "setNumberOfCycles(cycles) CYC%d", "SGO": "start() SGO, no reply read"}
#: default line settings of the dialect: 9600 baud (the client opens serial.Serial(port):
#: pyserial's default 9600 8N1)
DEFAULT_BAUD = 9600
#: the commands the client writes without reading an answer: maybe not answered at all
SILENT_COMMANDS = ("JOG", "STO", "SGO")


def dialect(overrides=()) -> CommandSet:
    """The command set with some command strings replaced: ``(("move", "MPA"), ...)``
    (three letters each).  ValueError for an unknown command or a malformed string."""
    overrides = dict(overrides)
    unknown = set(overrides) - {c.name for c in COMMANDS.commands}
    if unknown:
        raise ValueError(f"unknown aerosmith commands {sorted(unknown)} (known: "
                         f"{', '.join(c.name for c in COMMANDS.commands)})")
    for name, header in overrides.items():
        if not (isinstance(header, str) and len(header) == 3 and header.isalnum()):
            raise ValueError(f"aerosmith command {name!r}: {header!r} is not three letters or digits")
    if not overrides:
        return COMMANDS
    from dataclasses import replace
    cmds = tuple(replace(c, header=overrides.get(c.name, c.header).upper()) for c in COMMANDS.commands)
    if len({c.header for c in cmds}) != len(cmds):
        raise ValueError("aerosmith dialect: two commands with the same string")
    return replace(COMMANDS, commands=cmds)


PROMPT = b">"
ERROR_REPLY = "?"            # unverified
LINE_END = b"\r\n"           # the \r is the client's; the \n the twin's choice
REPLY_END = "\r\n"


def answer(reply: str = "") -> bytes:
    """The bytes of one answer: the reply line, then the prompt line."""
    return reply.encode("ascii") + LINE_END + PROMPT + LINE_END


#: notes appended to the driver's messages where they rest on an unverified rule
UNVERIFIED_STA = "(unverified: STA bit assignment)"
UNVERIFIED_REFUSAL = "(unverified: '?' as the refusal)"

# --- status word (STA): unverified ---------------------------------------------------------------
STA_DRIVE_ENABLED = 0x01     # servo on
STA_FAULT = 0x02             # fault latched (cleared on the controller's front panel)
STA_IN_MOTION = 0x04
STA_RATE_MODE = 0x08         # JOG active (else position mode / holding)
