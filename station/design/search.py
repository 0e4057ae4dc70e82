"""The criterion of a design and the exchange algorithm that minimises it within a time budget.

A design is a set of candidates: statics (one attitude each, with a dwell from a grid) and
rotation pairs (an axis, its elevation, a rate, whole revolutions).  Its information about the
shared columns G (station/design/information.py) is

    F = sum_statics T_s m_s + sum_axis_groups Schur_A(sum_{pairs in group} M_c + W_group) + eps

(eps: a ridge of 1e-10 on F scaled to a unit diagonal, which only matters for a column no
candidate sees, e.g. the mounting offset with no rotation), and the covariance of the reported parameters is
the block of F^-1 in their columns, scaled to their reported units (scale factors in ppm).

Criteria (lower is better):
    D        -log det of the reported parameters' information (their covariance's log det)
    A        the sum of their variances in reported units (ppm, arc-seconds, µg, °/h, mm, ...)
    worst:P  the largest 1σ of the parameters named by the patterns P (fnmatch), each in its
             reported unit (so name parameters of one kind: worst:accel_position_*)

The search (Fedorov's exchange, with a budget): nine statics first (the estimator takes every
static's attitude as unknown from nine on, as the information here does), chosen greedily; then
greedily the candidate that lowers the criterion most per second of table time until the budget
is spent; then exchanges: each chosen candidate in turn against every one not chosen (a static's dwell
against another dwell of it is such an exchange), its best exchange that improves the criterion
and keeps the time within the budget applied at once, then additions the freed time allows;
passes until one changes nothing, or ``max_passes``.  Only the axis groups a step touches are
recomputed (State).
"""
from __future__ import annotations

import functools

import fnmatch
import math
from dataclasses import dataclass, field

import numpy as np

from station.core.errors import UserError
from station.design.information import group_schur, schur as _schur, static_information

RIDGE = 1e-10            # on the unit-diagonal information: a column nothing sees gets 1σ 1e5 of its size
CRITERIA = ("D", "A", "worst")    # (station/cli/choices.py copies it)
MIN_STATICS = 9           # lsq's attitudes="auto": every static's attitude unknown from nine on
# designs of known attitudes (lsq's attitudes="table" below nine statics: each static's attitude
# the table's, to its angle error): six to eight statics (six: sizeeffect's, +/-1 g on each axis)
MIN_STATICS_TABLE, MAX_STATICS_TABLE = 6, 8
# designs of unknown attitudes turn about at least this many body axes with the table axis level
# (elevation 0): the 1,500 s size-effect design with every turn about a vertical axis was refused
# by the noisy dry runs (fits ending at a reduced chi-square of 1e7 from turns' phases started
# from noise), the same with two of its 26 pairs made level was not (docs/design.md)
MIN_LEVEL_AXES = 2
# exchange passes of the second, timed stage (timed_exchange): each pass re-places every candidate
# on the design's timeline (the first, untimed stage has brought the design near; docs/design.md)
TIMED_PASSES = 3
# the order of the segments on the timeline (order_search; fifteenth session): after the timed
# stage ORDER_ROUNDS rounds of (order search, TIMED_PASSES timed exchange passes on that order),
# then the order once more; each order search at most ORDER_PASSES passes of pairwise exchanges
# within a mounting and chamber level (0: no order search).  Measured on the temperature design
# (3715 s, docs/design.md): no round 3.687 µg/°C in 46 s of CPU, one round 3.618 in 66 s -- over
# the minute; so none
ORDER_ROUNDS = 0
ORDER_PASSES = 3
WORST_POWER = 20          # the worst criterion searched as this power mean of the 1σ (Scorer.value_of)


@dataclass
class Criterion:
    kind: str                     # "D" | "A" | "worst"
    patterns: tuple = ()

    @property
    def text(self) -> str:
        return self.kind if self.kind != "worst" else "worst:" + ",".join(self.patterns)


