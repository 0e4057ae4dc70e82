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
After each addition every effect the loop added earlier is tested again (backward elimination):
one that the data no longer need with the new effect in the model (removing it raises chi2 by
less than the significance level allows, over-dispersion-corrected, and the other segments
predict each left-out segment no worse without it) is dropped, and the step says so.  An effect
added early can be the partial stand-in for a later one (a scale asymmetry fitted to part of a
rate-squared term when the rotations are at several rates).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import special

from station.diagnose.core import (ALPHA, Diagnosis, chi2_sf, diagnose, fit_fails, overdispersion, rms_by_kind,
                                   within_calibration_threshold, not_converged)
from station.diagnose.holdout import Holdout, judge, leave_one_segment_out
from station.diagnose.words import caveats, failure_account
from station.estimate import lsq, profile
from station.model.registry import EffectRegistry

# failures that name a fault of the bench (station.diagnose.words): terms found outside the library
# would fit the bench's fault into the IMU's calibration (a table vibrating once per revolution was
# taken for gyro terms that raised the held-out gyro error from 417 to 210,574 ppm), so --auto
# does not carry them while one is named
BENCH_FAULTS = ("once per revolution along the rotation's own axis", "was moved or remounted")
REMOUNT_FAULT, REMOUNT = BENCH_FAULTS[1], "remount_per_segment"    # tried first when the words say it


def bench_fault(d: Diagnosis) -> str:
    """The first failure sentence of ``d`` that names a fault of the bench ("" when none)."""
    return next((f for f in d.failures if any(k in f for k in BENCH_FAULTS)), "")


def named_in_words(cands, d: Diagnosis, registry) -> list:
    """The candidates whose effect the failure's words name (the effect's ``named_by`` phrases, e.g.
    table_vibration_once_per_rev for "once per revolution along the rotation's own axis"), in rank
    order: the words point at a fault of the bench, so its own effect is tried before the IMU's
    effects that could take part of it (a vibration once taken for gyro terms, above)."""
    from station.core.errors import UserError

    out = []
    for c in cands:
        try:
            phrases = getattr(registry.create(c.effect), "named_by", ())
        except UserError:
            continue
        if any(p in f for p in phrases for f in d.failures):
            out.append(c)
    return out


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
    separations: list = field(default_factory=list)  # the station design --separate commands for those
                                             #   caveats that name a library effect (diagnose/suggest.py)
    removed: list = field(default_factory=list)  # (effect, reason): earlier additions no longer needed
    discovered: bool = False                 # terms found outside the library (terms.TermsEffect)
    instead_of: str = ""                     # the library effect the terms beat out of sample
    rivals: list = field(default_factory=list)  # library effects that explain this step's misfit too: the
                                             #   capture cannot tell the added one from them (or from terms
                                             #   they stand for); suggest.py prints the commands that separate them
    proposal: object = None                  # terms.Proposal of a discovered step

    @property
    def not_revealed(self) -> list:
        """The added effect's parameters the refit holds by their prior (not revealed by the
        capture: a calibration does not write them, docs/calibration-file.md); their estimate
        is that posterior, said so where it is printed."""
        model = getattr(getattr(self.after, "result", None), "model", None)
        held = set(getattr(model, "unobservable", None) or ())
        return [n for n, _, _, _ in self.estimate if n in held]

    @property
    def held_pulled(self) -> dict:
        """{name: pull in sigma} of the held parameters whose prior the data contradict
        (lsq.contradicted_held: beyond the prior's own check; issue 28, nineteenth session)."""
        result = getattr(self.after, "result", None)
        if result is None or not getattr(getattr(result, "model", None), "unobservable", None):
            return {}
        from station.estimate import lsq

        return lsq.contradicted_held(result)[0]

    def held_words(self, name: str) -> str:
        """What follows a held parameter's estimate where a step is printed."""
        if name not in self.not_revealed:
            return ""
        pull = self.held_pulled.get(name)
        return (" (not revealed: held by its prior, not written"
                + ("" if pull is None else f"; the data pull it {pull:+.1f} sigma from that prior") + ")")


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


def _rebuild(effects, registry, extra=()) -> list:
    """Fresh instances of the model's library effects (by id) and the same discovered terms
    (they are not in the registry), then ``extra``."""
    from station.diagnose.terms import TermsEffect

    return [e if isinstance(e, TermsEffect) else _created(registry, e.id, e.state()) for e in effects] + list(extra)


