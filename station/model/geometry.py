"""Small vector helpers for the measurement model (fast on 3-vectors and short stacks)."""
from __future__ import annotations

import numpy as np


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product over the last axis (np.cross is slow on the model's small arrays)."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def tangent_basis(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors completing the unit vector u to a right-handed frame (u, t1, t2)."""
    e = np.zeros(3)
    e[int(np.argmin(np.abs(u)))] = 1.0
    t1 = cross(u, e)
    t1 /= np.linalg.norm(t1)
    return t1, cross(u, t1)


# --- complex-step safe forms (the fit's Jacobian, station/estimate/lsq.py) ------------------
# No absolute value, conjugate or comparison on the values: v . v instead of |v|^2; a branch is
# chosen on the real part only.

def normalised(v: np.ndarray) -> np.ndarray:
    """v / |v| over the last axis, with |v| = sqrt(v . v) (analytic in v)."""
    return v / np.sqrt(np.einsum("...i,...i->...", v, v))[..., None]


def positive_part(z: np.ndarray) -> np.ndarray:
    """max(z, 0), the branch chosen on the real part (analytic where z's real part is not 0)."""
    return np.where(np.real(z) > 0, z, 0.0)


def analytic_abs(z: np.ndarray) -> np.ndarray:
    """|z| for real z; for complex z, z or -z by the sign of its real part (the analytic
    continuation of |x| away from 0, what complex step needs: np.abs would give the modulus)."""
    return np.where(np.real(z) < 0, -z, z)


#: gravity directions closer than this are one attitude (a hand pose repeated on the same face
#: lies within a degree; two poses chosen to differ are tens of degrees apart)
ATTITUDE_TOLERANCE_DEG = 5.0


def distinct_directions(vectors, tolerance_deg: float = ATTITUDE_TOLERANCE_DEG) -> np.ndarray:
    """Cluster label of each vector (rows, any length) by direction: a vector joins the first
    cluster whose first member is within ``tolerance_deg`` of it, else starts a new one.  The
    number of distinct directions is ``labels.max() + 1``.  Used on the static poses'
    accelerometer means: poses are not attitudes (a pose held twice on the same face gives the
    accelerometers the same equation twice)."""
    v = np.asarray(vectors, float).reshape(-1, 3)
    n = np.linalg.norm(v, axis=1)
    u = v / np.where(n > 0, n, 1.0)[:, None]
    cos_tol = np.cos(np.radians(tolerance_deg))
    labels = np.full(len(u), -1, int)
    heads = np.empty_like(u)            # the clusters' first members, in order: heads[:m]
    m = 0
    for i, d in enumerate(u):
        # every head at once (one pair at a time in Python was quadratic: 100,000 random
        # attitudes make ~1,600 clusters at 5 degrees, 10^8 Python steps)
        near = np.flatnonzero(heads[:m] @ d >= cos_tol)
        if len(near):
            labels[i] = near[0]
        else:
            labels[i] = m
            heads[m] = d
            m += 1
    return labels
