"""table_vibration: the table accelerates once per revolution (an imbalance of the platter, a
bearing, a belt), in a direction fixed to the table's frame."""
from __future__ import annotations

import numpy as np

from station.model import table_revolution as rev
from station.model.effect import Effect, Param

MG = 9.80665e-3              # m/s^2 per mg
RATE_ROUND_DPS = 1.0         # rotations whose rates differ by less share a vibration


class TableVibration(Effect):
    id = "table_vibration_once_per_rev"
    title = "Table vibration once per revolution: the platter and IMU accelerated at the rotation frequency"
    physics = ("A platter out of balance, a bearing or a belt shakes the table at the rotation frequency: the "
               "sensing point accelerates by a(theta) = cos(theta) P + sin(theta) Q, P and Q fixed in the "
               "table's (the Earth's) frame, along the axis and across it.  The part along the axis is seen by "
               "the IMU once per revolution; the part across it turns in the IMU's frame against the platter's "
               "turn, so it shows as a constant and a twice-per-revolution part across the axis.  Its size and "
               "phase follow the rotation rate (an imbalance's force grows with its square, the mount's "
               "response has its own phase), so each rate has its own.  A fault of the bench, not of the IMU: "
               "station apply compensates nothing for it.")
    term = ("rotations only (the fit's phase grid, p the signed angle turned about l): accel_raw += M_a Rot(l, -p) "
            "(cos p P + sin p Q), P = P_l l + P_v v_hat + P_u (l x v_hat) and Q alike, v_hat gravity's direction "
            "across the axis at the rotation's start; one (P, Q) per table axis and rate (rotations start at the "
            "same platter angle)")
    excited_by = ("rotations about an axis with gravity across it (the frame is fixed by gravity; not modelled about "
                  "an axis within 20° of the vertical); the part along the axis is seen once per revolution, the "
                  "part across it as a constant and twice per revolution")
    magnitudes = "< 0.01 mg (balanced precision tables), 0.1-1 mg (an unbalanced load), several mg (a worn bearing or belt)"
    signature = ("accelerometer, rotation segments: a first harmonic along the rotation's own axis (which gravity "
                 "cannot make about a horizontal axis), of one size and phase in every rotation at that rate; "
                 "across the axis a constant and a second harmonic; the statics fit")
    signature_variable = "signed_rate"
    complex_step = True
    bench = True
    named_by = ("once per revolution along the rotation's own axis",)   # station.diagnose.words: tried first
    state_fields = ("groups",)

    def __init__(self):
        self.groups = []              # [table axis, rate deg/s] with a vibration of their own
        self.frame = {}               # segment index -> (l, v_hat, u)
        self.group_of = {}            # segment index -> position in groups
        self.count = {}

    def setup(self, summaries) -> None:
        self.frame = rev.frames(summaries)
        steady = [r for r in summaries.rotations if int(r.index) in self.frame]
        key = {int(r.index): (rev.table_axis_of(r), float(np.round(abs(r.rate_dps) / RATE_ROUND_DPS) * RATE_ROUND_DPS))
               for r in steady}
        groups = sorted(set(key.values()))
        self.groups = [[int(k), float(rate)] for k, rate in groups]
        self.group_of = {i: groups.index(g) for i, g in key.items()}
        self.count = {g: sum(1 for v in self.group_of.values() if v == g) for g in range(len(groups))}

    def _tag(self, g) -> str:
        k, rate = self.groups[g]
        return (f"_axis{k}" if k else "") + f"_{rate:g}dps"

    @property
    def params(self):
        return tuple(Param(f"table_vibration{self._tag(g)}_{d}_{h}", "mg", 1.0 / MG, 0.1, 100.0)
                     for g in range(len(self.groups)) for h in ("cos", "sin") for d in ("axis", "gravity", "third"))

    def accel(self, x, ctx):
        if getattr(ctx, "turned_s", None) is None:      # station apply: the bench's fault, not the IMU's
            return None
        out = np.zeros((len(ctx), 3), dtype=np.result_type(x, ctx.f_p))
        for index, (l, v, u) in self.frame.items():
            rows, p = rev.phase_rows(ctx, index)
            if not len(rows):
                continue
            g = self.group_of[index]
            P = x[6 * g] * l + x[6 * g + 1] * v + x[6 * g + 2] * u
            Q = x[6 * g + 3] * l + x[6 * g + 4] * v + x[6 * g + 5] * u
            c, s = np.cos(p)[:, None], np.sin(p)[:, None]
            a = c * P[None, :] + s * Q[None, :]                          # table frame at the start
            along = (a @ l)[:, None] * l[None, :]
            # Rot(l, -p) a: the IMU has turned by p since the start
            a_body = along + c * (a - along) - s * np.cross(l[None, :], a)
            out[rows] = a_body @ ctx.accel_matrix.T
        return out

    def words(self, x, sigma) -> list[str]:
        """The vibration of each table axis and rate that stands out (> 3 sigma), in mg."""
        out = []
        for g in range(len(self.groups)):
            v, sg = np.asarray(x[6 * g:6 * g + 6], float), np.asarray(sigma[6 * g:6 * g + 6], float)
            if len(v) < 6:
                break
            axial = rev.amplitude(v[0], v[3], sg[0], sg[3])
            across = rev.amplitude(np.hypot(v[1], v[2]), np.hypot(v[4], v[5]),
                                   float(np.hypot(sg[1], sg[2]) / np.sqrt(2)), float(np.hypot(sg[4], sg[5]) / np.sqrt(2)))
            big = [f"{m:.3g} ± {s:.2g} mg {where}" for (m, s), where in ((axial, "along its axis"),
                                                                           (across, "across it")) if m > 3 * s]
            if not big:
                continue
            k, rate = self.groups[g]
            which = f"table axis {k}" if k else "the table"
            out.append(f"{which} vibrates once per revolution at {rate:g} °/s: {' and '.join(big)} (seen in "
                       f"{self.count.get(g, 0)} rotations); a fault of the bench (an imbalance of the platter or its "
                       "load, a bearing, a belt), not of the IMU, and not compensated: balance the platter or load it "
                       "symmetrically")
        return out
