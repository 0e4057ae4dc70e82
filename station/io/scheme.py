"""Calibration schemes: what a run must measure, written in IMU body axes.

A scheme file (YAML, see ``schemes/optimal9.yaml``) lists static attitudes (the direction of
local "up" in IMU axes and a dwell; optionally a heading: ``heading_body``, an IMU direction
that points horizontally towards ``heading_deg``, clockwise from north) and rotations (an axis
in IMU axes, run as a +/- pair at a rate for a duration, unless ``pair: false``; the table axis
horizontal unless ``axis_elevation_deg`` says otherwise; measured by an encoder unless
``encoder: false``; ``turn_deg``: the angle a hand turn makes by protocol, e.g. one whole turn).
``table: none`` marks a scheme performed by hand, without a rate table (docs/schemes.md).  This
module loads and validates such a file and expands it into the ordered list of segments a run
records.  It knows nothing about tables or hardware.
"""
from __future__ import annotations

import collections
import math
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np

from station.core.errors import UserError
from station.core import yaml_text

DEFAULT_KEYS = ("dwell_s", "rate_dps", "rotation_s")
SEGMENT_KEYS = {"static": ("static", "up_body", "dwell_s", "heading_body", "heading_deg", "chamber_c"),
                "rotation": ("rotation", "axis_body", "rate_dps", "rotation_s", "axis_elevation_deg", "pair",
                             "encoder", "turn_deg", "chamber_c", "record_ramp")}
# record_ramp: which of the table's ramps a rotation's recorded window keeps (issue 28 item 3): "start"
# (the window opens with the table at rest, RAMP_REST_S before the ramp, and keeps the ramp up to the
# rate), "end" (the window keeps the brake from the rate and closes with the table at rest, RAMP_REST_S
# after it).  Such a turn's rate changes within its window, the only thing that shows a time offset
# between the IMU's stamps and the table's encoder (station/model/time_offset.py).
RECORD_RAMPS = ("start", "end")
RAMP_REST_S = 0.5       # s of the table at rest kept in a ramp's window (the rate there is exactly 0)


@dataclass(frozen=True)
class StaticSpec:
    """Hold the IMU still with ``up_body`` (unit vector, IMU axes) pointing up for ``dwell_s``."""

    name: str
    up_body: tuple[float, float, float]
    dwell_s: float
    kind: str = "static"
    heading_body: tuple[float, float, float] | None = None   # unit, perpendicular to up_body
    heading_deg: float | None = None                          # where heading_body points, from north
    chamber_c: float | None = None    # set the chamber to this (degC) before the segment; None: as it is

    @property
    def duration_s(self) -> float:
        return self.dwell_s


@dataclass(frozen=True)
class RotationSpec:
    """Rotate right-handed about ``axis_body`` at ``rate_dps`` (signed) for ``duration_s``."""

    name: str
    axis_body: tuple[float, float, float]
    rate_dps: float
    duration_s: float
    axis_elevation_deg: float = 0.0   # the table axis above the horizontal (90: vertical, up)
    encoder: bool = True              # False: hand or screwdriver, no angle measured
    kind: str = "rotation"
    turn_deg: float | None = None     # a hand turn's angle by protocol (e.g. 360: one whole turn)
    chamber_c: float | None = None    # set the chamber to this (degC) before the segment; None: as it is
    record_ramp: str | None = None    # "start" | "end": the window keeps that ramp (RECORD_RAMPS); None: steady

    @property
    def revolutions(self) -> float:
        return abs(self.rate_dps) * self.duration_s / 360.0


@dataclass(frozen=True)
class Scheme:
    name: str
    title: str
    reference: str
    defaults: dict
    segments: tuple  # of StaticSpec | RotationSpec
    centred: bool = False   # the IMU's reference point sits on the table's rotation axes
    table: bool = True      # False (``table: none``): performed by hand, no rate table

    @property
    def duration_s(self) -> float:
        """Time spent recording (moves and settling excluded)."""
        return sum(s.duration_s for s in self.segments)

    @property
    def chamber_steps(self) -> list:
        """(segment, setpoint degC) of every segment that sets the temperature chamber, in order."""
        return [(s, s.chamber_c) for s in self.segments if s.chamber_c is not None]


def builtin_names() -> list[str]:
    return sorted(p.name[:-5] for p in resources.files("schemes").iterdir() if p.name.endswith(".yaml"))


