"""What a calibration may claim: the fit verdict, honest 1-sigma, and the parameters the capture
determines.  Applied to every estimate before it is written (station.estimate.estimate_capture).

- **Fit verdict** (``fit.verdict``): the reduced chi-square and its p-value against the chi-square
  distribution of ``dof`` degrees of freedom; the fit *fails* when the p-value is below
  ``P_FAIL`` and the reduced chi-square above ``REDUCED_CHI2_FAIL`` (the residuals are then
  larger than the noise explains: a missing effect, a bad segment, a table that slipped).  The
  fit is *noise overestimated* when the lower tail is as improbable (P(chi2 < observed) below
  ``P_FAIL``) and the reduced chi-square below 1 / ``REDUCED_CHI2_FAIL``: the residuals are
  smaller than the stated noise, so every 1-sigma is too large (kept: conservative, said).  A
  least-squares fit stopped at its evaluation limit is *not converged* whatever its chi-square:
  the values are where it stopped, not a minimum.  A fit without redundant data (0 degrees of
  freedom, or a method without a chi-square) is *untested*, which is said, not hidden.  The
  verdicts that make ``estimate``/``run`` exit 3: ``fails`` and ``not converged``
  (:data:`UNUSABLE`).
- **Honest 1-sigma**: when the fit fails, every 1-sigma is multiplied by sqrt(reduced chi-square)
  (the Birge ratio) and ``fit.sigma_scale`` says so.
- **Identifiability**: a base parameter whose 1-sigma is infinite (it lies in the null space of
  the fit) or above its bound in ``BOUNDS`` is not determined by the capture and is not written.
  The gyro block (scale factors, misalignments, biases) is written whole or not at all; without
  any rotation segment it is never written (a scale factor needs a known rotation: the Earth
  rate alone is 0.004 deg/s).  The inter-triad rotation alone may be missing: the gyro output
  then stays in its own frame o.
- **Effect parameters not revealed**: an added effect's parameter the capture cannot reveal is
  held by a prior in the fit and not written (station.estimate.lsq.to_calibration names it in
  ``fit.not_determined``; its compensation uses the effect's nominal).  Not a failure: the
  verdict does not change.  When the data pull such a parameter beyond its prior's own check
  (``fit.held_contradicted``, station.estimate.lsq.held_pulls) the verdict's reason names it and
  the pull in sigma (``verdict.held_contradicted``): the parameters correlated with it rest on a
  prior the capture contradicts.
- **Words for large rotations**: an inter-triad rotation above ``LARGE_ROTATION_DEG``, or a
  negative scale factor, is named in the notes (axes swapped or inverted between the triads).
"""
from __future__ import annotations

import math

import numpy as np
from station.estimate import distributions

from station.core.errors import UserError
from station.model.calibration import Calibration

P_FAIL = distributions.P_FAIL                        # one honest fit in a thousand fails by chance
REDUCED_CHI2_FAIL = distributions.REDUCED_CHI2_FAIL  # and only when the residuals exceed the noise by half its variance
P_EDGE = 1e-2               # a passing fit whose chi2 comes by chance less often than this is said to be
                            #   at the edge of the noise model, not to agree with it (it still passes)
#: the verdicts a calibration file may carry, and those it must not be used with (exit status 3)
VERDICTS = ("passes", "fails", "not converged", "noise overestimated", "untested")
UNUSABLE = ("fails", "not converged")
LARGE_ROTATION_DEG = 1.0    # an inter-triad rotation above this is named in the notes
INVERTED_DEG = 90.0         # above this the triads' axes point (partly) the opposite way

# 1-sigma above which a base parameter is "not determined" (stated in docs/calibration-file.md);
# scale factors relative, biases in their reported unit (raw units: converted through the scale)
BOUNDS = {"scale": 1e-2,                # 10,000 ppm
          "misalignment": 3600.0,       # arcsec (1 deg)
          "inter_triad": 3600.0,        # arcsec (1 deg)
          "accel_bias": 1e4,            # ug (0.01 g)
          "gyro_bias": 360.0}           # deg/h (0.1 deg/s)

ACCEL_BLOCK = [f"accel_{q}_{a}" for q, axes in (("scale", "xyz"), ("misalignment", ("yz", "zy", "zx")),
                                                ("bias", "xyz")) for a in axes]
