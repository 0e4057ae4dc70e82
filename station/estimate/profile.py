"""Effects with a discrete parameter (the time of a bias step): located by a profile of the score
test over their candidate values at a fit without them, then fitted at the best one.

The score (Lagrange-multiplier) statistic of adding an effect at a fit is the chi2 drop a first
Gauss-Newton step with it would give: g' A^+ g, g = Jp' r and A = Jp' Jp, Jp its Jacobian columns
less what the fitted model can already produce.  One model per candidate value shares the fit's
start and nuisances (lsq.Model's like), so a profile over 30 boundaries costs 30 Jacobians of six
columns, not 30 fits.  The maximum over candidates is optimistic: the caller corrects its p-value
for the number of candidates (Bonferroni).
"""
from __future__ import annotations

import copy

import numpy as np

from station.estimate import lsq


def fit_jacobian(result) -> np.ndarray:
    """The model's Jacobian at the fitted parameters, computed once per fit and shared by the
    candidates' basis and the leave-one-segment-out check (callers must not modify it)."""
    J = getattr(result, "_jacobian", None)
    if J is None:
        J = result.model.jacobian(result.x)
        result._jacobian = J
    return J


def model_basis(result) -> np.ndarray:
    """Orthonormal basis of what the fitted model's parameters can change in the residuals
    (its Jacobian's column space), computed once per fit (a small model's: outside_model)."""
    cached = getattr(result, "_basis", None)
    if cached is None:
        J = fit_jacobian(result)
        u, sv, _ = np.linalg.svd(J, full_matrices=False)
        cached = u[:, sv > 1e-10 * sv[0]]
        result._basis = cached
    return cached


def outside_model(result, M: np.ndarray) -> np.ndarray:
    """M (rows x k) less its projection on what the fitted model's parameters can change in the
    residuals (its Jacobian's column space): a large model's with its segments' nuisances
    eliminated (lsq._Reduced.outside: linear in the segments; the whole Jacobian's SVD took 51 s
    and 2.8 GB at 1,000 segments), a small one's through model_basis."""
    if result.model.is_large:
        return lsq.reduced_at_solution(result).outside(M)
    basis = model_basis(result)
    return M - basis @ (basis.T @ M)


def is_profiled(effect) -> bool:
    return callable(getattr(effect, "candidate_times", None)) and callable(getattr(effect, "locate", None))


def score(result, effect) -> float:
    """The score statistic (predicted chi2 drop, nominal noise) of adding ``effect`` to the fit."""
    model = result.model
    extended = lsq.Model(model.s, [*model.effects, effect], model.attitudes, like=model)
    extended.priors = dict(model.priors)
    n = model.layout.size
    x = np.concatenate([result.x, np.zeros(extended.layout.size - n)])
    r = extended.residuals(x)
    Jp = outside_model(result, extended.jacobian_columns(x, list(range(n, extended.layout.size))))
    g = Jp.T @ r
    return float(g @ (np.linalg.pinv(Jp.T @ Jp, rcond=1e-10) @ g))


