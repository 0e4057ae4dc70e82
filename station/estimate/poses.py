"""Never worse than the poses alone; poses are not attitudes (issue 24, items 2 and 3).

After the joint least-squares fit (statics with rotations and/or hand turns), the accelerometer
block (scale factors, misalignments, biases: 9 parameters) is compared with the fit of the same
static poses alone (rotations and turns left out: the accelerometer-only fit the capture would
give without them).

**Distinct attitudes.**  The static poses' accelerometer means are clustered by direction
(station.model.geometry.distinct_directions, within ATTITUDE_TOLERANCE_DEG): a pose held twice on
the same face is one attitude.  With unknown attitudes each distinct gravity direction gives the
accelerometers one equation (3 components less its 2 attitude angles), so their 9 unknowns need
at least MIN_ATTITUDES (9) distinct directions.  Fewer, and the poses cannot tell the
misalignments (the six faces of a Ferraris layout see scale factors and biases to first order,
the misalignments only to second): the joint fit's misalignments then rest on the turns alone.
They are not written (``fit.not_determined``, with the reason); the scale factors and biases come
from the poses with the misalignments held at 0, and the gyros are refitted with those
accelerometers held (below).  With attitudes given (``up_body``: the table path, the placement
prior) nothing changes here: the prior's 1-sigma says what the poses leave open.

**The consistency check.**  Under the model and its weights the joint fit is the pose-only fit
plus information independent of the poses' (the turns, the rotations): the joint estimate is
then efficient and the pose-only one is not, so (Hausman 1978) their difference has covariance
Sigma_pose - Sigma_joint, not the sum (the two share the static data; the sum would hide a
difference).  Each of the m compared parameters gives z = |difference| / sqrt((Sigma_pose -
Sigma_joint)_ii) (the diagonal floored at 1e-4 Sigma_pose,ii: a parameter the other groups do not
inform differs by rounding only); both covariances are scaled by the pose-only fit's reduced chi2
when it exceeds 1 (the poses' own scatter).  The fits disagree when the largest z exceeds the
two-sided Bonferroni bound for a false alarm of P_FALSE (1e-3) over the m parameters:
ndtri(1 - P_FALSE / 2m), 3.87 for m = 9.

**What is written.**  When they agree, the joint fit (unchanged).  When they disagree (or the
misalignments are not determined by the poses), the pose-only accelerometer block, which no
mis-weighted turn or rotation can bend, and every other parameter (gyros, inter-triad, nuisances,
effects) refitted with the accelerometers held at it; the held parameters carry the pose-only
covariance, propagated into the others: Sigma_other = (J_o^T J_o)^-1 + G Sigma_pose G^T,
G = -(J_o^T J_o)^-1 J_o^T J_a the change of the refitted parameters with the held ones (to first
order; the correlation between the pose-only block and the refit through the shared static data
is neglected).  The group that pulls is named: the joint fit's one-step leave-one-group-out
change of the accelerometer block, (H - J_g^T J_g)^-1 J_g^T r_g, for the hand turns together, the
table rotations together and each segment, in units of the difference's 1-sigma.
"""
from __future__ import annotations

import copy
import dataclasses
import math

import numpy as np

from station.core import units
from station.estimate import lsq, solver
from station.estimate.distributions import norm_ppf
from station.estimate.summaries import summarise
from station.model.geometry import ATTITUDE_TOLERANCE_DEG, distinct_directions

P_FALSE = 1e-3              # one consistent joint fit in a thousand is called inconsistent
MIN_ATTITUDES = 9           # unknown attitudes: one equation per gravity direction, 9 unknowns
HELD_PRIOR_RAD = 1e-9       # a misalignment held at 0 (a prior row; not a datum)
FLOOR = 1e-4                # Sigma_pose - Sigma_joint >= FLOOR Sigma_pose on the diagonal
ACCEL_COLUMNS = np.arange(9)    # accel_scale xyz, accel_misalignment yz zy zx, accel_bias xyz (lsq.GLOBAL)
NAMES = ([f"accel_scale_{a}" for a in "xyz"] + [f"accel_misalignment_{a}" for a in ("yz", "zy", "zx")]
         + [f"accel_bias_{a}" for a in "xyz"])