def parse_criterion(text: str, names: list) -> tuple[Criterion, np.ndarray]:
    """The criterion and the indices of the parameters it is over (UserError naming what is wrong)."""
    text = text.strip()
    if text in ("D", "A"):
        return Criterion(text), np.arange(len(names))
    if text.startswith("worst:"):
        patterns = tuple(p.strip() for p in text[6:].split(",") if p.strip())
        if not patterns:
            raise UserError("--criterion worst: name the parameters, e.g. worst:accel_position_*")
        chosen = sorted({i for p in patterns for i, n in enumerate(names) if fnmatch.fnmatchcase(n, p)})
        missing = [p for p in patterns if not any(fnmatch.fnmatchcase(n, p) for n in names)]
        if missing:
            raise UserError(f"--criterion: no parameter of this model matches {', '.join(missing)} "
                            f"(the model's parameters: {', '.join(names)})")
        return Criterion("worst", patterns), np.array(chosen, int)
    raise UserError(f"--criterion must be D, A or worst:PARAM[,PARAM...], got {text!r}")


@dataclass
class Candidate:
    key: tuple
    kind: str                     # "static" | "rotation"
    seconds: float                # table time: recording, moves, settling, ramps (candidates.py)
    dwell_s: float = 0.0          # statics
    slot: tuple = ()              # at most one candidate per slot: a static's attitude (and chamber level)
    axis: tuple = ()              # rotations: (axis, elevation) group; one elevation per axis
    level: float | None = None    # the chamber's setpoint it is recorded at (degC), None: the room's


def complement(info, g, S: np.ndarray, G: int) -> np.ndarray:
    """An axis group's information about G (its nuisances eliminated): information.group_schur for
    a group with columns of its own beyond the axis' (a vertical turn's vibration across it), else
    the plain Schur complement."""
    own = getattr(info, "own_columns", {}).get(g, 0)
    return group_schur(S, G, own, RIDGE) if own else _schur(S, G)


