"""Add the missing effect and watch the error fall: the diagnose -> add -> refit loop.

An effect is kept only if it passes three checks, so that adding it cannot make the calibration
worse where it is used:
  1. significant: its score test, over-dispersion-corrected and Holm-corrected over the family of
     candidates, with a plausible size (station.diagnose.core);
  2. out of sample: with it, the other segments predict each left-out segment better (the
     leave-one-segment-out score of station.diagnose.holdout falls);
  3. it explains the failure: when the fit failed, the chi2 drop is at least MIN_SHARE (half) of the
     excess misfit (chi2 - dof); a smaller drop "reduces chi2 but does not explain the failure".
Candidates that fail are reported with the reason and the next one is tried (at most
MAX_TRIES per step).
"""
from __future__ import annotations

from dataclasses import dataclass, field

from station.diagnose.core import Diagnosis, diagnose, fit_fails, rms_by_kind
from station.diagnose.holdout import judge, leave_one_segment_out
from station.diagnose.words import caveats
from station.estimate import lsq
from station.model.registry import EffectRegistry

MAX_STEPS = 6
MAX_TRIES = 3          # significant candidates tried per step


@dataclass
class Step:
    added: str
    before: Diagnosis
    after: Diagnosis
    predicted_drop: float
    actual_drop: float
    estimate: list            # (name, value, sigma, unit) of the added effect, after the refit
    holdout_before: float = float("nan")     # leave-one-segment-out score, same segments
    holdout_after: float = float("nan")
    share: float | None = None               # of the excess chi2 explained (None: the fit passed)
    caveats: list = field(default_factory=list)  # what this capture cannot tell apart from it


@dataclass
class Rejection:
    effect: str
    reason: str
    actual_drop: float
    holdout_before: float
    holdout_after: float
    share: float | None
    estimate: list = field(default_factory=list)


def added_parameters(after: Diagnosis, effect_id: str) -> list:
    res = after.result
    names, values, units_, cov = lsq.reported(res, "m/s^2", "deg/s")
    effect = next(e for e in res.model.effects if e.id == effect_id)
    own = {p.name for p in effect.params}
    return [(n, float(v), float(cov[i, i]) ** 0.5, u)
            for i, (n, v, u) in enumerate(zip(names, values, units_)) if n in own]


def run(summaries, effects=(), attitudes="auto", progress=None,
        registry: EffectRegistry | None = None) -> tuple[list[Step], Diagnosis]:
    """Diagnose; while a significant candidate passes the checks, add it, refit, diagnose again."""
    registry = registry or EffectRegistry()
    current = diagnose(lsq.fit(summaries, [registry.create(e) for e in effects], attitudes), registry=registry)
    h_current = None          # the leave-one-segment-out check, only once a candidate is tried
    steps, rejected = [], []
    refused: set = set()
    while len(steps) < MAX_STEPS:
        tries = [c for c in current.candidates if c.significant and c.effect not in refused][:MAX_TRIES]
        kept = None
        for cand in tries:
            if progress:
                progress(cand.effect)
            ids = [e.id for e in current.result.model.effects] + [cand.effect]
            after = diagnose(lsq.fit(summaries, [registry.create(e) for e in ids], attitudes), registry=registry)
            if h_current is None:
                h_current = leave_one_segment_out(current.result)
            h_after = leave_one_segment_out(after.result)
            ok, reason, share, cv_b, cv_a = judge(current, after, h_current, h_after)
            if ok:
                kept = Step(cand.effect, current, after, cand.predicted_chi2_drop, current.chi2 - after.chi2,
                            added_parameters(after, cand.effect), cv_b, cv_a, share,
                            caveats(summaries, cand.effect))
                break
            refused.add(cand.effect)
            rejected.append(Rejection(cand.effect, reason, current.chi2 - after.chi2, cv_b, cv_a, share,
                                      added_parameters(after, cand.effect)))
        if kept is None:
            break
        steps.append(kept)
        current, h_current = kept.after, h_after
    current.rejected = rejected
    conclude(current, summaries, steps)
    return steps, current


def conclude(d: Diagnosis, summaries, steps=(), search_terms: bool = True) -> Diagnosis:
    """The final verdict: when the model still fails and no significant library effect is left
    to add, search the dictionary of terms outside the library and say what it found."""
    if not fit_fails(d.result):
        return d

    def specific(failures):
        return [f for f in failures if "a step in time" in f or "was moved or remounted" in f
                or "drift steadily with time" in f]

    now = specific(d.failures)
    first = specific(steps[0].before.failures) if steps else []
    added = f" after adding {', '.join(st.added for st in steps)}" if steps else ""
    pending = [c for c in d.candidates if c.significant and c.effect not in {r.effect for r in d.rejected}]
    if pending and not steps and not d.rejected:
        # plain diagnose: the verdict already names the likely effect; a step, drift or moved
        # axis in the words comes first all the same
        if now:
            d.verdict += f"; but first look at this: {now[0]}"
        return d
    if search_terms:
        from station.diagnose import terms

        d.proposal = terms.propose(d, summaries)
    head = f"the model does not explain the data{added} (reduced chi2 {d.reduced_chi2:.3g})"
    if now:
        head += f"; first look at this: {now[0]}"
    elif first:
        head += f"; first look at this (seen before any effect was added): {first[0]}"
    if d.rejected:
        head += f"; tried and not kept: {', '.join(r.effect for r in d.rejected)}"
    prop = d.proposal
    if prop is not None:
        check = ("and predicts left-out segments better" if prop.kept
                 else f"but is not kept: {prop.reason}")
        d.verdict = (f"{head}; outside the library the residuals follow {'; '.join(prop.lines())} "
                     f"(with these terms reduced chi2 {prop.reduced_after:.3g}, {check}); write them "
                     "as an effect plugin with --emit-effect FILE, check the physics, add it with --add")
    else:
        d.verdict = (f"{head}; no effect of the library and no term of the dictionary accounts for it: "
                     "see where it fails")
    return d


def comparison_rows(before: Diagnosis, after: Diagnosis) -> list[tuple[str, float, float]]:
    """(what, before, after): chi2, reduced chi2 and RMS residual per segment kind, sensor, axis."""
    rows = [("chi2", before.chi2, after.chi2), ("reduced chi2", before.reduced_chi2, after.reduced_chi2)]
    b, a = rms_by_kind(before.segments), rms_by_kind(after.segments)
    for key in b:
        rows.append((f"RMS {key[0]} {key[1]} {key[2]} (sigma)", b[key], a.get(key, float("nan"))))
    return rows
