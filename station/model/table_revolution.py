"""What the table's own once-per-revolution faults (table_wobble, table_vibration) share: each
rotation's frame at its start and the phase of the fit's points.

A fault fixed to the table (a platter axis that wobbles, a base that vibrates at the rotation
frequency) is fixed in the table's frame, not the IMU's.  The capture knows the table's frame at
a rotation's start through gravity: the rotation's measured first harmonic is gravity's part
across the axis, v (at the start), turning as Rot(l, -p) v with the signed angle p turned about
the axis l.  So every rotation gets the right-handed frame (l, v_hat, u = l x v_hat) from its own
data (constants: the fit's parameters do not move it; a scale or misalignment error of a percent
turns it by far less than the faults' phase is known to).  A rotation about an axis within
VERTICAL_DEG of the vertical has no gravity across it to fix the frame: the wobble is not
modelled there, and the vibration is modelled on a frame fixed to the case per group of rotations
that start at the same platter angle with the same mounting (vertical_frames; table_vibration's
docstring).  The phase and the frame are the same for every rotation about one table axis
when each rotation starts at the same angle of the platter relative to the world, as a table
does that moves to its start before it turns (the simulator's faults, sim_devices/world.py,
assume that too, written independently).
"""
from __future__ import annotations

import numpy as np

VERTICAL_DEG = 20.0       # an axis nearer the vertical than this: gravity across it below sin 20° = 0.34 g


def _vertical(r):
    """Whether steady rotation ``r`` is about an axis within VERTICAL_DEG of the vertical (its
    first harmonic, gravity's part across the axis, below sin VERTICAL_DEG of gravity); None for a
    rotation neither frame takes (not steady, no harmonics, no gravity)."""
    if not (r.steady or getattr(r, "record_ramp", None)) or r.accel_cos is None:
        return None
    c, s, dc = (np.asarray(v, float) for v in (r.accel_cos, r.accel_sin, r.accel_dc))
    across = np.sqrt(0.5 * (c @ c + s @ s))
    total = np.hypot(across, np.linalg.norm(dc))
    if not total > 0:
        return None
    return bool(not across >= np.sin(np.radians(VERTICAL_DEG)) * total)


def frames(summaries) -> dict:
    """{segment index: (l, v_hat, u)} of every steady rotation whose axis is far enough from the
    vertical (unit 3-vectors in the IMU's frame, from the rotation's measured harmonics)."""
    out = {}
    for r in summaries.rotations:
        if _vertical(r) is not False:
            continue
        c, s = np.asarray(r.accel_cos, float), np.asarray(r.accel_sin, float)
        v = c / np.linalg.norm(c)
        u = -s - (-s @ v) * v                      # Rot(l, -p) v = cos p v - sin p (l x v)
        u = u / np.linalg.norm(u)
        out[int(r.index)] = (np.cross(v, u), v, u)
    return out


def vertical_frames(summaries) -> dict:
    """{segment index: (l, e1, e2)} of every steady rotation about an axis within VERTICAL_DEG of
    the vertical (the ones :func:`frames` leaves out): l the recorded ``axis_body`` (the direction
    the signed angle turns about, as in :func:`frames`), e1 the case axis most nearly across it made
    perpendicular to it, e2 = l x e1.  A frame fixed to the IMU's case, not to the table: nothing in
    the data fixes the table's frame about a vertical axis (table_vibration's docstring)."""
    out = {}
    for r in summaries.rotations:
        if _vertical(r) is not True:
            continue
        l = np.asarray(r.axis_body, float)
        l = l / np.linalg.norm(l)
        k = int(np.argmin(np.abs(l)))
        e1 = np.eye(3)[k] - l[k] * l
        e1 = e1 / np.linalg.norm(e1)
        out[int(r.index)] = (l, e1, np.cross(l, e1))
    return out


def table_axis_of(r) -> int:
    """The table axis a rotation was turned by (0: not recorded, one axis)."""
    k = getattr(r, "table_axis", None)
    return 0 if k is None else int(k)


def phase_rows(ctx, index: int):
    """(rows, phase p in rad) of one rotation's points in a SampleContext: the fit passes each
    rotation as one block of points on a uniform grid of the signed angle turned, p = 2 pi j / n."""
    rows = np.flatnonzero(ctx.column("segment_index") == index)
    return rows, 2.0 * np.pi * np.arange(len(rows)) / max(len(rows), 1)


def amplitude(a, b, sa, sb) -> tuple[float, float]:
    """|(a, b)| and its 1-sigma (first order, the two taken independent; at zero the larger)."""
    m = float(np.hypot(a, b))
    if m == 0:
        return 0.0, float(max(sa, sb))
    return m, float(np.hypot(a * sa, b * sb) / m)
