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

``LevenbergMarquardt`` is the solve as an object whose ``run`` a watch can pause and that goes on
with its state (scaling, radius, damping), also from another point (``move_to``): lsq._lm pauses
it where it creeps and resumes it after a dogbox detour (docs/method-lsq.md, fourteenth session);
``least_squares`` runs it once.  The result has scipy's fields the callers use: x, fun, jac (at x), cost, nfev, njev, status
(0: the evaluation limit reached; 1: gtol; 2: ftol; 3: xtol; 4: ftol and xtol), success,
message, optimality.

``dogbox`` is that detour: the dogleg in a rectangular trust region of scipy's
``least_squares(method="dogbox", x_scale="jac")`` without bounds, in numpy (scipy.optimize's
import was ~0.25-0.39 s of CPU of each estimate whose fit creeps: imucal's session, imu_tk's
log).  The same steps as scipy's to rounding (tests/test_solver.py).

Both take ``canonical``, a function returning another point of the same data (lsq.Model.canonical:
the statics' rotation vectors wound past 1.5 pi turned back, the same rotations, weak-prior rows
lower) or None: each accepted point is replaced by it, one more evaluation, where it returns one
and its sum of squares is not higher.  A parameterisation's chart: the solver's path is its own
otherwise, step for step (None everywhere: no evaluation, nothing changed).
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


def _svd_projected(A, f):
    """The singular values s and right singular vectors Vt of A (m x n), and U^T f (U its left
    singular vectors, m x n): all _step needs of A = U S Vt.  For a tall A from the QR
    factorisation of [A f] (R's last column above its corner is Q^T f), then the SVD of the n x n
    R: the same s, Vt and U^T f to rounding, without forming the m x n U (a 303 x 99 scaled
    Jacobian, one BLAS thread: 1.8 ms against 2.8 ms for the SVD of A with U; issue 27).  A square
    or wide A, or one the factorisations fail on (not finite), as the SVD of A answers it."""
    m, n = A.shape
    if m > n > 0:
        try:
            R = np.linalg.qr(np.column_stack([A, f]), mode="r")
            U, s, Vt = np.linalg.svd(R[:n, :n])
            return s, Vt, U.T @ R[:n, n]
        except np.linalg.LinAlgError:
            pass
    U, s, Vt = np.linalg.svd(A, full_matrices=False)
    return s, Vt, U.T @ f


