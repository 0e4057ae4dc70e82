"""Compare the fitted model with the measurements; find which physical effect is missing.

Everything here works on the whitened residuals of the least-squares fit (each residual divided
by its noise, so a model that explains the data leaves residuals of unit spread):
  * the fit as a whole: chi2, degrees of freedom, reduced chi2 and its p-value;
  * per segment and quantity: the RMS of the whitened residuals (where the model fails);
  * per candidate effect of the library not yet in the model: the score (Lagrange-multiplier)
    test at the current fit, i.e. the chi2 drop a first Gauss-Newton step with the effect
    added would give, its p-value corrected for testing several candidates (Holm), the
    one-step estimate and its 1-sigma, whether that size is physically plausible, which of
    its parameters the capture cannot tell apart from the model's, and the smallest size the
    capture could detect.
"""
from __future__ import annotations

import fnmatch
from dataclasses import dataclass, field

import numpy as np
from scipy import special

from station.estimate import lsq, profile
from station.estimate.profile import fit_jacobian, model_basis, outside_model  # noqa: F401 (shared)
from station.model.registry import EffectRegistry
from station.estimate.verdict import P_FAIL


def chi2_sf(x: float, k: int) -> float:
    """P(chi2_k > x)."""
    return float(special.chdtrc(k, x))


def norm_isf(p: float) -> float:
    """z with P(N(0,1) > z) = p."""
    return float(-special.ndtri(p))


PRIOR_QUANTITIES = ("weak_prior", "effect_prior", "attitude_prior", "axis_prior", "earth_prior")
ALPHA = 0.01            # significance level of the whole family of candidate tests
POWER_Z = 0.8416        # z of 80 % power, for the smallest detectable size


@dataclass
class SegmentResidual:
    name: str
    kind: str
    rms: float                               # RMS of all its whitened data residuals
    by_quantity: dict                        # quantity -> RMS
    values: dict                             # (quantity, axis) -> whitened residual


@dataclass
class Candidate:
    effect: str
    title: str
    predicted_chi2_drop: float
    dof: int                                 # parameters the capture can reveal
    p_value: float
    p_value_corrected: float = 1.0
    significant: bool = False
    plausible: bool = True
    names: list = field(default_factory=list)
    units: list = field(default_factory=list)
    estimate: list = field(default_factory=list)   # one-step estimate, reported units
    sigma: list = field(default_factory=list)
    detectable: list = field(default_factory=list)  # smallest detectable size, reported units
    aliased: list = field(default_factory=list)     # parameters the capture cannot reveal
    advice: str = ""
    overdispersion: float = 1.0                     # the statistics were divided by this (>1 when
                                                    #   the fit fails: its reduced chi2)
    signature_rows: np.ndarray | None = None        # predicted whitened change, one step
    signature_variable: str = ""
    source: str = "library"
    bench: bool = False                             # a nuisance of the bench that can stand in for an
                                                   #   effect of the IMU: ranked after the IMU's
    state: dict = field(default_factory=dict)      # what the effect's setup or profile chose (its
                                                   #   state(): a bias step's time), for the refit
    suggestion: str = ""                           # the station design --from command that would reveal
                                                   #   what the capture cannot (station/diagnose/suggest.py)
    separations: list = field(default_factory=list)  # station design --from ... --separate commands: the
                                                   #   effects this capture cannot tell it from (suggest.py)
    alike: list = field(default_factory=list)       # significant candidates this capture cannot tell it from
                                                   #   and no --separate command can be designed for (suggest.py)

    def largest_estimate(self) -> str:
        """The one-step estimate largest against its 1-sigma, in words ("" without parameters)."""
        if not self.names:
            return ""
        k = max(range(len(self.names)), key=lambda i: abs(self.estimate[i]) / max(self.sigma[i], 1e-300))
        return f"{self.names[k]} {self.estimate[k]:.3g} ± {self.sigma[k]:.2g} {self.units[k]}"

    def note(self) -> str:
        """What to say beside the candidate: its advice, or that its size is implausible."""
        return self.advice or ("size implausible for any IMU" if not self.plausible else "")