MISALIGNMENT = [3, 4, 5]


def threshold(m: int) -> float:
    """The |z| above which one of m Gaussian differences is called a disagreement (Bonferroni,
    two-sided, false alarm P_FALSE in all)."""
    return float(norm_ppf(1.0 - P_FALSE / (2.0 * m)))


def attitudes(s, result: lsq.FitResult | None = None) -> tuple[int, int]:
    """(static poses, distinct gravity directions among them) of the summaries: the poses'
    accelerometer means compensated by the fit's accelerometer block when there is one (raw
    counts, offset-binary or not, point anywhere until their bias is removed)."""
    if not s.statics:
        return 0, 0
    means = np.array([st.accel for st in s.statics], float)
    if result is not None:
        Ma, _ = result.model._matrices(result.x)
        means = np.linalg.solve(Ma, (means - result.x[result.model.layout["accel_bias"]]).T).T
    labels = distinct_directions(means)
    return len(s.statics), int(labels.max()) + 1


# ------------------------------------------------------------------------------------ fits

def pose_only(s, attitudes_mode: str, hold_misalignment: bool = False, effects=(), pose_extra=None,
              start_from: lsq.FitResult | None = None) -> lsq.FitResult:
    """The fit of the static poses alone (rotations and turns left out), in the joint model's
    attitude mode and with its effects (copies: an effect is set up for the summaries it
    models) and its poses' weights (``pose_extra``: the joint model's, so that the two fits
    weight the shared static data alike, as the comparison's covariance assumes); the
    misalignments held at 0 when asked (prior rows of HELD_PRIOR_RAD).  ``start_from``: the
    joint fit, whose values start the blocks both have (lsq.fit's start_from: fewer evaluations,
    the same minimum)."""
    sp = dataclasses.replace(s, rotations=[], hand_rotations=[], skipped=[])
    effects = copy.deepcopy(list(effects))
    if not hold_misalignment:
        return lsq.fit(sp, effects, attitudes_mode, pose_extra=pose_extra, start_from=start_from)
    model = lsq.Model(sp, effects, attitudes_mode)
    if start_from is not None:
        lsq.start_blocks(model, start_from)
    if pose_extra is not None:
        model.set_pose_extra(pose_extra)
    model.unobservable = []
    L = model.layout
    held = 0
    for block, width in lsq.NO_ROTATION_PRIORS.items():
        for c in range(L[block].start, L[block].stop):
            model.priors[c] = width
            held += 1
    if hold_misalignment:
        x0 = model.x0
        x0[L["accel_misalignment"]] = 0.0
        for c in range(L["accel_misalignment"].start, L["accel_misalignment"].stop):
            model.priors[c] = HELD_PRIOR_RAD
            held += 1
    model.refresh()
    x, cov, r, reduced = lsq._solve(model, model.x0)
    r = r[model.data_rows]
    dof = len(r) - L.size - held
    return lsq.FitResult(x=x, covariance=cov, model=model, chi2=float(r @ r), dof=dof, residuals=r,
                         rank_deficient=reduced.full(reduced.svd.null_columns()),
                         covariance_columns=reduced.columns if model.is_large else None)


def _dense_jacobian(model, x) -> np.ndarray:
    J = model.sparse_jacobian(x) if model.is_large else model.jacobian(x)
    return J.toarray() if hasattr(J, "toarray") else np.asarray(J)