class LevenbergMarquardt:
    """The solve as an object, so that it can be paused and resumed with its state: where it is
    (x, the residuals, their norm), the column scaling ``diag``, the trust region's radius
    ``delta`` and the Levenberg-Marquardt parameter ``par``.  ``run`` iterates until a convergence
    test, the evaluation limit, or ``watch(x, f, fnorm)`` (called after every evaluation) says
    stop; ``move_to`` continues from another point (a detour's: lsq._lm's dogbox) with the scaling,
    radius and damping the iterations had found, not from a fresh start (whose first radius,
    factor x ||D x||, is rejected and shrunk again step by step: lsq._lm's confirming LM took
    tens of evaluations to relearn them)."""

    def __init__(self, fun, x0, jac, *, xtol: float = 1e-8, ftol: float = 1e-8, gtol: float = 1e-8,
                 factor: float = 100.0, canonical=None):
        self.fun, self.jac = fun, jac
        self.canonical = canonical      # (the module's docstring: an accepted point's own chart)
        self.xtol, self.ftol, self.gtol, self.factor = xtol, ftol, gtol, factor
        self.x = np.array(x0, dtype=float)
        self.x0 = self.x.copy()     # where the solve started (lsq._last_phase: dogbox from there)
        self.f = np.asarray(fun(self.x), dtype=float)
        self.nfev, self.njev = 1, 0
        self.fnorm = float(np.linalg.norm(self.f))
        self.diag = None
        self.delta = self.xnorm = self.par = 0.0
        self.status = None
        self.J = None
        self.J_at_x = False
        self.first = True           # lmder's first iteration: until a step is accepted
        self.rescale = 0.0

    def move_to(self, x, f=None, rescale: float = 0.0) -> None:
        """Continue from x (residuals f, evaluated here when not given) with the state kept;
        ``rescale`` > 0: a column whose scale exceeds ``rescale`` times its norm at x is scaled by
        that norm (a scale kept from a start far off)."""
        self.x = np.array(x, dtype=float)
        if f is None:
            f = self.fun(self.x)
            self.nfev += 1
        self.f = np.asarray(f, dtype=float)
        self.fnorm = float(np.linalg.norm(self.f))
        if self.diag is not None:
            self.xnorm = float(np.linalg.norm(self.diag * self.x))
            self.rescale = rescale
        self.J_at_x = False
        self.status = None

    def run(self, max_nfev: int, watch=None):
        """Iterate until a convergence test (status 1-4), ``max_nfev`` evaluations in all (status 0),
        or ``watch`` returns True after an evaluation (the status stays None: paused; ``run`` goes
        on from there).  Returns the status."""
        fun, jac = self.fun, self.jac
        xtol, ftol, gtol = self.xtol, self.ftol, self.gtol
        self.status = None
        while self.status is None:
            if not self.J_at_x:
                self.J = np.asarray(jac(self.x), dtype=float)
                self.njev += 1
                self.J_at_x = True
            J, f, fnorm, x = self.J, self.f, self.fnorm, self.x
            norms = np.linalg.norm(J, axis=0)
            if self.rescale:
                stale = (norms > 0) & (self.diag > self.rescale * norms)
                self.diag = np.where(stale, norms, self.diag)
                self.xnorm = float(np.linalg.norm(self.diag * x))
                self.rescale = 0.0
            elif self.diag is None:
                self.diag = np.where(norms > 0, norms, 1.0)
                self.xnorm = float(np.linalg.norm(self.diag * x))
                self.delta = self.factor * self.xnorm if self.xnorm > 0 else self.factor
            else:
                self.diag = np.maximum(self.diag, norms)
            diag = self.diag
            # gtol: the largest cosine between f and a column of J
            gnorm = 0.0
            if fnorm > 0:
                g = J.T @ f
                nz = norms > 0
                if nz.any():
                    gnorm = float(np.max(np.abs(g[nz]) / (norms[nz] * fnorm)))
            if fnorm == 0 or gnorm <= max(gtol, EPS):
                self.status = 1
                break
            s, Vt, uf = _svd_projected(J / diag, f)
            while True:                                   # until a step reduces the sum of squares
                p, self.par = _step(s, Vt, uf, diag, self.delta, self.par)
                par = self.par
                step = p / diag
                pnorm = float(np.linalg.norm(p))
                if self.first:
                    self.delta = min(self.delta, pnorm)   # lmder: the first radius no longer than the first step
                x_new = x + step
                f_new = np.asarray(fun(x_new), dtype=float)
                self.nfev += 1
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
                    self.delta = temp * min(self.delta, pnorm / 0.1)
                    self.par = par / temp
                elif par == 0 or ratio >= 0.75:
                    self.delta = pnorm / 0.5
                    self.par = 0.5 * par
                if ratio >= 1e-4:                         # accepted
                    if self.canonical is not None and self.nfev < max_nfev:
                        x_new, f_new, fnorm1 = self._canonical(x_new, f_new, fnorm1)
                    x, f, fnorm = x_new, f_new, fnorm1
                    self.x, self.f, self.fnorm = x, f, fnorm
                    self.xnorm = float(np.linalg.norm(diag * x))
                    self.J_at_x = False
                    self.first = False
                # lmder's tests; a tolerance below the machine's precision is met at that precision
                # (lmder's info 6 and 7: no further reduction, no further step possible)
                f_ok = abs(actred) <= max(ftol, EPS) and prered <= max(ftol, EPS) and 0.5 * ratio <= 1
                x_ok = self.delta <= max(xtol, EPS) * self.xnorm
                if f_ok and x_ok:
                    self.status = 4
                elif f_ok:
                    self.status = 2
                elif x_ok:
                    self.status = 3
                elif self.nfev >= max_nfev:
                    self.status = 0
                if self.status is not None:
                    break
                if watch is not None and watch(x_new, f_new, fnorm1):
                    return None                           # paused (the state is kept)
                if ratio >= 1e-4:
                    break
        return self.status

    def _canonical(self, x, f, fnorm):
        """The accepted point x (residuals f, their norm) in its own chart (canonical(x), one
        evaluation) where that is another point and its sum of squares is not higher."""
        other = self.canonical(x)
        if other is None:
            return x, f, fnorm
        f_other = np.asarray(self.fun(other), dtype=float)
        self.nfev += 1
        with np.errstate(over="ignore", invalid="ignore"):
            norm = float(np.linalg.norm(f_other))
        return (other, f_other, norm) if norm <= fnorm else (x, f, fnorm)

    def result(self) -> Result:
        """The result where the iterations are (the Jacobian evaluated there if it is not yet)."""
        if not self.J_at_x:
            self.J = np.asarray(self.jac(self.x), dtype=float)
            self.njev += 1
            self.J_at_x = True
        g = self.J.T @ self.f
        return Result(x=self.x, fun=self.f, jac=self.J, cost=0.5 * float(self.f @ self.f), nfev=self.nfev,
                      njev=self.njev, status=0 if self.status is None else self.status,
                      optimality=float(np.max(np.abs(g))) if len(g) else 0.0)


