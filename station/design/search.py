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
is spent; then exchanges: every chosen candidate against every one not chosen (a static's dwell
against another dwell of it is such an exchange), the best improving exchange that keeps the
time within the budget taken, until none improves or ``max_passes`` passes.
"""
from __future__ import annotations

import fnmatch
import math
from dataclasses import dataclass, field

import numpy as np

from station.core.errors import UserError

RIDGE = 1e-10            # on the unit-diagonal information: a column nothing sees gets 1σ 1e5 of its size
MIN_STATICS = 9           # lsq's attitudes="auto": every static's attitude unknown from nine on


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
    slot: tuple = ()              # at most one candidate per slot: a static's attitude
    axis: tuple = ()              # rotations: (axis, elevation) group; one elevation per axis


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
        for c in candidates:
            if c.kind == "static":
                self.M.append(info.static[c.key[:-1]] * c.dwell_s)
            else:
                self.M.append(info.rotation[c.key][1])

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
                g = c.axis
                groups[g] = groups.get(g, self.info.group_prior[g]) + self.M[i]
        for S in groups.values():
            F += _schur(S, G)
        return F

    def covariance(self, chosen) -> np.ndarray:
        """Covariance of every reported parameter, reported units (F scaled to a unit diagonal
        first: its columns' information spans twenty decades in the model's internal units)."""
        F = self.information(chosen)
        d = np.sqrt(np.diag(F))
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
        cov = self.covariance(chosen)
        w = self.which
        sub = cov[np.ix_(w, w)]
        if self.criterion.kind == "D":
            sign, logdet = np.linalg.slogdet(sub)
            return float(logdet) if sign > 0 else math.inf
        if self.criterion.kind == "A":
            return float(np.trace(sub))
        return float(np.sqrt(np.max(np.diag(sub))))


def _schur(S: np.ndarray, G: int) -> np.ndarray:
    A = S[G:, G:]
    B = S[:G, G:]
    d = np.sqrt(np.diag(A))
    d[d == 0] = 1.0         # (scaled to unit diagonal: a nuisance held only by its prior is kept)
    Bs = B / d
    return S[:G, :G] - Bs @ np.linalg.pinv(A / np.outer(d, d), rcond=1e-13, hermitian=True) @ Bs.T


@dataclass
class Result:
    chosen: list
    value: float
    seconds: float
    passes: int
    evaluations: int
    history: list = field(default_factory=list)


def exchange(scorer: Scorer, budget_s: float, fixed_s: float = 0.0, max_passes: int = 20,
             min_statics: int = MIN_STATICS) -> Result:
    """The design within ``budget_s`` (``fixed_s`` of it spent on steps no candidate pays for:
    the first mounting, a warm-up) minimising the criterion (module doc)."""
    cands = scorer.cands
    n = len(cands)
    secs = np.array([c.seconds for c in cands])
    evaluations = 0

    def allowed(chosen: set, j: int) -> bool:
        c = cands[j]
        if j in chosen:
            return False
        for i in chosen:
            o = cands[i]
            if c.slot and o.slot == c.slot:
                return False
            if c.kind == "rotation" and o.kind == "rotation" and o.axis[0] == c.axis[0] and o.axis != c.axis:
                return False
        return True

    def time_of(chosen) -> float:
        return fixed_s + float(sum(secs[i] for i in chosen))

    def score(chosen) -> float:
        nonlocal evaluations
        evaluations += 1
        return scorer.value(chosen)

    chosen: set = set()
    statics = [j for j in range(n) if cands[j].kind == "static"]
    shortest = {}
    for j in statics:
        s = cands[j].slot
        if s not in shortest or cands[j].dwell_s < cands[shortest[s]].dwell_s:
            shortest[s] = j
    # 1. nine statics, greedily, at their shortest dwell
    while sum(cands[i].kind == "static" for i in chosen) < min_statics:
        best, best_v = None, math.inf
        for j in shortest.values():
            if allowed(chosen, j) and time_of(chosen | {j}) <= budget_s:
                v = score(chosen | {j})
                if v < best_v:
                    best, best_v = j, v
        if best is None:
            raise UserError(f"a budget of {budget_s:.0f} s holds fewer than {min_statics} static attitudes on "
                            f"this table (the least: {fixed_s + sorted(secs[list(shortest.values())])[:min_statics].sum():.0f} s)")
        chosen.add(best)
    # 2. greedy: the largest fall of the criterion per second
    current = score(chosen)
    while True:
        best, best_gain = None, 0.0
        for j in range(n):
            if not allowed(chosen, j) or time_of(chosen | {j}) > budget_s:
                continue
            v = score(chosen | {j})
            gain = (current - v) / secs[j] if math.isfinite(current) else (-v if math.isfinite(v) else 0.0)
            if (not math.isfinite(current) and math.isfinite(v)) or gain > best_gain:
                if best is None or gain > best_gain or not math.isfinite(current):
                    best, best_gain = j, gain
        if best is None:
            break
        chosen.add(best)
        current = score(chosen)
    # 3. exchanges (and additions that the freed time allows)
    passes = 0
    history = [current]
    for passes in range(1, max_passes + 1):
        best_swap, best_v = None, current
        for i in list(chosen):
            rest = chosen - {i}
            if cands[i].kind == "static" and sum(cands[k].kind == "static" for k in rest) < min_statics:
                swaps = [j for j in statics if cands[j].slot == cands[i].slot or True]
                swaps = [j for j in swaps if cands[j].kind == "static"]
            else:
                swaps = range(n)
            t_rest = time_of(rest)
            for j in swaps:
                if j == i or not allowed(rest, j) or t_rest + secs[j] > budget_s:
                    continue
                v = score(rest | {j})
                if v < best_v - 1e-12 * max(1.0, abs(best_v)):
                    best_swap, best_v = (i, j), v
        if best_swap is None:
            # room left for one more?
            added = False
            for j in range(n):
                if allowed(chosen, j) and time_of(chosen | {j}) <= budget_s:
                    v = score(chosen | {j})
                    if v < best_v:
                        best_swap, best_v, added = (None, j), v, True
            if not added:
                break
        i, j = best_swap
        if i is not None:
            chosen.discard(i)
        chosen.add(j)
        current = best_v
        history.append(current)
    return Result(sorted(chosen), current, time_of(chosen), passes, evaluations, history)
