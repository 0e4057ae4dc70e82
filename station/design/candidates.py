"""The candidate set: what the configured table can do, and what each candidate costs in time.

Attitudes: the 26 directions of a cube's faces, edges and corners as "up" in IMU axes (the
paper's nine positions are among them).  Rotations: the 13 axes through them (one sign: a pair
turns both ways), the table axis horizontal (elevation 0) or vertical (90), at each rate of
``rates_dps`` the table's continuous axes allow, for whole revolutions (the compiler records
whole revolutions: station/bench/compile.py).  A candidate is kept when the table reaches it
with the IMU in one of the 24 right-angle mountings (an operator remounts it; unattended: only
the configured mounting) -- by the compiler's own gimbal kinematics (station/bench/gimbal.py),
solved once per requirement as the platform sees it (a direction's image under a mounting is
again one of the 26, so a few dozen solutions serve every candidate and mounting).

The time model is the compiler's (station/bench/compile.py): a static costs its dwell, a move
(a 90 degree move of the slowest axis at its move rate and acceleration, plus the driver's
settling estimate) and the settling ``run.settle_s``; each direction of a rotation pair costs
its whole revolutions, the ramps up and down at ``rate_accel_dps2``, the settling and a move; a
mounting beyond the first costs ``run.operator_s``.  The designed scheme is compiled at the end
and its compiled time is what is checked against the budget (designer.py).
"""
from __future__ import annotations

import itertools
import math
from dataclasses import replace

import numpy as np

from station.bench.compile import MOVE_SETTLE_S, Compiler
from station.bench.gimbal import right_angle_mountings
from station.design.search import Candidate
from station.io.scheme import RAMP_REST_S, RotationSpec, Scheme, StaticSpec

DEFAULT_RATES_DPS = (10.0, 30.0, 100.0, 200.0)
DEFAULT_REVOLUTIONS = (1, 2, 5)
DEFAULT_DWELLS_S = (10.0, 20.0, 50.0, 100.0, 200.0, 500.0, 1000.0)
ELEVATIONS_DEG = (0.0, 90.0)


def directions() -> list:
    """The 26 directions of a cube (unit vectors, rounded to 12 digits)."""
    out = []
    for v in itertools.product((-1, 0, 1), repeat=3):
        if any(v):
            u = np.array(v, float) / np.linalg.norm(v)
            out.append(tuple(float(round(x, 12)) + 0.0 for x in u))
    return out


def axes() -> list:
    """The 13 axes (first non-zero component positive)."""
    return [d for d in directions() if next(x for x in d if x != 0) > 0]


def name_of(v) -> str:
    """x, -y, xy, x-z, xyz, ... for a cube direction."""
    v = np.round(np.asarray(v) * math.sqrt(sum(1 for x in v if abs(x) > 1e-9)), 6)
    return "".join(("" if x > 0 else "m") + "xyz"[i] for i, x in enumerate(v) if abs(x) > 1e-9)