def _bias_like_profile(result, effect) -> list[tuple[float, str, str, float]]:
    """The profile of an effect that is the model's biases changing from a time on (a bias step):
    its columns at each candidate time are the Jacobian's bias columns on the rows of the segments
    after that time (the score is unchanged by each column's scale), so no model is built."""
    model = result.model
    s = model.s
    L = model.layout
    cols = list(range(L["accel_bias"].start, L["accel_bias"].stop)) + list(range(L["gyro_bias"].start,
                                                                                   L["gyro_bias"].stop))
    # a large model's bias columns alone: its whole Jacobian dense is rows x parameters (12,000
    # segments: 126,006 x 32,048, 30 GiB, a MemoryError; issue 27 item 4)
    Jb = model.jacobian_columns(result.x, cols) if model.is_large else fit_jacobian(result)[:, cols]
    r = model.residuals(result.x)
    t_of = {x.name: x.t_mid_s - model.t0 for x in (*s.statics, *s.rotations) if np.isfinite(x.t_mid_s)}
    seg_t = np.array([t_of.get(name, np.nan) for name, _, _, _ in model.row_labels(result.x)])
    candidates = effect.candidate_times(s)
    out = _bias_like_profile_linear(result, Jb, r, seg_t, candidates) if model.is_large and candidates else None
    # each candidate's predicted size and calibration (a small model's: location_spread)
    sizes = effect.profile_sizes = {}
    pinv_J = None if model.is_large else np.linalg.pinv(fit_jacobian(result), rcond=1e-10)
    if out is None:
        out = []
        for t, before, after in candidates:
            M = Jb * (seg_t >= t)[:, None]
            Jp = outside_model(result, M)
            g = Jp.T @ r
            out.append((t, before, after, float(g @ (np.linalg.pinv(Jp.T @ Jp, rcond=1e-10) @ g))))
            if pinv_J is not None:
                sizes[(t, before, after)] = _spread_operators(result, effect, M, Jp, r, pinv_J)
    effect.time_ranges = {}
    # a step inside a segment: one projection of every row per segment, quadratic in the segments:
    # above INTERIOR_MAX_SEGMENTS the boundaries only (issue 27 item 4: linear to 100,000 segments)
    if callable(getattr(effect, "interior_segments", None)) and \
            len(s.statics) + len(s.rotations) <= INTERIOR_MAX_SEGMENTS:
        names = np.array([lab[0] for lab in model.row_labels(result.x)])
        for seg in effect.interior_segments(s):
            best = _interior_profile(result, Jb, r, seg_t, names, seg)
            if best is not None:
                t, score_, lo, hi = best
                out.append((t, seg["name"], seg["name"], score_))
                if pinv_J is not None:
                    h = (seg["last"] - seg["first"]) / max(seg["samples"] - 1, 1)     # the split's share after t
                    w = (seg["samples"] - 0.5 - (t - seg["first"]) / h) / seg["samples"]
                    later = (seg_t > 0.5 * (seg["first"] + seg["last"]) + 1e-9) & (names != seg["name"])
                    M = Jb * (later + w * (names == seg["name"]))[:, None]
                    Jp = outside_model(result, M)
                    sizes[(t, seg["name"], seg["name"])] = _spread_operators(result, effect, M, Jp, r, pinv_J)
                effect.time_ranges[seg["name"]] = (lo, hi)
    return out


