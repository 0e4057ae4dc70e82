"""How much each data group scatters against the noise it was weighted with (issue 24, item 1).
The hand turns' group is reweighted by it (an explicit turn-angle 1-sigma: station/estimate/
noise_model.py and lsq.fit); every other group is tested against its stated noise and named
when it scatters beyond it.

The residuals of a least-squares fit are whitened by the noise model (white noise per sample from
the statics' first differences, the rotations' arcs, the hand turns' integration): each should be
N(0, 1) if the model and the noise model are right.  Per data group g (static accelerometer
means, static gyro means, the rotations' accelerometer harmonics, the rotations' gyro integrals,
the hand turns' closures) the variance-component estimate (Helmert; Förstner 1979) is

    s_g^2 = r_g^T r_g / (n_g - sum_{i in g} h_ii),

h_ii the leverages of the whitened Jacobian (its hat matrix' diagonal: the share of a row the fit
uses up), so that sum_g (n_g - sum h) = n - p and s_g^2 = 1 for every group when the noise model
holds.  s_g is the factor by which the group scatters more (or less) than its stated noise; with
its redundancy f_g, f_g s_g^2 is chi2(f_g) under the noise model, which gives the p-value that
names a group whose noise the fit understates ("hand turns scatter 6.9 times their stated
noise").  Only for models whose Jacobian is taken dense (not Model.is_large).
"""
from __future__ import annotations

import math

import numpy as np
from station.estimate.distributions import chi2_sf

P_NAMED = 1e-3          # a group is named when its scatter is this improbable under its stated noise
MIN_REDUNDANCY = 2.0    # below this a group's scatter says too little to be reported

GROUP_WORDS = {"static accel": "the static accelerometer means",
               "static gyro": "the static gyro means",
               "rotation accel": "the rotations' accelerometer harmonics",
               "rotation gyro": "the rotations' gyro integrals",
               "hand turn": "the hand turns (gravity after each turn)"}


CAUSES = {
    "static accel": ("a missing effect (station diagnose), or a bias that moves between the poses although "
                     "their halves do not show it moving (then record longer poses, or fewer and longer)"),
    "static gyro": ("a missing effect (g-sensitivity: station diagnose), or a bias that moves between the "
                    "poses although their halves do not show it moving (then record longer poses)"),
    "rotation accel": "a missing effect or a bench fault (station diagnose shows which segments)",
    "rotation gyro": "a missing effect, an encoder angle off, or a table that slipped (station diagnose)",
    "hand turn": ("the turns miss by more than their stated 1-sigma (--turn-sigma-deg; without it the "
                  "station estimates it from their scatter)"),
}


def group_of(kind: str, quantity: str) -> str | None:
    """The data group of a residual row from its label (lsq.Model.row_labels); None: not data."""
    if kind == "static":
        return "static accel" if quantity.startswith("accel") else (
            "static gyro" if quantity.startswith(("gyro", "|w|")) else None)
    if kind == "rotation":
        if quantity.startswith("accel"):
            return "rotation accel"
        if quantity.startswith("gyro"):
            return "rotation gyro"
        if quantity.startswith("gravity_after"):
            return "hand turn"
    return None


def leverages(J: np.ndarray, svd=None) -> np.ndarray:
    """The hat matrix' diagonal of J (column-scaled; directions the data do not see take none).
    ``svd``: (U, singular values) of J with its columns scaled by their norms (a zero one by 1),
    when the caller has that SVD already (lsq's at the solution: the same numbers, one
    factorisation of J fewer)."""
    if svd is not None:
        U, sv = svd
    else:
        norms = np.linalg.norm(J, axis=0)
        norms[norms == 0] = 1.0
        U, sv, _ = np.linalg.svd(J / norms, full_matrices=False)
    keep = sv > sv[0] * 1e-10 if sv.size else sv.astype(bool)
    return np.einsum("ij,ij->i", U[:, keep], U[:, keep])


def variance_components(labels, residuals: np.ndarray, J: np.ndarray | None, parameters: int | None = None,
                        by_axis=(), svd=None) -> list[dict]:
    """Per data group: rows, redundancy, chi2, the scatter factor s_g and its p-value.

    ``labels``: lsq.Model.row_labels of every row of ``J`` (and ``residuals``), priors included;
    the prior rows take their share of the leverage but belong to no group.  ``J`` None (a large
    model, whose Jacobian is not taken dense): every row takes the same share of the
    ``parameters`` (an approximation, used only to reweight the hand turns).  ``by_axis``: groups
    whose rows are also split by sensor axis, under the entry's "axes" ({axis: the same numbers}:
    a bias that wanders on one axis of a triad only is its own component).  ``svd``: leverages'."""
    h = leverages(J, svd) if J is not None else np.full(len(residuals), (parameters or 0) / max(len(residuals), 1))
    groups: dict[str, list[int]] = {}
    for i, (_, kind, quantity, _) in enumerate(labels):
        g = group_of(kind, quantity)
        if g is not None:
            groups.setdefault(g, []).append(i)
    out = []
    for g, rows in groups.items():
        entry = {"group": g, **_component(np.array(rows), residuals, h)}
        if g in by_axis:
            axes: dict[str, list[int]] = {}
            for i in rows:
                axes.setdefault(labels[i][3], []).append(i)
            entry["axes"] = {a: _component(np.array(r), residuals, h) for a, r in axes.items()}
        out.append(entry)
    return out


def _component(rows: np.ndarray, residuals: np.ndarray, h: np.ndarray) -> dict:
    f = float(len(rows) - h[rows].sum())
    chi2 = float(residuals[rows] @ residuals[rows])
    entry = {"rows": int(len(rows)), "redundancy": f, "chi2": chi2}
    if f >= MIN_REDUNDANCY:
        entry["scatter"] = math.sqrt(chi2 / f)
        entry["p_value"] = chi2_sf(f, chi2)
    return entry


def words(components: list[dict]) -> list[str]:
    """A note for every group that scatters more than its stated noise beyond chance."""
    notes = []
    for c in components:
        if c.get("p_value", 1.0) < P_NAMED and c["scatter"] > 1.0:
            notes.append(f"{GROUP_WORDS.get(c['group'], c['group'])} scatter {c['scatter']:.3g} times their "
                         f"stated noise (chi2 {c['chi2']:.4g} on a redundancy of {c['redundancy']:.1f}, "
                         f"p = {c['p_value']:.2g}): " + CAUSES.get(c["group"], "a missing effect or an understated noise"))
    return notes