GYRO_BLOCK = [f"gyro_{q}_{a}" for q, axes in (("scale", "xyz"), ("misalignment", ("yz", "zy", "zx")),
                                              ("bias", "xyz")) for a in axes]
INTER_TRIAD = [f"inter_triad_{a}" for a in "xyz"]


def judge(cal: Calibration) -> Calibration:
    """Add the verdict, widen the 1-sigma of a failing fit, drop what is not determined, name
    large rotations; in place, and returned."""
    _verdict(cal)
    _identifiability(cal)
    _convergence(cal)
    _held_contradicted(cal)
    _rotations_in_words(cal)
    return cal


def _held_contradicted(cal: Calibration) -> None:
    """Held effect parameters whose prior the data contradict (fit.held_contradicted:
    station.estimate.lsq.held_pulls, beyond its false-alarm limit) are named in the verdict with
    their pull: they exceed their typical size (the values correlated with them then rest on a
    prior the capture contradicts) or the model misses what pulls on them (a linear tempco beside
    the quadratic term held alone fired so: review of held28).  The
    result is not changed: the verdict's chi-square is the data's, and the data agree with the
    noise while the prior rows take the conflict (optimal9 with rate-squared terms 5 times their
    typical size: the data's chi2 193.31 against 193.32 without them, the held priors' rows 61.2)."""
    pulled = cal.fit.get("held_contradicted")
    verdict = cal.fit.get("verdict")
    if not pulled or not isinstance(verdict, dict):
        return
    verdict["held_contradicted"] = dict(pulled)
    verdict["reason"] = (str(verdict.get("reason", "")) + "; but the data pull "
                         + ", ".join(f"{n} {w:+.1f} sigma" for n, w in pulled.items())
                         + " from the prior that holds each (0 +/- its typical size: not revealed, compensated "
                         "at 0): they exceed their typical size or the model misses what pulls on them (notes)")


def fit_fails(cal: Calibration) -> bool:
    """The fit fails or did not converge: the file says so and the command exits 3."""
    return cal.fit.get("verdict", {}).get("result") in UNUSABLE


def not_determined(cal: Calibration) -> list:
    return list(cal.fit.get("not_determined", []))


# ------------------------------------------------------------------------------------ verdict

def chi2_verdict(chi2: float, dof: float) -> dict:
    """The verdict of a chi2 on ``dof`` (> 0) degrees of freedom: result ("passes", "fails",
    "noise overestimated"), reduced chi2, p-value above and below.  The one rule of every
    surface: the calibration file (:func:`judge`) and station diagnose (station/diagnose/core.py),
    both on station.estimate.lsq.verdict_test's chi2 and redundancy (issue 29)."""
    return distributions.chi2_verdict(chi2, dof, P_FAIL, REDUCED_CHI2_FAIL)