class Scorer:
    """Scores designs (sets of candidate indices) under a criterion."""

    def __init__(self, info, candidates: list, criterion: Criterion, which: np.ndarray):
        self.info, self.cands, self.criterion = info, candidates, criterion
        p = info.parameters
        self.cols = p.columns
        self.factors = p.factors
        self.which = which
        G = info.shared
        self.G = G
        self.M = []
        # each rotation's axis group as the information keys it (information._group_key: one per
        # estimator axis group, whose nuisances and prior are counted once), not its (axis,
        # elevation): the capture's own turns about one axis in two sessions are two groups
        self.group: list = []
        for c in candidates:
            if c.kind == "static":
                self.M.append(static_information(info, c.key[:-1], c.dwell_s))
                self.group.append(None)
            else:
                self.group.append(info.rotation[c.key][0])
                self.M.append(info.rotation[c.key][1])
        # effects in the temperature (information.py, timeline=True): M above is each candidate's
        # information at dT = 1 degC; self.M is set at the temperature it has on the design's
        # timeline (retime)
        self.M1 = list(self.M)
        self.dt_c: dict = {}
        # effects in the time (bias_drift: information.Information.time_shear): M1 is each candidate's
        # information at its time in the candidates' capture (natural_time); self.M at the time it
        # has on the design's timeline less the statics' mean (dt_s, s; retime)
        self.dt_s: dict = {}
        self.shear = list(getattr(info, "time_shear", None) or [])
        natural_time = getattr(info, "natural_time", {})
        self.t0 = [natural_time.get(self._info_key(c), 0.0) for c in candidates]
        self.chamber = None       # station.core.chamber.ChamberConfig when candidates have levels
        # the sequence the chosen candidates are written in within each mounting (order_search;
        # None: the writer's rule, statics first): candidate indices, timeline.written_order's
        self.order: list | None = None

    @staticmethod
    def _info_key(c) -> tuple:
        """A candidate's key in the Information (a static's without its dwell)."""
        return c.key[:-1] if c.kind == "static" else c.key

    @property
    def timed(self) -> bool:
        """Effects in the temperature or in the time, informed on the design's own timeline."""
        return self.temperature_timed or bool(self.shear)

    @property
    def temperature_timed(self) -> bool:
        return getattr(self.info, "temp_power", None) is not None

    def set_temperatures(self, dt_c: dict, dt_s: dict | None = None) -> None:
        """Each candidate's information at its temperature difference ``dt_c[i]`` (degC) and, with
        effects in the time, at its time less the statics' mean ``dt_s[i]`` (s; None: as it was
        in the candidates' capture)."""
        self.dt_c = dict(dt_c)
        self.dt_s = dict(dt_s) if dt_s is not None else {}
        p = self.info.temp_power
        self.M = [self._placed(i, M, p, self.dt_c.get(i, 0.0), self.dt_s.get(i)) for i, M in enumerate(self.M1)]

    def _placed(self, i, M1, power, dt_c, dt_s):
        from station.design.information import at_temperature, at_time

        M = at_temperature(M1, power, dt_c) if power is not None else M1
        if self.shear and dt_s is not None:
            M = at_time(M, self.shear, dt_s - self.t0[i])
        return M

    def natural(self) -> None:
        """Every candidate at the temperature and the time it had in the candidates' own capture
        (the search's first stage: information.Information.natural_dt, natural_time)."""
        nat = self.info.natural_dt
        shift = self._level_shift()
        self.set_temperatures({i: nat.get(self._info_key(c), 0.0) + shift(c) for i, c in enumerate(self.cands)})

    def _level_shift(self):
        """A candidate's chamber level less the middle of the levels (degC; 0 without a chamber):
        where the first stage places it before there is a timeline (the room's level at the
        chamber's ambient_c)."""
        if self.chamber is None:
            return lambda c: 0.0
        values = {self.chamber.ambient_c if c.level is None else c.level for c in self.cands}
        mid = 0.5 * (min(values) + max(values))
        return lambda c: (self.chamber.ambient_c if c.level is None else c.level) - mid

    def retime(self, chosen, masks=None, budget_s: float | None = None) -> bool:
        """Place every candidate at the temperature (with bias_drift also the time) it has on the
        timeline of the design ``chosen`` (timeline.py: the written order, the simulated bench's clock): a chosen one
        where it is, a static not chosen where its attitude's chosen dwell is (else at the chosen
        statics' mean), a rotation not chosen at its axis group's chosen ones (else the chosen
        rotations').  With nothing chosen yet, the notional timeline (timeline.notional).  False
        when the model has no temperature effect (nothing to do)."""
        if not self.timed:
            return False
        from station.design import timeline

        info = self.info
        if not chosen:
            shift = self._level_shift()
            dt_c = {}
            if self.temperature_timed:
                notional = timeline.notional(self.cands, info.temperature, info.clock, budget_s or 3600.0,
                                             info.start_s)
                dt_c = {i: d + shift(self.cands[i]) for i, d in notional.items()}
            dt_s = timeline.notional_times(self.cands, budget_s or 3600.0) if self.shear else None
            self.set_temperatures(dt_c, dt_s)
            return True
        dt_c = {}
        if self.temperature_timed:
            placed, reference = timeline.differences(chosen, self.cands, info.temperature, info.clock, masks,
                                                     self.chamber, with_reference=True, order=self.order,
                                                     start_s=info.start_s)
            dt_c = self._spread(placed, reference)
        dt_s = None
        if self.shear:
            # (a time with no chosen candidate at its level or axis: the statics' mean, 0)
            dt_s = self._spread(timeline.time_differences(chosen, self.cands, info.clock, masks, self.chamber,
                                                          order=self.order, start_s=info.start_s,
                                                          temperature=info.temperature), None)
        self.set_temperatures(dt_c, dt_s)
        return True

    def _spread(self, placed: dict, reference) -> dict:
        """retime's placement of every candidate from the chosen ones' ``placed`` (index: value less
        the reference): a chosen one where it is, a static not chosen where its attitude's chosen
        dwell is (else at the chosen statics' mean), a rotation not chosen at its axis group's
        chosen ones (else the chosen rotations'); ``reference`` (degC) a temperature's, for a
        chamber level nothing is chosen at (None: a time's, 0 there)."""
        by_slot, by_axis, statics, rotations = {}, {}, {}, {}
        for i, d in placed.items():
            c = self.cands[i]
            if c.kind == "static":
                by_slot[c.slot] = d
                statics.setdefault(c.level, []).append(d)
            else:
                by_axis.setdefault((c.axis, c.level), []).append(d)
                rotations.setdefault(c.level, []).append(d)

        def at_level(level, first, second):
            # a level nothing is chosen at: its setpoint (the room: the statics' mean) less the reference
            if level in first:
                return float(np.mean(first[level]))
            if level in second:
                return float(np.mean(second[level]))
            if level is None or self.chamber is None or reference is None:
                return 0.0
            return float(level) - reference

        dt = {}
        for i, c in enumerate(self.cands):
            if i in placed:
                dt[i] = placed[i]
            elif c.kind == "static":
                dt[i] = by_slot[c.slot] if c.slot in by_slot else at_level(c.level, statics, rotations)
            else:
                key = (c.axis, c.level)
                dt[i] = float(np.mean(by_axis[key])) if key in by_axis else at_level(c.level, rotations, statics)
        return dt

    def value_in_sequence(self, chosen, sequence) -> float:
        """The criterion of the design ``chosen`` written in ``sequence`` (its candidates in the
        order of the scheme file): each placed at its temperature on that timeline (as retime,
        for the chosen candidates only: what the order search needs, ~1 ms for 30 candidates)."""
        from station.design import timeline

        info = self.info
        dt = (timeline.differences(chosen, self.cands, info.temperature, info.clock, chamber=self.chamber,
                                   sequence=sequence, start_s=info.start_s) if self.temperature_timed else {})
        ds = (timeline.time_differences(chosen, self.cands, info.clock, chamber=self.chamber, sequence=sequence,
                                        start_s=info.start_s, temperature=info.temperature) if self.shear else {})
        G = self.G
        F = np.zeros((G, G))
        groups: dict = {}
        for i in chosen:
            c = self.cands[i]
            M = self._placed(i, self.M1[i], info.temp_power, dt.get(i, 0.0), ds.get(i))
            if c.kind == "static":
                F += M
            else:
                g = self.group[i]
                groups[g] = groups.get(g, info.group_prior[g]) + M
        for g, S in groups.items():
            F += complement(info, g, S, G)
        return self.value_of(F)

    # ---------------------------------------------------------------- information
    def information(self, chosen) -> np.ndarray:
        G = self.G
        F = np.zeros((G, G))
        groups: dict = {}
        for i in chosen:
            c = self.cands[i]
            if c.kind == "static":
                F += self.M[i]
            else:
                g = self.group[i]
                groups[g] = groups.get(g, self.info.group_prior[g]) + self.M[i]
        for g, S in groups.items():
            F += complement(self.info, g, S, G)
        return F

    def covariance(self, chosen) -> np.ndarray:
        """Covariance of every reported parameter, reported units."""
        return self.covariance_of(self.information(chosen))

    def covariance_of(self, F) -> np.ndarray:
        """Covariance of every reported parameter from the information F of G, reported units
        (F scaled to a unit diagonal first: its columns' information spans twenty decades in the
        model's internal units)."""
        d = np.sqrt(np.clip(np.diag(F), 0.0, None))       # (a column no candidate informs: 0, rounding -1e-8)
        d[d == 0] = 1.0
        Fs = F / np.outer(d, d) + RIDGE * np.eye(self.G)
        try:
            c = np.linalg.cholesky(Fs)
            inv = np.linalg.inv(c)
            cov = inv.T @ inv
        except np.linalg.LinAlgError:
            cov = np.linalg.pinv(Fs, hermitian=True)
        cov = (cov / np.outer(d, d))[np.ix_(self.cols, self.cols)]
        return cov * np.outer(self.factors, self.factors)

    def sigma(self, chosen) -> np.ndarray:
        return np.sqrt(np.clip(np.diag(self.covariance(chosen)), 0.0, None))

    def value(self, chosen) -> float:
        return self.value_of(self.information(chosen))

    def value_of(self, F) -> float:
        cov = self.covariance_of(F)
        w = self.which
        sub = cov[np.ix_(w, w)]
        if self.criterion.kind == "D":
            sign, logdet = np.linalg.slogdet(sub)
            return float(logdet) if sign > 0 else math.inf
        if self.criterion.kind == "A":
            return float(np.trace(sub))
        sig = np.sqrt(np.clip(np.diag(sub), 0.0, None))
        if WORST_POWER and len(sig) > 1:
            # a power mean near the max (within n^(1/p): 12 % for 9 parameters): smooth, so that a
            # step lowering every 1σ near the worst counts, not only one that lowers the max itself
            top = float(np.max(sig))
            return top * float(np.mean((sig / top) ** WORST_POWER)) ** (1.0 / WORST_POWER) if top > 0 else 0.0
        return float(np.max(sig))