def least_squares(fun, x0, jac, *, xtol: float = 1e-8, ftol: float = 1e-8, gtol: float = 1e-8,
                  max_nfev: int | None = None, factor: float = 100.0, canonical=None) -> Result:
    """Minimise 0.5 ||fun(x)||^2 from x0 (Levenberg–Marquardt, MINPACK's updates, column-norm
    scaling); ``jac(x)`` the dense Jacobian (m x n, m >= n); ``canonical``: the module's docstring."""
    lm = LevenbergMarquardt(fun, x0, jac, xtol=xtol, ftol=ftol, gtol=gtol, factor=factor, canonical=canonical)
    lm.run(100 * len(lm.x) if max_nfev is None else int(max_nfev))
    return lm.result()


def _box_dogleg(newton, g, a, b, half):
    """The dogleg step in the box |step_i| <= half_i (Voglis & Lagaris 2004): the Gauss-Newton step
    ``newton`` when it is inside the box; else the minimum of the quadratic model along the
    steepest descent -g within the box (the Cauchy point: a t^2 + b t with a = ||J g||^2 / 2,
    b = -||g||^2, t from 0 to the box's face), then from there towards the Gauss-Newton step
    until a face is met.  In a box the constrained Cauchy point is improved on too (the classical
    dogleg returns it when it reaches the region's boundary).  Returns (step, whether a face of
    the box was hit)."""
    if np.all(np.abs(newton) <= half):
        return newton, False
    moving = g != 0
    if not moving.any():
        cauchy = np.zeros_like(g)
    else:
        to_face = float(np.min(half[moving] / np.abs(g[moving])))
        # the minimum of t (a t + b) on [0, to_face]: an end, or the vertex -b / 2a inside
        ts = [0.0, to_face]
        if a != 0 and 0.0 < -0.5 * b / a < to_face:
            ts.append(-0.5 * b / a)
        t = min(ts, key=lambda t: t * (a * t + b))
        cauchy = -t * g
    d = newton - cauchy
    along = d != 0
    with np.errstate(over="ignore"):
        # the largest s with |cauchy + s d| <= half in every component along which d moves
        s = float(np.min(np.maximum((-half[along] - cauchy[along]) / d[along],
                                    (half[along] - cauchy[along]) / d[along])))
    return cauchy + s * d, True