def _verdict(cal: Calibration) -> None:
    fit = cal.fit
    chi2, dof = fit.get("chi2"), fit.get("dof")
    if chi2 is None or dof is None or not dof > 0 or not math.isfinite(chi2):
        fit["verdict"] = {"result": "untested",
                          "reason": f"no redundant data ({max(dof, 0) if dof is not None else 'no'} degrees of "
                                    f"freedom for method {fit.get('method')}): the model cannot be "
                                    "checked against the measurements"}
        return
    redundancy = fit.get("data_redundancy")
    if redundancy is not None and redundancy < 0.5:
        fit["verdict"] = {"result": "untested",
                          "reason": f"the data have no redundancy of their own ({redundancy:.2g}; the "
                                    f"{dof} degrees of freedom counted are the priors'): the model "
                                    "cannot be checked against the measurements"}
        return
    # the test: the data's chi2 on the data's own redundancy (the leverages: priors take none
    # of it), less a group whose noise was estimated from its own scatter (noise_model: the hand
    # turns), when the fit says what it tested; else the counted degrees of freedom
    tested = (fit.get("noise_model") or {}).get("tested")
    left_out = []
    if tested:
        chi2, dof, left_out = float(tested["chi2"]), float(tested["redundancy"]), list(tested.get("left_out", []))
        if dof < 0.5:
            fit["verdict"] = {"result": "untested",
                              "reason": f"no redundancy is left to test the model ({dof:.2g}) once the noise of "
                                        f"{', '.join(left_out) or 'the data'} is estimated from its own scatter"}
            return
    test = chi2_verdict(chi2, dof)
    reduced, p_value, p_below, result = test["reduced_chi2"], test["p_value"], test["p_below"], test["result"]
    fails, overestimated = result == "fails", result == "noise overestimated"
    verdict = {"result": result, "reduced_chi2": float(reduced), "dof": round(dof, 2) if tested else int(dof),
               "p_value": p_value}
    if left_out:
        verdict["left_out"] = left_out
    terms = (fit.get("noise_model") or {}).get("terms")
    if terms:
        verdict["noise_model"] = ", ".join(terms)
    if fit.get("converged") is False and not _written_at_minimum(cal, fit.get("remaining_step_sigma")):
        verdict["result"] = "not converged"
        how = ("on its tolerances short of its minimum (a Gauss-Newton step from there still lowers chi2)"
               if fit.get("stopped_short") else "where it crept" if _settled(fit) else "at its evaluation limit")
        verdict["reason"] = (f"the fit stopped {how} before it converged (reduced chi2 "
                             f"{reduced:.3g} where it stopped): the values and 1-sigma are not those of a "
                             "minimum; do not use this calibration (station diagnose shows which "
                             "parameters the data barely see)")
        fit["verdict"] = verdict
        return
    if overestimated:
        verdict["p_below"] = p_below
        verdict["reason"] = (f"reduced chi2 {reduced:.3g} (P(chi2 below) = {p_below:.2g} for {dof:.4g} degrees of "
                             f"freedom): the residuals are smaller than the stated noise, so every 1-sigma "
                             f"is too large, by up to {1 / math.sqrt(reduced):.3g} times (kept as they are: "
                             "conservative); the noise given to the fit is overestimated (a noise figure "
                             "from a datasheet, or samples averaged before recording)")
        fit["verdict"] = verdict
        return
    if fails:
        verdict["reason"] = (f"reduced chi2 {reduced:.3g} (p = {p_value:.2g} for {dof:.4g} degrees of freedom): "
                             "the residuals are larger than the noise explains (a missing effect, a "
                             "bad segment, data lost or a table that slipped); station diagnose "
                             "shows where")
        scale = math.sqrt(reduced)
        # a pose-only accelerometer block (station.estimate.poses) carries its own fit's scale
        own = set(ACCEL_BLOCK) if str(fit.get("pose_check", {}).get("written", "")).startswith("pose-only") else set()
        cal.sigma = {name: s * (1.0 if name in own else scale) for name, s in cal.sigma.items()}
        # the 1-sigma of a value an effect holds and the fit freed (station.estimate.lsq.
        # _held_values_freed: "<name>_sigma" beside "<name>" in its state, a bias step's time)
        for entry in getattr(cal, "effect_compensation", None) or []:
            state = entry.get("state") if isinstance(entry, dict) else None
            for key, v in list((state or {}).items()):
                if (key.endswith("_sigma") and key[:-len("_sigma")] in state and isinstance(v, float)
                        and math.isfinite(v)):
                    state[key] = v * scale
        fit["sigma_scale"] = scale
        fit.setdefault("notes", []).append(
            f"the fit fails (reduced chi2 {reduced:.3g}): every 1-sigma is multiplied by "
            f"sqrt(reduced chi2) = {scale:.3g}"
            + (f", except the accelerometers', which are the poses' own fit's (scaled by its own "
               f"sqrt(reduced chi2) = {fit['pose_check'].get('sigma_scale', 1.0):.3g})" if own else ""))
    else:
        at_edge = p_value < P_EDGE and reduced > 1.0
        verdict["reason"] = (f"reduced chi2 {reduced:.3g} (p = {p_value:.2g}): the residuals "
                             + ("are at the edge of what the noise" if at_edge else "agree with the noise")
                             + (f" model ({verdict['noise_model']})" if terms and terms != ["white"] else "")
                             + (f" explains (a chi2 this large comes by chance in a share {p_value:.2g} of the "
                                f"fits of a right model; a fit fails below {P_FAIL:g}: station diagnose shows "
                                "where the residuals are largest)" if at_edge else "")
                             + (f"; {', '.join(left_out)} not tested (their noise estimated from their scatter)"
                                if left_out else ""))
    fit["verdict"] = verdict


REMAINING_STEP_SIGMA = 0.01   # a stopped fit whose written parameters would all move less is at its minimum


