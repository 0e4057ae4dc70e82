"""The temperature chamber's front panel, served on a pseudo-terminal (``station sim serve
--chamber``): where the operator of a manual chamber sets it.

A manual chamber is set by hand at its own panel; the station asks the operator to set it and
waits (station/bench/sequencer.py, the chamber step).  On the device twins the panel is a
pseudo-terminal that takes one command a line (ASCII, ended by a line feed or carriage return),
so that an operator at a shell sets it with ``echo 60 > PANEL`` and a test writes the same:

    60 | SET 60      set the chamber to 60 degC now: its air ramps there (silent: nothing to read
                     for a writer that never reads; the serving program says it on its console)
    SET?             the setpoint in force ("none": never set, the room's air), degC
    AIR?             the chamber's air temperature now, degC
    anything else    "ERR <why>"

The panel answers the commands it has just been given: what it said before and nobody read (the
``ERR`` of an ``echo hello > PANEL``, whose writer never reads) is dropped when the next command
comes, so that a reader who asks ``SET?`` reads the answer to ``SET?``.  (A real serial line loses
what is sent while no program has the port open; the twin keeps the pseudo-terminal open, so the
panel drops it itself.)  Ask, read the answer, ask again: commands sent together in one write
are answered together, in order.

The physics is the dry run's (sim_devices/chamber.py ChamberAir): the air ramps at the chamber's
own rate (``--chamber-ramp-c-per-min``, its heater and cooler; the station's ``chamber:
ramp_c_per_min`` is the station's belief about it) and every IMU on the table follows the air as
a first-order lag plus its warm-up (sim_devices/truth.py TemperatureTruth.at).  Setpoints
outside the chamber's range are refused (``ERR``), as a real controller refuses them.
"""
from __future__ import annotations

import math

from .lines import take_lines
from .pty import PtyEndpoint


class ChamberPanel:
    """The panel's line protocol over a :class:`ChamberAir` (device time from the serving loop)."""

    def __init__(self, air, ramp_c_per_min: float, range_c=(-70.0, 180.0), said=None):
        self.air = air
        self.ramp_c_per_min = float(ramp_c_per_min)
        self.range_c = (float(range_c[0]), float(range_c[1]))
        self.setpoint_c: float | None = None
        self.said = said or (lambda text: None)      # the serving program's console
        self.port = PtyEndpoint()
        self._buffer = bytearray()

    @property
    def path(self) -> str:
        return self.port.path

    def set(self, now: float, setpoint_c: float) -> str | None:
        """Set the chamber at device time ``now``; the refusal's words, or None."""
        lo, hi = self.range_c
        if not (math.isfinite(setpoint_c) and lo <= setpoint_c <= hi):
            return f"setpoint {setpoint_c:g} degC outside the chamber's range {lo:g}..{hi:g} degC"
        was = float(self.air.air(now))
        self.air.set(now, setpoint_c, self.ramp_c_per_min)
        self.setpoint_c = float(setpoint_c)
        self.said(f"chamber: set to {setpoint_c:g} degC at device time {now:.1f} s (air {was:.2f} degC, ramp "
                  f"{self.ramp_c_per_min:g} degC/min)")
        return None

    def receive(self, data: bytes, now: float) -> bytes:
        self._buffer += data
        replies = []
        for raw in take_lines(self._buffer, b"\r\n"):
            line = raw.decode("ascii", "replace").strip()
            if not line:
                continue
            word = line.upper()
            if word == "SET?":
                replies.append("none" if self.setpoint_c is None else f"{self.setpoint_c:g}")
            elif word == "AIR?":
                replies.append(f"{float(self.air.air(now)):.3f}")
            else:
                value = line[3:].strip() if word.startswith("SET") else line
                try:
                    setpoint = float(value)
                except ValueError:
                    replies.append(f"ERR unknown command {line[:40]!r}: give a setpoint in degC (60 or SET 60), SET? or AIR?")
                    continue
                refused = self.set(now, setpoint)
                if refused:
                    replies.append(f"ERR {refused}")
        return b"".join(r.encode() + b"\r\n" for r in replies)

    def serve(self, readable, now: float) -> None:
        """One turn of the serving loop: the commands that came, answered at ``now``."""
        if self.port in readable:
            data = self.port.read()
            if data:
                # what was said before and is still unread answers nobody's question now
                self.port.discard_unread()
                self.port.write(self.receive(data, now))
        self.port.flush()

    def close(self) -> None:
        self.port.close()