class State:
    """A design's information kept by parts, so that adding or removing a candidate recomputes
    only its axis group's Schur complement: F = statics + sum of the groups' complements."""

    def __init__(self, scorer: Scorer, chosen=()):
        self.sc = scorer
        self.total = np.zeros((scorer.G, scorer.G))      # F: the statics' + every group's complement
        self.groups: dict = {}          # axis group -> [sum of M + prior, members, its complement]
        self.chosen: set = set()
        for i in chosen:
            self.add(i)

    def _group_after(self, g, remove=(), add=()):
        sc = self.sc
        S, members, _ = self.groups.get(g, (sc.info.group_prior[g], 0, None))
        S = S.copy()
        for i in remove:
            S -= sc.M[i]
        for i in add:
            S += sc.M[i]
        members += len(add) - len(remove)
        return S, members, (complement(sc.info, g, S, sc.G) if members > 0 else np.zeros((sc.G, sc.G)))

    def information(self, remove=(), add=()) -> np.ndarray:
        """F of the design with ``remove`` taken out and ``add`` put in (not applied)."""
        sc = self.sc
        F = self.total.copy()
        touched: dict = {}
        for i in remove:
            if sc.cands[i].kind == "static":
                F -= sc.M[i]
            else:
                touched.setdefault(sc.group[i], ([], []))[0].append(i)
        for i in add:
            if sc.cands[i].kind == "static":
                F += sc.M[i]
            else:
                touched.setdefault(sc.group[i], ([], []))[1].append(i)
        for g, (rm, ad) in touched.items():
            if g in self.groups:
                F -= self.groups[g][2]
            F += self._group_after(g, rm, ad)[2]
        return F

    def value(self, remove=(), add=()) -> float:
        return self.sc.value_of(self.information(remove, add))

    def add(self, i) -> None:
        self.total = self.information(add=(i,))
        g = self.sc.group[i]
        if g is not None:
            self.groups[g] = list(self._group_after(g, add=(i,)))
        self.chosen.add(i)

    def remove(self, i) -> None:
        self.total = self.information(remove=(i,))
        g = self.sc.group[i]
        if g is not None:
            self.groups[g] = list(self._group_after(g, remove=(i,)))
            if self.groups[g][1] == 0:
                del self.groups[g]
        self.chosen.discard(i)