def _written_at_minimum(cal: Calibration, steps) -> bool:
    """The solver stopped at its limit, but the step it would still take moves no parameter that
    can be written by REMAINING_STEP_SIGMA of its 1-sigma or more: what remains is in directions
    the data barely see (the poses' headings, an undetermined gyro block), which are not written.
    The parameters not determined are judged after this (_convergence does it again then)."""
    if not steps:
        return False
    dropped = set(cal.fit.get("not_determined", []))
    moving = {n: v for n, v in steps.items() if n not in dropped and n in cal.sigma}
    return bool(moving) and max(moving.values()) < REMAINING_STEP_SIGMA


def _convergence(cal: Calibration) -> None:
    """Once the undetermined parameters are left out: a stopped fit whose written parameters are
    at the minimum is said so (a note); one whose verdict said otherwise is not converged."""
    fit = cal.fit
    if fit.get("converged") is not False:
        return
    steps = fit.get("remaining_step_sigma") or {}
    if _written_at_minimum(cal, steps):
        if fit["verdict"].get("result") == "not converged":      # judged before the dropping
            fit["verdict"].pop("result")
            _verdict_without_convergence(cal)
        worst = max((v for n, v in steps.items() if n in cal.sigma), default=0.0)
        where = "where it crept" if _settled(fit) else "at its evaluation limit"
        # a failing fit's residuals can mislead the linear model the step is taken from: the
        # eighteenth session's settled fits, so judged, were 1.0-5.8 chi2 units above a minimum
        # dogbox from the start reaches (nineteenth session; that second solve is now tried where a
        # full solve ends not converged, but not on every path: a large model's, a short budget's)
        caveat = ("; by the linear model, which a failing fit's residuals can mislead (fits so judged have ended "
                  "1-6 chi2 units above a minimum another solver reached)"
                  if fit["verdict"].get("result") == "fails" else "")
        fit.setdefault("notes", []).append(
            f"the solver stopped {where}, but every parameter written is at the "
            f"minimum: the step it would still take is at most {worst:.2g} of a 1-sigma (what remains "
            f"is in directions the data barely see, not written){caveat}")


def _settled(fit: dict) -> bool:
    """Whether the fit stopped where it crept (lsq._last_phase), not at its limit: ``fit.settled``
    (true; written since the nineteenth session).  A file without the key is settled only if it
    is one the eighteenth session wrote for a settled fit, which said so in a note's first words
    (lsq.SETTLED_NOTE) and nowhere else; any other file without it: not settled."""
    if "settled" in fit:
        return fit["settled"] is True
    from station.estimate.lsq import SETTLED_NOTE

    return any(str(n).startswith(SETTLED_NOTE) for n in fit.get("notes", []))


def _verdict_without_convergence(cal: Calibration) -> None:
    converged = cal.fit.pop("converged")
    try:
        _verdict(cal)
    finally:
        cal.fit["converged"] = converged


# ------------------------------------------------------------------------------------ identifiability

def _bound(name: str, cal: Calibration) -> tuple[float, float]:
    """(1-sigma in the unit of the bound, the bound) of a base parameter."""
    sigma = cal.sigma.get(name)
    sigma = math.inf if sigma is None or not math.isfinite(sigma) else sigma
    values = {n: v for n, v, _ in cal.parameters()}
    if "_scale_" in name:
        value = abs(values[name])
        return (sigma / value if value > 0 else math.inf), BOUNDS["scale"]
    if "_misalignment_" in name:
        return sigma, BOUNDS["misalignment"]
    if name.startswith("inter_triad"):
        return sigma, BOUNDS["inter_triad"]
    axis = name[-1]
    if name.startswith("accel_bias"):
        if cal.accel_unit == "raw":           # raw -> m/s^2 -> ug through the scale factor
            scale = abs(values[f"accel_scale_{axis}"]) or math.inf
            sigma = sigma / scale / 9.80665e-6
        return sigma, BOUNDS["accel_bias"]
    if cal.gyro_unit == "raw":                # raw -> deg/s -> deg/h
        scale = abs(values[f"gyro_scale_{axis}"]) or math.inf
        sigma = sigma / scale * 3600.0
    return sigma, BOUNDS["gyro_bias"]


def _undetermined(cal: Calibration, names) -> list:
    out = []
    for name in names:
        sigma, bound = _bound(name, cal)
        if not sigma <= bound:
            out.append(name)
    return out


