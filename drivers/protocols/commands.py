"""Command tables: each command of a line protocol written down once, as data.

A :class:`CommandSet` both formats the driver's commands and parses what a twin receives,
so the driver and its twin cannot drift apart (the pyvisa-sim idea).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field


@dataclass(frozen=True)
class Arg:
    """One argument or reply value.

    ``kind``: ``axis`` (integer >= 1), ``int``, ``float`` (finite), ``choice`` (one of
    ``choices``, case-insensitive) or ``text``.  ``unit`` documents the value (deg, dps, ...).
    """

    name: str
    kind: str
    unit: str = ""
    choices: tuple[str, ...] = ()
    decimals: int = 6
    doc: str = ""
    compact: bool = False      # float: a whole number written as an integer ("90", not "90.0000")

    def format(self, value) -> str:
        if self.kind in ("axis", "int"):
            return str(int(value))
        if self.kind == "float":
            x = float(value)
            if not math.isfinite(x):
                raise ValueError(f"{self.name}: not a finite number: {value!r}")
            if self.compact and x == round(x) and abs(x) < 1e12:
                return str(int(round(x)))
            return f"{x:.{self.decimals}f}"
        if self.kind == "choice":
            s = str(value).upper()
            if s not in self.choices:
                raise ValueError(f"{self.name}: must be one of {', '.join(self.choices)}")
            return s
        return str(value)

    def parse(self, text: str):
        """The value of ``text``; ValueError when it is not one."""
        s = text.strip()
        if self.kind in ("axis", "int"):
            if not s or len(s) > 12 or not s.lstrip("+-").isdigit():
                raise ValueError(f"{self.name}: not an integer: {s!r}")
            v = int(s)
            if self.kind == "axis" and v < 1:
                raise ValueError(f"{self.name}: axes count from 1, got {v}")
            return v
        if self.kind == "float":
            if not s or len(s) > 40:
                raise ValueError(f"{self.name}: not a number: {s!r}")
            v = float(s)
            if not math.isfinite(v):
                raise ValueError(f"{self.name}: not a finite number: {s!r}")
            return v
        if self.kind == "choice":
            u = s.upper()
            if u not in self.choices:
                raise ValueError(f"{self.name}: must be one of {', '.join(self.choices)}, got {s!r}")
            return u
        return s


@dataclass(frozen=True)
class Command:
    """One command: ``header`` then the ``args`` (a query when ``reply`` is set)."""

    name: str
    header: str
    args: tuple[Arg, ...] = ()
    reply: Arg | None = None
    doc: str = ""
    example: tuple[str, str | None] | None = None   # (sent, answered) for the docs

    @property
    def is_query(self) -> bool:
        return self.reply is not None


@dataclass(frozen=True)
class CommandSet:
    """A protocol's commands and how they are written on the line.

    ``header_sep`` separates the header from the first argument (``" "`` for SCPI, ``""``
    for the three-letter dialect), ``arg_sep`` the arguments, ``chain`` several commands on
    one line (SCPI ``;``; empty: one command a line).  ``terminator`` ends a command line.
    """

    name: str
    commands: tuple[Command, ...]
    header_sep: str = " "
    arg_sep: str = ","
    chain: str = ""
    terminator: str = "\n"
    header_length: int | None = None       # fixed-length headers (three-letter dialect)
    _by_name: dict = field(default=None, init=False, repr=False, compare=False)
    _by_header: dict = field(default=None, init=False, repr=False, compare=False)

    def __post_init__(self):
        object.__setattr__(self, "_by_name", {c.name: c for c in self.commands})
        object.__setattr__(self, "_by_header", {c.header.upper(): c for c in self.commands})

    def command(self, name: str) -> Command:
        return self._by_name[name]

    def format(self, name: str, *values) -> str:
        """The text of command ``name`` with ``values`` (no terminator)."""
        cmd = self._by_name[name]
        if len(values) != len(cmd.args):
            raise TypeError(f"{name} takes {len(cmd.args)} values, got {len(values)}")
        if not cmd.args:
            return cmd.header
        return cmd.header + self.header_sep + self.arg_sep.join(
            a.format(v) for a, v in zip(cmd.args, values))

    def parse(self, text: str) -> tuple[Command, list]:
        """(command, argument values) of one command's text; ValueError if it is not one."""
        s = text.strip()
        if self.header_length is not None:
            head, rest = s[:self.header_length], s[self.header_length:]
        elif self.header_sep and self.header_sep in s:
            head, rest = s.split(self.header_sep, 1)
        else:
            head, rest = s, ""
        cmd = self._by_header.get(head.strip().upper())
        if cmd is None:
            raise ValueError(f"unknown command {head[:40]!r}")
        rest = rest.strip()
        if not cmd.args:
            if rest:
                raise ValueError(f"{cmd.header} takes no arguments")
            return cmd, []
        parts = rest.split(self.arg_sep) if (self.arg_sep and len(cmd.args) > 1) else [rest]
        if len(parts) != len(cmd.args):
            raise ValueError(f"{cmd.header} takes {len(cmd.args)} arguments, got {len(parts)}")
        return cmd, [a.parse(p) for a, p in zip(cmd.args, parts)]

    def split_line(self, line: str) -> list[str]:
        """The commands chained on one line."""
        parts = line.split(self.chain) if self.chain else [line]
        return [p for p in (q.strip() for q in parts) if p]
