"""remount_per_segment: the IMU placed anew on the table for every rotation (each half of a +/- pair
included), each placement a small attitude of its own.

What each segment can reveal of its placement, and what the base model already carries:

* a static: its attitude is a nuisance of the base model (station/estimate/lsq.py: the tilt that
  gravity sees, and with a latitude the heading the Earth rate gives), so a static placed anew
  needs no parameter here;
* a rotation: the base model has one axis l per physical axis (shared by the rotations about it)
  and one start phase psi of gravity per rotation.  A placement of its own turns everything the
  IMU senses in that rotation by a small rotation delta: the rate w_p = (A/T + e) l into
  w_p + delta x w_p (the gyros see the axis moved in the body) and the specific force f_p (gravity
  along the axis, its harmonics across it, the centripetal terms) into f_p + delta x f_p.  The part
  of delta along l only moves gravity's phase about the axis, which psi already is: two
  parameters per rotation, delta across its commanded axis.

Gauge: the first rotation about each axis (in the capture's order) is the reference, delta = 0;
every other rotation about that axis has its own delta, relative to it.  The axis l (and the
mounting and misalignments behind it) therefore keeps its meaning, the reference placement's,
and no delta can trade with it.  A bench nuisance: ``station apply`` compensates nothing for it.
"""
from __future__ import annotations

import numpy as np

from station.core import units
from station.model.effect import Effect, Param
from station.model.geometry import cross, tangent_basis


def axis_groups(summaries, per: str = "segment") -> tuple[dict, list, dict]:
    """(placement of each rotation segment index, the placements with parameters, names).

    ``per`` "segment": every rotation is a placement; the first rotation about each axis group is
    its group's reference (no parameters).  Placements are (group, position in the group)."""
    rots = list(summaries.rotations)
    placement_of, free, names = {}, [], {}
    seen: dict[int, int] = {}
    for r in rots:
        g = int(r.group)
        n = seen.get(g, 0)
        seen[g] = n + 1
        key = (g, n)
        placement_of[int(r.index)] = key
        names[key] = r.name
        if n > 0:
            free.append(key)
    return placement_of, free, names


