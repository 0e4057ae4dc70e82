"""Add the missing effect and watch the error fall: the diagnose -> add -> refit loop."""
from __future__ import annotations

from dataclasses import dataclass

from station.diagnose.core import Diagnosis, diagnose, rms_by_kind
from station.estimate import lsq
from station.model.registry import EffectRegistry

MAX_STEPS = 6


@dataclass
class Step:
    added: str
    before: Diagnosis
    after: Diagnosis
    predicted_drop: float
    actual_drop: float
    estimate: list            # (name, value, sigma, unit) of the added effect, after the refit


def added_parameters(after: Diagnosis, effect_id: str) -> list:
    res = after.result
    names, values, units_, cov = lsq.reported(res, "m/s^2", "deg/s")
    effect = next(e for e in res.model.effects if e.id == effect_id)
    own = {p.name for p in effect.params}
    return [(n, float(v), float(cov[i, i]) ** 0.5, u)
            for i, (n, v, u) in enumerate(zip(names, values, units_)) if n in own]


def run(summaries, effects=(), attitudes="auto", progress=None,
        registry: EffectRegistry | None = None) -> tuple[list[Step], Diagnosis]:
    """Diagnose; while a candidate is significant, add the best one, refit, diagnose again."""
    registry = registry or EffectRegistry()
    current = diagnose(lsq.fit(summaries, [registry.create(e) for e in effects], attitudes), registry=registry)
    steps = []
    while len(steps) < MAX_STEPS:
        best = next((c for c in current.candidates if c.significant), None)
        if best is None:
            break
        if progress:
            progress(best.effect)
        ids = [e.id for e in current.result.model.effects] + [best.effect]
        after = diagnose(lsq.fit(summaries, [registry.create(e) for e in ids], attitudes), registry=registry)
        steps.append(Step(best.effect, current, after, best.predicted_chi2_drop,
                          current.chi2 - after.chi2, added_parameters(after, best.effect)))
        current = after
    return steps, current


def comparison_rows(before: Diagnosis, after: Diagnosis) -> list[tuple[str, float, float]]:
    """(what, before, after): chi2, reduced chi2 and RMS residual per segment kind, sensor, axis."""
    rows = [("chi2", before.chi2, after.chi2), ("reduced chi2", before.reduced_chi2, after.reduced_chi2)]
    b, a = rms_by_kind(before.segments), rms_by_kind(after.segments)
    for key in b:
        rows.append((f"RMS {key[0]} {key[1]} {key[2]} (sigma)", b[key], a.get(key, float("nan"))))
    return rows
