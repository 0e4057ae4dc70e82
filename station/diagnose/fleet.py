"""The fleet view: the calibrations of many units (of an IMU model, a lot, since a date) side by
side, from the numbers the calibration store holds (station/io/history.py ``Store.filed``).

Per parameter, the distribution across units: each unit counted once, by its latest usable
calibration (verdict ``passes`` or ``noise overestimated``: a failing fit's numbers are not a
calibration and are not mixed in; they are counted).  Each unit is judged within its own lot
(the lot filed with it; the units of no stated lot are one group).  A unit is **outside the lot's
spread** when
its value is improbable for a unit drawn from the same lot as the others: leave-one-out, the
others' mean m and standard deviation s (n - 1 units) predict a new unit as m ± s·√(1 + 1/(n-1)),
and (x - m) / (s·√(1 + 1/(n-1))) follows Student's t with n - 2 degrees of freedom when the lot
is normal; the unit is flagged when that exceeds the t quantile of the same two-sided tail as
±3σ of a normal (0.27 %, :data:`TAIL`), so that a small lot does not flag by its own noise.  Its
distance is also given in σ of the lot, (x - m)/s, and in its own 1σ, (x - m)/σ_unit (a unit
far from the lot in its own σ but inside the lot's spread is a lot that spreads more than one
unit's uncertainty, not a bad unit).  With many units and parameters some flags are chance:
:attr:`Fleet.expected_by_chance` says how many.

Drift per unit: every unit with two or more usable calibrations, its first against its latest,
parameter by parameter in units and in combined σ (station/io/calcompare.py, > 3σ flagged), and
per year.
"""
from __future__ import annotations

import datetime as _dt
import math
from dataclasses import dataclass, field

from station.io.calcompare import FLAG_SIGMA, changes

TAIL = 0.0026997960632601965        # two-sided tail beyond 3σ of a normal: 2·(1 - Φ(3))
USABLE = ("passes", "noise overestimated")
MIN_UNITS = 3                         # leave-one-out needs n - 2 >= 1 degrees of freedom
FORMAT = "station-fleet/1"


def category(verdict: str) -> str:
    """A verdict's class: passes, fails, not converged, noise overestimated, untested, not stated."""
    word = (verdict or "").split(":")[0].strip()
    for known in ("passes", "fails", "not converged", "noise overestimated", "untested"):
        if word == known:
            return known
    return "not stated"


@dataclass
class UnitValue:
    serial: str
    calibration: int            # its id in the store
    date_utc: str
    value: float
    sigma: float | None
    lot: str | None = None
    z_lot: float | None = None  # (x - m) / s: in σ of the rest of the lot
    z_own: float | None = None  # (x - m) / σ_unit: in the unit's own 1σ
    t: float | None = None      # (x - m) / (s·sqrt(1 + 1/(n-1))): Student's t, n - 2 dof
    t_limit: float | None = None    # of its lot (None: not judged)
    outside: bool = False


@dataclass
class Spread:
    name: str
    unit: str
    units: int
    mean: float
    std: float | None           # across units (n - 1 in the denominator)
    median: float
    min: float
    max: float
    median_sigma: float | None  # the units' own 1σ, median
    t_limit: float | None       # |t| beyond this: outside the lot's spread (one lot; None: several
                                #  lots, each unit's own in UnitValue.t_limit, or too few units)
    values: list = field(default_factory=list)        # UnitValue per unit

    @property
    def outside(self) -> list:
        return [v for v in self.values if v.outside]


@dataclass
class Drift:
    serial: str
    calibrations: int
    first: int
    last: int
    first_date: str
    last_date: str
    changes: list               # dicts: parameter, unit, change, change_ppm, z, flagged, per_year


