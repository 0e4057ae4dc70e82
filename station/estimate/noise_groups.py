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

The recorded ramps' gyro integrals (rotations whose manifest states an ``angle_sigma_deg``, the
placement of the table's reads on the IMU's clock: station/bench/ramp_angle.py) are a group of
their own, "ramp gyro" (issue 28, eighteenth session): their stated placement 1-sigma is
deliberately conservative, and lsq.fit estimates the factor k on it from their own scatter
(placement_component) where they are enough to say.
"""
from __future__ import annotations

import math

import numpy as np
from station.estimate.distributions import chi2_sf

P_NAMED = 1e-3          # a group is named when its scatter is this improbable under its stated noise
MIN_REDUNDANCY = 2.0    # below this a group's scatter says too little to be reported
# the ramp windows' placement variance k^2 sigma^2 is estimated only from this many degrees of
# freedom (placement_component's f: k^2's relative standard deviation is sqrt(2 / f), 0.45 at 10;
# the chance that the estimate puts k at half the truth or less, chi2(f)/f < 1/4, is 0.9 % at 10,
# 4 % at 6, 9 % at 4); below it the stated (conservative) 1-sigma is kept
RAMP_MIN_DOF = 10.0
# the windows' placement residuals correlated from one window to the next beyond this many of the
# lag-1 correlation's 1-sigma for independent windows (1 / sqrt n; p ~ 0.01 one-sided): their
# placement errors are not independent (a host whose latency drifts over the session), so the
# scatter about the fit understates what the parameters carry -- the stated 1-sigma is kept
# (review of the eighteenth session: an AR(1) of 2 ms at rho 0.9 between neighbouring windows put
# the time offset's spread at 2.5 of its estimated 1-sigma, 1.02 of the stated one)
RAMP_LAG1_Z = 2.33

GROUP_WORDS = {"static accel": "the static accelerometer means",
               "static gyro": "the static gyro means",
               "rotation accel": "the rotations' accelerometer harmonics",
               "rotation gyro": "the rotations' gyro integrals",
               "ramp gyro": "the recorded ramps' gyro integrals",
               "hand turn": "the hand turns (gravity after each turn)"}


CAUSES = {
    "static accel": ("a missing effect (station diagnose), or a bias that moves between the poses although "
                     "their halves do not show it moving (then record longer poses, or fewer and longer)"),
    "static gyro": ("a missing effect (g-sensitivity: station diagnose), or a bias that moves between the "
                    "poses although their halves do not show it moving (then record longer poses)"),
    "rotation accel": "a missing effect or a bench fault (station diagnose shows which segments)",
    "rotation gyro": "a missing effect, an encoder angle off, or a table that slipped (station diagnose)",
    "ramp gyro": ("the table's reads placed on the IMU's clock scatter beyond their stated 1-sigma "
                  "(angle_sigma_deg), a missing effect, or a table that slipped (station diagnose)"),
    "hand turn": ("the turns miss by more than their stated 1-sigma (--turn-sigma-deg; without it the "
                  "station estimates it from their scatter)"),
}


def group_of(kind: str, quantity: str, ramp: bool = False) -> str | None:
    """The data group of a residual row from its label (lsq.Model.row_labels); None: not data.
    ``ramp``: the row's segment is a recorded ramp whose angle carries a stated placement 1-sigma
    (RotationSummary.angle_sigma_deg > 0): its gyro integral is "ramp gyro"."""
    if kind == "static":
        return "static accel" if quantity.startswith("accel") else (
            "static gyro" if quantity.startswith(("gyro", "|w|")) else None)
    if kind == "rotation":
        if quantity.startswith("accel"):
            return "rotation accel"
        if quantity.startswith("gyro"):
            return "ramp gyro" if ramp else "rotation gyro"
        if quantity.startswith("gravity_after"):
            return "hand turn"
    return None


def _hat_basis(J: np.ndarray, svd=None) -> np.ndarray:
    """An orthonormal basis of J's column space (the left singular vectors of J column-scaled
    that the data see): the hat matrix is its product with its transpose."""
    if svd is not None:
        U, sv = svd
    else:
        norms = np.linalg.norm(J, axis=0)
        norms[norms == 0] = 1.0
        U, sv, _ = np.linalg.svd(J / norms, full_matrices=False)
    keep = sv > sv[0] * 1e-10 if sv.size else sv.astype(bool)
    return U[:, keep]


def leverages(J: np.ndarray, svd=None) -> np.ndarray:
    """The hat matrix' diagonal of J (column-scaled; directions the data do not see take none).
    ``svd``: (U, singular values) of J with its columns scaled by their norms (a zero one by 1),
    when the caller has that SVD already (lsq's at the solution: the same numbers, one
    factorisation of J fewer)."""
    U = _hat_basis(J, svd)
    return np.einsum("ij,ij->i", U, U)


def variance_components(labels, residuals: np.ndarray, J: np.ndarray | None, parameters: int | None = None,
                        by_axis=(), svd=None, ramps=frozenset()) -> list[dict]:
    """Per data group: rows, redundancy, chi2, the scatter factor s_g and its p-value.

    ``labels``: lsq.Model.row_labels of every row of ``J`` (and ``residuals``), priors included;
    the prior rows take their share of the leverage but belong to no group.  ``J`` None (a large
    model, whose Jacobian is not taken dense): every row takes the same share of the
    ``parameters`` (an approximation, used only to reweight the hand turns).  ``by_axis``: groups
    whose rows are also split by sensor axis, under the entry's "axes" ({axis: the same numbers}:
    a bias that wanders on one axis of a triad only is its own component).  ``svd``: leverages'.
    ``ramps``: the names of the rotations whose gyro integrals are "ramp gyro" (group_of)."""
    h = leverages(J, svd) if J is not None else np.full(len(residuals), (parameters or 0) / max(len(residuals), 1))
    groups: dict[str, list[int]] = {}
    for i, (name, kind, quantity, _) in enumerate(labels):
        g = group_of(kind, quantity, name in ramps)
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


def placement_component(labels, residuals: np.ndarray, J: np.ndarray, windows: dict, svd=None,
                        signs: dict | None = None) -> dict | None:
    """The ramp windows' placement variance from their residuals (Helmert's variance-component
    estimate for one component beside known ones; Förstner 1979, Koch 1999 ch. 3.6).

    Each window's gyro integral has the covariance C_i = N_i + k^2 sigma_i^2 a_i a_i^T (N_i the
    white noise, the bias' instability and the encoder: known; sigma_i its stated placement
    1-sigma, a_i the turn's axis in the gyro's raw frame) and is whitened by C_i's Cholesky factor
    W_i at the current k.  ``windows``: {rotation name: u_i = W_i a_i k sigma_i}, the placement's
    share of the whitened rows (3,).  With M the whitened rows' matrix whose column i is u_i on
    window i's rows, Q the hat matrix's basis (what the fit's parameters take, the time offset's
    share of a placement common to all windows included) and G = M^T (I - Q Q^T) M:

        ratio = sum_i (u_i . r_i)^2 / tr G        (the factor on k^2: 1 at the estimate)
        dof   = tr(G G)                           (k^2's relative 1-sigma is sqrt(2 / dof))

    the REML score equation's fixed point and its Fisher information; tr G is the placement's share
    of the redundancy.  A window whose rows the fit uses up entirely (a turn alone about its axis)
    adds nothing to either.  ``signs``: {name: +-1} turning a window's angle error into its reads'
    timing error (lag1: a host's latency drifting over the session is a timing error shared by
    neighbouring windows, of opposite angle in a pair turned each way).  None without windows
    among the labels."""
    names = list(windows)
    at = {n: i for i, n in enumerate(names)}
    rows = [[] for _ in names]
    for j, (name, kind, quantity, _) in enumerate(labels):
        if name in at and kind == "rotation" and quantity.startswith("gyro"):
            rows[at[name]].append(j)
    kept = [i for i, r in enumerate(rows) if len(r) == 3]
    if not kept:
        return None
    M = np.zeros((len(residuals), len(kept)))
    for c, i in enumerate(kept):
        M[rows[i], c] = windows[names[i]]
    B = _hat_basis(J, svd).T @ M
    G = M.T @ M - B.T @ B
    share = float(np.trace(G))
    s = M.T @ residuals
    projected = float(np.sum(s ** 2))
    # the windows' placement residuals in their order (the capture's), each over its own spread:
    # their lag-1 correlation, ~N(0, 1/n) for independent windows (lag1_correlation)
    spread = np.sqrt(np.clip(np.diag(G), 1e-300, None))
    timing = np.array([(signs or {}).get(names[i], 1.0) for i in kept])
    return {"windows": len(kept), "ratio": projected / share if share > 0 else 1.0, "redundancy": share,
            "dof": float(np.sum(G * G)), "lag1": lag1_correlation(timing * s / spread)}


def lag1_correlation(z: np.ndarray) -> float:
    """sum z_i z_(i+1) / sum z_i^2 of a sequence (0 for fewer than three)."""
    z = np.asarray(z, float)
    den = float(z @ z)
    return float(z[:-1] @ z[1:]) / den if len(z) >= 3 and den > 0 else 0.0