class Table:
    """The configured table's reach and time, with the gimbal's answers cached."""

    def __init__(self, config):
        self.config = config
        dummy = Scheme("design", "", "", {}, (StaticSpec("s", (0.0, 0.0, 1.0), 1.0),))
        self.compiler = Compiler(dummy, config)
        t = config.table
        self.limits = t.axis_limits()
        self.operator = config.run.operator
        self.mountings = right_angle_mountings() if self.operator else [t.mounting_matrix()]
        self._cache: dict = {}
        self.settle_s = config.run.settle_s
        slowest = min(self.limits, key=lambda lim: lim.move_rate_dps)
        v, a = slowest.move_rate_dps, slowest.move_accel_dps2
        d = 90.0
        self.move_s = (d / v + v / a if d > v * v / a else 2.0 * math.sqrt(d / a)) + MOVE_SETTLE_S

    def continuous(self, rate_dps: float) -> tuple:
        """The table axes (1-based) that can turn continuously at this rate."""
        return tuple(i for i, lim in enumerate(self.limits, 1)
                     if lim.angle_limits is None and rate_dps <= lim.max_rate_dps)

    def mask(self, spec) -> int:
        """Bit m set: mounting m reaches ``spec`` exactly (statics; rotations at their elevation).
        With an operator, a requirement no face reaches gets the bit of a fixture holding the IMU
        askew with it up (the compiler's fixture mounting, station/bench/compile.py): bit 24 + the
        direction's index, shared by a turn about that direction with the table axis vertical."""
        bits = self._faces(spec)
        if bits or not self.operator:
            return bits
        if isinstance(spec, StaticSpec):
            return 1 << (FIXTURE_BIT + _direction_index(spec.up_body))
        # the compiler turns a rotation a face reaches at another elevation at that elevation
        # (a note), not on a fixture: such a candidate is left to its other elevation
        relaxed = ("relaxed", _key(np.asarray(spec.axis_body)), self.continuous(abs(spec.rate_dps)))
        if relaxed not in self._cache:
            self._cache[relaxed] = any(self.compiler._reachable(spec, m, exact=False) for m in self.mountings)
        if not self._cache[relaxed] and spec.axis_elevation_deg == 90.0 and any(
                np.allclose(self.compiler.gimbal0.axes_enu[i - 1], (0.0, 0.0, 1.0), atol=1e-9)
                for i in self.continuous(abs(spec.rate_dps))):
            return 1 << (FIXTURE_BIT + _direction_index(spec.axis_body))
        return 0

    def _faces(self, spec) -> int:
        bits = 0
        for m, mounting in enumerate(self.mountings):
            if isinstance(spec, StaticSpec):
                key = ("s", _key(mounting @ np.asarray(spec.up_body)))
            else:
                key = ("r", _key(mounting @ np.asarray(spec.axis_body)), spec.axis_elevation_deg,
                       self.continuous(abs(spec.rate_dps)))
            if key not in self._cache:
                self._cache[key] = self.compiler._reachable(spec, mounting, exact=True)
            if self._cache[key]:
                bits |= 1 << m
        return bits

    def ramp_s(self, rate_dps: float) -> float:
        usable = [self.limits[i - 1].rate_accel_dps2 for i in self.continuous(rate_dps)]
        return rate_dps / min(usable) if usable else math.inf

    def static_s(self, dwell_s: float) -> float:
        return dwell_s + self.settle_s + self.move_s

    def rotation_pair_s(self, rate_dps: float, revolutions: int, record_ramp: str | None = None) -> float:
        """Both directions: whole revolutions, the ramps up and down, the settling and a move each
        (the compiler's Rotate step); a recorded ramp adds its RAMP_REST_S at rest to the window."""
        one = revolutions * 360.0 / rate_dps + 2.0 * self.ramp_s(rate_dps) + self.settle_s + self.move_s
        return 2.0 * (one + (RAMP_REST_S if record_ramp else 0.0))


def static_spec(up, dwell_s: float, name: str | None = None) -> StaticSpec:
    return StaticSpec(name or f"up_{name_of(up)}", tuple(up), float(dwell_s))


def rotation_pair(axis, elevation: float, rate: float, revolutions: int, name: str | None = None,
                  record_ramp: str | None = None) -> tuple:
    base = name or (f"rot_{name_of(axis)}_e{elevation:g}_{rate:g}dps_{revolutions}rev"
                    + (f"_ramp{record_ramp}" if record_ramp else ""))
    T = revolutions * 360.0 / rate
    return (RotationSpec(f"{base}_p", tuple(axis), +rate, T, axis_elevation_deg=elevation, record_ramp=record_ramp),
            RotationSpec(f"{base}_m", tuple(axis), -rate, T, axis_elevation_deg=elevation, record_ramp=record_ramp))


def ramp_of(key) -> str | None:
    """A rotation candidate's recorded ramp: its key (axis, elevation, rate, revolutions[, ramp])."""
    return key[4] if len(key) > 4 else None