def _created(registry, effect_id: str, state: dict | None = None):
    """A fresh instance of a library effect with what an earlier instance or the candidate's
    score test decided restored (a bias step's located time); setup() decides the rest again.  An
    effect of station/model/unlisted.py that --auto added (unlisted_candidates) is made from its
    class: it is not in the registry, so later diagnoses do not rank it among the library's."""
    from station.model.unlisted import UNLISTED

    if effect_id in UNLISTED and effect_id not in registry:
        from station.model.raw_counts import in_capture_units

        e = in_capture_units(UNLISTED[effect_id])()
        e._station_source = f"{UNLISTED_SPEC}:{UNLISTED[effect_id].__name__}"
        if state:
            e.restore(state)
        return e
    e = registry.create(effect_id)
    if state:
        e.restore(state)
    return e


def _said(after: Diagnosis, effect_id: str) -> list[str]:
    """An added effect's own words at the refit (a bias step: "gyro z bias steps by ... at t = ...")
    and its notes (where its time was located)."""
    import numpy as np

    effect = next((e for e in after.result.model.effects if e.id == effect_id), None)
    if effect is None or not callable(getattr(effect, "words", None)):
        return []
    est = added_parameters(after, effect_id)
    # a parameter held by its prior (not revealed, not written) is no finding: its 1-sigma taken as
    # infinite, as station estimate's notes do (lsq: held_names)
    held = set(getattr(after.result.model, "unobservable", None) or ())
    return effect.words(np.array([v for _, v, _, _ in est]),
                        np.array([np.inf if n in held else s for n, _, s, _ in est])) + list(effect.notes())


DISCOVERED = "discovered_terms"
UNLISTED_SPEC = "station.model.unlisted"


def revealed(cand, effect) -> bool:
    """The data reveal every parameter of ``effect``: none aliased with the model's, each 1-sigma
    from this capture (the score test's, with the over-dispersion) at most its typical size -- the
    estimator's own "not revealed" rule (station estimate).  A significant score whose parameters
    the capture cannot size is a misfit the effect's columns happen to match, not the effect: on
    the goal harness's clean capture of 10 deg/s partial turns the gyro axes' tilt with temperature
    scored p = 9e-5 (Holm 0.002) at 394 +/- 98 arcsec/degC, 1-sigma 68-128 against a typical 10,
    and was added (a false alarm) before this rule."""
    typical = {p.name: p.typical for p in effect.params}
    return not cand.aliased and all(s <= typical[n] for n, s in zip(cand.names, cand.sigma))


def unlisted_candidates(current: Diagnosis, exclude=()) -> list:
    """The effects of station/model/unlisted.py not in the model, by the rule --auto applies to the
    library's (core.rank_candidates): each score-tested at the current fit with its over-dispersion,
    significant when its p-value, Holm-corrected over the family of the library's candidates at
    this fit and these together (the family enlarged by them: no effect gets an easier test for
    being outside the library), is below ALPHA, its one-step estimate is of a plausible size, and
    the data reveal it (``revealed``: every parameter's 1-sigma at most its typical size).  The significant ones, the largest predicted
    chi2 drop first; each tried as a library candidate is (the out-of-sample check and the share
    of the excess misfit, holdout.judge)."""
    from station.diagnose.core import score_test
    from station.model.raw_counts import in_capture_units
    from station.model.unlisted import UNLISTED

    result = current.result
    in_model = {e.id for e in result.model.effects}
    phi = overdispersion(result)
    mine = []
    for eid, cls in UNLISTED.items():
        if eid in in_model or eid in exclude:
            continue
        try:
            c = score_test(result, in_capture_units(cls)(), overdispersion=phi)
        except Exception:       # nothing of it on this capture (no temperature, no rotation): not a candidate
            continue
        c.source = f"{UNLISTED_SPEC}:{cls.__name__}"
        mine.append(c)
    family = sorted([*current.candidates, *mine], key=lambda c: c.p_value)
    m, running, corrected = len(family), 0.0, {}
    for rank, c in enumerate(family):            # Holm's step-down over the enlarged family
        running = max(running, min(1.0, c.p_value * (m - rank)))
        corrected[id(c)] = running
    for c in mine:
        c.p_value_corrected = corrected[id(c)]
        c.significant = (c.dof > 0 and c.p_value_corrected < ALPHA and c.plausible
                         and revealed(c, UNLISTED[c.effect]()))
    return sorted([c for c in mine if c.significant], key=lambda c: -c.predicted_chi2_drop)
MAX_TERM_STEPS = 2       # searches of the dictionary whose terms are added by --auto