def held_refit(joint: lsq.FitResult, values: np.ndarray, cov_held: np.ndarray) -> lsq.FitResult:
    """The joint model refitted with the accelerometer block held at ``values`` (internal units,
    lsq.GLOBAL order), which carry ``cov_held``; the covariance of the others propagated from it
    (module doc)."""
    model = joint.model
    size = model.layout.size
    held = ACCEL_COLUMNS
    free = np.setdiff1d(np.arange(size), held)
    x = joint.x.copy()
    x[held] = values

    def full(z):
        xx = x.copy()
        xx[free] = z
        return xx

    def fun(z):
        return model.residuals(full(z))

    def jac(z):
        J = model.sparse_jacobian(full(z)) if model.is_large else model.jacobian(full(z))
        return J.tocsc()[:, free] if hasattr(J, "tocsc") else np.asarray(J)[:, free]

    options = dict(xtol=1e-10, ftol=1e-10, gtol=1e-10, max_nfev=lsq.MAX_EVALUATIONS)
    if model.is_large:
        from scipy.optimize import least_squares     # (large models only)

        res = least_squares(fun, x[free], jac=jac, method="trf", tr_solver="lsmr", x_scale="jac", **options)
    else:       # MINPACK's Levenberg-Marquardt in numpy (station/estimate/solver.py: no scipy import)
        res = solver.least_squares(fun, x[free], jac, **options)
    x = full(res.x)
    model.converged = res.status != 0
    J = _dense_jacobian(model, x)
    J_f, J_h = J[:, free], J[:, held]
    svd = lsq._ScaledSVD(J_f)          # one factorisation for the covariance and the null space
    cov_ff = svd.covariance()
    G = -cov_ff @ (J_f.T @ J_h)
    cov = np.zeros((size, size))
    cov[np.ix_(free, free)] = cov_ff + G @ cov_held @ G.T
    cov[np.ix_(free, held)] = G @ cov_held
    cov[np.ix_(held, free)] = (G @ cov_held).T
    cov[np.ix_(held, held)] = cov_held
    r = res.fun[model.data_rows]
    null = [int(free[k]) for k in svd.null_columns()]
    return lsq.FitResult(x=x, covariance=cov, model=model, chi2=float(r @ r), dof=joint.dof + len(held),
                         residuals=r, rank_deficient=null, covariance_columns=None)


# ------------------------------------------------------------------------------------ comparison

def _in_units(x_block: np.ndarray, values: np.ndarray, accel_raw: bool) -> tuple[np.ndarray, list]:
    """Accelerometer-block differences (internal) in reported units: ppm, arcsec, micro-g (raw)."""
    out = np.array(x_block, float).copy()
    out[:3] = out[:3] / np.abs(values[:3]) * 1e6
    out[3:6] = out[3:6] / units.ARCSEC_RAD
    if not accel_raw:
        out[6:] = out[6:] / units.UG_MPS2
    return out, ["ppm"] * 3 + ["arcsec"] * 3 + (["raw"] if accel_raw else ["ug"]) * 3


def _groups(model, x) -> dict:
    """Residual rows of each segment and the class it belongs to (hand turns, rotations,
    poses)."""
    labels = model.row_labels(x)
    hands = {h.name for h in model.hands}
    rows: dict = {}
    for i, (seg, kind, quantity, _) in enumerate(labels):
        if kind == "static":
            cls = "poses"
        elif seg in hands:
            cls = "hand turns"
        elif kind == "rotation" and not seg.startswith("axis"):
            cls = "rotations"
        else:
            continue
        rows.setdefault((cls, seg), []).append(i)
    return rows


def _pulls(joint: lsq.FitResult, sigma_diff: np.ndarray, compared: np.ndarray) -> tuple[list, dict]:
    """Per segment and per class: the largest change of the compared accelerometer parameters,
    in sigma of the difference, were it left out (one Gauss-Newton step from the joint solution);
    and each class's chi2 per row."""
    model, x = joint.model, joint.x
    J = _dense_jacobian(model, x)
    r = model.residuals(x)
    norms = np.linalg.norm(J, axis=0)
    norms[norms == 0] = 1.0
    Js = J / norms
    H = Js.T @ Js
    rows = _groups(model, x)
    classes: dict = {}
    for (cls, seg), idx in rows.items():
        classes.setdefault(cls, []).extend(idx)

    def pull(idx):
        Jg, rg = Js[idx], r[idx]
        step = np.linalg.pinv(H - Jg.T @ Jg, rcond=1e-12) @ (Jg.T @ rg) / norms
        return float(np.max(np.abs(step[ACCEL_COLUMNS][compared]) / sigma_diff[compared]))

    per_class = {cls: {"pull_sigma": pull(idx), "chi2_per_row": float(r[idx] @ r[idx] / len(idx))}
                 for cls, idx in classes.items() if cls != "poses"}
    per_class["poses"] = {"chi2_per_row": float(r[classes["poses"]] @ r[classes["poses"]] / len(classes["poses"]))} \
        if "poses" in classes else {}
    segments = sorted(((pull(idx), seg) for (cls, seg), idx in rows.items() if cls != "poses"), reverse=True)
    return segments, per_class


