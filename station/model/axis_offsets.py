"""rotation_axis_offsets: the IMU sits at a different distance from each rotation axis (remounted
between the axes, or a table whose axes do not meet)."""
from __future__ import annotations

import numpy as np

from station.model.effect import Effect, Param
from station.model.geometry import cross


class RotationAxisOffsets(Effect):
    id = "rotation_axis_offsets"
    title = "A mounting offset of its own for each rotation axis (IMU remounted between axes; axes that do not meet)"
    physics = ("Turning about an axis that does not pass through the IMU adds a centripetal acceleration w x (w x d) "
               "and a tangential one dw/dt x d, d the offset from the axis.  The model has one offset for every "
               "rotation; when the IMU was taken off and put back for each axis (a fixture turned by hand, "
               "a cube remounted on its faces) or the table's axes do not meet, each axis has its own.  A bench "
               "nuisance, not a property of the IMU: station apply compensates nothing for it.")
    term = ("rotation segments about axis group k >= 1: accel_raw += M_a (w x (w x d_k) + dw/dt x d_k), d_k (m, "
            "frame p) the offset about that axis less the common one (the model's mounting offset, which group "
            "0 takes); d_k's part along its axis is not seen (its prior holds it)")
    excited_by = ("rotations about two or more axes at rates whose centripetal acceleration w^2 d exceeds the "
                  "accelerometer noise of a rotation's mean (at 100 °/s = 1.75 rad/s, 1 mm gives 3.0 mm/s² = 310 µg)")
    magnitudes = "0 (one mounting, axes that meet to < 1 mm), 1-50 mm (remounted by hand, axes that do not meet)"
    signature = ("accelerometer, rotation segments: a constant offset (the mean) that grows with the square of the "
                 "rate, of a different direction and size for each rotation axis, the same for both directions "
                 "about one axis; the statics fit")
    signature_variable = "rate_squared"
    complex_step = True
    bench = True              # ranked after the IMU's effects (station.diagnose.core.rank_candidates): its
                              #   offsets per axis hold the accelerometers' size effect (accel_lever_arm) too
    state_fields = ("group_of", "groups", "group_names")

    def __init__(self):
        self.group_of = {}           # segment index -> axis group of its rotation
        self.groups = [1, 2]         # the groups with an offset of their own (all but the first)
        self.group_names = {}        # group -> its rotations' names

    def setup(self, summaries) -> None:
        steady = [r for r in summaries.rotations if r.steady]
        line = offset_groups(steady)
        self.group_of = {int(r.index): line[int(r.group)] for r in steady}
        order = sorted(set(self.group_of.values()))
        self.groups = [int(g) for g in order[1:]]
        self.group_names = {int(g): [r.name for r in steady if line[int(r.group)] == g] for g in order}

    def words(self, x, sigma) -> list[str]:
        """Each axis' offset that differs from the first's by more than 3 sigma, in words (mm)."""
        first = ", ".join(self.group_names.get(min(self.group_names, default=0), []))
        out = []
        for n, g in enumerate(self.groups):
            v, s = np.asarray(x[3 * n:3 * n + 3], float), np.asarray(sigma[3 * n:3 * n + 3], float)
            big = [f"{v[i]:+.3g} ± {s[i]:.2g} mm along {a}" for i, a in enumerate("xyz") if abs(v[i]) > 3 * s[i]]
            if big:
                out.append(f"the IMU sits {', '.join(big)} further from the axis of "
                           f"{', '.join(self.group_names.get(g, []))} than from that of {first}: it was moved or "
                           "remounted between those rotations, or the table's axes do not meet")
        return out

    @property
    def params(self):
        return tuple(Param(f"axis{g}_offset_{a}", "mm", 1e3, 5.0, 1000.0) for g in self.groups for a in "xyz")

    def accel(self, x, ctx):
        if getattr(ctx, "turned_s", None) is None:      # station apply: the bench's, not the IMU's
            return None
        # each point's group, looked up once per segment (point by point it was 9 ms a call at
        # ~2,000 points: a third of the effect's residuals; nineteenth session)
        values, where = np.unique(ctx.column("segment_index"), return_inverse=True)
        group = np.array([self.group_of.get(int(i), -1) if np.isfinite(i) else -1 for i in values], dtype=int)
        group = group[where.reshape(-1)]
        # x (p,), or a batch X (B, p) with a batch context (accel_batch): the points' axis second to last
        d = np.zeros((*np.shape(x)[:-1], len(group), 3), dtype=np.result_type(x, ctx.f_p))
        for n, g in enumerate(self.groups):
            d = d + (group == g).astype(float)[:, None] * x[..., None, 3 * n:3 * n + 3]
        return (ctx.centripetal(d) + cross(ctx.wdot_table, d)) @ ctx.accel_matrix.mT

    accel_batch = accel


def offset_groups(rotations) -> dict:
    """{axis group: the axis group whose offset it has}: the first group (the lowest number) about
    the same body axis turned by the same table axis (``table_axis``, None where the bench does not
    say).  Within one run that is the group itself (summaries give one group per body axis and
    recorded elevation; a level and a vertical turn about one body axis on one table axis share
    the offset); a
    rotation of an extension recorded later (``appended: N``, run --append) is a group of its own
    for its direction on the table (the table may start that axis at another angle: its gravity
    angle and heading are the group's), but its offset is the capture's group's about the same
    axis.  The offset d_k is the IMU's distance from the line the table axis turns it about, fixed
    in the IMU's case axes while the table turns (the line is the rotation's axis, the IMU rides
    on it): a property of the table's axis and of the IMU's mounting on it, not of a run or of the
    table's angle when the run starts -- and --append continues the run with the same IMU, still
    mounted (the model shares the mounting offset and the mounting rotation across the two
    sessions for the same reason).  The simulator's table is built so (sim_devices/truth.py,
    ``axis_offsets_m``: one line per case axis, for every rotation about it).  Sharing it is what
    lets turns appended at a second rate tell the offsets (w^2 d) from a vibration once per
    revolution (one per rate): docs/design.md, fifteenth session."""
    first: list = []                    # (axis, table axis, its group)
    out: dict = {}
    for r in sorted(rotations, key=lambda r: (int(r.group), int(r.index))):
        g = int(r.group)
        if g in out:
            continue
        a = np.asarray(r.axis_body, float)
        a = a / np.linalg.norm(a)
        k = getattr(r, "table_axis", None)
        out[g] = next((h for b, kk, h in first if kk == k and np.allclose(a, b, atol=1e-6)), g)
        if out[g] == g:
            first.append((a, k, g))
    return out