def _terms_step(current: Diagnosis, h_current, summaries, registry, instead=None, ties=None):
    """The terms of the dictionary as a step, when they pass the stop rule (judge): with
    ``instead`` = (effect id, its diagnosis, its Holdout), only when they also beat that library
    effect out of sample (a lower leave-one-segment-out score on the same segments) and in chi2
    by more than the 1 % point of chi2 on as many degrees of freedom as the terms have
    parameters beyond the effect's (at least one): a library effect and its equivalent terms fit
    alike, and more terms always fit a little better; only a clearly better fit displaces it.
    Nor when any term is the effect's own (its column inside what the effect's parameters can do:
    terms.within): then the effect stays and the rest is searched at the next step.  Only properties of the
    sensor are carried into the model: a drift in time or a step at a segment boundary is an
    event of this capture (the verdict says it in words; apply could not compensate it)."""
    from scipy import special

    from station.diagnose import terms

    prop = _determined(terms.propose(current, summaries, h_current, events=False), current, summaries, h_current)
    if prop is None or not prop.kept:
        return None
    if instead is not None:
        eid, lib_after, h_lib = instead
        own = terms.within(current.result, registry.create(eid), [f.term for f in prop.found])
        if any(c >= terms.OWN_COS for c in own):
            # some of the terms are the effect's own physics: keep the effect, and what it leaves
            # is searched at the next step (library first).  Terms that also cover a second effect
            # always beat one library effect alone: an accelerometer K3 hidden with a gyro scale
            # that follows temperature was replaced by K3 terms, the w·T terms and a spurious
            # w_z·f_x of 7.7 %/g (2.5 sigma), and the held-out gyro error grew 874 -> 15,748 ppm
            # (benchmarks/diagnose_goal.py, K3+gyro_scale_tempco)
            return None
        cv_lib, cv_terms = h_lib.common_score(prop.h_after)
        extra = max(lib_after.dof - prop.after.dof, 1)      # the terms' parameters beyond the effect's
        if not (cv_terms < cv_lib and prop.chi2_after < lib_after.chi2 - special.chdtri(extra, ALPHA)):
            if ties is not None and prop.chi2_after < lib_after.chi2 + special.chdtri(1, ALPHA):
                # the terms fit as well, not clearly better: the library effect stays, and the words
                # say that this capture cannot tell it from them (issue 28, twenty-first session:
                # a bias step fitted alike by an x accelerometer term in f_z^3 of -2,713 ug/g^3)
                ties.append(f"this capture cannot tell {eid} from terms found outside the library that fit "
                            f"it as well: {'; '.join(prop.lines())} (chi2 {prop.chi2_after:.1f} against "
                            f"{lib_after.chi2:.1f}, leave-one-segment-out {cv_terms:.1f} against {cv_lib:.1f}); "
                            f"{eid} is kept: an effect of the library is displaced only by terms that fit "
                            "clearly better")
            return None
    after = diagnose(prop.after.result, registry=registry)       # with the library's candidates
    effect, values, sigmas = terms.in_model(after.result)
    new = {f.term.name for f in prop.found}
    estimate = [(t.name, t.natural(v), abs(t.natural(sg)), t.meaning()[1])
                for t, v, sg in zip(effect.terms, values, sigmas) if t.name in new]
    caveat = prop.alias_lines()
    if instead is not None:
        caveat.insert(0, f"the terms replace {instead[0]}, which fits this capture too but predicts the left-out "
                         f"segments worse (leave-one-segment-out {cv_lib:.1f} against {cv_terms:.1f} with the "
                         f"terms) and leaves chi2 {lib_after.chi2:.1f} against {prop.chi2_after:.1f}")
    return Step(DISCOVERED, current, after, sum(f.chi2_drop for f in prop.found), current.chi2 - after.chi2,
                estimate, prop.holdout_before, prop.holdout_after, prop.share, caveat, discovered=True,
                instead_of=instead[0] if instead else "", proposal=prop), prop.h_after


DETERMINED_SIGMA = 3.0    # a discovered term carried into the calibration is this many sigma from 0


def _determined(prop, current: Diagnosis, summaries, h_current):
    """The proposal with only the terms its refit determines (|value| > DETERMINED_SIGMA sigma),
    refitted and judged again (the stop rule); None when none is left.  A calibration never
    carries a term the capture does not determine: a term chosen among aliases whose refit leaves
    it at 1.8 sigma (a gyro w_z·f_x of 5.65e4 ± 3.1e4 ppm/g, 0.999 alike to w_x·f_z, beside
    the w·T terms of a gyro scale that follows temperature) extrapolates to any size elsewhere:
    on the held-out capture it raised the gyro error from 874 to 15,748 ppm
    (benchmarks/diagnose_goal.py, K3+gyro_scale_tempco)."""
    if prop is None:
        return None
    from station.diagnose import terms
    from station.diagnose.holdout import judge

    size = {t.name: (v, sg) for t, v, sg in zip(prop.effect.terms, prop.values, prop.sigmas)}
    keep = [f for f in prop.found if abs(size[f.term.name][0]) > DETERMINED_SIGMA * size[f.term.name][1]]
    if len(keep) == len(prop.found):
        return prop
    if not keep:
        return None
    after_result, effect = terms.refit(summaries, current.result, keep)
    _, values, sigmas = terms.in_model(after_result)
    after = diagnose(after_result, exclude=EffectRegistry().ids())
    h_after = leave_one_segment_out(after_result)
    ok, reason, share, cv_b, cv_a = judge(current, after, h_current, h_after)
    return terms.Proposal(keep, effect, values, sigmas, current.chi2, after.chi2, after.reduced_chi2, cv_b, cv_a, ok,
                          reason, after=after, h_after=h_after, share=share)