def check(s, joint: lsq.FitResult, accel_unit: str) -> tuple[dict, lsq.FitResult | None]:
    """The pose check's record (for ``fit.pose_check``) and, when the joint accelerometers are
    not to be written, the fit to write instead (held_refit); None: write the joint fit."""
    poses, distinct = attitudes(s, joint)
    mode = joint.model.attitudes
    few = mode == "unknown" and distinct < MIN_ATTITUDES
    pose = pose_only(s, mode, hold_misalignment=few, effects=joint.model.effects, pose_extra=joint.model.pose_extra,
                     start_from=joint)
    k2 = max(1.0, pose.chi2 / pose.dof) if pose.dof > 0 else 1.0
    cov_pose = pose.covariance_of(ACCEL_COLUMNS) * k2
    cov_joint = joint.covariance_of(ACCEL_COLUMNS) * k2
    d = joint.x[ACCEL_COLUMNS] - pose.x[ACCEL_COLUMNS]
    var_pose = np.diag(cov_pose)
    var_diff = np.maximum(var_pose - np.diag(cov_joint), FLOOR * var_pose)
    sigma_diff = np.sqrt(np.clip(var_diff, 0.0, None))
    blind = set(int(c) for c in pose.rank_deficient)
    compared = np.array([c not in blind and np.isfinite(sigma_diff[c]) and sigma_diff[c] > 0
                         and not (few and c in MISALIGNMENT) for c in ACCEL_COLUMNS])
    z = np.where(compared, np.abs(d) / np.where(sigma_diff > 0, sigma_diff, 1.0), 0.0)
    m = int(compared.sum())
    zc = threshold(max(m, 1))
    worst = int(np.argmax(z))
    raw = accel_unit == "raw"
    d_rep, unit = _in_units(d, joint.x[ACCEL_COLUMNS], raw)
    s_rep, _ = _in_units(sigma_diff, joint.x[ACCEL_COLUMNS], raw)
    record = {
        "poses": poses, "distinct_attitudes": distinct, "attitude_tolerance_deg": ATTITUDE_TOLERANCE_DEG,
        "pose_only_reduced_chi2": float(pose.chi2 / pose.dof) if pose.dof > 0 else None,
        "compared": m, "threshold_sigma": zc, "largest_sigma": float(z[worst]), "parameter": NAMES[worst],
        "differences": {NAMES[c]: {"joint_minus_poses": float(d_rep[c]), "sigma": float(s_rep[c]),
                                   "in_sigma": float(z[c]), "unit": unit[c]}
                        if compared[c] else
                        {"joint_minus_poses": float(d_rep[c]), "sigma": None, "in_sigma": None, "unit": unit[c]}
                        for c in range(9) if compared[c] or (few and c in MISALIGNMENT)},
    }
    disagree = bool(m and z[worst] > zc)
    record["result"] = "disagree" if disagree else "agree"
    notes = []
    if few:
        record["compared_with"] = "the poses' fit with the misalignments held at 0"
        record["misalignments"] = (f"not determined by the poses: {poses} poses in {distinct} distinct attitudes "
                                   f"(gravity directions {ATTITUDE_TOLERANCE_DEG:g} deg apart); with unknown "
                                   f"attitudes each gives the accelerometers one equation, their 9 unknowns need "
                                   f"{MIN_ATTITUDES}: the joint fit's misalignments rest on the turns alone")
        notes.append(f"accelerometer misalignments not written: {record['misalignments']}; the scale factors and "
                     "biases are the poses' (misalignments held at 0), the gyros refitted with them held")
    if disagree or few:
        segments, per_class = _pulls(joint, np.where(sigma_diff > 0, sigma_diff, np.inf), compared)
        movers = {cls: v for cls, v in per_class.items() if cls != "poses"}
        pulling = max(movers, key=lambda c: movers[c]["pull_sigma"]) if movers else None
        record["groups"] = per_class
        record["pulling"] = pulling
        record["pulling_segments"] = [{"segment": seg, "pull_sigma": p} for p, seg in segments[:3]]
    if disagree:
        c = worst
        top = ", ".join(f"{e['segment']} ({e['pull_sigma']:.1f} sigma)" for e in record["pulling_segments"])
        chi = per_class.get(record["pulling"], {}).get("chi2_per_row")
        notes.append(
            f"the joint fit bends the accelerometers: {NAMES[c]} differs from the poses' own fit by "
            f"{d_rep[c]:+.4g} {unit[c]}, {z[c]:.1f} sigma of the difference (threshold {zc:.2f} sigma: a false "
            f"alarm of {P_FALSE:g} over {m} parameters); the {record['pulling']} pull"
            + (f" (their rows scatter {math.sqrt(chi):.3g} times their sigma)" if chi else "")
            + (f", most {top}" if top else "")
            + "; written: the poses' accelerometer block, every other parameter refitted with it held "
              "(the joint fit's accelerometers are in fit.pose_check)")
    if not (disagree or few):
        record["written"] = "joint fit"
        return {**record, "notes": notes}, None
    values = pose.x[ACCEL_COLUMNS].copy()
    if few:
        values[MISALIGNMENT] = 0.0
    record["written"] = "pose-only accelerometers, the rest refitted with them held"
    record["joint_accelerometers"] = {NAMES[c]: float(joint.x[c]) for c in range(9)}
    record["sigma_scale"] = math.sqrt(k2)
    refit = held_refit(joint, values, cov_pose)
    return {**record, "notes": notes}, refit


