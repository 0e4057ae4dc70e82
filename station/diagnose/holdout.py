"""Out-of-sample check: how well a fitted model predicts each segment it was not fitted to.

Leave-one-segment-out cross-validation of the linearised model at the fit.  For segment g, the
model is fitted to every other segment, then g's own nuisances (its attitude, or its rotation's
start phases) are fitted to g's data alone and what is left of g's residuals is its prediction
error.  At the least-squares solution this needs no refits: with each segment's own nuisance
columns projected out of its rows (P_g = I - J_gl (J_gl' J_gl)^+ J_gl'), the profiled problem is a
linear regression on the shared parameters with design X and residuals e, and deleting a block
of rows gives the classical deleted residuals
    e_(g) = (I - H_gg)^-1 e_g,      H = X (X'X)^+ X'.
The score is each left-out segment's predictive chi2 (its deleted residuals against their own
covariance, plus the log-determinant of that covariance), summed.  A segment whose data alone
determine some shared parameter (H_gg has an eigenvalue 1) cannot be predicted from the others
and is left out of the score, and named.

An effect is worth adding when it makes the other segments predict each one better: a term
that only absorbs the noise or the misfit of one segment raises this score.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from station.diagnose.core import fit_fails, fit_jacobian

LEVERAGE_LIMIT = 1.0 - 1e-6      # a block whose largest leverage reaches this is unpredictable
MIN_SHARE = 0.5                  # of the excess chi2 (chi2 - dof) an added effect must explain
                                 #   when the fit fails: at one rate a bench vibration, a bias
                                 #   step or a remount can be fitted in part by a library effect
                                 #   whose extrapolation is wrong (22-35 % of the excess in the
                                 #   simulated cases of docs/diagnose.md); the cause explains most


@dataclass
class Holdout:
    score: float                     # sum of the predictable segments' predictive chi2
    per_segment: dict                # segment name -> its predictive chi2
    unpredictable: list = field(default_factory=list)   # segments the others cannot predict
    press: dict = field(default_factory=dict)   # segment name -> its squared deleted residuals (the
                                                #   score until run 3 of issue 25; judge: a fit that passes)

    def common_press(self, other: "Holdout") -> tuple[float, float]:
        """Both sums of squared deleted residuals over the segments both models can predict."""
        names = set(self.press) & set(other.press)
        return (sum(self.press[n] for n in names), sum(other.press[n] for n in names))

    def common_score(self, other: "Holdout") -> tuple[float, float]:
        """Both scores over the segments that both models can predict."""
        names = set(self.per_segment) & set(other.per_segment)
        return (sum(self.per_segment[n] for n in names), sum(other.per_segment[n] for n in names))


def _blocks(model, x):
    """Row indices and local (nuisance) columns of every segment; rows of nothing else."""
    _, tags = model._pieces(x)
    rows, at = {}, 0
    for tag, n, quantity in tags:
        rows.setdefault(tag, []).extend(range(at, at + n))
        at += n
    L = model.layout
    names = {("static", j): st.name for j, st in enumerate(model.s.statics)}
    names.update({("rot", i): r.name for i, r in enumerate(model.s.rotations)})
    blocks = []
    for (kind, j), name in names.items():
        data = rows.get((kind, j), [])
        if not data:
            continue
        weak = rows.get(("weak", j), []) if kind == "static" else []
        col = L[f"static{j}"] if kind == "static" else L[f"phase{j}"]
        blocks.append((name, np.array(data, int), np.array(weak, int), np.arange(col.start, col.stop)))
    return blocks, at


def leave_one_segment_out(result) -> Holdout:
    model, x = result.model, result.x
    r = model.residuals(x)
    # a large model's Jacobian sparse (the whole of it dense: rows x columns, 290 MB at 1,000
    # segments); only the shared columns are needed whole
    J = model.sparse_jacobian(x).tocsr() if model.is_large else fit_jacobian(result)
    blocks, n_rows = _blocks(model, x)
    local = np.zeros(J.shape[1], bool)
    for _, _, _, cols in blocks:
        local[cols] = True
    shared = np.flatnonzero(~local)
    X = J[:, shared].toarray() if model.is_large else J[:, shared].copy()
    e = r.copy()
    for _, data, weak, cols in blocks:
        rows = np.concatenate([data, weak])
        if not len(cols):
            continue
        Jl = J[rows][:, cols].toarray() if model.is_large else J[np.ix_(rows, cols)]
        q, s, _ = np.linalg.svd(Jl, full_matrices=False)
        q = q[:, s > 1e-10 * max(s.max(initial=0.0), 1e-300)]
        X[rows] -= q @ (q.T @ X[rows])
        e[rows] -= q @ (q.T @ e[rows])
    norms = np.linalg.norm(X, axis=0)
    norms[norms == 0] = 1.0
    u, s, _ = np.linalg.svd(X / norms, full_matrices=False)
    u = u[:, s > 1e-10 * s[0]] if len(s) else u[:, :0]
    per, press, bad = {}, {}, []
    for name, data, weak, _ in blocks:
        rows = np.concatenate([data, weak])
        Ug = u[rows]
        H = Ug @ Ug.T
        w, V = np.linalg.eigh(H)
        if w.max(initial=0.0) >= LEVERAGE_LIMIT:
            bad.append(name)
            continue
        # the left-out segment's predictive chi2: its deleted residuals e_(g) = (I - H_gg)^-1 e_g
        # against their own covariance, (I - H_gg)^-1 (whitened): e_g' (I - H_gg)^-1 e_g, plus
        # log det (I - H_gg)^-1, the price of an uncertain prediction (twice the negative log
        # predictive density, less a constant).  The squared deleted residuals alone (until run 3
        # of issue 25) weighed a segment of leverage w by 1/(1 - w)^2 against its expected
        # 1/(1 - w): in a design the parameters nearly saturate (15 anisoelastic terms from nine
        # statics and six rotation pairs) one segment's extrapolation outweighed the others and a
        # real effect was refused (gyro_anisoelastic: 720 -> 807, predictive 420 -> 344; its
        # held-out gyro error 51 -> 20 ppm once added); on a clean capture the same term scores
        # worse either way (296 -> 342)
        z = V.T @ e[rows]
        w = np.minimum(w, LEVERAGE_LIMIT)
        per[name] = float(np.sum(z * z / (1.0 - w) - np.log1p(-w)))
        press[name] = float(np.sum((V @ (z / (1.0 - w)))[:len(data)] ** 2))
    return Holdout(score=float(sum(per.values())), per_segment=per, unpredictable=bad, press=press)


def judge(before, after, h_before: Holdout, h_after: Holdout):
    """(kept, reason, share, holdout before, holdout after) for an effect added to ``before``."""
    drop = before.chi2 - after.chi2
    cv_b, cv_a = h_before.common_score(h_after)
    share = None
    if fit_fails(before.result):
        excess = max(before.chi2 - before.dof, 1e-300)
        share = drop / excess
    if not cv_a < cv_b:
        return (False, f"reduces chi2 by {drop:.1f} but predicts the left-out segments worse "
                       f"(leave-one-segment-out {cv_b:.1f} -> {cv_a:.1f}): it fits noise or another "
                       "effect's misfit", share, cv_b, cv_a)
    if not fit_fails(before.result):
        # the fit already passes: nothing fails for the effect to explain, and a refinement must
        # not make any segment's extrapolation worse in sum either (the squared deleted residuals,
        # run 2's score): after accel_cross_axis a K2 the truth does not have lowered the
        # predictive chi2 (313 -> 301) but raised these (501 -> 506) and the held-out
        # accelerometer error (23.5 -> 35.1 µg)
        p_b, p_a = h_before.common_press(h_after)
        if p_b and not p_a < p_b:
            return (False, f"reduces chi2 by {drop:.1f}, but the fit passed without it and the left-out "
                           f"segments' squared deleted residuals rise ({p_b:.1f} -> {p_a:.1f})", share, cv_b, cv_a)
    if share is not None and share < MIN_SHARE:
        return (False, f"reduces chi2 by {drop:.1f} but does not explain the failure (only "
                       f"{100 * share:.0f} % of the excess chi2; at least {100 * MIN_SHARE:.0f} % "
                       "needed)", share, cv_b, cv_a)
    return True, "", share, cv_b, cv_a