NEAR_TIE = 0.5       # a candidate whose predicted chi2 drop is at least this share of the first passing
                     #   one's, and whose fit is not significantly worse, is a rival for the same
                     #   misfit: the one that predicts left-out segments best is kept


def _trial(cand, current: Diagnosis, h_current, summaries, attitudes, registry):
    """(after, its Holdout, judge(...)) of ``cand`` added to the model of ``current``."""
    effect = registry.create(cand.effect)
    if profile.is_profiled(effect):     # a bias step: its time from fits of the best candidates
        profile.locate(current.result, effect)
    after = diagnose(lsq.fit(summaries, _rebuild(current.result.model.effects, registry, [effect]),
                             attitudes, like=current.result.model), registry=registry)
    h_after = leave_one_segment_out(after.result)
    return after, h_after, judge(current, after, h_current, h_after)


def _best_out_of_sample(cand, first, tries, refused, current, h_current, summaries, attitudes, registry):
    """Of the first candidate that passes the checks, when the capture cannot tell it from another
    (words.caveats), and its near-tied rivals of the same kind (IMU or
    bench) among this step's tries (a predicted chi2 drop at least NEAR_TIE of its own, a chi2 after not
    significantly above its own), the one
    whose model predicts the left-out segments best (the lowest leave-one-segment-out score over
    the segments all of them predict).  Rivals fit the same misfit alike in chi2; out of sample
    the physics shows: over a 2 degC warm-up with every rotation at 100 deg/s a gyro scale that
    follows temperature and a rate-squared term leave chi2 163.1 and 163.2, but the rate term
    (aliased at one rate with a scale asymmetry) predicts the left-out segments worse (898 against
    690) and raised the held-out gyro error 64 -> 135 ppm (benchmarks/diagnose_goal.py,
    gyro_scale_tempco_2C).  Returns (cand, after, h_after, ok, reason, share, cv_b, cv_a, words)."""
    after, h_after, ok, reason, share, cv_b, cv_a = first
    passing = [(cand, after, h_after, (ok, reason, share, cv_b, cv_a))]
    rivals = []
    if caveats(summaries, cand.effect):
        # only an effect this capture cannot tell from another (words.caveats: a rate term at one
        # rate) is put against its rivals of its kind: over a warm-up that follows the time, a drift
        # in time predicts the left-out segments better than the biases' temperature slope and was
        # kept for a bias quadratic in temperature (held-out accelerometer 40 -> 65 ug, floor 29)
        rivals = [c for c in tries if c is not cand and c.effect not in refused and c.bench == cand.bench
                  and c.predicted_chi2_drop >= NEAR_TIE * cand.predicted_chi2_drop
                  and tries.index(c) > tries.index(cand)]
    # an event located in time (a bias step) against a property of the sensor, either way: on a
    # capture that visits each attitude once, an IMU effect fits part of a step's misfit and passed
    # first (accel_cross_axis: chi2 123.8, leave-one-segment-out 315.6), the step (ranked after
    # the IMU's effects, core.Candidate.bench) was never tried (97.2, 241.3), and terms of an
    # implausible size replaced the IMU effect (issue 28, twenty-first session)
    event = _is_event(registry, cand.effect)
    rivals += [c for c in tries if c is not cand and c not in rivals and c.effect not in refused
               and c.predicted_chi2_drop >= NEAR_TIE * cand.predicted_chi2_drop
               and _is_event(registry, c.effect) != event]
    for rival in rivals:
        try:
            r_after, r_h, verdict = _trial(rival, current, h_current, summaries, attitudes, registry)
        except Exception:        # a rival that cannot be fitted here is no rival
            continue
        # a rival explains the misfit as well: its chi2 is not significantly above the first one's
        # (over-dispersion-corrected, the 1 % point on one degree of freedom: a scale_temperature that
        # leaves chi2 2802 where accel_cubic leaves 801 is no rival)
        worse = (r_after.chi2 - after.chi2) / overdispersion(after.result)
        if verdict[0] and worse < special.chdtri(1, ALPHA):
            passing.append((rival, r_after, r_h, verdict))
    if len(passing) == 1:
        return (cand, after, h_after, ok, reason, share, cv_b, cv_a, [], [], [])
    names = set.intersection(*(set(h.per_segment) for _, _, h, _ in passing))
    score = [sum(h.per_segment[n] for n in names) for _, _, h, _ in passing]
    best = int(np.argmin(score))
    # an event's time is located on every segment, the left-out one too (the best of the profile's
    # candidate times): its leave-one-segment-out score is optimistic by what that choice takes.  It
    # displaces a property of the sensor only when it also fits clearly better: its chi2 lower by the
    # 1 % point on its extra parameters and its time, over the candidate times (Bonferroni), as terms
    # outside the library must fit clearly better (_terms_step).  With a real accelerometer cubic and
    # no step, a step located among 14 times predicted the left-out segments better (237.4 against
    # 249.4) at chi2 85.9 against 93.5 and displaced the cubic (review of the twenty-first session)
    not_clearly = ""
    if _is_event(registry, passing[best][0].effect):
        e_id, e_after = passing[best][0].effect, passing[best][1]
        located = next((e for e in e_after.result.model.effects if e.id == e_id), None)
        times = max(len(getattr(located, "profile", None) or ()), 1)
        sensor = [k for k, p in enumerate(passing) if not _is_event(registry, p[0].effect)]
        if any((passing[k][1].chi2 - e_after.chi2) / overdispersion(e_after.result)
               < special.chdtri(max(passing[k][1].dof - e_after.dof, 0) + 1, ALPHA / times) for k in sensor):
            best = min(sensor, key=lambda k: score[k])
            not_clearly = (f"{e_id} predicts the left-out segments better, but its time was located on them too "
                           f"(the best of {times} candidate times) and its chi2 is not clearly lower (the 1 % "
                           "point over those times): an event does not displace a property of the sensor on that")
    c, a, h, (ok, reason, share, cv_b, cv_a) = passing[best]
    others = [f"{p[0].effect} (leave-one-segment-out {sc:.1f} against {score[best]:.1f}, chi2 {p[1].chi2:.1f} "
              f"against {a.chi2:.1f})" for k, (p, sc) in enumerate(zip(passing, score)) if k != best]
    words = [f"kept rather than {'; '.join(others)}: both explain the misfit, "
             + (not_clearly or f"{c.effect} predicts the left-out segments better")]
    # the rivals whose chi2 is not significantly above the kept one's: the capture cannot tell them apart
    tied = [p[0].effect for k, p in enumerate(passing) if k != best
            and (p[1].chi2 - a.chi2) / overdispersion(a.result) < special.chdtri(1, ALPHA)]
    if tied:
        words.append(f"this capture cannot tell {c.effect} from {', '.join(tied)}: "
                     f"{'they fit' if len(tied) > 1 else 'it fits'} the misfit as well (chi2 not significantly "
                     "above); " + ("the segments that separate them decide" if not_clearly
                                   else "the held-out segments decide"))
    passed = [p[0].effect for k, p in enumerate(passing) if k != best]
    return (c, a, h, ok, reason, share, cv_b, cv_a, words, tied, passed)


