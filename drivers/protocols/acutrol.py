"""The SCPI-style command language of Acutronic Acutrol controllers: the subset used here.

Commands are keywords of a colon tree, case-insensitive, the axis (1 = outermost) as first
argument, arguments separated by ``,``, several commands chained with ``;`` on one line ended
by ``\\n``.  Only queries answer: one line with their answers joined by ``;``.  A command the
controller cannot execute sets the command-error bit of the status byte; the driver ends
every line with ``*STB?`` so that each line gets an answer and each error is seen at once.
"""
from __future__ import annotations

from .commands import Arg, Command, CommandSet

AXIS = Arg("axis", "axis", doc="axis number, 1 = outermost")
MODE = Arg("mode", "choice", choices=("P", "R"), doc="P: position-mode limit, R: rate-mode limit")

COMMANDS = CommandSet(
    name="acutrol", header_sep=" ", arg_sep=",", chain=";", terminator="\n",
    commands=(
        Command("identify", "*IDN?", reply=Arg("identity", "text"),
                doc="manufacturer, model, serial number, firmware",
                example=("*IDN?", "Acutronic,ACUTROL3000-SIM,3AX-0001,3.1.0")),
        Command("status_byte", "*STB?", reply=Arg("status", "int"),
                doc="status byte (bits below); reading it clears the command-error bit",
                example=("*STB?", "7")),
        Command("interlock_reset", ":Interlock:Reset",
                doc="clear latched faults; tripped interlocks stay open until closed again",
                example=(":Interlock:Reset;*STB?", "0")),
        Command("interlock_close", ":Interlock:Close", (AXIS,),
                doc="close the axis interlock (power the axis); refused while a fault is latched",
                example=(":Interlock:Close 1;*STB?", "1")),
        Command("interlock_open", ":Interlock:Open", (AXIS,),
                doc="open the axis interlock: the axis brakes to rest and is unpowered",
                example=(":Interlock:Open 1;*STB?", "0")),
        Command("mode_position", ":Mode:Position", (AXIS,),
                doc="position mode, holding the present position; needs a closed interlock",
                example=(":Mode:Position 2;*STB?", "3")),
        Command("mode_rate", ":Mode:Rate", (AXIS,),
                doc="rate mode, the rate demand set to 0; needs a closed interlock",
                example=(":Mode:Rate 1;*STB?", "3")),
        Command("mode_off", ":Mode:Off", (AXIS,),
                doc="servo off: the axis brakes to rest and is not held",
                example=(":Mode:Off 1;*STB?", "3")),
        Command("demand_position", ":Demand:Position",
                (AXIS, Arg("position_deg", "float", "deg", decimals=6)),
                doc="position demand (position mode): reached the shortest way round, within "
                    "the position-mode rate and acceleration limits",
                example=(":Demand:Position 2,90.000000;*STB?", "3")),
        Command("demand_rate", ":Demand:Rate",
                (AXIS, Arg("rate_dps", "float", "deg/s", decimals=6)),
                doc="rate demand (rate mode), reached within the rate-mode acceleration limit",
                example=(":Demand:Rate 1,-10.000000;*STB?", "3")),
        Command("limit_rate", ":Limit:Rate", (MODE, AXIS, Arg("rate_dps", "float", "deg/s")),
                doc="rate limit of a mode (P or R) for the axis; at most the axis hardware limit",
                example=(":Limit:Rate P,1,50.000000;*STB?", "3")),
        Command("limit_acceleration", ":Limit:Acceleration",
                (MODE, AXIS, Arg("accel_dps2", "float", "deg/s^2")),
                doc="acceleration limit of a mode (P or R) for the axis",
                example=(":Limit:Acceleration P,1,100.000000;*STB?", "3")),
        Command("read_position", ":Read:Position?", (AXIS,),
                reply=Arg("position_deg", "float", "deg", decimals=6),
                doc="encoder position, deg in [0, 360)",
                example=(":Read:Position? 1;:Read:Position? 2;*STB?", "0.000000;90.000012;3")),
        Command("read_rate", ":Read:Rate?", (AXIS,),
                reply=Arg("rate_dps", "float", "deg/s", decimals=6),
                doc="measured rate, deg/s",
                example=(":Read:Rate? 1;*STB?", "-10.000001;3")),
    ),
)

# --- status byte (*STB?) -----------------------------------------------------------------------
#: bit (n - 1): interlock of axis n closed (n = 1..3)
STB_INTERLOCK_CLOSED = (0x01, 0x02, 0x04)
#: bit (n + 2): fault latched on axis n (interlock tripped, drive fault); cleared by :Interlock:Reset
STB_FAULT = (0x08, 0x10, 0x20)
#: a command on this line (or since the last *STB?) could not be executed
STB_COMMAND_ERROR = 0x80
MAX_AXES = 3