def estimate(capture, effects=None, attitudes_mode: str = "auto", table_angle_arcsec=None,
             turn_sigma_deg: float | None = None):
    """lsq.estimate with the pose check: the calibration to write, ``fit.pose_check`` said.
    ``turn_sigma_deg``: the hand turns' stated 1-sigma per turn (None: estimated, lsq.fit)."""
    s = summarise(capture, table_angle_arcsec=table_angle_arcsec)
    joint = lsq.fit(s, effects, attitudes_mode, turn_sigma_deg=turn_sigma_deg)
    au, gu = capture.imu.accel_unit, capture.imu.gyro_unit
    poses, distinct = attitudes(s, joint)
    if not (s.rotations or s.hand_rotations) or len(s.statics) < 2:
        cal = lsq.to_calibration(joint, au, gu)
        cal.fit["attitudes"] = {"poses": poses, "distinct": distinct}
        return cal
    if joint.model.effects:
        # effects the poses alone cannot reveal are held by priors in a pose-only fit, which then
        # is not the joint model less independent data: the difference would not be a test
        cal = lsq.to_calibration(joint, au, gu)
        cal.fit["attitudes"] = {"poses": poses, "distinct": distinct}
        cal.fit["pose_check"] = {"result": "not checked", "written": "joint fit",
                                 "reason": "effects added: the poses alone are another model"}
        return cal
    record, refit = check(s, joint, au)
    notes = record.pop("notes")
    cal = lsq.to_calibration(refit if refit is not None else joint, au, gu, notes=notes)
    cal.fit["attitudes"] = {"poses": poses, "distinct": distinct}
    cal.fit["pose_check"] = record
    if refit is not None and record.get("misalignments"):
        cal.fit["accel_not_determined"] = [NAMES[c] for c in MISALIGNMENT]
    return cal