def _is_event(registry, effect_id: str) -> bool:
    """An effect located in time (a bias step: station.estimate.profile), not a property of the sensor."""
    try:
        return profile.is_profiled(registry.create(effect_id))
    except Exception:       # an effect that cannot be made here is no event
        return False


def _tried(summaries, current, h_current, effect, registry, attitudes):
    """One effect tried at the current fit: (its diagnosis, the current fit's leave-one-segment-out
    scores (computed once), its own, judge()'s verdict on it) -- the library's candidates and the
    effects outside its ranking by one rule."""
    after = diagnose(lsq.fit(summaries, _rebuild(current.result.model.effects, registry, [effect]), attitudes,
                             like=current.result.model), registry=registry)
    if h_current is None:
        h_current = leave_one_segment_out(current.result)
    h_after = leave_one_segment_out(after.result)
    return after, h_current, h_after, judge(current, after, h_current, h_after)


def run(summaries, effects=(), attitudes="auto", progress=None,
        registry: EffectRegistry | None = None, on_first=None, discover: bool = True,
        unlisted: bool = True) -> tuple[list[Step], Diagnosis]:
    """Diagnose; while a significant candidate passes the checks, add it, refit, diagnose again.
    When no library effect is kept and the fit still fails, the terms found outside the library
    (station.diagnose.terms) are added when they pass the same checks (``discover``), marked as
    discovered; a library effect that passes is replaced by terms that beat it out of sample.
    ``on_first(diagnosis)``, when given, is called with the diagnosis of the model as fitted as
    soon as it is made (a report draws its candidates' figures meanwhile).  When no library effect
    is kept, the effects of station/model/unlisted.py are tried by the same rule (``unlisted``:
    unlisted_candidates) before the terms."""
    registry = registry or EffectRegistry()
    current = diagnose(profile.fit_located(summaries, [registry.create(e) for e in effects], attitudes),
                       registry=registry)
    if on_first is not None:
        on_first(current)
    h_current = None          # the leave-one-segment-out check, only once a candidate is tried
    steps, rejected = [], []
    refused: set = set()
    term_steps = 0
    while len(steps) < MAX_STEPS:
        open_ = [c for c in current.candidates if c.significant and c.effect not in refused]
        # the effects the failure's words name first (a table wobble for "a wobbling or tilted table
        # platter"), then the IMU's effects, then the bench's and the events' (core.Candidate.bench);
        # a placement per rotation (two parameters each) bends any rotation's misfit across its axis
        # away: tried only, and first, where the words saw a ± pair's axis move (the IMU moved)
        named = [c for c in named_in_words(open_, current, registry) if c.effect != REMOUNT]
        rest = [c for c in open_ if c not in named and c.effect != REMOUNT]
        tries = named + [c for c in rest if not c.bench][:MAX_TRIES] + [c for c in rest if c.bench][:MAX_TRIES]
        if REMOUNT_FAULT in bench_fault(current):
            tries = [c for c in open_ if c.effect == REMOUNT] + tries
        kept = None
        for cand in tries:
            if progress:
                progress(cand.effect)
            effect = registry.create(cand.effect)
            if profile.is_profiled(effect):     # a bias step: its time from fits of the best candidates
                profile.locate(current.result, effect)
            after, h_current, h_after, (ok, reason, share, cv_b, cv_a) = _tried(
                summaries, current, h_current, effect, registry, attitudes)
            if ok:
                cand, after, h_after, ok, reason, share, cv_b, cv_a, preferred, tied, passed = _best_out_of_sample(
                    cand, (after, h_after, ok, reason, share, cv_b, cv_a), tries, refused, current, h_current,
                    summaries, attitudes, registry)
                kept = Step(cand.effect, current, after, cand.predicted_chi2_drop, current.chi2 - after.chi2,
                            added_parameters(after, cand.effect), cv_b, cv_a, share,
                            preferred + _said(after, cand.effect) + caveats(summaries, cand.effect),
                            rivals=list(tied))
                if discover and term_steps < MAX_TERM_STEPS and fit_fails(current.result) and not bench_fault(current):
                    ties: list = []
                    alt = _terms_step(current, h_current, summaries, registry, (cand.effect, after, h_after), ties)
                    if alt is not None:       # the effect stays a candidate for the next steps
                        kept, h_after = alt
                        term_steps += 1
                    elif ties:
                        # the terms stand for the library effects that also passed here: the segments
                        # that separate those from the kept one are the ones to record
                        kept.caveats.append(ties[0] + (f"; of the library, {', '.join(passed)} also explain"
                                                       f"{'s' if len(passed) == 1 else ''} the misfit"
                                                       if passed else ""))
                        kept.rivals += [e for e in passed if e not in kept.rivals]
                break
            if cand not in named:
                refused.add(cand.effect)
            # else tried again after another effect is added: the fault the words name can explain only
            # part of a failure that has a second cause (a 30" wobble beside gyro g-sensitivity: 23 % of
            # the excess chi2 before g-sensitivity is in the model, all of it after)
            rejected = [r for r in rejected if r.effect != cand.effect]
            rejected.append(Rejection(cand.effect, reason, current.chi2 - after.chi2, cv_b, cv_a, share,
                                      added_parameters(after, cand.effect)))
        if kept is None and unlisted and not bench_fault(current):
            # the effects kept outside the library's ranking (station/model/unlisted.py), by the
            # library's rule, before the dictionary's terms (which would name the same physics as
            # terms: an effect with its physics and units is the better calibration)
            for cand in unlisted_candidates(current, refused):
                if progress:
                    progress(cand.effect)
                after, h_current, h_after, (ok, reason, share, cv_b, cv_a) = _tried(
                    summaries, current, h_current, _created(registry, cand.effect), registry, attitudes)
                if ok:
                    kept = Step(cand.effect, current, after, cand.predicted_chi2_drop, current.chi2 - after.chi2,
                                added_parameters(after, cand.effect), cv_b, cv_a, share,
                                [f"outside the library's ranking ({cand.source}, station effects does not list it): "
                                 f"significant by the library's rule (p = {cand.p_value_corrected:.2g}, Holm over "
                                 "the library's candidates and the unlisted effects)"] + caveats(summaries, cand.effect))
                    break
                refused.add(cand.effect)
                rejected = [r for r in rejected if r.effect != cand.effect]
                rejected.append(Rejection(cand.effect, reason, current.chi2 - after.chi2, cv_b, cv_a, share,
                                          added_parameters(after, cand.effect)))
        if (kept is None and discover and term_steps < MAX_TERM_STEPS and fit_fails(current.result)
                and bench_fault(current)):
            current.notes.append("terms outside the library not carried into the calibration: the failure names a "
                                 "fault of the bench (" + bench_fault(current)[:80] + "...), which no term of the "
                                 "IMU's model should take")
        elif kept is None and discover and term_steps < MAX_TERM_STEPS and fit_fails(current.result):
            if h_current is None:
                h_current = leave_one_segment_out(current.result)
            alt = _terms_step(current, h_current, summaries, registry)
            if alt is not None:
                kept, h_after = alt
                term_steps += 1
        if kept is None:
            break
        steps.append(kept)
        current, h_current = kept.after, h_after
        current, h_current = eliminate(summaries, kept, [st.added for st in steps[:-1]], current, h_current,
                                       attitudes, registry, refused)
    current.rejected = [r for r in rejected if r.effect not in {st.added for st in steps}]
    conclude(current, summaries, steps, search_terms=not (discover and term_steps >= MAX_TERM_STEPS))
    return steps, current