def scheme_text(name_or_path: str) -> tuple[str, str]:
    """(YAML text, source name) of a built-in scheme or a scheme file."""
    path = Path(name_or_path)
    if name_or_path in builtin_names():
        return (resources.files("schemes").joinpath(f"{name_or_path}.yaml").read_text(),
                f"scheme '{name_or_path}'")
    if path.suffix in (".yaml", ".yml") or path.exists():
        from station.core.user_files import read_user_text

        return read_user_text(path, "scheme file"), str(path)      # (a FIFO is refused, not read: it hung)
    raise UserError(f"unknown scheme '{name_or_path}': built-in schemes are "
                    f"{', '.join(builtin_names())}, or give a path to a .yaml file")


def load_scheme(name_or_path: str, overrides: dict | None = None) -> Scheme:
    """Load a built-in scheme by name, or a scheme file by path; apply default overrides."""
    text, source = scheme_text(name_or_path)
    return scheme_from_text(text, source, overrides)


def scheme_from_text(text: str, source: str, overrides: dict | None = None) -> Scheme:
    doc = yaml_text.load_text(text, source)
    return parse_scheme(doc, source, overrides or {})


def _number(value, where: str, *, positive: bool = False, nonzero: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise UserError(f"{where}: must be a finite number, got {value!r}")
    if positive and value <= 0:
        raise UserError(f"{where}: must be > 0, got {value!r}")
    if nonzero and value == 0:
        raise UserError(f"{where}: must not be zero")
    return float(value)


def _unit_vector(value, where: str) -> tuple[float, float, float]:
    if not isinstance(value, list) or len(value) != 3:
        raise UserError(f"{where}: must be a list of 3 numbers, got {value!r}")
    v = np.array([_number(x, where) for x in value])
    n = np.linalg.norm(v)
    if n == 0:
        raise UserError(f"{where}: must not be the zero vector")
    return tuple(float(x) for x in v / n)


def parse_scheme(doc, source: str, overrides: dict) -> Scheme:
    if not isinstance(doc, dict):
        raise UserError(f"{source}: a scheme must be a YAML mapping")
    for key in ("name", "segments"):
        if key not in doc:
            raise UserError(f"{source}: missing field '{key}'")
    defaults = doc.get("defaults") or {}
    if not isinstance(defaults, dict):
        raise UserError(f"{source}: defaults: must be a mapping (dwell_s, rate_dps, rotation_s), "
                        f"got {type(defaults).__name__}")
    defaults = dict(defaults)
    for key, value in overrides.items():
        if key not in DEFAULT_KEYS:
            raise UserError(f"{source}: unknown default '{key}' (known: {', '.join(DEFAULT_KEYS)})")
        defaults[key] = value
    for key, value in defaults.items():
        if key not in DEFAULT_KEYS:         # (a key from a file: shown as written, control characters escaped)
            raise UserError(f"{source}: defaults: unknown field {key!r} (known: {', '.join(DEFAULT_KEYS)})")
        _number(value, f"{source}: defaults.{key}", positive=True)

    uses_table = _table_key(doc.get("table", True), source)
    entries = doc["segments"]
    if not isinstance(entries, list) or not entries:
        raise UserError(f"{source}: 'segments' must be a non-empty list")
    segments: list = []
    for i, entry in enumerate(entries):
        where = f"{source}: segments[{i}]"
        if not isinstance(entry, dict):
            raise UserError(f"{where}: must be a mapping")
        kind = "static" if "static" in entry else "rotation" if "rotation" in entry else None
        unknown = [k for k in entry if kind is not None and k not in SEGMENT_KEYS[kind]]
        if unknown:             # (a key ignored changed the run without a word: duration_s on a static)
            raise UserError(f"{where}: unknown field {str(unknown[0])[:40]!r} for a {kind} "
                            f"(known: {', '.join(SEGMENT_KEYS[kind])})")
        if "static" in entry:
            dwell = entry.get("dwell_s", defaults.get("dwell_s"))
            if dwell is None:
                raise UserError(f"{where}: no dwell_s here nor in defaults")
            up = _unit_vector(entry.get("up_body"), f"{where}.up_body")
            segments.append(StaticSpec(
                name=str(entry["static"]), up_body=up,
                dwell_s=_number(dwell, f"{where}.dwell_s", positive=True),
                chamber_c=_chamber(entry, where, uses_table), **_heading(entry, up, where)))
        elif "rotation" in entry:
            rate = entry.get("rate_dps", defaults.get("rate_dps"))
            duration = entry.get("rotation_s", defaults.get("rotation_s"))
            if rate is None or duration is None:
                raise UserError(f"{where}: rate_dps and rotation_s needed here or in defaults")
            rate = abs(_number(rate, f"{where}.rate_dps", nonzero=True))
            duration = _number(duration, f"{where}.rotation_s", positive=True)
            axis = _unit_vector(entry.get("axis_body"), f"{where}.axis_body")
            elevation = _number(entry.get("axis_elevation_deg", 0.0), f"{where}.axis_elevation_deg")
            if not -90.0 <= elevation <= 90.0:
                raise UserError(f"{where}.axis_elevation_deg: must be within [-90, 90], got {elevation}")
            flags = {}
            for key in ("pair", "encoder"):
                flags[key] = entry.get(key, True)
                if not isinstance(flags[key], bool):
                    raise UserError(f"{where}.{key}: must be true or false, got {flags[key]!r}")
            if not uses_table and flags["encoder"]:
                raise UserError(f"{where}.encoder: a scheme without a table has no encoder: "
                                "write encoder: false")
            turn = entry.get("turn_deg")
            if turn is not None:
                turn = _number(turn, f"{where}.turn_deg", positive=True)
                if flags["encoder"]:
                    raise UserError(f"{where}.turn_deg: only for turns without an encoder "
                                    "(encoder: false); the encoder measures a table's turns")
            ramp = entry.get("record_ramp")
            if ramp is not None:
                if ramp not in RECORD_RAMPS:
                    raise UserError(f"{where}.record_ramp: must be start or end (which ramp the recorded "
                                    f"window keeps), got {str(ramp)[:40]!r}")
                if not flags["encoder"] or not uses_table:
                    raise UserError(f"{where}.record_ramp: only for a table's turns (measured by its encoder)")
            base = str(entry["rotation"])
            common = dict(axis_elevation_deg=elevation, encoder=flags["encoder"], turn_deg=turn,
                          record_ramp=ramp)
            chamber = _chamber(entry, where, uses_table)
            if flags["pair"]:
                segments.append(RotationSpec(f"{base}_p", axis, +rate, duration, **common, chamber_c=chamber))
                segments.append(RotationSpec(f"{base}_m", axis, -rate, duration, **common))
            else:
                segments.append(RotationSpec(base, axis, rate, duration, **common, chamber_c=chamber))
        else:
            raise UserError(f"{where}: must have a 'static' or a 'rotation' key")
    # (counted once: names.count per name was quadratic, minutes for a scheme of 100,000 segments)
    duplicates = sorted(n for n, k in collections.Counter(s.name for s in segments).items() if k > 1)
    if duplicates:
        raise UserError(f"{source}: duplicate segment names: {', '.join(duplicates)}")
    centred = doc.get("centred", False)
    if not isinstance(centred, bool):
        raise UserError(f"{source}: centred: must be true or false, got {centred!r}")
    return Scheme(name=str(doc["name"]), title=str(doc.get("title", "")),
                  reference=str(doc.get("reference", "")), defaults=defaults,
                  segments=tuple(segments), centred=centred, table=uses_table)


def _chamber(entry: dict, where: str, uses_table: bool) -> float | None:
    """A segment's ``chamber_c`` (the temperature chamber's setpoint from this segment on, degC),
    None without one; whether the bench has a chamber that reaches it is the compiler's check."""
    if "chamber_c" not in entry:
        return None
    x = _number(entry["chamber_c"], f"{where}.chamber_c")
    if not -100.0 <= x <= 200.0:
        raise UserError(f"{where}.chamber_c: must be within -100..200 degrees C, got {x:g}")
    if not uses_table:
        raise UserError(f"{where}.chamber_c: a scheme done by hand (table: none) has no chamber")
    return x


def _table_key(value, source: str) -> bool:
    """``table``: true (default, a rate table), or none/false (by hand)."""
    if value is True or value is False:
        return value
    if isinstance(value, str) and value.strip().lower() == "none":
        return False
    raise UserError(f"{source}: table: must be none (a scheme done by hand) or true, got {value!r}")


def _heading(entry: dict, up: tuple, where: str) -> dict:
    """heading_body/heading_deg of a static entry (both or neither), checked."""
    body, deg = entry.get("heading_body"), entry.get("heading_deg")
    if body is None and deg is None:
        return {}
    if body is None or deg is None:
        raise UserError(f"{where}: heading_body and heading_deg go together (give both or neither)")
    body = _unit_vector(body, f"{where}.heading_body")
    if abs(float(np.dot(body, up))) > 1e-6:
        raise UserError(f"{where}.heading_body: must be perpendicular to up_body (a horizontal "
                        f"direction), got {list(body)} with up_body {list(up)}")
    deg = _number(deg, f"{where}.heading_deg")
    if not 0.0 <= deg < 360.0:
        raise UserError(f"{where}.heading_deg: must be within [0, 360), got {deg}")
    return {"heading_body": body, "heading_deg": deg}