@dataclass
class Diagnosis:
    effects: list
    chi2: float
    dof: int
    reduced_chi2: float
    p_value: float
    segments: list
    candidates: list
    failures: list                           # sentences: where and how the model fails
    verdict: str
    result: object                           # the lsq.FitResult diagnosed
    labels: list
    notes: list = field(default_factory=list)   # how the statistics were taken (over-dispersion)
    rejected: list = field(default_factory=list)  # auto.Rejection: tried by --auto and not kept
    proposal: object = None                  # terms.Proposal: terms found outside the library
    account: list = field(default_factory=list)  # a fit that still fails: what was tried, what each
                                             #   explained, what the residuals follow (words.failure_account)
    design_suggestions: list = field(default_factory=list)  # lines: the model's parameters not revealed
                                             #   and the station design --from command (suggest.py)
    not_revealed: list = field(default_factory=list)  # lines: effects outside the library and the model
                                             #   this capture could not detect at their typical size, and the
                                             #   station design --from command (unrevealed.py)
    test: dict | None = None                 # the verdict's test, as the calibration file takes it (fit_test)


def _data_mask(labels) -> np.ndarray:
    return np.array([q not in PRIOR_QUANTITIES
                     for _, _, q, _ in labels])


def segment_residuals(result, labels) -> list[SegmentResidual]:
    r = result.model.residuals(result.x)
    mask = _data_mask(labels)
    out, order = {}, []
    for (name, kind, quantity, axis), value, is_data in zip(labels, r, mask):
        if not is_data:
            continue
        if name not in out:
            out[name] = (kind, {})
            order.append(name)
        out[name][1][(quantity, axis)] = float(value)
    segs = []
    for name in order:
        kind, values = out[name]
        v = np.array(list(values.values()))
        by_q = {}
        for (q, _), value in values.items():
            by_q.setdefault(q, []).append(value)
        segs.append(SegmentResidual(name, kind, float(np.sqrt(np.mean(v**2))),
                                    {q: float(np.sqrt(np.mean(np.square(vals)))) for q, vals in by_q.items()},
                                    values))
    return segs


# effect parameters that the model's own take where the capture turned about the IMU's axes only:
# a vibration once per revolution along a level turn's axis is a first harmonic of the accelerometer
# along it, what a tilt of the turn's axis in the accelerometers' frame makes (g x the tilt), and the
# gyros' misalignments and the inter-triad alignment take that tilt; the statics do not pin them (they
# see no turn).  Not exactly aliased (a few parameters' worth of information remains): named with
# the aliased ones when the score test's 1-sigma is above the typical size, where the estimator
# would hold them by their prior (lsq._blind_effect_parameters' rule).  Measured (docs/design.md,
# twenty-first session): nine statics and turns about x, y, z at 100 deg/s, 1-sigma 1.5 and 1.0 mg
# against the typical 0.1; with turns about the diagonals too 0.012 mg
TILT_ALIKE = {"table_vibration_once_per_rev": ("table_vibration_*dps_axis_cos", "table_vibration_*dps_axis_sin")}


