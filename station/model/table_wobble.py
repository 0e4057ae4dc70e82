"""table_wobble: the platter's axis is tilted from the line it turns about, the tilt turning with
the platter (a bearing that wobbles once per revolution)."""
from __future__ import annotations

import numpy as np

from station.model import table_revolution as rev
from station.model.effect import Effect, Param
from station.model.geometry import cross

ARCSEC = np.pi / 180.0 / 3600.0


class TableWobble(Effect):
    id = "table_wobble"
    title = "Table wobble: the platter's axis tilted by a few arc-seconds, the tilt turning with the platter"
    physics = ("A platter whose bearing is not true turns about a line while its own axis, which the IMU is "
               "fixed to, leans from that line by a small angle b; the lean is fixed to the platter, so seen from "
               "the IMU its direction turns once per revolution the other way from gravity.  Gravity seen "
               "through the leaning platter gets a part along the axis twice per revolution (size b times gravity "
               "across the axis) and, about a tilted axis, a part across it once per revolution (b times gravity "
               "along it); the platter's rate leans with it, adding 2 b w across the axis once per revolution "
               "(zero over whole revolutions, seen in the angle of part of one).  A fault of the bench, not of "
               "the IMU: station apply compensates nothing for it.")
    term = ("rotations only (the fit's phase grid, p the signed angle turned about l): accel_raw += M_a (-eps(p) x f), "
            "eps(p) = Rot(l, p) w, w = b_v v_hat + b_u (l x v_hat) in radians, v_hat gravity's direction across "
            "the axis at the rotation's start; gyro integral += 2 (sin A (l x w) - (1 - cos A) w) over the angle "
            "A; one (b_v, b_u) per table axis (the rotations start at the same platter angle); the lean's "
            "centripetal and tangential change at the mounting offset (2 b w^2 d: 1 µg at 100 °/s, 10 mm) "
            "neglected")
    excited_by = ("rotations about an axis with gravity across it (the twice-per-revolution part along the axis, "
                  "b g: 30 arc-seconds give 143 µg) or, about a tilted axis, along it; not about a vertical axis "
                  "(no gravity across it to fix the lean's direction: not modelled there)")
    magnitudes = "< 1 arc-second (air bearings), 1-5 arc-seconds (precision rate tables), 10-100 arc-seconds (worn or light tables)"
    signature = ("accelerometer, rotation segments: a second harmonic along the rotation's own axis in every "
                 "rotation about that table axis, of one size (b g_across) and one phase against gravity's; "
                 "the statics fit")
    signature_variable = "signed_rate"
    complex_step = True
    bench = True
    named_by = ("a wobbling or tilted table platter",)     # station.diagnose.words: tried first when said
    state_fields = ("axes",)

    def __init__(self):
        self.axes = [0]               # the table axes with a wobble of their own (0: not recorded)
        self.frame = {}               # segment index -> (l, v_hat, u)
        self.group_of = {}            # segment index -> position of its table axis in axes
        self.count = {}               # position -> rotations it is seen in

    def setup(self, summaries) -> None:
        self.frame = rev.frames(summaries)
        steady = [r for r in summaries.rotations if int(r.index) in self.frame]
        self.axes = sorted({rev.table_axis_of(r) for r in steady})     # none: nothing to fix its frame
        self.group_of = {int(r.index): self.axes.index(rev.table_axis_of(r)) for r in steady}
        self.count = {g: sum(1 for v in self.group_of.values() if v == g) for g in range(len(self.axes))}

    @property
    def params(self):
        out = []
        for k in self.axes:
            tag = f"_axis{k}" if k else ""
            out += [Param(f"table_wobble{tag}_along_gravity", "arcsec", 1.0 / ARCSEC, 10.0, 3600.0),
                    Param(f"table_wobble{tag}_across_gravity", "arcsec", 1.0 / ARCSEC, 10.0, 3600.0)]
        return tuple(out)

    def _lean(self, x, index):
        l, v, u = self.frame[index]
        g = self.group_of[index]
        bv, bu = x[2 * g], x[2 * g + 1]
        return l, bv * v + bu * u, bv * u - bu * v           # l, w, l x w

    def accel(self, x, ctx):
        if getattr(ctx, "turned_s", None) is None:      # station apply: the bench's fault, not the IMU's
            return None
        out = np.zeros((len(ctx), 3), dtype=np.result_type(x, ctx.f_p))
        for index in self.frame:
            rows, p = rev.phase_rows(ctx, index)
            if not len(rows):
                continue
            _, w, lxw = self._lean(x, index)
            eps = np.cos(p)[:, None] * w[None, :] + np.sin(p)[:, None] * lxw[None, :]
            out[rows] = -cross(eps, ctx.f_p[rows]) @ ctx.accel_matrix.T
        return out

    def accel_batch(self, X, ctx):
        """accel() of every row of X (B, p) with a batch context (Effect.accel_batch)."""
        if getattr(ctx, "turned_s", None) is None:
            return None
        out = np.zeros(ctx.f_p.shape, dtype=np.result_type(X, ctx.f_p))
        for index in self.frame:
            rows, p = rev.phase_rows(ctx, index)
            if not len(rows):
                continue
            _, v, u = self.frame[index]
            g = self.group_of[index]
            bv, bu = X[:, 2 * g, None], X[:, 2 * g + 1, None]
            w, lxw = bv * v + bu * u, bv * u - bu * v                   # (B, 3), as _lean
            eps = np.cos(p)[None, :, None] * w[:, None, :] + np.sin(p)[None, :, None] * lxw[:, None, :]
            out[:, rows] = -cross(eps, ctx.f_p[:, rows]) @ ctx.accel_matrix.mT
        return out

    def integral(self, x, rotation):
        index = int(getattr(rotation, "index", -1))
        if index not in self.frame:
            return None
        _, w, lxw = self._lean(x, index)
        A = np.radians(rotation.angle_deg)
        # the output per degree (1 in deg; counts per degree for a raw gyro), from the rotation itself
        per_deg = np.linalg.norm(rotation.gyro_integral) / abs(rotation.angle_deg) if rotation.angle_deg else 1.0
        return per_deg * (180.0 / np.pi) * 2.0 * (np.sin(A) * lxw - (1.0 - np.cos(A)) * w)

    def words(self, x, sigma) -> list[str]:
        """The lean of each table axis that stands out (> 3 sigma), in arc-seconds."""
        out = []
        for g, k in enumerate(self.axes):
            if 2 * g + 1 >= len(x):
                break
            b, sb = rev.amplitude(x[2 * g], x[2 * g + 1], sigma[2 * g], sigma[2 * g + 1])
            if not b > 3 * sb:
                continue
            phase = np.degrees(np.arctan2(x[2 * g + 1], x[2 * g]))
            which = f"table axis {k}" if k else "the table"
            out.append(f"{which} wobbles: its platter's axis leans {b:.3g} ± {sb:.2g} arc-seconds from the line it "
                       f"turns about, the lean turning with the platter ({phase:+.0f}° from gravity across the axis "
                       f"at the rotations' start; seen in {self.count.get(g, 0)} rotations as a twice-per-revolution "
                       "accelerometer residual along the axis); a fault of the bench, not of the IMU, and not "
                       "compensated: check the axis' wobble against the table's specification (precision tables: "
                       "1-5 arc-seconds)")
        return out
