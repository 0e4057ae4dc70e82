"""Rotations for the least-squares model, complex-step safe (pure numpy).

The fit's Jacobian is taken by complex step (station/estimate/lsq.py): the parameters get an
imaginary part i h, and every operation between them and the residuals must be complex-analytic
so that Im r(x + i h e_j) / h is the derivative.  scipy's ``Rotation`` takes real input only, and
the textbook formulas have non-analytic steps (|v| = sqrt(sum |v_i|^2), a comparison on the
angle): these helpers avoid both.  The angle enters only as theta^2 = v . v (no absolute value,
no conjugate); the functions of theta that are needed are even, hence functions of theta^2, and
are computed from the complex square root (any branch: they are even) away from zero and from
their Taylor series near it.  A branch is chosen on the real part of theta^2 only (the
imaginary part is ~1e-20 of it while the Jacobian is taken): the value is then the analytic
continuation of the real formula.

Conventions as scipy's: a rotation vector v turns by |v| rad about v/|v| (right hand); a
quaternion is (x, y, z, w), scalar last; ``matrix_from_rotvec(v)`` is
``Rotation.from_rotvec(v).as_matrix()`` (tests/test_rotation.py compares them).
"""
from __future__ import annotations

import numpy as np

SERIES_BELOW = 1e-3         # theta^2 (rad^2) below which the series are used (four terms after
                            #   the 1: the first omitted one is theta^10 / 11! < 3e-23 there); the
                            #   closed forms above cancel nothing (1 - cos is 2 sin^2 of the half)


def _small(t2) -> np.ndarray:
    return np.real(t2) < SERIES_BELOW


def sinc(t2) -> np.ndarray:
    """sin(theta) / theta as a function of theta^2 (any shape, real or complex)."""
    t2 = np.asarray(t2)
    small = _small(t2)
    series = 1.0 - t2 / 6.0 * (1.0 - t2 / 20.0 * (1.0 - t2 / 42.0 * (1.0 - t2 / 72.0)))
    with np.errstate(invalid="ignore", divide="ignore"):
        theta = np.sqrt(np.where(small, 1.0, t2))
        closed = np.sin(theta) / theta
    return np.where(small, series, closed)


def cos_half(t2) -> np.ndarray:
    """cos(theta / 2) as a function of theta^2."""
    t2 = np.asarray(t2)
    small = _small(t2)
    q = t2 / 4.0
    series = 1.0 - q / 2.0 * (1.0 - q / 12.0 * (1.0 - q / 30.0 * (1.0 - q / 56.0)))
    closed = np.cos(np.sqrt(np.where(small, 1.0, t2)) / 2.0)
    return np.where(small, series, closed)


def squared_norm(v) -> np.ndarray:
    """v . v over the last axis: |v|^2 for real v, its analytic continuation for complex v."""
    return np.einsum("...i,...i->...", v, v)


def skew(v) -> np.ndarray:
    """The cross-product matrix [v]x of each vector (..., 3) -> (..., 3, 3)."""
    v = np.asarray(v)
    z = np.zeros_like(v[..., 0])
    return np.stack([np.stack([z, -v[..., 2], v[..., 1]], axis=-1),
                     np.stack([v[..., 2], z, -v[..., 0]], axis=-1),
                     np.stack([-v[..., 1], v[..., 0], z], axis=-1)], axis=-2)


def matrix_from_rotvec(v) -> np.ndarray:
    """Rotation matrix of each rotation vector (..., 3) -> (..., 3, 3), Rodrigues' formula
    R = I + sinc(theta) K + (1 - cos theta) / theta^2 K^2 with (1 - cos theta) / theta^2 written
    as sinc(theta / 2)^2 / 2 (no cancellation for small angles)."""
    v = np.asarray(v)
    t2 = squared_norm(v)
    K = skew(v)
    a = sinc(t2)[..., None, None]
    b = 0.5 * sinc(t2 / 4.0)[..., None, None] ** 2
    return np.eye(3) + a * K + b * (K @ K)


def quat_from_rotvec(v) -> np.ndarray:
    """Unit quaternion (x, y, z, w) of each rotation vector (..., 3) -> (..., 4)."""
    v = np.asarray(v)
    t2 = squared_norm(v)
    return np.concatenate([0.5 * sinc(t2 / 4.0)[..., None] * v, cos_half(t2)[..., None]], axis=-1)


def quat_product(a, b) -> np.ndarray:
    """Hamilton product a b of quaternions (..., 4), scalar last: the rotation b first, then a
    (scipy's Rotation a * b)."""
    ax, ay, az, aw = a[..., 0], a[..., 1], a[..., 2], a[..., 3]
    bx, by, bz, bw = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    return np.stack([aw * bx + bw * ax + ay * bz - az * by,
                     aw * by + bw * ay + az * bx - ax * bz,
                     aw * bz + bw * az + ax * by - ay * bx,
                     aw * bw - ax * bx - ay * by - az * bz], axis=-1)


def matrix_from_quat(q) -> np.ndarray:
    """Rotation matrix of each unit quaternion (..., 4), scalar last -> (..., 3, 3)."""
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], axis=-1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], axis=-1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], axis=-1)], axis=-2)


def align_vectors(a, b, weights=None) -> np.ndarray:
    """The rotation matrix C minimising sum_i w_i |a_i - C b_i|^2 (Wahba's problem, by the SVD
    of the weighted attitude profile matrix, Markley 1988): what
    ``Rotation.align_vectors(a, b, weights)[0].as_matrix()`` gives for finite weights, real
    input only (the fit's starts: no scipy import, issue 27).  Degenerate vectors (fewer than
    two independent directions) give one of the rotations that align them."""
    a = np.atleast_2d(np.asarray(a, dtype=float))
    b = np.atleast_2d(np.asarray(b, dtype=float))
    w = np.ones(len(a)) if weights is None else np.asarray(weights, dtype=float)
    B = (a * w[:, None]).T @ b
    U, _, Vt = np.linalg.svd(B)
    d = np.sign(np.linalg.det(U @ Vt)) or 1.0
    return U @ np.diag([1.0, 1.0, d]) @ Vt


def rotvec_from_matrix(R) -> np.ndarray:
    """The rotation vector of a rotation matrix (angle in [0, pi], rad): what
    ``Rotation.from_matrix(R).as_rotvec()`` gives (through the quaternion by Shepperd's method,
    the largest of its four components first: no cancellation at any angle), real input only."""
    R = np.asarray(R, dtype=float)
    trace = R[0, 0] + R[1, 1] + R[2, 2]
    diag = np.array([R[0, 0], R[1, 1], R[2, 2], trace])
    k = int(np.argmax(diag))
    q = np.empty(4)                                     # (x, y, z, w)
    if k == 3:
        q[3] = 1.0 + trace
        q[0], q[1], q[2] = R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]
    else:
        i, j, m = k, (k + 1) % 3, (k + 2) % 3
        q[i] = 1.0 - trace + 2.0 * R[i, i]
        q[j] = R[j, i] + R[i, j]
        q[m] = R[m, i] + R[i, m]
        q[3] = R[m, j] - R[j, m]
    q /= np.linalg.norm(q)
    if q[3] < 0:
        q = -q
    s = float(np.linalg.norm(q[:3]))
    angle = 2.0 * np.arctan2(s, q[3])
    if s < 1e-3:        # small angle: angle / sin(angle / 2) by its series (no 0 / 0)
        scale = 2.0 + angle * angle / 12.0 + 7.0 * angle**4 / 2880.0
    else:
        scale = angle / s
    return scale * q[:3]