def score_test(result, effect_id, registry: EffectRegistry | None = None, overdispersion: float = 1.0) -> Candidate:
    """The Lagrange-multiplier test of adding ``effect_id`` (an id, or an Effect instance) to the
    fitted model.  With ``overdispersion`` phi > 1 (a fit that fails: phi is its reduced chi2) the
    statistic is divided by phi and the 1-sigma multiplied by sqrt(phi) (quasi-likelihood): a
    drop that is large only against the nominal noise is not taken for a missing effect."""
    model = result.model
    if isinstance(effect_id, str):
        effect = (registry or EffectRegistry()).create(effect_id)
    else:
        effect, effect_id = effect_id, effect_id.id
    located = 1
    if profile.is_profiled(effect) and getattr(effect, "step_time_s", 0.0) is None:
        located = max(len(profile.locate(result, effect, refine=0)), 1)   # the best of this many candidates
    extended = lsq.Model(model.s, [*model.effects, effect], model.attitudes, like=model)
    extended.priors = dict(model.priors)
    n = model.layout.size
    x = np.concatenate([result.x, np.zeros(extended.layout.size - n)])
    r = extended.residuals(x)
    cols = list(range(n, extended.layout.size))
    if not cols:        # nothing of it on this capture (a bench effect with no rotation about a table axis)
        from station.core.errors import UserError

        raise UserError(f"{effect.title}: it has no parameter on this capture (nothing it acts on was recorded)")
    Jc = extended.jacobian_columns(x, cols)
    # the part of the candidate's columns the current model cannot already produce
    Jp = outside_model(result, Jc)
    A = Jp.T @ Jp
    scale = np.sqrt(np.maximum(np.diag(Jc.T @ Jc), 1e-300))
    w, V = np.linalg.eigh(A / np.outer(scale, scale))
    keep = w > 1e-8 * max(w.max(), 1e-300)
    Vk = V[:, keep] / scale[:, None]
    A_pinv = (Vk / w[keep]) @ Vk.T
    g = Jp.T @ r
    step = -A_pinv @ g
    lm = float(g @ A_pinv @ g)                   # the predicted chi2 drop, nominal noise
    k = int(keep.sum())
    sigma = np.sqrt(np.clip(np.diag(A_pinv), 0.0, None) * overdispersion)
    # parameters with no component in the revealable subspace are aliased
    revealable = np.abs(V[:, keep]).max(axis=1) if k else np.zeros(len(cols))
    params = effect.params
    aliased = [p.name for p, reach in zip(params, revealable) if reach < 1e-3]
    # parameters alike with the model's, not exactly but beyond their typical size (TILT_ALIKE): the
    # nominal 1-sigma, as the estimator's rule (a fit failing for another reason widens it, not the alias)
    nominal = np.sqrt(np.clip(np.diag(A_pinv), 0.0, None))
    tilt_alike = [p.name for p, s in zip(params, nominal) if p.name not in aliased and s * abs(p.scale) > p.typical
                  and any(fnmatch.fnmatchcase(p.name, pat) for pat in TILT_ALIKE.get(effect_id, ()))]
    aliased += tilt_alike
    cand = Candidate(effect=effect_id, title=effect.title, predicted_chi2_drop=lm, dof=k,
                     p_value=min(1.0, located * chi2_sf(lm / overdispersion, k)) if k else 1.0,
                     overdispersion=overdispersion, state=effect.state(), bench=bool(getattr(effect, "bench", False)),
                     names=[p.name for p in params], units=[p.unit for p in params],
                     estimate=[float(v * p.scale) for v, p in zip(step, params)],
                     sigma=[float(s * p.scale) for s, p in zip(sigma, params)],
                     aliased=aliased, signature_rows=Jp @ step,
                     signature_variable=effect.signature_variable,
                     source=getattr(effect, "_station_source", "library"))
    too_large = [abs(v) > p.plausible and abs(v) > 3 * s
                 for v, s, p in zip(cand.estimate, cand.sigma, params)]
    cand.plausible = not any(too_large)
    if callable(getattr(effect, "words", None)) and k:      # e.g. a bias step: its size and time in words
        said = effect.words(np.array(cand.estimate), np.array(cand.sigma))
        if said:
            cand.advice = "; ".join(said) + (f" ({effect.located_by})" if getattr(effect, "located_by", "") else "")
    if not k:
        cand.advice = f"this capture cannot reveal {effect_id}: it needs {effect.excited_by}"
    elif aliased:
        said = (f"this capture cannot tell {', '.join(aliased)} apart from the model's "
                f"parameters; {effect.excited_by} would")
        if tilt_alike and set(aliased) == set(tilt_alike):     # only the tilt-alike parts: what reveals them
            said = (f"this capture cannot tell {', '.join(aliased)} apart from the model's parameters (a first "
                    "harmonic along a turn's axis is what a tilt of that axis makes, which the gyros' misalignments "
                    "take); level turns about another axis (a diagonal) or turns about a vertical axis would")
        cand.advice = f"{cand.advice}; {said}" if cand.advice else said
    return cand


def _tested(result, effect_id, registry, phi) -> Candidate:
    """score_test, or a candidate that says why it cannot be tested on this capture (an effect
    whose term cannot be sized here, e.g. a raw gyro without a nominal scale): one candidate
    that cannot be tested does not stop the diagnosis."""
    from station.core.errors import UserError

    try:
        return score_test(result, effect_id, registry, phi)
    except UserError as e:
        effect = registry.create(effect_id)
        return Candidate(effect=effect_id, title=effect.title, predicted_chi2_drop=0.0, dof=0, p_value=1.0,
                         overdispersion=phi, advice=f"cannot be tested on this capture: {e}",
                         source=getattr(effect, "_station_source", "library"))