@dataclass
class Result:
    chosen: list
    value: float
    seconds: float
    passes: int
    evaluations: int
    history: list = field(default_factory=list)
    order: list | None = None     # the written sequence within each mounting (order_search), None: the rule


def exchange(scorer: Scorer, budget_s: float, fixed_s: float = 0.0, max_passes: int = 20,
             min_statics: int = MIN_STATICS, masks=None, remount_s: float = 0.0, start=None,
             max_statics: int | None = None, retime: bool = True, min_level_axes: int = 0,
             level_cost=None) -> Result:
    """The design within ``budget_s`` (``fixed_s`` of it spent on steps no candidate pays for:
    the first mounting, a warm-up) minimising the criterion (module doc).  ``masks``: each
    candidate's reachable mountings (bits), a mounting beyond the first costing ``remount_s``;
    ``start``: a design to start the exchanges from (its candidates kept while within budget);
    ``max_statics``: at most this many statics (designs of known attitudes: fewer than nine,
    MIN_STATICS_TABLE to MAX_STATICS_TABLE).  ``retime`` (a model with temperature effects,
    Scorer.timed): every candidate placed at its temperature on the design's own timeline at
    the start and at each pass (Scorer.retime); False: at the temperatures the scorer has.
    ``min_level_axes``: at least this many body axes turned about with the table axis horizontal
    (elevation 0), chosen greedily after the statics and kept by every exchange (designs of
    unknown attitude: MIN_LEVEL_AXES).  ``level_cost(levels)``: the time (s) the chamber's
    setpoints of the candidates' levels cost (ramps, soaks, the operator), for a chamber's
    candidates (Candidate.level); the remounts are then counted level by level (the scheme is
    written so: timeline.written_order)."""
    timed = scorer.timed and retime

    cands = scorer.cands
    n = len(cands)
    secs = np.array([c.seconds for c in cands])
    evaluations = 0

    def allowed(chosen: set, j: int) -> bool:
        c = cands[j]
        if j in chosen:
            return False
        if (max_statics is not None and c.kind == "static"
                and sum(cands[i].kind == "static" for i in chosen) >= max_statics):
            return False
        for i in chosen:
            o = cands[i]
            if c.slot and o.slot == c.slot:
                return False
            if c.kind == "rotation" and o.kind == "rotation" and o.axis[0] == c.axis[0] and o.axis != c.axis:
                return False
        return True

    def level_axes(chosen) -> int:
        return len({cands[i].axis[0] for i in chosen if cands[i].kind == "rotation" and cands[i].axis[1] == 0.0})

    def keeps_level(rest, j) -> bool:
        """A design of ``rest`` plus j keeps min_level_axes (or adds to them when short)."""
        have = level_axes(rest)
        if have >= min_level_axes:
            return True
        c = cands[j]
        return c.kind == "rotation" and c.axis[1] == 0.0 and c.axis[0] not in {
            cands[i].axis[0] for i in rest if cands[i].kind == "rotation"}

    costs: dict = {}

    def time_of(chosen) -> float:
        t = fixed_s + float(sum(secs[i] for i in chosen))
        if level_cost is not None:
            levels = frozenset(cands[i].level for i in chosen)
            if levels not in costs:
                costs[levels] = float(level_cost(levels))
            t += costs[levels]
            if masks is not None and remount_s:
                by_level: dict = {}
                for i in chosen:
                    by_level.setdefault(cands[i].level, []).append(masks[i])
                t += remount_s * max(0, sum(mountings_needed(m) for m in by_level.values()) - 1)
            return t
        if masks is not None and remount_s:
            t += remount_s * max(0, mountings_needed([masks[i] for i in chosen]) - 1)
        return t

    if timed:
        scorer.retime(start or (), masks, budget_s)
    state = State(scorer)

    def score(remove=(), add=()) -> float:
        nonlocal evaluations
        evaluations += 1
        return state.value(remove, add)

    if start is not None:
        # the statics and the turns about level axes first: a budget shrunk by the compiler's
        # count drops other turns, not those the rules keep
        for j in sorted(start, key=lambda j: (cands[j].kind != "static",
                                              not (cands[j].kind == "rotation" and cands[j].axis[1] == 0.0))):
            if allowed(state.chosen, j) and time_of(state.chosen | {j}) <= budget_s:
                state.add(j)
    statics = [j for j in range(n) if cands[j].kind == "static"]
    shortest = {}
    for j in statics:
        s = cands[j].slot
        if s not in shortest or cands[j].dwell_s < cands[shortest[s]].dwell_s:
            shortest[s] = j
    longer_of = {i: [j for j in statics if cands[j].slot == cands[i].slot and cands[j].dwell_s > cands[i].dwell_s]
                 for i in statics}
    # 1. nine statics, greedily, at their shortest dwell
    while sum(cands[i].kind == "static" for i in state.chosen) < min_statics:
        best, best_v = None, math.inf
        for j in shortest.values():
            if allowed(state.chosen, j) and time_of(state.chosen | {j}) <= budget_s:
                v = score(add=(j,))
                if best is None or v < best_v:
                    best, best_v = j, v
        if best is None:
            least = fixed_s + float(np.sort(secs[list(shortest.values())])[:min_statics].sum())
            raise UserError(f"a budget of {budget_s:.0f} s holds fewer than {min_statics} static attitudes on "
                            f"this table (the least: {least:.0f} s)")
        state.add(best)
    # 1b. turns about level axes (a design of unknown attitudes whose turns are all about vertical
    # axes is one the estimator's noisy fits do not converge on: docs/design.md, thirteenth session)
    while level_axes(state.chosen) < min_level_axes:
        best, best_v = None, math.inf
        for j in range(n):
            if (cands[j].kind == "rotation" and cands[j].axis[1] == 0.0 and keeps_level(state.chosen, j)
                    and allowed(state.chosen, j) and time_of(state.chosen | {j}) <= budget_s):
                v = score(add=(j,))
                if best is None or v < best_v:
                    best, best_v = j, v
        if best is None:
            break           # (the table turns about no further level axis, or no time: as it is)
        state.add(best)
    must_level = min(min_level_axes, level_axes(state.chosen))
    # 2. greedy: the largest fall of the criterion per second of table time
    current = score()
    while True:
        best, best_gain = None, 0.0
        for j in range(n):
            if not allowed(state.chosen, j) or time_of(state.chosen | {j}) > budget_s:
                continue
            v = score(add=(j,))
            if not math.isfinite(current):
                gain = math.inf if math.isfinite(v) else 0.0
                if best is None and gain > 0:
                    best, best_gain = j, gain
                continue
            gain = (current - v) / secs[j]
            if gain > best_gain:
                best, best_gain = j, gain
        if best is None:
            break
        state.add(best)
        current = score()
    # 3. exchanges: for each chosen candidate in turn its best exchange (or, with time left, an
    # addition), applied at once when it improves; passes until one changes nothing
    passes = 0
    history = [current]
    for passes in range(1, max_passes + 1):
        changed = False
        if timed:
            # every candidate at its temperature on this design's timeline (the last pass moved it)
            scorer.retime(state.chosen, masks, budget_s)
            state = State(scorer, state.chosen)
            current = score()
        state.total = scorer.information(state.chosen)      # (no rounding carried from pass to pass)
        for i in sorted(state.chosen):
            if i not in state.chosen:
                continue
            rest = state.chosen - {i}
            if cands[i].kind == "static" and sum(cands[k].kind == "static" for k in rest) < min_statics:
                swaps = statics             # (the nine statics stay nine)
            else:
                swaps = range(n)
            t_rest = time_of(rest)
            short = level_axes(rest) < must_level
            best_j, best_v = None, current
            for j in swaps:
                if j == i or not allowed(rest, j) or t_rest + secs[j] > budget_s:
                    continue
                if short and not keeps_level(rest, j):
                    continue
                if time_of(rest | {j}) > budget_s:
                    continue
                v = score(remove=(i,), add=(j,))
                if v < best_v - 1e-9 * max(1.0, abs(best_v)):
                    best_j, best_v = j, v
            if best_j is not None:
                state.remove(i)
                state.add(best_j)
                _take_place(scorer, i, best_j)
                current = best_v
                history.append(current)
                changed = True
        # a static lengthened, paid for by dropping another chosen candidate: a move one exchange
        # cannot make when the budget is spent (a longer dwell needs more time than it frees)
        for i in sorted(state.chosen):
            if i not in state.chosen or cands[i].kind != "static":
                continue
            longer = [j for j in longer_of[i] if j not in state.chosen]
            best_move, best_v = None, current
            for k in sorted(state.chosen):
                if k == i:
                    continue
                rest = state.chosen - {i, k}
                if cands[k].kind == "static" and sum(cands[m].kind == "static" for m in rest) + 1 < min_statics:
                    continue
                if level_axes(rest) < must_level:
                    continue
                for j in longer:
                    if not allowed(rest, j) or time_of(rest | {j}) > budget_s:
                        continue
                    v = score(remove=(i, k), add=(j,))
                    if v < best_v - 1e-9 * max(1.0, abs(best_v)):
                        best_move, best_v = (k, j), v
            if best_move is not None:
                k, j = best_move
                state.remove(i)
                state.remove(k)
                state.add(j)
                _take_place(scorer, i, j)
                current = best_v
                history.append(current)
                changed = True
        for j in range(n):          # time freed by the exchanges
            if allowed(state.chosen, j) and time_of(state.chosen | {j}) <= budget_s:
                v = score(add=(j,))
                if v < current - 1e-9 * max(1.0, abs(current)):
                    state.add(j)
                    current = v
                    history.append(current)
                    changed = True
        if not changed:
            break
    chosen = state.chosen
    if timed:                       # the value on the design's own timeline
        scorer.retime(chosen, masks, budget_s)
        state = State(scorer, chosen)
        current = score()
    return Result(sorted(chosen), current, time_of(chosen), passes, evaluations, history, order=scorer.order)


