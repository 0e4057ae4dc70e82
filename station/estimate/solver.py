"""Nonlinear least squares by Levenberg–Marquardt in numpy: what the fits of a small capture call
instead of ``scipy.optimize.least_squares(method="lm")`` (MINPACK's lmder), so that estimating a
small capture does not import scipy (its import was ~0.28 s of CPU of a 0.75 s `station
estimate`, the fit itself ~3 %: issue 27, docs/performance.md).

The algorithm is MINPACK's (Moré 1978, "The Levenberg–Marquardt algorithm: implementation and
theory"): a trust region in the variables scaled by the Jacobian's column norms (``x_scale="jac"``,
MINPACK's mode 1: each scale the largest norm its column has had), the region's radius and the
Levenberg–Marquardt parameter updated by the ratio of the actual to the predicted reduction as
lmder updates them, and lmder's three convergence tests (relative reduction ``ftol``, relative
step ``xtol``, the cosine between the residuals and the Jacobian's columns ``gtol``).  One thing
differs: the step of a given radius is computed from the SVD of the scaled Jacobian (the
secular equation ||D p(λ)|| = Δ solved by Newton's method on 1/||D p||, Moré's iteration, with
the SVD's exact derivative) where lmder uses a pivoted QR factorisation and lmpar; the same
step to rounding, and as cheap for the fit's sizes (200 × 90: 1 ms).  The solution is the same
within the tolerances (tests/test_solver.py compares it with scipy's on the fit's models).

The result has scipy's fields the callers use: x, fun, jac (at x), cost, nfev, njev, status
(0: the evaluation limit reached; 1: gtol; 2: ftol; 3: xtol; 4: ftol and xtol), success,
message, optimality.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

MESSAGES = {0: "The maximum number of function evaluations is exceeded.",
            1: "`gtol` termination condition is satisfied.",
            2: "`ftol` termination condition is satisfied.",
            3: "`xtol` termination condition is satisfied.",
            4: "Both `ftol` and `xtol` termination conditions are satisfied."}
EPS = np.finfo(float).eps


@dataclass
class Result:
    x: np.ndarray
    fun: np.ndarray
    jac: np.ndarray
    cost: float
    nfev: int
    njev: int
    status: int
    optimality: float

    @property
    def success(self) -> bool:
        return self.status > 0

    @property
    def message(self) -> str:
        return MESSAGES[self.status]


def _step(s, Vt, uf, diag, delta, par):
    """The scaled step p (||p|| <= delta) minimising ||J x + f|| with J D^-1 = U S Vt, and its
    Levenberg–Marquardt parameter (0 for the Gauss–Newton step inside the region)."""
    keep = s > s[0] * EPS * max(len(diag), 1) if len(s) else s > 0
    s_k, uf_k, Vt_k = s[keep], uf[keep], Vt[keep]

    def p_of(lam):
        return -(Vt_k.T @ (s_k * uf_k / (s_k * s_k + lam)))

    gn = p_of(0.0)
    gn_norm = float(np.linalg.norm(gn))
    if gn_norm <= 1.1 * delta:          # lmpar: the Gauss-Newton step is accepted within 10 %
        return gn, 0.0
    # Moré's Newton iteration on phi(lam) = ||p(lam)|| - delta, from the bracket [lo, hi]
    a = s_k * uf_k
    hi = float(np.linalg.norm(a)) / delta           # ||J^T f|| / delta (scaled)
    lo = 0.0
    lam = min(max(par, lo), hi) if par > 0 else 0.0
    for _ in range(30):
        if not (lo < lam < hi):
            lam = max(0.001 * hi, math.sqrt(lo * hi)) if lo > 0 else 0.001 * hi
        den = s_k * s_k + lam
        q = a / den
        q_norm = float(np.linalg.norm(q))
        phi = q_norm - delta
        if abs(phi) <= 0.1 * delta:
            break
        if phi < 0:
            hi = lam
        else:
            lo = lam
        dphi = -float(np.sum(q * q / den)) / q_norm           # d||q|| / d lam
        lam = lam - (q_norm / delta) * (phi / dphi) if dphi != 0 else 0.5 * (lo + hi)
    return -(Vt_k.T @ (a / (s_k * s_k + lam))), lam


def least_squares(fun, x0, jac, *, xtol: float = 1e-8, ftol: float = 1e-8, gtol: float = 1e-8,
                  max_nfev: int | None = None, factor: float = 100.0) -> Result:
    """Minimise 0.5 ||fun(x)||^2 from x0 (Levenberg–Marquardt, MINPACK's updates, column-norm
    scaling); ``jac(x)`` the dense Jacobian (m x n, m >= n)."""
    x = np.array(x0, dtype=float)
    n = len(x)
    max_nfev = 100 * n if max_nfev is None else int(max_nfev)
    f = np.asarray(fun(x), dtype=float)
    nfev, njev = 1, 0
    fnorm = float(np.linalg.norm(f))
    diag = None
    delta = xnorm = par = 0.0
    status = None
    J = None
    J_at_x = False
    first = True                # lmder's first iteration: until a step is accepted
    while status is None:
        J = np.asarray(jac(x), dtype=float)
        njev += 1
        J_at_x = True
        norms = np.linalg.norm(J, axis=0)
        if diag is None:
            diag = np.where(norms > 0, norms, 1.0)
            xnorm = float(np.linalg.norm(diag * x))
            delta = factor * xnorm if xnorm > 0 else factor
        else:
            diag = np.maximum(diag, norms)
        # gtol: the largest cosine between f and a column of J
        gnorm = 0.0
        if fnorm > 0:
            g = J.T @ f
            nz = norms > 0
            if nz.any():
                gnorm = float(np.max(np.abs(g[nz]) / (norms[nz] * fnorm)))
        if fnorm == 0 or gnorm <= max(gtol, EPS):
            status = 1
            break
        U, s, Vt = np.linalg.svd(J / diag, full_matrices=False)
        uf = U.T @ f
        while True:                                   # until a step reduces the sum of squares
            p, par = _step(s, Vt, uf, diag, delta, par)
            step = p / diag
            pnorm = float(np.linalg.norm(p))
            if first:
                delta = min(delta, pnorm)             # lmder: the first radius no longer than the first step
            x_new = x + step
            f_new = np.asarray(fun(x_new), dtype=float)
            nfev += 1
            with np.errstate(over="ignore", invalid="ignore"):      # a trial step too far: rejected
                fnorm1 = float(np.linalg.norm(f_new))
            if not math.isfinite(fnorm1):
                fnorm1 = math.inf
            actred = 1.0 - (fnorm1 / fnorm) ** 2 if 0.1 * fnorm1 < fnorm else -1.0
            Jp = J @ step
            temp1 = float(np.linalg.norm(Jp)) / fnorm
            temp2 = math.sqrt(par) * pnorm / fnorm
            prered = temp1 * temp1 + temp2 * temp2 / 0.5
            dirder = -(temp1 * temp1 + temp2 * temp2)
            ratio = actred / prered if prered != 0 else 0.0
            if ratio <= 0.25:
                temp = 0.5 if actred >= 0 else 0.5 * dirder / (dirder + 0.5 * actred)
                if 0.1 * fnorm1 >= fnorm or temp < 0.1:
                    temp = 0.1
                delta = temp * min(delta, pnorm / 0.1)
                par = par / temp
            elif par == 0 or ratio >= 0.75:
                delta = pnorm / 0.5
                par = 0.5 * par
            if ratio >= 1e-4:                         # accepted
                x, f, fnorm = x_new, f_new, fnorm1
                xnorm = float(np.linalg.norm(diag * x))
                J_at_x = False
                first = False
            # lmder's tests; a tolerance below the machine's precision is met at that precision
            # (lmder's info 6 and 7: no further reduction, no further step possible)
            f_ok = abs(actred) <= max(ftol, EPS) and prered <= max(ftol, EPS) and 0.5 * ratio <= 1
            x_ok = delta <= max(xtol, EPS) * xnorm
            if f_ok and x_ok:
                status = 4
            elif f_ok:
                status = 2
            elif x_ok:
                status = 3
            elif nfev >= max_nfev:
                status = 0
            if status is not None or ratio >= 1e-4:
                break
    if not J_at_x:
        J = np.asarray(jac(x), dtype=float)
        njev += 1
    g = J.T @ f
    return Result(x=x, fun=f, jac=J, cost=0.5 * float(f @ f), nfev=nfev, njev=njev, status=status,
                  optimality=float(np.max(np.abs(g))) if len(g) else 0.0)


def huber_linear(A: np.ndarray, y: np.ndarray, f_scale: float, start=None, *, rtol: float = 1e-13,
                 max_iterations: int = 200) -> np.ndarray:
    """The coefficients c minimising sum_i rho((A c - y)_i), Huber's loss at ``f_scale`` (r^2 within
    it, 2 f_scale |r| - f_scale^2 beyond): what ``scipy.optimize.least_squares(lambda c: A @ c - y,
    start, loss="huber", f_scale=f_scale)`` converges to, by iteratively reweighted least
    squares (weights min(1, f_scale / |r|)) until the coefficients change by less than ``rtol``
    of their size: the loss is convex, so this is its minimum, to rounding where scipy's
    trust-region method stops at its 1e-8 tolerances."""
    A = np.asarray(A, dtype=float)
    y = np.asarray(y, dtype=float)
    c = np.linalg.lstsq(A, y, rcond=None)[0] if start is None else np.array(start, dtype=float)
    for _ in range(max_iterations):
        r = np.abs(A @ c - y)
        w = np.sqrt(np.minimum(1.0, f_scale / np.maximum(r, np.finfo(float).tiny)))
        new = np.linalg.lstsq(A * w[:, None], y * w, rcond=None)[0]
        done = np.all(np.abs(new - c) <= rtol * max(float(np.max(np.abs(new))), np.finfo(float).tiny))
        c = new
        if done:
            break
    return c