def fit_test(result) -> dict | None:
    """The verdict's test of ``result``, exactly as the calibration file takes it
    (station.estimate.lsq.verdict_test, station.estimate.verdict.chi2_verdict): chi2, dof (the
    data's redundancy, or the counted degrees of freedom for a large model), reduced_chi2,
    p_value and result ("passes", "fails", "noise overestimated"); None without redundancy."""
    from station.estimate.verdict import chi2_verdict

    cached = getattr(result, "_verdict_test", False)
    if cached is not False:
        return cached
    t = lsq.verdict_test(result)
    chi2, dof = (t["chi2"], t["redundancy"]) if t else (result.chi2, result.dof)
    out = None
    if dof >= 0.5 and np.isfinite(chi2):
        out = {"chi2": float(chi2), "dof": float(dof), **chi2_verdict(chi2, dof)}
    try:
        result._verdict_test = out          # the leverages once per fit (auto asks several times)
    except AttributeError:
        pass
    return out


def fit_fails(result) -> bool:
    """The fit's chi2 is beyond what the noise explains: the p-value of the verdict's test
    (:func:`fit_test`, the calibration file's) below P_FAIL (= ALPHA / 10)."""
    t = fit_test(result)
    return t is not None and t["p_value"] < P_FAIL


def overdispersion(result) -> float:
    """The reduced chi2 when the fit fails (and exceeds 1), else 1."""
    if not fit_fails(result):
        return 1.0
    return max(result.chi2 / result.dof, 1.0)


def rank_candidates(result, exclude=(), registry: EffectRegistry | None = None) -> list[Candidate]:
    registry = registry or EffectRegistry()
    ids = [e for e in registry.ids() if e not in {m.id for m in result.model.effects} and e not in exclude]
    phi = overdispersion(result)
    cands = [_tested(result, e, registry, phi) for e in ids]
    m = len(cands)
    threshold = norm_isf(ALPHA / (2 * max(m, 1))) + POWER_Z
    # Holm's step-down correction over the family of candidates
    for rank, c in enumerate(sorted(cands, key=lambda c: c.p_value)):
        c.p_value_corrected = min(1.0, c.p_value * (m - rank))
    running = 0.0
    for c in sorted(cands, key=lambda c: c.p_value):
        running = max(running, c.p_value_corrected)
        c.p_value_corrected = running
        c.significant = c.dof > 0 and c.p_value_corrected < ALPHA and c.plausible
        c.detectable = [threshold * s if name not in c.aliased else float("inf")
                        for name, s in zip(c.names, c.sigma)]
    # a bench nuisance general enough to take an IMU effect's place (an offset per rotation axis holds
    # the accelerometers' size effect) comes after the significant effects of the IMU
    return sorted(cands, key=lambda c: (not c.significant, c.bench and c.significant, -c.predicted_chi2_drop))


def within_calibration_threshold(reduced: float) -> str:
    """Words for a misfit that diagnose calls significant but a calibration's verdict lets pass
    (station/estimate/verdict.py: a fit fails only when its p-value is below P_FAIL *and* its
    reduced chi2 above REDUCED_CHI2_FAIL), so that the two never seem to contradict; '' above it."""
    from station.estimate.verdict import REDUCED_CHI2_FAIL

    if not reduced <= REDUCED_CHI2_FAIL:
        return ""
    return (f"; below the calibration's fail threshold (reduced chi2 {REDUCED_CHI2_FAIL:g}): a calibration "
            "from this fit passes, what is missing being smaller than half the noise's variance")


def not_converged(result) -> str:
    """The verdict's first words when the fit stopped at its evaluation limit: its chi2, the
    verdict and the candidates' scores are those where the solver stopped, not at the model's
    minimum (lsq._solve's note; verdict.py's "not converged"); "" for a converged fit."""
    if getattr(result.model, "converged", True):
        return ""
    where = ("on its tolerances short of its minimum (a Gauss-Newton step still lowers chi2)"
             if getattr(result.model, "stopped_short", False)
             else "where it crept, before its minimum" if getattr(result.model, "settled", False)
             else "at its evaluation limit before its minimum")
    return f"not converged: the fit stopped {where}, so the chi2 and what follows are those where it stopped; "