class RemountPerSegment(Effect):
    id = "remount_per_segment"
    title = "The IMU placed anew for every rotation: a small attitude of its own in each (remounted, moved on the table)"
    physics = ("An IMU taken off the table and put back (a fixture turned by hand, a cube set on its face, a "
               "clamp loosened) sits a little differently each time: by 0.01-0.5 degrees.  In a rotation the "
               "gyros then see the table's axis moved in the body, and the accelerometers see gravity along "
               "and across it moved with it; the base model has one axis per physical table axis, shared by "
               "every rotation about it.  A static's attitude is already a nuisance of the base model.  A "
               "bench nuisance, not a property of the IMU: station apply compensates nothing for it.")
    term = ("rotation segment s about axis group k, not the first about k: accel_raw += M_a (R(delta_s) - I) f_p, "
            "gyro_raw += M_g (R(delta_s) - I) w_p, R(delta) the rotation by the vector delta (to 4th order in "
            "|delta|) and the mounting offset's centripetal part w' x (w' x d) + dw'/dt x d made with the turned rate w' = R w (d fixed "
            "in the IMU's frame), delta_s = a_s t1 + b_s t2 (rad; t1, t2 across the segment's "
            "commanded axis); the first rotation about each axis has delta = 0 (the gauge: the axis l is "
            "its placement's)")
    excited_by = ("two or more rotations about one axis (a +/- pair) with the IMU put back between them: the "
                  "gyros see the axis' direction to (gyro noise / rate) / sqrt(samples) rad, 1-5 arc-seconds "
                  "at 100 °/s over 10 revolutions")
    magnitudes = ("0 (one mounting for the whole run), 30-300 arc-seconds (a fixture put back against its stops), "
                  "0.1-1 degree (a cube placed by hand)")
    signature = ("gyro integrals across the axis, and accelerometer means and harmonics, of a different size and "
                 "direction for each rotation about one axis, the + and - halves of a pair disagreeing about "
                 "where the axis is; the statics fit")
    signature_variable = "signed_rate"
    complex_step = True
    bench = True
    state_fields = ("placement_of", "free", "names", "basis")

    def __init__(self):
        self.placement_of = {}        # rotation segment index -> placement key (group, n)
        self.free = []                # placements with parameters (all but each group's first)
        self.names = {}               # placement -> its rotation's name
        self.basis = {}               # placement -> (t1, t2), across its commanded axis
        self._prepared = None         # (segment_index bytes, D): the points' placement matrix

    def setup(self, summaries) -> None:
        self.placement_of, self.free, self.names = axis_groups(summaries)
        by_index = {int(r.index): r for r in summaries.rotations}
        self.basis = {}
        for index, key in self.placement_of.items():
            t1, t2 = tangent_basis(np.asarray(by_index[index].axis_body, float))
            self.basis[key] = (t1, t2)
        self._prepared = None

    def state(self) -> dict:
        """Plain lists (the calibration file): placements as [group, n]."""
        return {"placement_of": [[int(i), list(k)] for i, k in self.placement_of.items()],
                "free": [list(k) for k in self.free],
                "names": [[list(k), v] for k, v in self.names.items()],
                "basis": [[list(k), np.asarray(v, float).tolist()] for k, v in self.basis.items()]}

    def restore(self, state: dict) -> None:
        """Undo state()."""
        if "placement_of" in state:
            self.placement_of = {int(i): tuple(k) for i, k in state["placement_of"]}
        if "free" in state:
            self.free = [tuple(k) for k in state["free"]]
        if "names" in state:
            self.names = {tuple(k): v for k, v in state["names"]}
        if "basis" in state:
            self.basis = {tuple(k): tuple(np.asarray(v, float)) for k, v in state["basis"]}
        self._prepared = None

    def notes(self) -> tuple[str, ...]:
        refs = sorted({k[0] for k in self.placement_of.values()})
        first = [self.names.get((g, 0), "") for g in refs]
        return (f"remount_per_segment: each rotation's placement is relative to the first rotation about the same "
                f"axis ({', '.join(n for n in first if n)}), whose placement the axis and the mounting keep "
                "(the gauge); the statics' attitudes are the base model's own nuisances",)

    @property
    def params(self):
        return tuple(Param(f"{self.names.get(k, f'rotation{k[0]}_{k[1]}')}_tilt_{c}", "arcsec",
                           1.0 / units.ARCSEC_RAD, 100.0, 7200.0)
                     for k in self.free for c in ("t1", "t2"))

    def _rows(self, ctx):
        """(N, 3 * free) matrix D with delta at each point = D_k x, cached per point layout."""
        index = ctx.column("segment_index")
        key = np.asarray(index, float).tobytes()
        if getattr(self, "_prepared", None) is not None and self._prepared[0] == key:
            return self._prepared[1]
        col = {k: n for n, k in enumerate(self.free)}
        D = np.zeros((len(index), 3, 2 * len(self.free)))
        for i, idx in enumerate(index):
            if not np.isfinite(idx):
                continue
            k = self.placement_of.get(int(idx))
            if k is None or k not in col:
                continue
            t1, t2 = self.basis[k]
            D[i, :, 2 * col[k]] = t1
            D[i, :, 2 * col[k] + 1] = t2
        self._prepared = (key, D)
        return D

    def _delta(self, x, ctx):
        if not self.free or getattr(ctx, "turned_s", None) is None:     # station apply: the bench's
            return None
        D = self._rows(ctx)
        return np.einsum("ncj,j->nc", D, x)

    @staticmethod
    def _turned(delta, v):
        """R(delta) v - v, R the rotation by the vector delta, to fourth order in |delta|: the
        second-order part matters (a placement of 0.3° moves the length of w + delta x w by 14 ppm,
        beyond what a rotation's gyro integral resolves); in dot products only (complex-step safe)."""
        th2 = np.einsum("nc,nc->n", delta, delta)[:, None]
        dv = cross(delta, v)
        return (1.0 - th2 / 6.0) * dv + (0.5 - th2 / 24.0) * cross(delta, dv)

    def accel(self, x, ctx):
        """Gravity and the rest of f_p turned by the placement; the centripetal and tangential
        acceleration of the mounting offset d (fixed in the IMU's frame: the model's offset) made
        with the rate as the turned IMU senses it (w' = R w): w' x (w' x d) + dw'/dt x d."""
        delta = self._delta(x, ctx)
        if delta is None:
            return None
        term = self._turned(delta, ctx.f_p)
        d = getattr(ctx, "offset_m", None)
        if d is not None:
            w, wdot = ctx.w_table, ctx.wdot_table
            w2, wdot2 = w + self._turned(delta, w), wdot + self._turned(delta, wdot)
            c = cross(w, cross(w, d)) + cross(wdot, d)
            c2 = cross(w2, cross(w2, d)) + cross(wdot2, d)
            term = term - self._turned(delta, c) + (c2 - c)
        return term @ ctx.accel_matrix.T

    def gyro(self, x, ctx):
        delta = self._delta(x, ctx)
        return None if delta is None else self._turned(delta, ctx.w_p) @ ctx.gyro_matrix.T

    def words(self, x, sigma) -> list[str]:
        """The rotations whose placement moved by more than 3 sigma, largest first (arc-seconds)."""
        x, sigma = np.asarray(x, float), np.asarray(sigma, float)
        moved = []
        for n, k in enumerate(self.free):
            a, b = x[2 * n:2 * n + 2]
            sa, sb = sigma[2 * n:2 * n + 2]
            size = float(np.hypot(a, b))
            s = float(np.hypot(a * sa, b * sb) / size) if size > 0 else float(np.hypot(sa, sb))
            if size > 3.0 * s:
                moved.append((size, s, k))
        if not moved:
            return []
        moved.sort(key=lambda m: -m[0])
        parts = [f"{self.names.get(k, '?')} {size:.0f} ± {s:.1g} arcsec from {self.names.get((k[0], 0), '?')}"
                 for size, s, k in moved]
        return [f"the IMU was placed anew for {len(moved)} rotation{'s' if len(moved) > 1 else ''} (the axis it "
                f"turned about sits elsewhere in the body): {'; '.join(parts)}; it was moved or remounted between "
                "those rotations"]