def candidate_set(table: Table, rates_dps=DEFAULT_RATES_DPS, revolutions=DEFAULT_REVOLUTIONS,
                  dwells_s=DEFAULT_DWELLS_S, elevations=ELEVATIONS_DEG, levels=(None,), ramps: bool = False):
    """(candidates for the search, the chunks to compute their information from, notes, masks):
    masks[i] is the candidate's reachable-mounting bit mask (time model's remounts).  ``levels``:
    the temperature chamber's levels every candidate is offered at (None: the room's, no
    setpoint; a number: the chamber's setpoint, degC) -- one information block serves a segment
    at every level (the search places it at its temperature: information.at_temperature); a
    static's slot stays its attitude, so that each attitude is held at one level (designs whose
    attitudes were repeated at two levels left the accelerometers' scale factors undetermined
    for that temperature coefficients' sake: docs/design.md, fourteenth session).  ``ramps``
    (a model with a time offset, issue 28 item 3): every rotation pair is offered a second time
    with its ramp up recorded (``record_ramp: start``, key (axis, elevation, rate, revolutions,
    "start")), the one kind of segment whose rate changes within its window; one revolution
    only (the offset's information is the change of rate, not the length)."""
    from station.design.information import UNIT_DWELL_S

    cands, masks, notes = [], [], []
    statics_chunk, rot_chunks = [], {e: [] for e in elevations}
    for up in directions():
        m = table.mask(static_spec(up, 1.0))
        if not m:
            continue
        statics_chunk.append((("static", up), static_spec(up, UNIT_DWELL_S)))
        for dwell in dwells_s:
            cands.append(Candidate(("static", up, float(dwell)), "static", table.static_s(dwell),
                                   dwell_s=float(dwell), slot=up))
            masks.append(m)
    allowed = [r for r in rates_dps if table.continuous(r)]
    axes_ = set(axes())
    if len(allowed) < len(rates_dps):
        notes.append(f"rates above the table's max_rate_dps left out: "
                     f"{', '.join(f'{r:g}' for r in rates_dps if r not in allowed)} deg/s")
    for axis in directions():
        for e in elevations:
            if e != 90.0 and axis not in axes_:
                continue        # (about a tilted axis, -a with rate r is a with -r: the pair)
            for rate in allowed:
                m = table.mask(rotation_pair(axis, e, rate, 1)[0])
                if not m:
                    continue
                for rev in revolutions:
                    key = (axis, float(e), float(rate), int(rev))
                    rot_chunks[e].append((key, rotation_pair(axis, e, rate, rev)))
                    cands.append(Candidate(key, "rotation", table.rotation_pair_s(rate, rev),
                                           axis=(axis, float(e))))
                    masks.append(m)
                if ramps:
                    rev = min(revolutions)
                    key = (axis, float(e), float(rate), int(rev), "start")
                    rot_chunks[e].append((key, rotation_pair(axis, e, rate, rev, record_ramp="start")))
                    cands.append(Candidate(key, "rotation", table.rotation_pair_s(rate, rev, "start"),
                                           axis=(axis, float(e))))
                    masks.append(m)
    # rotations about one body axis at two elevations in one capture would share one axis group
    # (one gravity angle): one chunk per elevation, the statics with the first
    chunks = []
    for e in elevations:
        chunk = list(rot_chunks[e])
        if not chunk:
            continue
        if not chunks:
            chunk = statics_chunk + chunk
        else:
            chunk = [(("anchor",) + k, s) for k, s in statics_chunk] + chunk     # (the fit's start needs statics)
        chunks.append(chunk)
    if not chunks:
        chunks.append(statics_chunk)
    if tuple(levels) != (None,):
        cands, masks = ([replace(c, level=level) for level in levels for c in cands],
                        [m for level in levels for m in masks])
    return cands, chunks, notes, masks


FIXTURE_BIT = 24          # bits 0-23: the right-angle mountings; then one fixture per cube direction


def _direction_index(v) -> int:
    d = np.asarray(v, float) / np.linalg.norm(v)
    return int(np.argmin([np.linalg.norm(d - np.asarray(u)) for u in directions()]))


def _key(v) -> tuple:
    return tuple(np.round(np.asarray(v, float), 9) + 0.0)