def dogbox(fun, x0, jac, *, xtol: float = 1e-8, ftol: float = 1e-8, gtol: float = 1e-8,
           max_nfev: int | None = None, canonical=None) -> Result:
    """Minimise 0.5 ||fun(x)||^2 from x0 by dogleg steps in a rectangular trust region (Voglis &
    Lagaris 2004, "A rectangular trust region dogleg approach for unconstrained and bound
    constrained nonlinear optimization"): the algorithm of ``scipy.optimize.least_squares(
    method="dogbox", x_scale="jac")`` without bounds (tr_solver "exact"), in numpy, so that the
    detour lsq._lm takes where Levenberg-Marquardt creeps does not import scipy.optimize (~0.3 s
    of CPU of a small capture's estimate, issue 27).

    The trust region is the box |step_i| <= delta / d_i, d the Jacobian's column norms (each the
    largest its column has had; x_scale="jac"), delta first ||d x||_inf (1 if zero).  Each
    iteration: the Gauss-Newton step (least squares, singular values below eps x the largest
    dropped: lstsq's rcond=-1) if it fits in the box, else the box dogleg (_box_dogleg); a step
    that does not lower the sum of squares is rejected and the box shrunk to a quarter of the
    step's scaled size (also when the residuals are not finite there); a step whose actual
    reduction is below a quarter of the predicted one shrinks it so too; above three quarters,
    with the step on the box's face, the box doubles.  Termination as scipy's: gtol on ||J^T
    f||_inf (status 1), ftol on the actual reduction relative to the cost with a ratio above 0.25
    (2), xtol on ||step|| < xtol (xtol + ||x||) (3), both (4), ``max_nfev`` evaluations (0, 100 n
    by default).  ``fun`` may raise to stop it (lsq._CreepWatch).  The result has solver.Result's
    fields (x, fun, jac at x, cost, nfev, njev, status, optimality = ||J^T f||_inf); it finds the
    same minimum as scipy's within the tolerances (tests/test_solver.py)."""
    x = np.array(x0, dtype=float)
    f = np.asarray(fun(x), dtype=float)
    nfev = 1
    if not np.all(np.isfinite(f)):
        raise ValueError("dogbox: the residuals are not finite at the start")
    J = np.asarray(jac(x), dtype=float)
    njev = 1
    if max_nfev is None:
        max_nfev = 100 * len(x)
    cost = 0.5 * float(f @ f)
    g = J.T @ f
    d = np.sqrt(np.sum(J * J, axis=0))             # x_scale="jac": the columns' norms, 1 where zero
    d[d == 0] = 1.0
    scale = 1.0 / d
    delta = float(np.max(np.abs(x * d))) if len(x) else 0.0
    if delta == 0:
        delta = 1.0
    status = None
    while True:
        g_norm = float(np.max(np.abs(g))) if len(g) else 0.0
        if g_norm < gtol:
            status = 1
        if status is not None or nfev >= max_nfev:
            break
        newton = np.linalg.lstsq(J, -f, rcond=-1)[0]
        Jg = J @ g
        a, b = 0.5 * float(Jg @ Jg), -float(g @ g)   # the model along -g: a t^2 + b t
        reduction = -1.0
        while reduction <= 0 and nfev < max_nfev:
            step, on_face = _box_dogleg(newton, g, a, b, delta * scale)
            Js = J @ step
            predicted = -(0.5 * float(Js @ Js) + float(g @ step))
            x_new = x + step
            f_new = np.asarray(fun(x_new), dtype=float)
            nfev += 1
            scaled = float(np.max(np.abs(step * d)))
            if not np.all(np.isfinite(f_new)):
                delta = 0.25 * scaled
                continue
            cost_new = 0.5 * float(f_new @ f_new)
            reduction = cost - cost_new
            if predicted > 0:
                ratio = reduction / predicted
            elif predicted == reduction == 0:
                ratio = 1.0
            else:
                ratio = 0.0
            if ratio < 0.25:
                delta = 0.25 * scaled
            elif ratio > 0.75 and on_face:
                delta *= 2.0
            f_ok = reduction < ftol * cost and ratio > 0.25
            x_ok = float(np.linalg.norm(step)) < xtol * (xtol + float(np.linalg.norm(x)))
            status = 4 if f_ok and x_ok else 2 if f_ok else 3 if x_ok else None
            if status is not None:
                break
        if reduction > 0:                          # accepted: the Jacobian and scaling there
            other = canonical(x_new) if canonical is not None else None
            if other is not None and nfev < max_nfev:       # (its own chart: the module's docstring)
                f_other = np.asarray(fun(other), dtype=float)
                nfev += 1
                with np.errstate(over="ignore", invalid="ignore"):
                    cost_other = 0.5 * float(f_other @ f_other)
                if cost_other <= cost_new:
                    x_new, f_new, cost_new = other, f_other, cost_other
            x, f, cost = x_new, f_new, cost_new
            J = np.asarray(jac(x), dtype=float)
            njev += 1
            g = J.T @ f
            d = np.maximum(np.sqrt(np.sum(J * J, axis=0)), d)
            scale = 1.0 / d
    return Result(x=x, fun=f, jac=J, cost=cost, nfev=nfev, njev=njev,
                  status=0 if status is None else status, optimality=g_norm)


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


GOLDEN = (3.0 - math.sqrt(5.0)) / 2.0      # 0.381966...: the golden section's smaller part


def minimise_bounded(f, lo: float, hi: float, xatol: float = 1e-5) -> float:
    """The minimum of a function of one variable on [lo, hi] (unimodal there) by golden-section
    search (Kiefer 1953): the bracket shrinks by 0.618 per evaluation until it is narrower than
    2 ``xatol``; one evaluation per step, ~log(width/xatol)/0.48 in all (15 for a bracket of 0.94
    at 1e-3).  What the hand-rotation start calls instead of scipy.optimize.minimize_scalar
    (bounded Brent), whose import alone was ~0.39 s of a 1.5 s estimate of imu_tk's log (issue
    27); the answer agrees with Brent's within ``xatol`` (tests/test_solver.py)."""
    a, b = float(lo), float(hi)
    if not a < b:
        raise ValueError("minimise_bounded: lo must be below hi")
    c, d = a + GOLDEN * (b - a), b - GOLDEN * (b - a)
    fc, fd = f(c), f(d)
    while b - a > 2.0 * xatol:
        if fc <= fd:                         # the minimum is in [a, d]
            b, d, fd = d, c, fc
            c = a + GOLDEN * (b - a)
            fc = f(c)
        else:                                # in [c, b]
            a, c, fc = c, d, fd
            d = b - GOLDEN * (b - a)
            fd = f(d)
    return c if fc <= fd else d
