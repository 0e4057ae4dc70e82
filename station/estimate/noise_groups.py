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
# the windows' placement errors not independent (a host whose latency drifts over the session):
# their scatter about the fit understates what the parameters carry, so the stated 1-sigma is kept
# (review of the eighteenth session: an AR(1) of 2 ms at rho 0.9 between neighbouring windows put
# the time offset's spread at 2.5 of its estimated 1-sigma, 1.02 of the stated one).  The test
# (nineteenth session; the lag-1 correlation above 2.33 / sqrt n before, with less power): the
# windows' placement residuals, in their reads' timing, against an AR(1) drift of the host's
# latency beside their independent scatter -- the restricted likelihood's ratio (drift_test), its
# p-value from its own null distribution (independent windows, this capture's residual space)
# below this: correlated
RAMP_DRIFT_P = 0.01
DRIFT_RHOS = (0.5, 0.7, 0.8, 0.9, 0.95)         # the drift's correlation between neighbours, profiled
DRIFT_SHARES = tuple(np.linspace(0.05, 0.95, 10))   # its share of the windows' placement variance
DRIFT_NULL_DRAWS = 400                          # draws of the statistic without drift (p to 1/400)

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
                        signs: dict | None = None, drift: bool = False) -> dict | None:
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
    neighbouring windows, of opposite angle in a pair turned each way).  ``drift``: also
    drift_test's drift_lr and drift_p (the windows' residuals drifting along the session).  None
    without windows among the labels."""
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
    out = {"windows": len(kept), "ratio": projected / share if share > 0 else 1.0, "redundancy": share,
           "dof": float(np.sum(G * G)), "lag1": lag1_correlation(np.sign(timing) * s / spread)}
    if drift:
        out.update(drift_test(G, s, timing))
    return out


_DRIFT_CACHE: dict = {}


def drift_test(G: np.ndarray, s: np.ndarray, timing: np.ndarray) -> dict:
    """Whether the windows' placement errors drift along the session (a host whose latency
    wanders with its load), from their placement residuals s (placement_component's M^T r, in
    recording order) and their covariance G under independent windows.

    The windows' timing errors are taken as an independent part plus an AR(1) part (share phi of
    their placement variance, correlation rho between neighbours); a window's angle error is its
    timing error times its sign (``timing``: a pair turned each way, a ramp up against a brake).
    In G's eigenbasis (G = U L U^T, y = L^-1/2 U^T s: N(0, I) for independent windows) the
    residuals' covariance is then lambda U^T D C D U, C = (1 - phi) I + phi rho^|i - j| (up to the
    white noise' share of the placement direction, 1 - L, small): the restricted (REML)
    likelihood, every parameter's share taken out by the fit, and the direction of a timing error
    common to all windows too (the time offset's: a constant is not a drift, and with the offset
    held by its prior the windows' common placement would read as one).  The statistic is its ratio, lambda and (phi,
    rho) profiled over DRIFT_SHARES x DRIFT_RHOS, against phi = 0; its null distribution is drawn
    (y ~ N(0, I): independent windows at the estimated k, this capture's G, a fixed seed, so the
    same capture gives the same answer) -- the p-value is exact whatever the approximations in
    the statistic.  Against an AR(1) drift no statistic of the residuals does much better
    (benchmarks/ramp_drift_power.py: the likelihood ratio at the true rho), and none has power
    where the drift is small beside the windows' own scatter over few windows (24 windows,
    2 ms at rho 0.9 beside 3.8 ms: 6 % at p 0.01, for lag-1 as for this; 96 windows: 47 %
    against lag-1's 23 %).  {"drift_lr", "drift_p"}."""
    # (the timing scale relative: rms 1, so that the drift's share phi is of the placement variance)
    timing = np.asarray(timing, float) / max(float(np.sqrt(np.mean(np.square(timing)))), 1e-300)
    w, U = np.linalg.eigh(G)
    keep = w > 1e-6 * max(float(w.max()), 1e-300)
    U, w = U[:, keep], w[keep]
    half = np.sqrt(w)
    # whitened (independent windows: N(0, I)), less the direction of a timing error common to
    # every window: that is the time offset's (or, held by its prior, what its release is about),
    # not a drift
    common = half * (U.T @ timing)
    Z = np.linalg.svd(np.eye(len(w)) - np.outer(common, common) / max(float(common @ common), 1e-300))[0]
    Z = Z[:, :len(w) - 1] if common @ common > 0 else Z
    m = Z.shape[1]
    if m < 3:
        return {"drift_lr": 0.0, "drift_p": 1.0}
    y = Z.T @ ((U.T @ s) / half)
    # the statistic is scale-free (lambda profiled): taken on the unit vector, so that y'y neither
    # under- nor overflows; residuals that are all zero say nothing, NaN ones nothing readable --
    # neither is a drift (a NaN ratio counted no null draw above it: p = 1/401)
    size = float(np.max(np.abs(y))) if len(y) else 0.0
    if not np.isfinite(size):
        return {"drift_lr": float("nan"), "drift_p": float("nan")}
    if size == 0.0:
        return {"drift_lr": 0.0, "drift_p": 1.0}
    y = y / size
    y = y / np.sqrt(y @ y)
    key = (G.tobytes(), timing.tobytes())
    grid = _DRIFT_CACHE.get(key)
    if grid is None:
        n = len(timing)
        lags = np.abs(np.subtract.outer(np.arange(n), np.arange(n)))
        DUZ = (timing[:, None] * U) @ Z
        invs, logdets = [], []
        for rho in DRIFT_RHOS:
            KR = DUZ.T @ (rho ** lags) @ DUZ
            for phi in DRIFT_SHARES:
                L = np.linalg.cholesky((1.0 - phi) * np.eye(m) + phi * KR)
                Li = np.linalg.inv(L)
                invs.append(Li.T @ Li)
                logdets.append(2.0 * float(np.sum(np.log(np.diag(L)))))
        invs, logdets = np.array(invs), np.array(logdets)

        def ratio(Y):
            """2 (max over the grid - the independent windows') of the profiled restricted
            log-likelihood, for each row of Y."""
            independent = -0.5 * m * np.log(np.einsum("dm,dm->d", Y, Y) / m)
            q = np.einsum("dm,gmk,dk->gd", Y, invs, Y)
            best = np.max(-0.5 * (m * np.log(q / m) + logdets[:, None]), axis=0)
            return 2.0 * np.maximum(best - independent, 0.0)

        draws = np.random.default_rng(20261128).standard_normal((DRIFT_NULL_DRAWS, m))
        grid = (ratio, np.sort(ratio(draws)))
        _DRIFT_CACHE.clear()
        _DRIFT_CACHE[key] = grid
    ratio, null = grid
    lr = float(ratio(y[None, :])[0])
    p = (1.0 + float(np.sum(null >= lr))) / (1.0 + len(null))
    return {"drift_lr": lr, "drift_p": p}


def lag1_correlation(z: np.ndarray) -> float:
    """sum z_i z_(i+1) / sum z_i^2 of a sequence (0 for fewer than three)."""
    z = np.asarray(z, float)
    den = float(z @ z)
    return float(z[:-1] @ z[1:]) / den if len(z) >= 3 and den > 0 else 0.0