def _take_place(scorer: Scorer, old: int, new: int) -> None:
    """In the search's written sequence (Scorer.order), candidate ``new`` takes ``old``'s place
    (an exchange keeps the timeline of the rest)."""
    if scorer.order is not None:
        scorer.order = [new if i == old else i for i in scorer.order if i != new]


def order_search(scorer: Scorer, chosen, masks=None, max_passes: int = 3) -> tuple[list, float, int]:
    """The sequence of a design's candidates on its timeline that minimises the criterion: from
    the written order (Scorer.order, else the writer's rule), every two candidates of one chamber
    level and one mounting exchanged in place (a remount or a chamber step is never added), the
    best exchange of each candidate applied at once, passes until one changes nothing (or
    ``max_passes``).  Only the temperatures move: a temperature coefficient is told from the
    biases by the data whose bias is seen alone (turns about a vertical axis, statics with the
    axis level) at the coldest and the warmest times, the attitudes that fix the scale factors
    and misalignments best near the mean temperature, where the coefficient does not couple to
    them (docs/design.md, fifteenth session).  Sets Scorer.order; (sequence, value, evaluations)."""
    from station.design import timeline

    groups = timeline.written_groups(chosen, scorer.cands, masks, scorer.chamber, scorer.order)
    sequence = [i for g in groups for i in g]
    span = []                   # per position, the (first, end) positions of its group
    k = 0
    for g in groups:
        span += [(k, k + len(g))] * len(g)
        k += len(g)
    best = scorer.value_in_sequence(chosen, sequence)
    evaluations = 1
    for _ in range(max_passes):
        changed = False
        for a in range(len(sequence)):
            first, end = span[a]
            best_b, best_v = None, best
            for b in range(first, end):
                if b == a:
                    continue
                trial = list(sequence)
                trial[a], trial[b] = trial[b], trial[a]
                v = scorer.value_in_sequence(chosen, trial)
                evaluations += 1
                if v < best_v - 1e-9 * max(1.0, abs(best_v)):
                    best_b, best_v = b, v
            if best_b is not None:
                sequence[a], sequence[best_b] = sequence[best_b], sequence[a]
                best = best_v
                changed = True
        if not changed:
            break
    scorer.order = list(sequence)
    return sequence, best, evaluations