def still_needed(with_it: Diagnosis, without: Diagnosis, h_with: Holdout, h_without: Holdout) -> tuple[bool, str]:
    """Whether the data still need an effect: (needed, why).  Not needed when removing it raises
    chi2 by less than the significance level allows (the rise divided by the over-dispersion of
    the fit with it, on as many degrees of freedom as it takes) and the other segments predict
    each left-out segment no worse without it."""
    rise = without.chi2 - with_it.chi2
    k = max(without.dof - with_it.dof, 1)
    phi = overdispersion(with_it.result)
    p = chi2_sf(max(rise, 0.0) / phi, k)
    cv_with, cv_without = h_with.common_score(h_without)
    if p < ALPHA:
        return True, f"removing it raises chi2 by {rise:.1f} (p = {p:.2g})"
    if cv_without > cv_with:
        return True, (f"without it the left-out segments are predicted worse (leave-one-segment-out "
                      f"{cv_with:.1f} -> {cv_without:.1f})")
    return False, (f"removing it raises chi2 by only {rise:.1f} on {k} degrees of "
                   f"freedom (p = {p:.2g}{f', over-dispersion {phi:.3g}' if phi > 1 else ''}) and the "
                   f"left-out segments are predicted as well without it (leave-one-segment-out "
                   f"{cv_with:.1f} -> {cv_without:.1f})")