@dataclass
class Fleet:
    selection: dict
    calibrations: int
    units: int
    verdicts: dict              # category -> count of calibrations
    latest_verdicts: dict       # category -> count of units, by their latest calibration
    unusable_units: list        # serials without a usable calibration
    parameters: list            # Spread
    drift: list                 # Drift
    tests: int = 0              # unit x parameter judgements made
    # rows not counted: their file is missing, outside the store or not the one filed
    # ({"calibration", "serial", "date_utc", "problem"})
    not_counted: list = field(default_factory=list)

    @property
    def expected_by_chance(self) -> float:
        return self.tests * TAIL

    @property
    def outside(self) -> list:
        return [(p, v) for p in self.parameters for v in p.outside]


def _mean_std(xs):
    n = len(xs)
    m = math.fsum(xs) / n
    s = math.sqrt(math.fsum((x - m) ** 2 for x in xs) / (n - 1)) if n > 1 else None
    return m, s


def _t_limit(dof: int) -> float:
    from scipy.special import stdtrit

    return float(stdtrit(dof, 1.0 - TAIL / 2))


def _judge(values: list[UnitValue]) -> float | None:
    """Each unit of one lot against the rest of that lot (sets z_lot, z_own, t, outside); the
    |t| limit, or None for a lot of fewer than MIN_UNITS units.  All units at once, O(n): the
    values centred on the lot's mean first (a scale factor's spread of 1e-5 around 1 keeps its
    digits), then the rest's mean and variance from the sums without unit i."""
    import numpy as np

    n = len(values)
    if n < MIN_UNITS:
        return None
    limit = _t_limit(n - 2)
    x = np.array([v.value for v in values], dtype=float)
    c = x - x.mean()
    total, squares = c.sum(), (c * c).sum()
    m = (total - c) / (n - 1)                                   # the rest's mean (centred)
    var = np.maximum((squares - c * c - (n - 1) * m * m) / (n - 2), 0.0)
    s = np.sqrt(var)
    # a rest without any spread (every other unit the same value) judges nothing
    uniq, counts = np.unique(x, return_counts=True)
    flat = np.full(n, len(uniq) == 1)
    if len(uniq) == 2:
        flat = counts[np.searchsorted(uniq, x)] == 1
    for i, v in enumerate(values):
        if flat[i] or not s[i] > 0:
            continue
        d = float(c[i] - m[i])
        v.z_lot = d / float(s[i])
        v.t = d / (float(s[i]) * math.sqrt(1.0 + 1.0 / (n - 1)))
        v.z_own = d / v.sigma if v.sigma else None
        v.t_limit = limit
        v.outside = abs(v.t) > limit
    return limit