def _identifiability(cal: Calibration) -> None:
    fit = cal.fit
    notes = fit.setdefault("notes", [])
    has_sigma = bool(cal.sigma)
    # accelerometer parameters the poses cannot determine (station.estimate.poses: too few
    # distinct attitudes), held at 0 in the fit: not written, the reason in the notes
    held = [n for n in fit.get("accel_not_determined", []) if n in ACCEL_BLOCK]
    accel = [n for n in _undetermined(cal, ACCEL_BLOCK) if n not in held] if has_sigma else []
    if accel:
        raise UserError(f"the capture does not determine the accelerometers ({', '.join(accel)}: 1-sigma "
                        "infinite or above its bound): record more static attitudes (at least 9, each "
                        "axis up and down)")
    rotations = fit.get("rotation_segments", fit.get("rotation_pairs"))
    if rotations is not None:       # hand turns of unknown angle calibrate the gyros too
        rotations += fit.get("hand_rotations", 0)
    gyro = _undetermined(cal, GYRO_BLOCK) if has_sigma else []
    dropped: list = []
    if rotations == 0 or gyro:
        why = ("no rotation segment with a known angle" if rotations == 0
               else f"{', '.join(gyro)}: 1-sigma infinite or above its bound")
        dropped = GYRO_BLOCK + INTER_TRIAD
        fit["gyro_calibrated"] = False
        cal.R_po = np.eye(3)
        cal.effects = [e for e in cal.effects if e != "inter_triad"]
        notes.append(f"accelerometer-only calibration: the capture does not determine the gyros ({why}); "
                     "the gyro parameters are not written and station apply passes the gyro through "
                     "untouched (unit conversion only)")
    else:
        inter = _undetermined(cal, INTER_TRIAD) if has_sigma else []
        if inter:
            dropped = INTER_TRIAD
            cal.R_po = np.eye(3)
            cal.effects = [e for e in cal.effects if e != "inter_triad"]
            notes.append(f"the inter-triad rotation is not determined ({', '.join(inter)}: 1-sigma infinite "
                         "or above its bound): not written; the compensated gyro output stays in the "
                         "gyros' own frame o")
    dropped = held + dropped
    # the effect parameters the capture does not reveal (held by their priors: lsq.to_calibration
    # leaves them out and names them) stay named after the base parameters dropped here
    effects = [n for n in fit.get("not_determined", []) if n not in dropped]
    if dropped:
        fit["not_determined"] = dropped + effects
        for name in dropped:
            cal.sigma.pop(name, None)


# ------------------------------------------------------------------------------------ words

def _axis_words(axis: np.ndarray) -> str:
    return "[" + ", ".join(f"{c:+.3f}" for c in axis) + "]"


def _rotations_in_words(cal: Calibration) -> None:
    notes = cal.fit.setdefault("notes", [])
    for sensor, scale in (("accelerometer", cal.accel_scale), ("gyro", cal.gyro_scale)):
        if sensor == "gyro" and cal.fit.get("gyro_calibrated") is False:
            continue
        for axis, k in zip("xyz", scale):
            if k < 0:
                notes.append(f"warning: the {sensor} {axis} axis is inverted (scale factor {k:.6g}): "
                             "its sign in the IMU's output is opposite to the case marking")
    if "inter_triad" not in cal.effects:
        return
    rotvec = cal.inter_triad_rad
    angle = math.degrees(float(np.linalg.norm(rotvec)))
    if angle <= LARGE_ROTATION_DEG:
        return
    axis = rotvec / np.linalg.norm(rotvec)
    if angle > INVERTED_DEG:
        inverted = [a for a, d in zip("xyz", np.diag(cal.R_po)) if d < 0]
        notes.append(f"warning: the gyro axes are inverted against the accelerometers': a rotation of "
                     f"{angle:.1f} deg about {_axis_words(axis)} between the triads (gyro "
                     f"{', '.join(inverted) or 'axes'} pointing opposite to the accelerometer ones): check "
                     "the axis order and signs of the IMU's output")
    else:
        notes.append(f"warning: a large rotation between the triads: {angle:.2f} deg about "
                     f"{_axis_words(axis)} (a mounting or axis-order problem; the usual size is arcseconds "
                     "to arcminutes)")