def eliminate(summaries, step: Step, earlier: list, current: Diagnosis, h_current: Holdout, attitudes,
              registry, refused: set) -> tuple[Diagnosis, Holdout]:
    """Backward elimination after ``step``: drop each effect added earlier by the loop that the
    data no longer need (most dispensable first, one at a time, refitting after each)."""
    remaining = list(earlier)
    while remaining:
        trials = []
        for eid in remaining:
            effects = [e for e in current.result.model.effects if e.id != eid]
            without = diagnose(lsq.fit(summaries, _rebuild(effects, registry), attitudes,
                                       like=current.result.model), registry=registry)
            h_without = leave_one_segment_out(without.result)
            needed, why = still_needed(current, without, h_current, h_without)
            if not needed:
                trials.append((without.chi2, eid, without, h_without, why))
        if not trials:
            break
        _, eid, current, h_current, why = min(trials, key=lambda t: t[0])
        step.removed.append((eid, f"{eid}: no longer needed with {step.added} in the model: {why}"))
        step.after, step.holdout_after = current, h_current.score
        if not step.discovered:
            step.estimate = added_parameters(current, step.added)
        refused.add(eid)
        remaining.remove(eid)
    return current, h_current


def redundant_with(d: Diagnosis, extra, added: set, summaries) -> list:
    """(effect, why) for every effect in ``added`` (added by the loop) that the data no longer
    need once ``extra`` (the terms found outside the library) is in the model (still_needed)."""
    from station.diagnose.terms import TermsEffect

    effects = [e for e in d.result.model.effects if not isinstance(e, TermsEffect)]
    attitudes = d.result.model.attitudes
    every = EffectRegistry().ids()          # no candidates ranked: only the fits are compared
    with_all = diagnose(lsq.fit(summaries, [*effects, extra], attitudes, like=d.result.model), exclude=every)
    h_all = leave_one_segment_out(with_all.result)
    out = []
    for e in effects:
        if e.id not in added:
            continue
        without = diagnose(lsq.fit(summaries, [x for x in effects if x is not e] + [extra], attitudes,
                                   like=d.result.model), exclude=every)
        needed, why = still_needed(with_all, without, h_all, leave_one_segment_out(without.result))
        if not needed:
            out.append((e.id, why))
    return out