def timed_exchange(scorer: Scorer, budget_s: float, fixed_s: float = 0.0, max_passes: int = 20, *,
                   start=None, **kw) -> Result:
    """exchange() for a model with temperature effects in two stages: first every candidate at
    the temperature it had in the candidates' own capture (the search before the thirteenth
    session, whose landscape the exchanges move through well), then from that design with every
    candidate placed on the design's own timeline at each pass (the honest criterion: a design
    is only left for a better one by it).  Measured on the temperature design (3715 s): the
    timeline alone from the start found a design of 8.40 µg/°C by the estimator's fit, the two
    stages (docs/design.md, thirteenth session).  Without temperature effects: exchange()."""
    if not scorer.timed:
        return exchange(scorer, budget_s, fixed_s, max_passes, start=start, **kw)
    if start is None:
        scorer.order = None
    scorer.natural()
    first = exchange(scorer, budget_s, fixed_s, max_passes, start=start, retime=False, **kw)
    second = exchange(scorer, budget_s, fixed_s, min(max_passes, TIMED_PASSES), start=first.chosen,
                      retime=True, **kw)
    second.evaluations += first.evaluations
    second.passes += first.passes
    if ORDER_PASSES:
        # the order of the segments on the timeline, then the exchanges again on it (each
        # exchange's newcomer in its predecessor's place), then the order again
        masks = kw.get("masks")
        for _ in range(ORDER_ROUNDS):
            _, _, n = order_search(scorer, second.chosen, masks, ORDER_PASSES)
            second.evaluations += n
            third = exchange(scorer, budget_s, fixed_s, min(max_passes, TIMED_PASSES), start=second.chosen,
                             retime=True, **kw)
            third.evaluations += second.evaluations
            third.passes += second.passes
            second = third
        _, value, n = order_search(scorer, second.chosen, masks, ORDER_PASSES)
        second.evaluations += n
        second.order = scorer.order
        scorer.retime(second.chosen, kw.get("masks"), budget_s)
        second.value = value
    return second


def mountings_needed(chosen_masks) -> int:
    """The fewest mountings (greedy set cover) that reach every chosen candidate: at each step the
    mounting (bit) that reaches the most candidates left, the lowest bit of equals.  Counted over
    the bits the masks have (not every bit up to the highest: the fixtures' are 24 and above), and
    remembered per set of masks: the exchange search times the same sets again and again (the
    nineteenth session: 9,815 calls, a third of `station design`'s CPU in test_design's design)."""
    return _mountings_needed(tuple(sorted(chosen_masks)))


@functools.lru_cache(maxsize=4096)
def _mountings_needed(masks: tuple) -> int:
    left, n = list(masks), 0
    while left:
        counts: dict = {}
        for m in left:
            while m:
                low = m & -m
                counts[low] = counts.get(low, 0) + 1
                m ^= low
        best = max(counts.items(), key=lambda kv: (kv[1], -kv[0]))[0]
        left = [m for m in left if not m & best]
        n += 1
    return n
