"""The three-letter ASCII dialect of single-axis rate tables (protocol ``aerosmith``).

A command is three letters, the number (if any) written right after them, ended by ``\\r``.
The controller answers with zero or one reply line (``\\r\\n``-ended), then the prompt ``>``.
A command it cannot execute is answered ``?`` (then the prompt).

What public material supports (``SOURCES``): the three-letter commands HOM, JOG, STO, SRV
(servo on/off), ACL (acceleration), CLU, CAL, REX of a public Python client of Ideal Aerosmith
tables (its ``ACLCommands``), and 9600 baud.  MOV, PPO, PVE and STA, the reply format, the
prompt and the status bits are **unverified**: every command string is data, and
:func:`dialect` builds the command set with other strings (``TableSettings.dialect``).
"""
from __future__ import annotations

from .commands import Arg, Command, CommandSet

COMMANDS = CommandSet(
    name="aerosmith", header_sep="", arg_sep="", chain="", terminator="\r", header_length=3,
    commands=(
        Command("home", "HOM", doc="move to 0 deg (position mode) at the position-mode limits",
                example=("HOM", None)),
        Command("move", "MOV", (Arg("position_deg", "float", "deg", decimals=4),),
                doc="move to a position, deg (position mode), the shortest way round",
                example=("MOV90.0000", None)),
        Command("jog", "JOG", (Arg("rate_dps", "float", "deg/s", decimals=4),),
                doc="turn at a rate, deg/s (rate mode)", example=("JOG-10.0000", None)),
        Command("stop", "STO", doc="controlled stop: brake to rest and hold there (position mode)",
                example=("STO", None)),
        Command("servo", "SRV", (Arg("on", "int"),), doc="servo (drive) on (1) or off (0)",
                example=("SRV1", None)),
        Command("acceleration", "ACL", (Arg("accel_dps2", "float", "deg/s^2", decimals=4),),
                doc="acceleration of JOG and moves, deg/s²", example=("ACL100.0000", None)),
        Command("position", "PPO", reply=Arg("position_deg", "float", "deg", decimals=4),
                doc="print position, deg in [0, 360)", example=("PPO", "90.0001")),
        Command("velocity", "PVE", reply=Arg("rate_dps", "float", "deg/s", decimals=4),
                doc="print velocity, deg/s", example=("PVE", "-10.0000")),
        Command("status", "STA", reply=Arg("status", "int"),
                doc="status word, decimal (bits below)", example=("STA", "9")),
    ),
)

#: where each command string comes from: "public" (a public client of Ideal Aerosmith tables:
#: HOM, JOG, STO, SRV, ACL) or "unverified" (no public material found)
SOURCES = {"home": "public", "jog": "public", "stop": "public", "servo": "public",
           "acceleration": "public", "move": "unverified", "position": "unverified",
           "velocity": "unverified", "status": "unverified"}
#: default line settings of the dialect: 9600 baud (public scripts)
DEFAULT_BAUD = 9600


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
ERROR_REPLY = "?"
REPLY_END = "\r\n"

# --- status word (STA) -------------------------------------------------------------------------
STA_DRIVE_ENABLED = 0x01     # interlock closed, axis powered
STA_FAULT = 0x02             # fault latched (cleared on the controller's front panel)
STA_IN_MOTION = 0x04
STA_RATE_MODE = 0x08         # JOG active (else position mode / holding)