def conclude(d: Diagnosis, summaries, steps=(), search_terms: bool = True) -> Diagnosis:
    """The final verdict: when the model still fails and no significant library effect is left
    to add, search the dictionary of terms outside the library and say what it found."""
    found = discovered_lines(d)
    if not fit_fails(d.result):
        if found:
            d.verdict += (f"; with terms found outside the library (discovered, in the model): {'; '.join(found)}; "
                          "--emit-effect FILE writes them as a working effect plugin")
        return d

    def specific(failures):
        return [f for f in failures if "a step in time" in f or "was moved or remounted" in f
                or "drift steadily with time" in f or "time stamps jitter" in f
                or "once per revolution along the rotation's own axis" in f
                or "a wobbling or tilted table platter" in f]

    now = specific(d.failures)
    first = specific(steps[0].before.failures) if steps else []
    added = f" after adding {', '.join(st.added for st in steps)}" if steps else ""
    pending = [c for c in d.candidates if c.significant and c.effect not in {r.effect for r in d.rejected}]
    if pending and not steps and not d.rejected:
        # plain diagnose: the verdict already names the likely effect; a step, drift or moved
        # axis in the words comes first all the same
        if now:
            d.verdict += f"; but first look at this: {now[0]}"
        d.account = failure_account(d, steps)
        return d
    if search_terms and bench_fault(d):
        d.notes.append("no term outside the library searched: the failure names a fault of the bench, which no "
                       "term of the IMU's model should take")
    elif search_terms:
        from station.diagnose import terms

        searched = [sensor for sensor, _, _ in terms.searchable(summaries)]
        if searched == ["accel"]:
            d.notes.append("terms outside the library searched in the accelerometers only: a raw gyro "
                           "output without a nominal scale (imu.gyro_nominal_dps_per_count) or a rotation "
                           "with an encoder angle cannot be sized")
        elif not searched:
            d.notes.append("no term outside the library searched: a raw accelerometer output without a "
                           "nominal scale (imu.accel_nominal_mps2_per_count) or statics cannot be sized")
        d.proposal = terms.propose(d, summaries)
        if d.proposal is not None and d.proposal.kept and steps:
            d.proposal.redundant = redundant_with(d, d.proposal.effect, {st.added for st in steps}, summaries)
    reduced = d.test["reduced_chi2"] if d.test else d.reduced_chi2       # the verdict's test (core.fit_test)
    on = f" on the data's redundancy {d.test['dof']:.1f}" if d.test and d.test["dof"] != d.dof else ""
    head = (not_converged(d.result) + f"the model does not explain the data{added} (reduced chi2 {reduced:.3g}{on})"
            + within_calibration_threshold(reduced))
    if now:
        head += f"; first look at this: {now[0]}"
    elif first:
        head += f"; first look at this (seen before any effect was added): {first[0]}"
    if d.rejected:
        head += f"; tried and not kept: {', '.join(r.effect for r in d.rejected)}"
    if found:
        head += f"; discovered outside the library and in the model: {'; '.join(found)}"
    prop = d.proposal
    if prop is not None:
        check = ("and predicts left-out segments better" if prop.kept
                 else f"but is not kept: {prop.reason}")
        instead = ""
        if prop.redundant:
            instead = (f"; with these terms {', '.join(e for e, _ in prop.redundant)} "
                       f"{'is' if len(prop.redundant) == 1 else 'are'} no longer needed "
                       f"({'; '.join(why for _, why in prop.redundant)}): add the terms instead")
        aliases = "".join(f"; {a}" for a in prop.alias_lines())
        d.verdict = (f"{head}; outside the library the residuals follow {'; '.join(prop.lines())} "
                     f"(with these terms reduced chi2 {prop.reduced_after:.3g}, {check}){aliases}{instead}; write them "
                     "as an effect plugin with --emit-effect FILE, check the physics, add it with --add")
    d.account = failure_account(d, steps)
    if prop is None:
        patterns = [line for line in d.account if line.startswith("the residual of ")]
        d.verdict = (f"{head}; no effect of the library and no term of the dictionary accounts for it"
                     + (f"; {patterns[0]}" if patterns else "; see what was tried and where it fails"))
    return d


def discovered_lines(d: Diagnosis) -> list[str]:
    """The discovered terms in the model of ``d``, in words and units (value ± 1σ)."""
    from station.diagnose.terms import in_model

    got = in_model(d.result)
    if got is None:
        return []
    effect, values, sigmas = got
    return [t.words(v, sg) for t, v, sg in zip(effect.terms, values, sigmas)]


def comparison_rows(before: Diagnosis, after: Diagnosis) -> list[tuple[str, float, float]]:
    """(what, before, after): chi2, reduced chi2 and RMS residual per segment kind, sensor, axis."""
    rows = [("chi2", before.chi2, after.chi2), ("reduced chi2", before.reduced_chi2, after.reduced_chi2)]
    b, a = rms_by_kind(before.segments), rms_by_kind(after.segments)
    for key in b:
        rows.append((f"RMS {key[0]} {key[1]} {key[2]} (sigma)", b[key], a.get(key, float("nan"))))
    return rows
