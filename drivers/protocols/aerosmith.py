"""The three-letter ASCII dialect of single-axis rate tables (protocol ``aerosmith``).

A command is three letters, the number (if any) written right after them, ended by ``\\r``.
The controller answers with zero or one reply line (``\\r\\n``-ended), then the prompt ``>``.
A command it cannot execute is answered ``?`` (then the prompt).
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
        Command("position", "PPO", reply=Arg("position_deg", "float", "deg", decimals=4),
                doc="print position, deg in [0, 360)", example=("PPO", "90.0001")),
        Command("velocity", "PVE", reply=Arg("rate_dps", "float", "deg/s", decimals=4),
                doc="print velocity, deg/s", example=("PVE", "-10.0000")),
        Command("status", "STA", reply=Arg("status", "int"),
                doc="status word, decimal (bits below)", example=("STA", "9")),
    ),
)

PROMPT = b">"
ERROR_REPLY = "?"
REPLY_END = "\r\n"

# --- status word (STA) -------------------------------------------------------------------------
STA_DRIVE_ENABLED = 0x01     # interlock closed, axis powered
STA_FAULT = 0x02             # fault latched (cleared on the controller's front panel)
STA_IN_MOTION = 0x04
STA_RATE_MODE = 0x08         # JOG active (else position mode / holding)
