"""Gimbal kinematics of a 1-3 axis rate table: forward kinematics and inverse kinematics.

Frames (as the device twins and docs/sequencer.md): ENU (x east, y north, z up); the platform
frame, which is ENU when every axis is at zero; the IMU case frame b.  Axes are listed
outer -> inner by their ENU direction at zero, a_i.  With R_i the rotation by theta_i about a_i
and M the mounting (case -> platform coordinates, ``v_platform = M v_case``):

    C_nb(theta) = R_1 R_2 ... R_k M           (case -> ENU)
    b_i(theta)  = R_1 ... R_(i-1) a_i         (axis i now, ENU; independent of theta_i..theta_k)

so d(C_nb v)/d theta_j = b_j x (C_nb v), and d b_i / d theta_j = b_j x b_i for j < i.

Inverse kinematics solves a few direction constraints for the angles: in closed form where the
solutions are finitely many up to axes the constraint does not involve (Paden-Kahan subproblems
for arbitrary unit axes, at the end of this module; issue 26), else by batched Gauss-Newton from
a grid of starting points plus the present angles, slid along the solution set; it keeps the
exact solutions inside the angle limits and returns the one with the least travel from the
present angles.
"""
from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product over the last axis, broadcast: the very arithmetic of
    station.model.geometry.cross (each component a1 b2 - a2 b1, the same floats) written into one
    array instead of stacking three (np.stack was 15 % of a compilation's time)."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    np.subtract(a1 * b2, a2 * b1, out=out[..., 0])
    np.subtract(a2 * b0, a0 * b2, out=out[..., 1])
    np.subtract(a0 * b1, a1 * b0, out=out[..., 2])
    return out

if TYPE_CHECKING:       # scipy.spatial is imported only when a Rotation is asked for (not by plan)
    from scipy.spatial.transform import Rotation

UP_ENU = np.array([0.0, 0.0, 1.0])
SOLVE_TOL = 1e-10            # residual (unit vectors) of an exact solution: 2e-5 arcsec
GRID_DEG = 90.0              # spacing of the starting points (and the present angles)
ITERATIONS = 40


def wrap180(x):
    """Angle(s) in [-180, 180)."""
    return (np.asarray(x, dtype=float) + 180.0) % 360.0 - 180.0


def heading_enu(heading_deg: float) -> np.ndarray:
    """Horizontal unit vector at azimuth ``heading_deg`` (clockwise from north)."""
    h = np.radians(heading_deg)
    return np.array([np.sin(h), np.cos(h), 0.0])


def right_angle_mountings() -> list[np.ndarray]:
    """The 24 mountings of a box on a face: proper rotation matrices with entries 0, +-1."""
    return list(_RIGHT_ANGLE_MOUNTINGS)


def _right_angle_mountings() -> tuple:
    out = []
    for perm in itertools.permutations(range(3)):
        for signs in itertools.product((1.0, -1.0), repeat=3):
            m = np.zeros((3, 3))
            for row, (col, s) in enumerate(zip(perm, signs)):
                m[row, col] = s
            if np.linalg.det(m) > 0:
                out.append(m)
    # identity first, then a fixed order
    out.sort(key=lambda m: (not np.allclose(m, np.eye(3)), tuple(-m.ravel())))
    for m in out:
        m.setflags(write=False)         # shared by every call
    return tuple(out)


_RIGHT_ANGLE_MOUNTINGS = _right_angle_mountings()


def _skew(axis) -> tuple[np.ndarray, np.ndarray]:
    """(K, K @ K) of the unit ``axis``: K v = axis x v."""
    x, y, z = axis
    K = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    return K, K @ K


def _rodrigues(skew: tuple, angle_rad: np.ndarray) -> np.ndarray:
    """(S, 3, 3) rotation matrices about the axis of ``skew`` (_skew) by ``angle_rad`` (S,)."""
    K, K2 = skew
    s, c = np.sin(angle_rad)[:, None, None], np.cos(angle_rad)[:, None, None]
    return _EYE3 + s * K + (1.0 - c) * K2


_EYE3 = np.eye(3)


@dataclass(frozen=True)
class Gimbal:
    """A table's axes (ENU directions at zero, outer -> inner) and the IMU's mounting."""

    axes_enu: tuple                   # k unit 3-vectors
    mounting: np.ndarray              # (3, 3): case -> platform coordinates
    angle_limits_deg: tuple = ()      # per axis: None (continuous) or (lo, hi)

    def __post_init__(self):
        axes = tuple(tuple(float(c) for c in np.asarray(a, float) / np.linalg.norm(a)) for a in self.axes_enu)
        object.__setattr__(self, "axes_enu", axes)
        object.__setattr__(self, "mounting", np.asarray(self.mounting, dtype=float).reshape(3, 3))
        limits = tuple(self.angle_limits_deg) or (None,) * len(axes)
        object.__setattr__(self, "angle_limits_deg", limits)
        object.__setattr__(self, "_axes", tuple((np.array(a), _skew(a)) for a in axes))   # not a field

    @property
    def n_axes(self) -> int:
        return len(self.axes_enu)

    def remounted(self, mounting: np.ndarray) -> "Gimbal":
        return Gimbal(self.axes_enu, mounting, self.angle_limits_deg)

    # ------------------------------------------------------------------ forward kinematics
    def frames(self, theta_deg):
        """(C_nb (S,3,3), b (S,k,3)) for angles (S, k) or (k,)."""
        th = np.radians(np.atleast_2d(np.asarray(theta_deg, dtype=float)))
        S, k = th.shape
        P = np.broadcast_to(np.eye(3), (S, 3, 3)).copy()
        b = np.empty((S, k, 3))
        for j, (a, skew) in enumerate(self._axes):
            b[:, j] = P @ a
            P = P @ _rodrigues(skew, th[:, j])
        return P @ self.mounting, b

    def attitude(self, theta_deg) -> Rotation:
        """C_nb (case -> ENU) as a scipy Rotation."""
        from scipy.spatial.transform import Rotation

        C, _ = self.frames(theta_deg)
        return Rotation.from_matrix(C[0] if np.ndim(theta_deg) == 1 else C)

    def up_body(self, theta_deg) -> np.ndarray:
        """Local up in case axes."""
        return self.attitude(theta_deg).inv().apply(UP_ENU)

    def axis_now(self, theta_deg, axis: int) -> tuple[np.ndarray, np.ndarray]:
        """(ENU direction, case-axes direction) of table axis ``axis`` (1 = outer)."""
        C, b = self.frames(theta_deg)
        return b[0, axis - 1], C[0].T @ b[0, axis - 1]

    # ------------------------------------------------------------------ inverse kinematics
    def _key(self, *args) -> tuple:
        """The exact inputs of a solve (every float by its bytes): the memo's key."""
        return (type(self), self.axes_enu, self.mounting.tobytes(), self.angle_limits_deg,
                tuple(None if a is None else np.asarray(a, dtype=float).tobytes() for a in args))

    def solve_static(self, up_body, theta0, heading_body=None, heading_deg=None):
        """Angles putting ``up_body`` up (and ``heading_body`` towards ``heading_deg``), the
        least travel from ``theta0``; None when no angles reach it."""
        if not MEMO:
            return self._solve_static(up_body, theta0, heading_body, heading_deg)
        key = ("static", *self._key(up_body, theta0, heading_body, heading_deg))
        if key not in _SOLVED:
            _remember(key, self._solve_static(up_body, theta0, heading_body, heading_deg))
        return _recall(key)

    def _solve_static(self, up_body, theta0, heading_body=None, heading_deg=None):
        pairs = [(np.asarray(up_body, float), UP_ENU)]
        if heading_body is not None:
            pairs.append((np.asarray(heading_body, float), heading_enu(heading_deg)))

        def residual(theta):
            C, b = self.frames(theta)
            res, jac = [], []
            for v_body, v_enu in pairs:
                w = C @ v_body                                  # (S, 3)
                res.append(w - v_enu)
                jac.append(cross(b, w[:, None, :]).transpose(0, 2, 1))   # (S, 3, k)
            return np.concatenate(res, axis=1), np.concatenate(jac, axis=1)

        closed = None
        if CLOSED_FORM:
            closed = lambda th0: self._closed_static(pairs, th0)     # noqa: E731
        return self._solve(residual, theta0, free=list(range(self.n_axes)), closed=closed)

    def _closed_static(self, pairs, theta0):
        """Candidate angles (rows) of a static in closed form, or None (iterate)."""
        axes = [a for a, _ in self._axes]
        v = self.mounting @ pairs[0][0]
        if len(pairs) == 1:                     # up only: R_1 ... R_k v = up
            sols = _direction(axes, v, UP_ENU)
            return None if sols is None else _combine(theta0, [range(self.n_axes)], [sols])
        h, H = self.mounting @ pairs[1][0], pairs[1][1]
        if abs(v @ h) > _PARALLEL or abs(v @ v - 1.0) > _PARALLEL or abs(h @ h - 1.0) > _PARALLEL:
            return None
        # the whole attitude: R_1 ... R_k = T with T v = up, T h = H
        T = np.column_stack([UP_ENU, H, _cx(UP_ENU, H)]) @ np.column_stack([v, h, _cx(v, h)]).T
        last = axes[-1]
        x = _cx(last, np.eye(3)[int(np.argmin(np.abs(last)))])
        x /= np.linalg.norm(x)                  # a direction the innermost axis turns
        if self.n_axes == 3:                    # R_1 R_2 a_3 = T a_3, then the inner angle
            outer = _sub2(axes[0], axes[1], axes[2], T @ axes[2])
        elif self.n_axes == 2:                  # R_1 a_2 = T a_2, then the inner angle
            if _norm(_cx(axes[0], axes[1])) < _DEGENERATE:
                return None
            outer = [(_sub1(axes[0], axes[1], T @ axes[1]),)]
        else:
            outer = [()]
        if outer is None:
            return None
        rows = []
        for angles in outer:
            y = T @ x
            for a, t in zip(axes, angles):      # (R_1 ... R_(k-1))^T T x
                y = _rot(a, -t, y)
            rows.append([math.degrees(t) for t in (*angles, _sub1(last, x, y))])
        return np.array(rows).reshape(-1, self.n_axes)

    def solve_rotation(self, axis_body, elevation_deg, theta0, axis: int, sign: float):
        """Start angles for turning table ``axis`` so that the rotation is about ``axis_body``
        (case axes) with that direction ``elevation_deg`` above the horizontal (None: any): the
        table axis points along ``sign`` x ``axis_body``.  The turning axis keeps its present
        angle."""
        if not MEMO:
            return self._solve_rotation(axis_body, elevation_deg, theta0, axis, sign)
        key = ("rotation", axis, *self._key(axis_body, elevation_deg, theta0, sign))
        if key not in _SOLVED:
            _remember(key, self._solve_rotation(axis_body, elevation_deg, theta0, axis, sign))
        return _recall(key)

    def _solve_rotation(self, axis_body, elevation_deg, theta0, axis: int, sign: float):
        i = axis - 1
        a = np.asarray(axis_body, float)
        rows = 4 if elevation_deg is not None else 3            # None: any elevation
        target = 0.0 if elevation_deg is None else np.sin(np.radians(elevation_deg))

        def residual(theta):
            C, b = self.frames(theta)
            w = C @ a                                           # (S, 3)
            bi = b[:, i]
            res = np.concatenate([w - sign * bi, (sign * bi[:, 2] - target)[:, None]], axis=1)
            jw = cross(b, w[:, None, :]).transpose(0, 2, 1)  # (S, 3, k)
            jb = cross(b, bi[:, None, :]).transpose(0, 2, 1)
            jb[:, :, i:] = 0.0                                  # b_i depends on outer axes only
            jac = np.concatenate([jw - sign * jb, sign * jb[:, 2:3, :]], axis=1)
            return res[:, :rows], jac[:, :rows]

        closed = None
        if CLOSED_FORM:
            closed = lambda th0: self._closed_rotation(a, elevation_deg, th0, i, sign)    # noqa: E731
        return self._solve(residual, theta0, free=[j for j in range(self.n_axes) if j != i], closed=closed)

    def _closed_rotation(self, axis_body, elevation_deg, theta0, i, sign):
        """Candidate angles of a rotation's start in closed form, or None (iterate).  C a = s b_i
        is R_(i+1) ... R_k (M a) = s a_i (the inner axes only); the elevation is
        (R_1 ... R_(i-1) a_i)_z = s sin(elevation) (the outer axes only)."""
        axes = [a for a, _ in self._axes]
        inner = _direction(axes[i + 1:], self.mounting @ axis_body, sign * axes[i])
        if inner is None:
            return None
        outer = [{}]
        if elevation_deg is not None:
            outer = _cone(axes[:i], axes[i], sign * math.sin(math.radians(elevation_deg)))
            if outer is None:
                return None
        return _combine(theta0, [range(i + 1, self.n_axes), range(i)], [inner, outer])

    def _solve(self, residual, theta0, free, closed=None):
        theta0 = self.unwrap(theta0)
        theta = None
        if closed is not None and all(lim is None or t <= lim[1] for t, lim in zip(theta0, self.angle_limits_deg)):
            # (from outside an axis's limits an axis that the target does not involve is not to
            # stay where it is: the iterative solve)
            theta = closed(theta0)
        if theta is not None:                   # every solution (a finite set): none to slide
            r, _ = residual(theta)
            theta = theta[np.linalg.norm(r, axis=1) < SOLVE_TOL]
        else:
            theta = self._iterate(residual, theta0, free)
        best, best_key = None, None
        for th in theta:
            th = self._in_limits(th)
            if th is None:
                continue
            # the least travel; between equal travels (1e-9 deg: an axis in gimbal lock makes a
            # line of them), the least squared travel, then the smallest angles: one answer,
            # whatever order the solutions were found in
            key = (round(self.travel(theta0, th), 9), round(self._travel2(theta0, th), 6), tuple(np.round(th, 9)))
            if best_key is None or key < best_key:
                best, best_key = th, key
        return best

    def _iterate(self, residual, theta0, free):
        """The solutions by Gauss-Newton from a grid of starts, slid to their least travel."""
        if free:
            grid = np.arange(0.0, 360.0, GRID_DEG)
            starts = np.tile(theta0, (len(grid) ** len(free) + 1, 1))
            combos = np.array(list(itertools.product(grid, repeat=len(free))))
            starts[1:, free] = combos
        else:
            starts = theta0[None, :].copy()
        theta = _newton(residual, starts, free)
        r, _ = residual(theta)
        theta = theta[np.linalg.norm(r, axis=1) < SOLVE_TOL]
        if len(theta) and free:
            theta = self._least_travel(residual, theta, theta0, free)
            r, _ = residual(theta)
            theta = theta[np.linalg.norm(r, axis=1) < SOLVE_TOL]
        return theta

    def _least_travel(self, residual, theta, theta0, free):
        """Slide solutions along their solution set (when it is not a point) towards the least
        travel from ``theta0``: whole steps against the travel gradient projected on the null
        space of the constraints' Jacobian (on a straight solution set one step reaches the
        least travel; on a curved one a few), each followed by a Newton correction.  Solutions
        that agree to 1e-6 deg (many starts end on the same one) are slid once.  (Half steps, as
        before: 35 slides to 1e-9 deg instead of 2-4, the same solutions: 98 compiled plans
        compared, tests/test_compile.py.)"""
        continuous = np.array([lim is None for lim in self.angle_limits_deg])
        key = np.round(np.where(continuous, theta % 360.0, theta), 6) % 360.0
        theta = theta[np.sort(np.unique(key, axis=0, return_index=True)[1])]
        for _ in range(ITERATIONS):
            _, J = residual(theta)
            Jf = J[:, :, free]
            null = np.eye(len(free)) - np.linalg.pinv(Jf, rcond=1e-9) @ Jf    # (S, f, f)
            d = theta - theta0
            d = np.where(continuous, wrap180(d), d)[:, free]
            step = -np.einsum("sij,sj->si", null, d)
            if np.all(np.abs(step) < 1e-9):
                break
            theta = theta.copy()
            theta[:, free] += np.clip(step, -30.0, 30.0)
            theta = _newton(residual, theta, free)
        return theta

    # ------------------------------------------------------------------ limits and travel
    def unwrap(self, theta) -> np.ndarray:
        """Angles (e.g. read back in [0, 360)) written inside the limits of limited axes."""
        theta = np.asarray(theta, dtype=float).reshape(self.n_axes).copy()
        for j, lim in enumerate(self.angle_limits_deg):
            if lim is not None:
                theta[j] = lim[0] + (theta[j] - lim[0]) % 360.0
        return theta

    def _in_limits(self, theta):
        """``theta`` written inside each axis's limits ([0, 360) for continuous axes), or None."""
        out = np.empty_like(theta)
        for j, (t, lim) in enumerate(zip(theta, self.angle_limits_deg)):
            if lim is None:
                out[j] = t % 360.0 if abs(t % 360.0 - 360.0) > 1e-9 else 0.0
                continue
            lo, hi = lim
            cand = lo + (t - lo) % 360.0
            if cand >= lo + 360.0 - 1e-9:       # a hair below the lower limit (round-off: a closed
                cand = lo                       # form's -1e-17 at a limit of 0): on it, as the
                                                # upper limit's 1e-9 below
            if cand > hi + 1e-9:
                return None
            out[j] = cand
        return out

    def _travel2(self, theta_from, theta_to) -> float:
        """Sum of the squared angles turned (deg^2), as travel()."""
        d = np.asarray(theta_to, float) - np.asarray(theta_from, float)
        continuous = np.array([lim is None for lim in self.angle_limits_deg])
        return float(np.sum(np.where(continuous, wrap180(d), d) ** 2))

    def travel(self, theta_from, theta_to) -> float:
        """Sum over axes of the angle turned (deg): the shortest way round on continuous axes,
        through the allowed range on limited ones."""
        total = 0.0
        for a, b, lim in zip(theta_from, theta_to, self.angle_limits_deg):
            total += abs(float(wrap180(b - a))) if lim is None else abs(float(b - a))
        return total


# Solves already done in this process, by their exact inputs (Gimbal._key): a compilation asks
# the same question several times (whether a static is reachable under each candidate mounting,
# then the plan's own move to it: 513 solves for the seven built-in schemes, 297 distinct).  A
# solve is a pure function of its inputs (the same floats in, the same floats out), so a
# remembered answer is the very answer: the plans are bit for bit those computed without it
# (tests/test_compile.py).  Bounded: the oldest half is dropped at MEMO_SIZE entries.
MEMO = True
MEMO_SIZE = 4096
_SOLVED: dict = {}


def _remember(key, theta) -> None:
    if len(_SOLVED) >= MEMO_SIZE:
        for old in list(_SOLVED)[:MEMO_SIZE // 2]:
            del _SOLVED[old]
    _SOLVED[key] = None if theta is None else np.array(theta, dtype=float)


def _recall(key):
    theta = _SOLVED[key]
    return None if theta is None else theta.copy()      # the caller may change its copy


def _newton(residual, theta, free):
    """Gauss-Newton (minimum-norm steps, at most 30 deg) on the ``free`` angles of every row; a
    row stops once its step is below 1e-12 deg (the others go on: one row that does not converge,
    a start with no solution near it, no longer keeps every row iterating)."""
    theta = np.array(theta, dtype=float)
    active = np.arange(len(theta))
    columns = np.asarray(free, dtype=np.intp)[None, :]
    for _ in range(ITERATIONS):
        r, J = residual(theta[active])
        step = -np.einsum("sij,sj->si", np.linalg.pinv(J[:, :, free], rcond=1e-9), r)
        step = np.clip(np.degrees(step), -30.0, 30.0)
        theta[active[:, None], columns] += step           # (np.ix_'s selection, without building it)
        active = active[np.any(np.abs(step) >= 1e-12, axis=1)]
        if not len(active):
            break
    return theta


# ---------------------------------------------------------------------- closed-form inverse kinematics
# The common cases solved by Paden-Kahan subproblems for arbitrary unit axes (issue 26): every
# solution, when they are finitely many up to axes the constraint does not involve (those keep
# their present angle: the least travel on a decoupled axis is none).  None means "not a case
# solved here" (a solution curve, a near-degenerate geometry): the iterative solve decides.  The
# candidates then go through the iterative solver's own residual test and least-travel choice.
CLOSED_FORM = True
_PARALLEL = 1e-12          # |a x q| below this: the axis leaves q as it is (an exact decoupling)
_DEGENERATE = 1e-6         # ... between this and _PARALLEL: too near a degenerate case, iterate

def _cx(a, b) -> np.ndarray:
    """a x b of two 3-vectors (np.cross's general machinery costs 20 us a call; this 2)."""
    a0, a1, a2 = a
    b0, b1, b2 = b
    return np.array([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0])


def _norm(v) -> float:
    return math.sqrt(float(v @ v))



def _sub1(a, p, q) -> float:
    """The angle (rad) turning ``p`` about the unit ``a`` onto ``q`` (in the plane normal to a)."""
    pp, qp = p - a * (a @ p), q - a * (a @ q)
    return math.atan2(float(a @ _cx(pp, qp)), float(pp @ qp))


def _rot(a, angle, p):
    """``p`` turned by ``angle`` (rad) about the unit ``a`` (Rodrigues)."""
    c, s = math.cos(angle), math.sin(angle)
    return p * c + _cx(a, p) * s + a * (a @ p) * (1.0 - c)


def _sub2(ao, ai, p, q):
    """Angles (rad) (outer, inner) with R(ao, outer) R(ai, inner) p = q: a list (0-2 pairs), or
    None when the case is degenerate (parallel axes, a tangency)."""
    d = float(ao @ ai)
    n = _cx(ao, ai)
    nn = float(n @ n)
    if nn < _DEGENERATE:
        return None
    den = d * d - 1.0
    alpha = (d * float(ai @ p) - float(ao @ q)) / den
    beta = (d * float(ao @ q) - float(ai @ p)) / den
    g2 = (float(p @ p) - alpha * alpha - beta * beta - 2.0 * alpha * beta * d) / nn
    if g2 < -_DEGENERATE:
        return []                               # the two cones do not meet: no solution
    if g2 < _DEGENERATE:
        return None                             # (nearly) touching: iterate
    out = []
    for gamma in (math.sqrt(g2), -math.sqrt(g2)):
        c = alpha * ao + beta * ai + gamma * n
        out.append((_sub1(ao, c, q), _sub1(ai, p, c)))
    return out


def _direction(axes, p, q):
    """Solutions of R(axes[0]) ... R(axes[-1]) p = q (unit p, q) as a list of dicts
    {index in axes: angle rad}; the axes not in a dict are not involved (they keep their present
    angle).  None: not solved here."""
    span = _involved(axes, q, p)
    if span is None:
        return None
    lo, hi = span
    n = hi - lo
    if n == 0:
        return [{}]
    if n == 1:
        return [{lo: _sub1(axes[lo], p, q)}]
    if n == 2:
        pairs = _sub2(axes[lo], axes[lo + 1], p, q)
        return None if pairs is None else [{lo: o, lo + 1: i} for o, i in pairs]
    return None


def _involved(axes, outer, inner):
    """(lo, hi): the axes[lo:hi] a solve involves -- the outer axes along ``outer`` leave it as it
    is, and so do the inner ones along ``inner`` (they keep their present angle); None when one
    of them is neither along it nor clearly across it (near-degenerate: iterate)."""
    lo, hi = 0, len(axes)
    while lo < hi and _norm(_cx(axes[lo], outer)) < _DEGENERATE:
        if _norm(_cx(axes[lo], outer)) >= _PARALLEL:
            return None
        lo += 1
    while lo < hi and _norm(_cx(axes[hi - 1], inner)) < _DEGENERATE:
        if _norm(_cx(axes[hi - 1], inner)) >= _PARALLEL:
            return None
        hi -= 1
    return lo, hi


def _cone(axes, p, height):
    """Solutions of (R(axes[0]) ... R(axes[-1]) p)_z = height, as _direction (None: a curve)."""
    z = UP_ENU
    span = _involved(axes, z, p)
    if span is None:
        return None
    lo, hi = span
    n = hi - lo
    if n == 0:
        return [{}]
    if n > 1:
        return None
    a = axes[lo]
    # z . R p = z.a a.p + cos (z.p - z.a a.p) + sin z.(a x p) = height
    mid = float(a @ z) * float(a @ p)
    A, B = float(p @ z) - mid, float(z @ _cx(a, p))
    r = math.hypot(A, B)
    if r < _DEGENERATE:
        return None
    c = (height - mid) / r
    phi = math.atan2(B, A)
    if abs(c) > 1.0 + _DEGENERATE:
        return []
    if abs(c) > 1.0 - _DEGENERATE:
        # (nearly) tangent: iterate.  Not the exact double root here: Gauss-Newton stops 6e-7 deg
        # short of it (the residual is quadratic there), and a compilation choosing between two
        # axes of equal travel (sizeeffect's y100) then takes the one whose travel is 6e-7 deg
        # "shorter": the exact root would change that plan's axis
        return None
    delta = math.acos(c)
    return [{lo: phi + delta}, {lo: phi - delta}]


def _combine(theta0, axes_idx, parts):
    """Candidate angle rows (deg): ``theta0`` with each combination of the parts' solutions."""
    rows = [theta0.copy()]
    for idx, sols in zip(axes_idx, parts):
        new = []
        for row in rows:
            for sol in sols:
                r = row.copy()
                for j, angle in sol.items():
                    r[idx[j]] = math.degrees(angle)
                new.append(r)
        rows = new
    return np.array(rows).reshape(-1, len(theta0))