def _spread(name: str, unit: str, values: list[UnitValue]) -> Spread:
    """The distribution across every selected unit; each unit judged within its own lot (units
    of no stated lot: one group)."""
    xs = [v.value for v in values]
    n = len(xs)
    mean, std = _mean_std(xs)
    ordered = sorted(xs)
    median = ordered[n // 2] if n % 2 else 0.5 * (ordered[n // 2 - 1] + ordered[n // 2])
    sigmas = sorted(v.sigma for v in values if v.sigma is not None)
    lots: dict = {}
    for v in values:
        lots.setdefault(v.lot, []).append(v)
    limits = {lot: _judge(group) for lot, group in lots.items()}
    limit = next(iter(limits.values())) if len(limits) == 1 else None
    return Spread(name, unit, n, mean, std, median, ordered[0], ordered[-1],
                  sigmas[len(sigmas) // 2] if sigmas else None, limit, values)


def _years(a: str, b: str) -> float | None:
    try:
        ta = _dt.datetime.fromisoformat(a.replace("Z", "+00:00"))
        tb = _dt.datetime.fromisoformat(b.replace("Z", "+00:00"))
    except ValueError:
        return None
    days = (tb - ta).total_seconds() / 86400.0
    return days / 365.25 if days > 0 else None


def _doc(filed) -> dict:
    return {"parameters": {n: {"value": p.value, "sigma": p.sigma, "unit": p.unit} for n, p in filed.numbers.items()}}


def fleet(filed: list, selection: dict | None = None) -> Fleet:
    """The fleet view of ``filed`` (history.Filed, any order); an entry whose file is not the one
    filed (``entry.problem``, Store.verify) is listed as not counted, never counted."""
    filed = sorted(filed, key=lambda f: (f.entry.serial, f.entry.date_utc, f.entry.id))
    not_counted = [{"calibration": f.entry.id, "serial": f.entry.serial, "date_utc": f.entry.date_utc,
                    "problem": f.entry.problem} for f in filed if getattr(f.entry, "problem", None)]
    filed = [f for f in filed if not getattr(f.entry, "problem", None)]
    verdicts: dict = {}
    per_unit: dict = {}
    for f in filed:
        c = category(f.entry.verdict)
        verdicts[c] = verdicts.get(c, 0) + 1
        per_unit.setdefault(f.entry.serial, []).append(f)
    latest_verdicts: dict = {}
    usable_latest, unusable, drift = {}, [], []
    for serial, cals in per_unit.items():
        c = category(cals[-1].entry.verdict)
        latest_verdicts[c] = latest_verdicts.get(c, 0) + 1
        usable = [f for f in cals if category(f.entry.verdict) in USABLE and f.numbers]
        if not usable:
            unusable.append(serial)
            continue
        usable_latest[serial] = usable[-1]
        if len(usable) >= 2:
            a, b = usable[0], usable[-1]
            years = _years(a.entry.date_utc, b.entry.date_utc)
            rows, _, _ = changes(_doc(a), _doc(b))
            drift.append(Drift(serial, len(usable), a.entry.id, b.entry.id, a.entry.date_utc, b.entry.date_utc, [
                {"parameter": r.name, "unit": r.unit, "change": r.change, "change_ppm": r.change_ppm, "z": r.z,
                 "flagged": r.flagged, "per_year": r.change / years if years else None} for r in rows]))
    by_name: dict = {}
    for serial, f in usable_latest.items():
        for name, p in f.numbers.items():
            by_name.setdefault((name, p.unit), []).append(
                UnitValue(serial, f.entry.id, f.entry.date_utc, p.value, p.sigma, f.entry.lot))
    spreads = [_spread(name, unit, values) for (name, unit), values in sorted(by_name.items())]
    tests = sum(1 for p in spreads for v in p.values if v.t is not None)
    return Fleet(dict(selection or {}), len(filed), len(per_unit), verdicts, latest_verdicts, unusable,
                 spreads, drift, tests, not_counted)


def _num(x):
    return None if x is None or (isinstance(x, float) and not math.isfinite(x)) else x


def to_json(f: Fleet) -> dict:
    """The fleet view as plain data (``station fleet --json``; docs/fleet.md)."""
    return {
        "format": FORMAT,
        "selection": f.selection,
        "calibrations": f.calibrations,
        "units": f.units,
        "verdicts": f.verdicts,
        "latest_verdicts": f.latest_verdicts,
        "units_without_usable_calibration": f.unusable_units,
        "not_counted": f.not_counted,
        "outside_tail": TAIL,
        "judgements": f.tests,
        "expected_outside_by_chance": f.expected_by_chance,
        "parameters": [{
            "name": p.name, "unit": p.unit, "units": p.units, "mean": p.mean, "std": _num(p.std),
            "median": p.median, "min": p.min, "max": p.max, "median_sigma": _num(p.median_sigma),
            "t_limit": _num(p.t_limit),
            "values": [{"serial": v.serial, "lot": v.lot, "calibration": v.calibration, "date_utc": v.date_utc,
                        "value": v.value, "sigma": _num(v.sigma), "z_lot": _num(v.z_lot), "z_own": _num(v.z_own),
                        "t": _num(v.t), "t_limit": _num(v.t_limit), "outside": v.outside} for v in p.values],
        } for p in f.parameters],
        "drift": [{"serial": d.serial, "calibrations": d.calibrations, "first": d.first, "last": d.last,
                   "first_date": d.first_date, "last_date": d.last_date, "flag_sigma": FLAG_SIGMA,
                   "changes": [{k: _num(v) for k, v in c.items()} for c in d.changes]} for d in f.drift],
    }