def diagnose(result, exclude=(), registry: EffectRegistry | None = None) -> Diagnosis:
    from station.diagnose.words import describe_failures

    labels = result.model.row_labels(result.x)
    segs = segment_residuals(result, labels)
    cands = rank_candidates(result, exclude, registry)
    p = chi2_sf(result.chi2, result.dof) if result.dof > 0 else float("nan")
    reduced = result.chi2 / result.dof if result.dof > 0 else float("nan")
    test = fit_test(result)
    # the verdict from the calibration's own test (the data's chi2 on their redundancy, the
    # calibration's rule): "explains" exactly when its p-value is not significant, so diagnose and
    # the file never disagree (issue 29: "fails" at 1.55 on a redundancy of 98.8 in the file,
    # "explains" at 1.42 on 108 counted degrees of freedom here, for one capture)
    t_reduced, t_p = (test["reduced_chi2"], test["p_value"]) if test else (reduced, p)
    on = f" on the data's redundancy {test['dof']:.1f}" if test and test["dof"] != result.dof else ""
    # "untested" where the file says so (the data have no redundancy of their own: the counted
    # degrees of freedom are the priors'), not "explains" on the counted ones (this session's
    # review: imucal's session imported with station import imucal, "explains, reduced chi2 0.030"
    # here, "untested" in the file), and the noise overestimated as the file says it; a misfit
    # significant by its p-value within the file's REDUCED_CHI2_FAIL is said with
    # within_calibration_threshold's words (a calibration from it passes)
    good = test is None or not t_p < P_FAIL
    failures = describe_failures(result, labels, segs, fails=not good)
    if test is None:
        verdict = ("untested: the data have no redundancy of their own (the degrees of freedom counted are the "
                   "priors'): the model cannot be checked against the measurements")
    elif test["result"] == "noise overestimated":
        verdict = (f"the residuals are smaller than the noise model says: reduced chi2 {t_reduced:.3f}{on} "
                   f"(p below = {test['p_below']:.3g}): the noise is overestimated")
    elif good:
        verdict = (f"the model explains the data: reduced chi2 {t_reduced:.3f}{on} (p = {t_p:.3g})")
    elif any(c.significant for c in cands):
        verdict = (f"the model does not explain the data (reduced chi2 {t_reduced:.3g}{on}); the most "
                   f"likely missing effect is {next(c for c in cands if c.significant).effect}")
    else:
        verdict = (f"the model does not explain the data (reduced chi2 {t_reduced:.3g}{on}, p = {t_p:.2g}) "
                   "and no effect of the library accounts for it: see where it fails")
    if not good:
        verdict += within_calibration_threshold(t_reduced)
    verdict = not_converged(result) + verdict
    notes = []
    phi = overdispersion(result)
    if phi > 1.0:
        notes.append(f"the fit fails, so the candidates' chi2 drops are divided and their 1-sigma "
                     f"multiplied by the over-dispersion (reduced chi2 {phi:.3g}, square root for "
                     "the 1-sigma): only a drop large against the misfit counts")
    # the data faults found before the fit (station/estimate/data_faults.py): what was left out
    notes += list(getattr(result.model.s, "data_fault_notes", None) or [])
    # where the solver stopped short of converging (at its limit, or settled): lsq._solve's note
    stop_note = getattr(result.model, "stop_note", None)
    notes += [stop_note] if stop_note else []
    return Diagnosis(effects=["base_triads", "inter_triad"] + [e.id for e in result.model.effects],
                     chi2=result.chi2, dof=result.dof, reduced_chi2=reduced, p_value=p,
                     segments=segs, candidates=cands, failures=failures, verdict=verdict,
                     result=result, labels=labels, notes=notes, test=test)


def rms_by_kind(segs) -> dict:
    """RMS of the whitened residuals per segment kind and quantity (accel/gyro, axis)."""
    acc = {}
    for seg in segs:
        for (q, axis), v in seg.values.items():
            sensor = "accel" if q.startswith("accel") else "gyro"
            acc.setdefault((seg.kind, sensor, axis), []).append(v)
    return {k: float(np.sqrt(np.mean(np.square(v)))) for k, v in sorted(acc.items())}