def _interior_profile(result, Jb, r, seg_t, names, seg):
    """A step inside one segment (issue 25, run 3): at every split of its samples (m of its n
    samples after the step, m/n between seg["w_min"] and seg["w_max"]) the step's columns are the
    bias columns on the rows of the segments after it plus m/n times those on its own rows (exact
    for a static's mean; for a rotation its mean and integral, the small part a step within a
    revolution leaves in the harmonics neglected here, fitted in full by locate), so the score is a
    ratio of quadratics in m/n, computed at every split from three 6x6 blocks.  Returns the best
    split's (time, score) and the times where the score is within 1 of it (the profile's 1-sigma
    range of the step's time), or None."""
    n = seg["samples"]
    mid = 0.5 * (seg["first"] + seg["last"])
    later = (seg_t > mid + 1e-9) & (names != seg["name"])
    own = names == seg["name"]
    if not own.any():
        return None
    oA = outside_model(result, Jb * later[:, None])
    oB = outside_model(result, Jb * own[:, None])
    m = np.arange(1, n)
    w = m / n
    keep = (w >= seg["w_min"]) & (w <= seg["w_max"])
    if not keep.any():
        return None
    m, w = m[keep], w[keep]
    gA, gB = oA.T @ r, oB.T @ r
    AA, AB, BB = oA.T @ oA, oA.T @ oB, oB.T @ oB

    def scores(w):
        M = AA[None] + w[:, None, None] * (AB + AB.T)[None] + (w * w)[:, None, None] * BB[None]
        g = gA[None] + w[:, None] * gB[None]
        return np.einsum("ki,kij,kj->k", g, np.linalg.pinv(M, rcond=1e-10), g)

    # the segment's edges: the step just before it (all its samples after) and just after it
    ends = scores(np.array([1.0, 0.0]))
    # every split costs a 6x6 pseudo-inverse (1.6 s for a capture's 50,000 samples): a grid of at
    # most COARSE splits, then every split within FINE grid steps of its best (the score is a
    # smooth ratio of quadratics in m/n)
    step_ = max(1, len(w) // COARSE)
    sc = np.full(len(w), -np.inf)
    sc[::step_] = scores(w[::step_])
    j = int(np.argmax(sc))
    near_ = slice(max(j - FINE * step_, 0), min(j + FINE * step_ + 1, len(w)))
    sc[near_] = scores(w[near_])
    j = int(np.argmax(sc))
    h = (seg["last"] - seg["first"]) / max(n - 1, 1)
    times = seg["first"] + (n - m - 0.5) * h          # between the last sample before and the first after
    # the contiguous run of evaluated splits around the best within 1 of its score
    done = np.flatnonzero(np.isfinite(sc))
    at = int(np.searchsorted(done, j))
    lo, hi = at, at
    while lo > 0 and sc[done[lo - 1]] >= sc[j] - 1.0:
        lo -= 1
    while hi + 1 < len(done) and sc[done[hi + 1]] >= sc[j] - 1.0:
        hi += 1
    lo_i, hi_i = done[lo], done[hi]
    if sc[j] < np.max(ends) + INSIDE_GAIN:
        # no better inside than at its edges (a step in the gap before or after it, where nothing
        # was measured): the boundary stands for it (it is a candidate unless it is the statics/
        # rotations one; the segment's edge is then the same step within the noise)
        return None
    return float(times[j]), float(sc[j]), float(min(times[lo_i], times[hi_i])), float(max(times[lo_i], times[hi_i]))


#: a large model's columns that are not one segment's own above which the linear profile is not
#: taken (it holds rows x that many numbers; the candidates one at a time then)
LINEAR_PROFILE_COLUMNS = 1000


def _bias_like_profile_linear(result, Jb, r, seg_t, candidates):
    """_bias_like_profile of a large model in time and memory linear in the segments (issue 27
    item 4: one projection per candidate time, 4,812 of them at 4,000 segments, was 98 s of a
    diagnosis and quadratic), the same scores.

    The candidate columns at time t are M_t = D_t Jb, D_t the rows of the segments after t.  The
    Jacobian's column space is split into the columns that are one segment's own (L': a static's
    attitude, a rotation's phase: every row of each at one segment time) and the others (G': the
    calibration, effects, axes shared by rotations), reduced by L' (R' = J_G' less its fit by
    J_L', orthonormal basis U).  The projection on L' (block-diagonal: one block per segment)
    commutes with D_t, so with W = Jb less its fit by J_L' (once), Jp_t = (I - U U^T) D_t W and
        Jp_t^T Jp_t = sum_{after t} W_i^T W_i - c_t^T c_t,   c_t = sum_{after t} U_i^T W_i,
        Jp_t^T r    = sum_{after t} W_i^T r_i - c_t^T (U^T r):
    sums over the segments after t, cumulated once from the last segment back.  None when the
    model is not so split (a column of a segment's own at rows of several times, or more than
    LINEAR_PROFILE_COLUMNS shared columns): the caller takes the candidates one at a time."""
    from scipy.sparse import csr_matrix, diags
    from scipy.sparse.linalg import splu

    model = result.model
    J = model.sparse_jacobian(result.x).tocsc()
    rows, n = J.shape
    own = []
    for c in model.local_columns():
        at = seg_t[J.indices[J.indptr[c]:J.indptr[c + 1]]]
        if len(at) and np.all(np.isfinite(at)) and np.all(at == at[0]):
            own.append(int(c))
    mask = np.ones(n, bool)
    mask[own] = False
    shared = np.flatnonzero(mask)
    if len(shared) > LINEAR_PROFILE_COLUMNS or not np.all(np.isfinite(r)):
        return None
    J_L = J[:, own]
    norms = np.sqrt(np.asarray(J_L.multiply(J_L).sum(axis=0))).ravel()
    J_L = J_L[:, np.flatnonzero(norms > 0)] @ diags(1.0 / norms[norms > 0])
    try:
        lu = splu((J_L.T @ J_L).tocsc())
    except RuntimeError:                # own nuisances the data cannot tell apart
        return None

    def less_own_fit(M):
        return M - J_L @ lu.solve(np.asarray(J_L.T @ M))

    J_G = J[:, shared].toarray()
    scale = np.linalg.norm(J_G, axis=0)
    R = less_own_fit(J_G)
    del J_G
    u, sv, _ = np.linalg.svd(R / np.where(scale > 0, scale, 1.0), full_matrices=False)
    del R
    U = u[:, sv > 1e-10 * sv[0]] if len(sv) else u
    del u
    W = less_own_fit(np.asarray(Jb, float))
    Ur = U.T @ r                        # over every row (a prior's too)
    # per segment time (ascending): the sums of W^T W, W^T r and U^T W over its rows
    known = np.flatnonzero(np.isfinite(seg_t))
    times, which = np.unique(seg_t[known], return_inverse=True)
    G = csr_matrix((np.ones(len(known)), (which, known)), shape=(len(times), rows))
    k = W.shape[1]
    WW = np.stack([G @ (W * W[:, [j]]) for j in range(k)], axis=2)        # (times, 6, 6)
    Wr = G @ (W * r[:, None])                                               # (times, 6)
    UW = np.stack([G @ (U * W[:, [j]]) for j in range(k)], axis=2)        # (times, basis, 6)
    del U, W
    # from the last segment time back: the sums over the segments at or after each candidate time
    order = sorted(range(len(candidates)), key=lambda i: -candidates[i][0])
    A = np.empty((len(candidates), k, k))
    g = np.empty((len(candidates), k))
    ww, wr, c = np.zeros((k, k)), np.zeros(k), np.zeros((UW.shape[1], k))
    at = len(times)
    for i in order:
        first = int(np.searchsorted(times, candidates[i][0], side="left"))     # seg_t >= t
        while at > first:
            at -= 1
            ww += WW[at]
            wr += Wr[at]
            c += UW[at]
        A[i] = ww - c.T @ c
        g[i] = wr - c.T @ Ur
    P = np.linalg.pinv(A, rcond=1e-10)
    scores = np.einsum("ni,nij,nj->n", g, P, g)
    return [(t, before, after, float(v)) for (t, before, after), v in zip(candidates, scores)]


def profile(result, effect) -> list[tuple[float, str, str, float]]:
    """(value, before, after, score) at every candidate of ``effect`` (a copy is tried at each)."""
    if getattr(effect, "bias_like", False):
        return _bias_like_profile(result, effect)
    out = []
    for t, before, after in effect.candidate_times(result.model.s):
        trial = copy.deepcopy(effect)
        trial.locate(t, "")
        out.append((t, before, after, score(result, trial)))
    return out


INTERIOR_MAX_SEGMENTS = 2000   # above this many segments a bias step is looked for at boundaries only
COARSE = 200        # a step inside a segment: splits on the first grid (_interior_profile)
FINE = 3            # and every split within this many of its steps around the best
INSIDE_GAIN = 1.0   # a step inside a segment is offered when its score beats the segment's edges by
                    #   this (chi2 on the one more number it takes, the time within the segment: 1 sigma)
ALIKE_CHI2 = 6.63    # the 1 % point of chi2 on one degree of freedom
REFINE = 3         # the candidates of largest score fitted in full, the best chi2 kept


def locate(result, effect, refine: int = REFINE) -> list:
    """Set ``effect`` at its best candidate for the fit ``result``: the REFINE candidates of
    largest score are fitted in full and the one of lowest chi2 kept (the score is a one-step
    prediction at the fit without the effect: two neighbouring boundaries that a parameter of the
    model can partly trade, a gyro's scale between a rotation's two directions, score alike).
    ``refine`` 0: the largest score only (a candidate's score test: no fit).  The profile is kept
    on it (``effect.profile``) and returned, and the spread of the step's size and the
    calibration over the times the capture cannot exclude (``effect.location_spread``:
    location_spread)."""
    prof = profile(result, effect)
    effect.location_spread = None
    if prof:
        top = sorted(prof, key=lambda p: -p[3])[:max(refine, 1)]
        fitted, fits = [], {}
        for cand in top if len(top) > 1 else ():
            trial = copy.deepcopy(effect)
            trial.locate(cand[0], "")
            trial.segment, trial.location_spread = "", None
            fit = lsq.fit(result.model.s, [*result.model.effects, trial], result.model.attitudes, like=result.model)
            fitted.append((fit.chi2, cand))
            fits[cand[0]] = fit
        best, (t, before, after, drop) = min(fitted, key=lambda f: f[0]) if fitted else (0.0, top[0])
        if before == after and fitted:
            # a step inside a segment takes one number more than one at a boundary (where in the
            # segment): a boundary that fits within INSIDE_GAIN of it stands for it (a step in the
            # gap between two segments, which the edge of either reaches as well)
            edge = [f for f in fitted if f[1][1] != f[1][2] and f[0] - best < INSIDE_GAIN]
            if edge:
                best, (t, before, after, drop) = min(edge, key=lambda f: f[0])
        located = t
        if before == after and t in fits:
            # inside a segment: the profile's split neglects what a step within a revolution leaves
            # in the harmonics; the time refined by the full fit (Gauss-Newton steps on it)
            t_fit, fit = refine_time(result, effect, fits[t], t, before)
            ranges = getattr(effect, "time_ranges", None) or {}
            if t_fit != t and before in ranges:      # the profile's range, moved with its best
                ranges[before] = tuple(float(v + t_fit - t) for v in ranges[before])
            best, t = fit.chi2, t_fit
        # the others whose chi2 is within the 1 % point of chi2 on one degree of freedom (scaled by
        # the over-dispersion of the best fit when it fails): the capture cannot tell them from the best
        dof = result.dof - len(effect.params)
        phi = max(best / dof, 1.0) if dof > 0 else 1.0
        close = [(chi2, c) for chi2, c in fitted if c[0] not in (t, located) and chi2 - best < ALIKE_CHI2 * phi]
        alike = [(f"inside {c[1]}" if c[1] == c[2] else f"{c[1]} -> {c[2]}") + f" (chi2 +{chi2 - best:.1f})"
                 for chi2, c in close]
        # what lies between the best boundary and each as likely one: the segments whose own free
        # parameters (a rotation pair's Earth-rate component along its axis, a static's attitude)
        # take a step that falls just before them as well as one just after (the words name them)
        s = result.model.s
        mids = [(x.t_mid_s - result.model.t0, x.name) for x in (*s.statics, *s.rotations) if np.isfinite(x.t_mid_s)]
        effect.alike = [{"before": c[1], "after": c[2], "chi2_more": float(chi2 - best),
                         "between": [n for tm, n in sorted(mids) if min(t, c[0]) < tm < max(t, c[0])]}
                        for chi2, c in close]
        # (the profile's candidate: refine_time may have moved the time off it, and the spread is
        # over where the profile puts it)
        spread = location_spread(getattr(effect, "profile_sizes", None) or {}, (located, before, after), phi)
        effect.location_spread = None if spread is None else ((*SPREAD_BLOCKS, f"effect:{effect.id}"), spread)
        effect.location_spread_of = lsq.segments_key(result.model.s)     # what it was computed from
        inside = before == after
        where = (f"inside {before}" if inside else f"between {before} and {after}")
        effect.locate(t, f"located {where} by a profile of the score test over {len(prof)} candidates (the "
                         f"boundaries between segments and, inside each segment, every split of its samples)"
                         + (f" (the best {len(top)} fitted)" if fitted else "")
                      + (f"; as likely: {', '.join(alike)}" if alike else ""))
        effect.segment = before if inside else ""
        effect.time_range = (getattr(effect, "time_ranges", {}) or {}).get(before) if inside else None
    effect.profile = prof
    return prof


SPREAD_BLOCKS = tuple(name for name, _, _ in lsq.GLOBAL)    # the calibration's blocks the spread covers, with the step's


def location_spread(cands: dict, best, phi: float = 1.0, draws: int = 400, seed: int = 0):
    """The covariance that the step's size and the calibration take from where the step is
    located (issue 28), by a parametric bootstrap of the location on the linear model: noise
    (unit, times sqrt(phi): a failing fit's over-dispersion) is added to what the step found at
    ``best`` produces; each draw is located as locate does (the candidate of largest score, one
    inside a segment less INSIDE_GAIN, its one more number) and reads the step's parameters and
    the calibration's there; the second moment of their error less that of the same read at
    ``best`` (the time taken as known: the fit's own covariance), clipped to be positive
    semi-definite,
        E[(v_located - v)(v_located - v)^T] - E[(v_best - v)(v_best - v)^T],
    is what putting the step at the wrong time adds to the error of a fit at the chosen time
    (measured on the twins: a 150 µg accelerometer step, 6 sigma, at 400 s was located in 32
    runs at six places 71 s apart, its size scattering 1.74x the stated 1-sigma; a 8 °/h gyro
    step, 4 sigma, up to 130 s away, its size 1.46x and the gyro bias before it 1.87x).  About
    zero when the step is well above the noise.  ``cands``: candidate -> its linear operators
    (_spread_operators: Jp, the step's columns less what the model produces; Ainv, the inverse of
    their normal matrix with the step's prior; W, from Jp^T r to the parameters read; signal,
    the residual the step found there makes at the fit without it).  None without them (a
    large model's profile)."""
    if best not in cands or len(cands) < 2:
        return None
    keys = list(cands)
    R = cands[best]["signal"][:, None] + np.sqrt(phi) * np.random.default_rng(seed).standard_normal(
        (len(cands[best]["signal"]), draws))
    scores, values = [], []
    for k in keys:
        G = cands[k]["Jp"].T @ R
        scores.append(np.einsum("id,id->d", G, cands[k]["Ainv"] @ G) - (INSIDE_GAIN if k[1] == k[2] else 0.0))
        values.append(cands[k]["W"] @ G)
    located = np.argmax(np.array(scores), axis=0)
    values = np.array(values)                                   # (candidates, parameters, draws)
    b = keys.index(best)
    truth = cands[best]["W"] @ (cands[best]["Jp"].T @ cands[best]["signal"])
    located_error = values[located, :, np.arange(draws)] - truth                 # (draws, parameters)
    best_error = values[b].T - truth
    extra = (located_error.T @ located_error - best_error.T @ best_error) / draws
    w, v = np.linalg.eigh(0.5 * (extra + extra.T))          # what locating adds: none may be negative
    # in the fit's nominal units (divided by phi): station.estimate.verdict multiplies a failing
    # fit's whole covariance, this with it, by its reduced chi2 (phi counted once)
    return (v * np.clip(w, 0.0, None)) @ v.T / phi


def _spread_operators(result, effect, M, Jp, r, pinv_J) -> dict:
    """location_spread's operators of a candidate whose step columns are M (the bias columns on
    the rows after it; Jp = M less what the model can produce): the step's size is Ainv Jp^T r,
    with the step's prior (Param.typical, as a fit holds an unrevealed step: station.estimate.lsq's
    blind parameters; without it a step the capture barely sees reads any size); W reads from
    Jp^T r the SPREAD_BLOCKS' move with it (-J^+ M size) and the step's parameters in their units
    (µg, °/h: the bias columns' m/s^2 and deg/s scaled)."""
    from station.core import units

    f = np.array([1.0 / units.UG_MPS2] * 3 + [3600.0] * 3)
    prior = np.diag((f / np.array([p.typical for p in effect.params])) ** 2)
    Ainv = np.linalg.inv(Jp.T @ Jp + prior)
    L = result.model.layout
    cols = np.concatenate([np.arange(L[b].start, L[b].stop) for b in SPREAD_BLOCKS])
    W = np.vstack([-(pinv_J[cols] @ M), np.diag(f)]) @ Ainv
    return {"Jp": Jp, "Ainv": Ainv, "W": W, "signal": M @ (Ainv @ (Jp.T @ r))}


REFINE_TIME = 3     # Gauss-Newton steps on a step's time inside a segment (refine_time)


def refine_time(result, effect, fit, t: float, segment: str):
    """(time, fit) of a step inside ``segment`` refined from ``fit`` (the full fit with it at
    ``t``): Gauss-Newton steps on the time with every parameter free (the residuals' derivative
    in the time by central differences, Effect.held_values; the step's time less what the
    parameters take), each refitted in full and kept while the chi2 falls, to REFINE_TIME steps
    or one under a tenth of the time's 1-sigma.  Issue 28: the profile's split neglects the
    harmonics a step within a revolution leaves; its time was off by 0.8 s RMS inside a 36 s turn
    (the fit's 1-sigma 0.5 s), the step's size scattering 1.49x its stated 1-sigma."""
    for _ in range(REFINE_TIME):
        model = fit.model
        trial = model.effects[-1]
        trial.segment = segment
        values = trial.held_values() if callable(getattr(trial, "held_values", None)) else []
        if not values:
            break
        name, h = values[0]
        v0 = getattr(trial, name)
        try:
            setattr(trial, name, v0 + h)
            up = model.residuals(fit.x)
            setattr(trial, name, v0 - h)
            down = model.residuals(fit.x)
        finally:
            setattr(trial, name, v0)
        c = outside_model(fit, ((up - down) / (2 * h))[:, None])[:, 0]
        d = float(c @ c)
        if not d > 0:
            break
        dt = -float(c @ model.residuals(fit.x)) / d
        span = next((x for x in trial._spans.values() if x["name"] == segment), None)
        t_new = float(np.clip(t + dt, span["first"] + 1e-6, span["last"] - 1e-6)) if span else t + dt
        again = copy.deepcopy(effect)
        again.locate(t_new, "")
        again.segment, again.location_spread = "", None
        refit = lsq.fit(result.model.s, [*result.model.effects, again], result.model.attitudes, like=result.model)
        if not refit.chi2 < fit.chi2:
            break
        t, fit = t_new, refit
        if abs(dt) < 0.1 / np.sqrt(d):
            break
    return t, fit


def fit_located(s, effects, attitudes: str = "auto", like=None):
    """lsq.fit, with every effect of a discrete parameter that is not located yet located first
    at the fit without it (one more fit)."""
    effects = list(effects)
    pending = [e for e in effects if is_profiled(e) and getattr(e, "step_time_s", 0.0) is None]
    if pending:
        base = lsq.fit(s, [e for e in effects if e not in pending], attitudes, like=like)
        for e in pending:
            locate(base, e)
        like = base.model
    return lsq.fit(s, effects, attitudes, like=like)
