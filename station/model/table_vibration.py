"""table_vibration: the table accelerates once per revolution (an imbalance of the platter, a
bearing, a belt), in a direction fixed to the table's frame.

The derivation (issue 28, the vibration about a vertical axis).  At a steady rate the simulator's
base accelerates (sim_devices/world.py ``table_vibration_enu``, read and not imported: the model
stays independent; since the twenty-first session ~ rate^2 and zero at rest, see (3) below) as

    a(theta) = cos(theta + phi) D,   D = A_axis a_n + A_ref r + A_perp (a_n x r)

theta the table's signed angle about its own axis a_n since the rotation's start, r the part of up
across a_n (north about a vertical axis).  The IMU's case at the start has attitude C0 (table ->
case) and at theta C0 Rot(a_n, -theta).  In case coordinates at the start, l = C0 a_n (the
direction the recorded signed angle p = theta turns about: a rotation turns about its axis_body in
the table's positive sense), P = cos phi C0 D and Q = -sin phi C0 D, the IMU senses

    f_vib(p) = Rot(l, -p) (cos p P + sin p Q)                                            (1)

Along l: (cos p P_l + sin p Q_l) l, a first harmonic along the axis; it needs no frame across the
axis.  Across it, Rot(l, -p) X = cos p X - sin p (l x X) gives, with P, Q the parts across l,

    f_across(p) = 1/2 (P - l x Q) + 1/2 cos 2p (P + l x Q) + 1/2 sin 2p (Q - l x P)         (2)

a constant (the vibration's part turning with the platter) and a second harmonic (the part turning
against it): four numbers for four parameters, each in a frame across the axis.

* About an axis with gravity across it (table_revolution.frames) that frame is gravity's at the
  start, (v_hat, u = l x v_hat), which is the table's (r = up's part across a_n is where gravity
  points across the axis): the same numbers for every rotation about that table axis at that rate,
  whatever body axis, mounting or half of a pair.  One (P, Q) per table axis and rate:
  ``table_vibration[_axisK]_{rate}dps_{axis|gravity|third}_{cos|sin}`` (as before).
* About an axis within table_revolution.VERTICAL_DEG of the vertical gravity is all along l and
  nothing in the data fixes where r is in the case.  The along part needs no frame: P_l, Q_l are one
  pair per table axis and rate over its vertical rotations,
  ``table_vibration_vertical[_axisK]_{rate}dps_axis_{cos|sin}``.  The across part needs C0's turn
  about l, i.e. the platter's angle at the start and the IMU's mounting on it: it holds only for
  rotations that start from the same platter angle with the IMU mounted the same way.  A capture
  says that of the rotations about one body axis recorded in one session (the summaries' axis
  group: both halves of a pair and repeats; an appended extension is a session of its own, the
  table may start that axis elsewhere) with one mounting (table.geometry's, where recorded).  One
  (P, Q) across per table axis, rate, axis group and mounting, on a case-fixed basis (e1 the case
  axis most nearly across l made perpendicular to it, e2 = l x e1: table_revolution.vertical_frames),
  ``table_vibration_vertical[_axisK]_{rate}dps_{rotation}_across{1|2}_{cos|sin}``, named by the
  group's first rotation.
* The two halves of a +/- pair: the - half turns by a negative p about the same l (the capture's
  harmonics are taken in the signed angle, station/estimate/summaries.py, and the fit's phase grid
  is that angle), and the world's theta is that same signed angle, so (1) is one function of p for
  both halves and nothing flips: they share every parameter.  (Parametrised instead by the angle
  turned, q = -p about -l, in the frame (-l, v_hat, -u), the - half's P_l, P_u and Q_v would flip
  sign and Q_l, P_v, Q_u would not; the signed angle avoids that.)  Checked on twins: the
  horizontal case with optimal9's pairs fits to the noise floor (tests/test_effects_table_revolution.py),
  the vertical one too (tests/test_vibration_vertical.py).
* What stays aliased (docs/design.md, sixteenth session): the constant of (2) is a constant in the
  case frame at that rate, as the centripetal acceleration -w^2 d_across of an offset d from the
  axis is; free per axis group and rate about a vertical axis, it leaves a vertical turn's constant
  across the axis to the vibration or the offsets alike.  What tells them apart there is the rest
  of (1) and (2): the first harmonic along the axis and the second across it, which an offset never
  makes.
* Over a recorded ramp (issue 28, twenty-first session).  A once-per-revolution vibration is driven
  by the platter's angle: an imbalance U = m rho pushes the base by U (w^2 e - dw/dt a_n x e), e its
  direction turning with the platter, and a base that moves as a mass M accelerates by that over M;
  a bearing's or pulley's eccentricity moves it by a displacement fixed to the platter.  Either way
  the base's displacement is a function of the table's angle, x(theta) = cos theta U + sin theta V
  (U, V fixed in the table's frame), and its acceleration is its second time derivative,

      a = w^2 x''(theta) + (dw/dt) x'(theta)
        = -w^2 (cos theta U + sin theta V) + (dw/dt) (-sin theta U + cos theta V)       (3)

  zero at rest, ~ w^2 at a steady rate (the per-rate (P, Q) above are P = -w_s^2 U, Q = -w_s^2 V at
  the steady rate w_s: a mount stiff against the rotation frequency would make them ~ w^4, which the
  per-rate parameters take as well), and with a part from the angular acceleration over a ramp.  In
  (P, Q) of the ramp's steady rate w_s (the table's rate at the window's steady edge, which also
  keys its group: _steady_rate_dps)

      a(p) = (w^2 / w_s^2) (cos p P + sin p Q) + ((dw/dt) / w_s^2) (sin p P - cos p Q)      (4)

  at each of the ramp's phase points, w^2 the square of the rate as the fit's rows take it
  (SampleContext.wsq_table) and dw/dt the table's angular acceleration about l (wdot_table . l),
  both signed with the angle p; then turned into the case as (1).  A steady turn's rows keep
  w^2 / w_s^2 = 1 and no dw/dt (its rate ripple's part is ripple-sized: 0.1 % ripple, 0.2 % of the
  vibration).  The twins (sim_devices/world.py table_vibration_enu, imbalance_acceleration_enu)
  write (3) independently; tests/test_vibration_ramp.py checks (4) against them point by point.
  A recorded ramp is framed (table_revolution.frames) whatever its rate's spread.
* What the fit compares over a ramp (review revvibphys, twenty-first session).  The fit does not
  see points: it sees a window's five harmonics over its angle (1, cos p, sin p, cos 2p, sin 2p:
  the least-squares projections of the samples, station/estimate/summaries.py), and projects its
  phase grid's values the same way.  A grid value made of w^2's own harmonics times cos p is not
  right there: over a ramp w^2 takes several values at one angle (the rest and the ramp's first
  turn, then the steady turns), and the harmonics of w^2(t) cos p(t) are not the product of w^2's
  harmonics with cos p (measured: 4.8-7.3 % of the vibration at 20 and 50 deg/s^2).  Written out,
  (1) with (4)'s a(p), W = w^2 / w_s^2, D = (dw/dt) / w_s^2, P_l = P . l, P_a = P - P_l l (Q alike):

      f_vib = [P_l (W cos p + D sin p) + Q_l (W sin p - D cos p)] l
              + P_a (W cos^2 p + D cos p sin p) + Q_a (W cos p sin p - D cos^2 p)
              - (l x P) (W cos p sin p + D sin^2 p) - (l x Q) (W sin^2 p - D cos p sin p)      (5)

  with cos^2 p = (1 + cos 2p) / 2, sin^2 p = (1 - cos 2p) / 2, cos p sin p = sin 2p / 2: a sum of
  vectors fixed over the window times w^2 and dw/dt times 1, cos p, sin p, cos 2p, sin 2p, ten
  functions of time.  The projection is linear, so the window's harmonics of f_vib are (5) with
  each function replaced by its own harmonics: the summaries project those ten products of the
  samples with the accelerometer's basis (RotationSummary.ramp_coef, recorded ramps only: w^2 and
  dw/dt times 1 are rate_sq_coef and rate_dot_coef), the fit puts each on its grid
  (SampleContext.ramp_products, whose projection gives the harmonics back) and the ramp's rows
  take (5) from them: the window's harmonics exactly (the review's test, to 1e-5 of the
  vibration: the gyro-tracked phase).  Without the products (station apply, a context that has
  none) the rows keep (4) on the rate's shapes.
* The wobble (table_wobble) needs no such parameters: about a vertical axis its lean tilts gravity
  by b across the axis once per revolution, which is what a tilt of the axis does (the fit's own
  gravity angle and phase per axis group take it), and its rate across the axis averages out over
  whole revolutions.
"""
from __future__ import annotations

import re

import numpy as np

from station.model import table_revolution as rev
from station.model.effect import Effect, Param

MG = 9.80665e-3              # m/s^2 per mg
RATE_ROUND_DPS = 1.0         # rotations whose rates differ by less share a vibration


def _steady_rate_dps(r) -> float:
    """A rotation's steady rate (deg/s, magnitude): for a recorded ramp the table's rate at the
    window's steady edge (the reported rate_end_dps of a ramp up, rate_start_dps of a brake), not
    the window's mean rate (angle / duration: ~75 deg/s for a 100 deg/s turn with its ramp and rest
    recorded, a rate the table never held; review of issue 28, twentieth session); else angle /
    duration."""
    rate = abs(r.rate_dps)
    ramp = getattr(r, "record_ramp", None)
    edge = {"start": getattr(r, "table_rate_end_dps", None), "end": getattr(r, "table_rate_start_dps", None)}.get(ramp)
    if edge is not None and np.isfinite(edge) and edge != 0:
        rate = abs(float(edge))
    return float(rate)


def _rate_key(r) -> float:
    """The rate a rotation's vibration is keyed by: its steady rate rounded to RATE_ROUND_DPS."""
    return float(np.round(_steady_rate_dps(r) / RATE_ROUND_DPS) * RATE_ROUND_DPS)


class TableVibration(Effect):
    id = "table_vibration_once_per_rev"
    title = "Table vibration once per revolution: the platter and IMU accelerated at the rotation frequency"
    physics = ("A platter out of balance, a bearing or a belt shakes the table at the rotation frequency: the "
               "sensing point accelerates by a(theta) = cos(theta) P + sin(theta) Q, P and Q fixed in the "
               "table's (the Earth's) frame, along the axis and across it.  The part along the axis is seen by "
               "the IMU once per revolution; the part across it turns in the IMU's frame against the platter's "
               "turn, so it shows as a constant and a twice-per-revolution part across the axis.  Its size and "
               "phase follow the rotation rate (an imbalance's force grows with its square, the mount's "
               "response has its own phase), so each rate has its own; through a recorded ramp it follows the "
               "rate's square and the angular acceleration from the steady rate's.  A fault of the bench, not of the IMU: "
               "station apply compensates nothing for it.")
    term = ("rotations only (the fit's phase grid, p the signed angle turned about l): accel_raw += M_a Rot(l, -p) "
            "(cos p P + sin p Q), P = P_l l + P_v v_hat + P_u (l x v_hat) and Q alike, v_hat gravity's direction "
            "across the axis at the rotation's start; one (P, Q) per table axis and rate (rotations start at the "
            "same platter angle); over a recorded ramp (w/w_s)^2 (cos p P + sin p Q) + (dw/dt / w_s^2) "
            "(sin p P - cos p Q) from its steady rate w_s's (P, Q) (zero at rest); about an axis within 20° of the vertical P_l, Q_l per table axis and rate and "
            "the parts across on a case-fixed basis (e1, e2 = l x e1) per axis group and mounting")
    excited_by = ("rotations about an axis with gravity across it (the frame is fixed by gravity: one vibration per "
                  "table axis and rate); about an axis within 20° of the vertical the part along the axis per table "
                  "axis and rate and the part across it per body axis, session and mounting (no gravity fixes the "
                  "table's frame there); the part along the axis is seen once per revolution, the part across it "
                  "as a constant and twice per revolution")
    magnitudes = "< 0.01 mg (balanced precision tables), 0.1-1 mg (an unbalanced load), several mg (a worn bearing or belt)"
    signature = ("accelerometer, rotation segments: a first harmonic along the rotation's own axis (which gravity "
                 "makes about a level axis only when the axis is tilted: with turns about the IMU's own axes alone "
                 "the gyros' misalignments take it -- a diagonal or a vertical turn tells them apart), of one size "
                 "and phase in every rotation at that rate; across the axis a constant and a second harmonic; the "
                 "statics fit")
    signature_variable = "signed_rate"
    complex_step = True
    bench = True
    named_by = ("once per revolution along the rotation's own axis",)   # station.diagnose.words: tried first
    state_fields = ("groups", "vertical_axial", "vertical_across")

    def __init__(self):
        self.groups = []              # [table axis, rate deg/s] with a vibration of their own
        self.frame = {}               # segment index -> (l, v_hat, u)
        self.group_of = {}            # segment index -> position in groups
        self.count = {}
        # about a vertical axis (the module's derivation): the part along the axis per [table axis,
        # rate], the part across it per [table axis, rate, first rotation's name] (an axis group and
        # mounting), on the case-fixed basis (l, e1, e2)
        self.vertical_axial = []
        self.vertical_across = []
        self.vframe = {}              # segment index -> (l, e1, e2)
        self.vaxial_of = {}           # segment index -> position in vertical_axial
        self.vacross_of = {}          # segment index -> position in vertical_across
        self.vcount = {}              # position in vertical_across -> rotations
        self.ramp_rate = {}           # segment index of a recorded ramp -> its steady rate, rad/s

    def setup(self, summaries) -> None:
        self.frame = rev.frames(summaries)
        steady = [r for r in summaries.rotations if int(r.index) in self.frame]
        key = {int(r.index): (rev.table_axis_of(r), _rate_key(r)) for r in steady}
        groups = sorted(set(key.values()))
        self.groups = [[int(k), float(rate)] for k, rate in groups]
        self.group_of = {i: groups.index(g) for i, g in key.items()}
        self.count = {g: sum(1 for v in self.group_of.values() if v == g) for g in range(len(groups))}
        self._setup_vertical(summaries)
        # a recorded ramp's steady rate, rad/s (the derivation's w_s: its rows are scaled from it)
        self.ramp_rate = {int(r.index): float(np.radians(_steady_rate_dps(r))) for r in summaries.rotations
                          if getattr(r, "record_ramp", None) and (int(r.index) in self.frame or int(r.index) in self.vframe)}

    def _setup_vertical(self, summaries) -> None:
        self.vframe = rev.vertical_frames(summaries)
        vertical = [r for r in summaries.rotations if int(r.index) in self.vframe]
        geometry = getattr(summaries, "geometry", None)
        mounting = getattr(geometry, "mounting", None) or {}
        axial, across, names = {}, {}, {}
        for r in vertical:
            k, rate = rev.table_axis_of(r), _rate_key(r)
            axial.setdefault((k, rate), []).append(int(r.index))
            m = mounting.get(r.name)
            key = (k, rate, int(r.group), None if m is None else repr(m))
            across.setdefault(key, []).append(int(r.index))
            names.setdefault(key, re.sub(r"\W", "_", str(r.name)))
        self.vertical_axial = [[int(k), float(rate)] for k, rate in axial]
        self.vaxial_of = {i: n for n, members in enumerate(axial.values()) for i in members}
        self.vertical_across = [[int(key[0]), float(key[1]), names[key]] for key in across]
        self.vacross_of = {i: n for n, members in enumerate(across.values()) for i in members}
        self.vcount = {n: len(members) for n, members in enumerate(across.values())}

    def state(self) -> dict:
        """As Effect.state, without the vertical lists when there are none (the calibration file of
        a capture without vertical turns is as before)."""
        out = super().state()
        out.pop("vertical_axial", None)
        out.pop("vertical_across", None)
        if self.vertical_axial:         # plain numbers and names (numpy would make the rows strings)
            out["vertical_axial"] = [[int(k), float(rate)] for k, rate in self.vertical_axial]
            out["vertical_across"] = [[int(k), float(rate), str(name)] for k, rate, name in self.vertical_across]
        return out

    def _tag(self, g) -> str:
        k, rate = self.groups[g]
        return (f"_axis{k}" if k else "") + f"_{rate:g}dps"

    @staticmethod
    def _vtag(k, rate) -> str:
        return "table_vibration_vertical" + (f"_axis{int(k)}" if int(k) else "") + f"_{float(rate):g}dps"

    @property
    def params(self):
        out = [Param(f"table_vibration{self._tag(g)}_{d}_{h}", "mg", 1.0 / MG, 0.1, 100.0)
               for g in range(len(self.groups)) for h in ("cos", "sin") for d in ("axis", "gravity", "third")]
        out += [Param(f"{self._vtag(k, rate)}_axis_{h}", "mg", 1.0 / MG, 0.1, 100.0)
                for k, rate in self.vertical_axial for h in ("cos", "sin")]
        out += [Param(f"{self._vtag(k, rate)}_{name}_{d}_{h}", "mg", 1.0 / MG, 0.1, 100.0)
                for k, rate, name in self.vertical_across for h in ("cos", "sin") for d in ("across1", "across2")]
        return tuple(out)

    @staticmethod
    def _sensed(P, Q, l, p):
        """(1) of the module's derivation: Rot(l, -p) (cos p P + sin p Q), rows per phase p."""
        c, s = np.cos(p)[:, None], np.sin(p)[:, None]
        a = c * P[None, :] + s * Q[None, :]                          # table frame at the start
        along = (a @ l)[:, None] * l[None, :]
        # Rot(l, -p) a: the IMU has turned by p since the start
        return along + c * (a - along) - s * np.cross(l[None, :], a)

    def _framed(self):
        """Every framed rotation at once: (segment indices sorted, their frames (R, 3, 3) as rows
        l, b1, b2, and the positions in x of their P_l, P_1, P_2, Q_l, Q_1, Q_2 (R, 6)); b1, b2 gravity's
        (v_hat, u) about a level axis, the case-fixed (e1, e2) about a vertical one."""
        axial0 = 6 * len(self.groups)
        across0 = axial0 + 2 * len(self.vertical_axial)
        rows = []
        for index, (l, v, u) in self.frame.items():
            g = 6 * self.group_of[index]
            rows.append((index, (l, v, u), (g, g + 1, g + 2, g + 3, g + 4, g + 5)))
        for index, (l, e1, e2) in self.vframe.items():
            a, b = axial0 + 2 * self.vaxial_of[index], across0 + 4 * self.vacross_of[index]
            rows.append((index, (l, e1, e2), (a, b, b + 1, a + 1, b + 2, b + 3)))
        rows.sort(key=lambda r: r[0])
        return (np.array([r[0] for r in rows], float), np.array([r[1] for r in rows], float).reshape(-1, 3, 3),
                np.array([r[2] for r in rows], int).reshape(-1, 6))

    def accel(self, x, ctx):
        if getattr(ctx, "turned_s", None) is None:      # station apply: the bench's fault, not the IMU's
            return None
        # x (p,), or a batch X (B, p) with a batch context (accel_batch): the points' axis second to last
        out = np.zeros(ctx.f_p.shape, dtype=np.result_type(x, ctx.f_p))
        known, frames, cols = self._framed()
        if not len(known):
            return out
        # every framed rotation's points at once (one pass, not one per rotation: the designer
        # evaluates hundreds of candidate rotations): each rotation is one block of points on the
        # uniform grid of its signed angle, p = 2 pi j / n (table_revolution.phase_rows)
        seg = np.asarray(ctx.column("segment_index"), float)
        pos = np.clip(np.searchsorted(known, seg), 0, len(known) - 1)
        rows = np.flatnonzero(known[pos] == seg)
        if not len(rows):
            return out
        r = pos[rows]
        counts = np.bincount(r, minlength=len(known))
        order = np.argsort(r, kind="stable")
        rank = np.empty(len(r), int)
        rank[order] = np.arange(len(r)) - (np.cumsum(counts) - counts)[r[order]]
        p = 2.0 * np.pi * rank / counts[r]
        l, b1, b2 = frames[r, 0], frames[r, 1], frames[r, 2]
        xv = x[..., cols[r]]                                        # (n, 6)
        P = xv[..., 0:1] * l + xv[..., 1:2] * b1 + xv[..., 2:3] * b2
        Q = xv[..., 3:4] * l + xv[..., 4:5] * b1 + xv[..., 5:6] * b2
        c, s = np.cos(p)[:, None], np.sin(p)[:, None]
        a = c * P + s * Q                                           # table frame at the start
        ramps = self._ramp_rows(known, r, rows, l, ctx)
        if ramps is not None:       # (4) of the derivation: a recorded ramp's rows
            k2, kd, on = ramps
            a = a + on * ((k2 - 1.0) * a + kd * (s * P - c * Q))
        along = (a[..., 0] * l[:, 0] + a[..., 1] * l[:, 1] + a[..., 2] * l[:, 2])[..., None] * l
        # (1) of the module's derivation, Rot(l, -p) a: the IMU has turned by p since the start
        sensed = along + c * (a - along) - s * np.cross(l, a)
        exact = self._ramp_products(known, r, rows, ctx)
        if exact is not None:       # (5) of the derivation: the window's harmonics of each product
            sensed = sensed + exact[1] * (self._sensed_products(P, Q, l, exact[0]) - sensed)
        out[..., rows, :] = sensed @ ctx.accel_matrix.mT
        return out

    @staticmethod
    def _sensed_products(P, Q, l, v):
        """(5) of the derivation: (1) with (4)'s a(p) at a recorded ramp's points, from ``v`` (n, 2, 5)
        the values of w^2 / w_s^2 and (dw/dt) / w_s^2 times 1, cos p, sin p, cos 2p, sin 2p as the fit's
        rows take them (SampleContext.ramp_products): each product's own harmonics."""
        W, D = v[:, 0], v[:, 1]
        wc, ws, dc, ds = W[:, 1:2], W[:, 2:3], D[:, 1:2], D[:, 2:3]
        wcc, wcs, wss = 0.5 * (W[:, 0:1] + W[:, 3:4]), 0.5 * W[:, 4:5], 0.5 * (W[:, 0:1] - W[:, 3:4])
        dcc, dcs, dss = 0.5 * (D[:, 0:1] + D[:, 3:4]), 0.5 * D[:, 4:5], 0.5 * (D[:, 0:1] - D[:, 3:4])
        Pl = (P[..., 0] * l[:, 0] + P[..., 1] * l[:, 1] + P[..., 2] * l[:, 2])[..., None]
        Ql = (Q[..., 0] * l[:, 0] + Q[..., 1] * l[:, 1] + Q[..., 2] * l[:, 2])[..., None]
        Pa, Qa = P - Pl * l, Q - Ql * l                             # across l
        return ((Pl * (wc + ds) + Ql * (ws - dc)) * l + Pa * (wcc + dcs) + Qa * (wcs - dcc)
                - np.cross(l, P) * (wcs + dss) - np.cross(l, Q) * (wss - dcs))

    def _ramp_products(self, known, r, rows, ctx):
        """(the products of (5) over w_s^2 at the points ``rows`` (n, 2, 5), 1 where a recorded ramp's
        point has them and 0 elsewhere (n, 1)); None where none has (station apply, a context
        without them: (4) with the harmonics of w^2 and dw/dt alone)."""
        products = getattr(ctx, "ramp_products", None)
        if products is None or not self.ramp_rate:
            return None
        w_s = np.array([self.ramp_rate.get(int(i), np.nan) for i in known])[r]
        v = np.asarray(products)[rows]
        on = np.isfinite(w_s) & np.isfinite(v).all(axis=(1, 2))
        if not on.any():
            return None
        scale = np.where(on, 1.0 / np.where(on, w_s, 1.0) ** 2, 0.0)
        return np.where(on[:, None, None], v, 0.0) * scale[:, None, None], on.astype(float)[:, None]

    accel_batch = accel

    def _ramp_rows(self, known, r, rows, l, ctx):
        """(4) of the derivation at the points ``rows`` (their framed rotations ``r``): (w^2 / w_s^2,
        (dw/dt) / w_s^2, 1 on a recorded ramp's points and 0 elsewhere), each (n, 1) or a batch's
        (B, n, 1); None without a recorded ramp among them.  w^2 the rate's square as the fit's rows
        take it (SampleContext.wsq_table; the square of w_table where the context has none), dw/dt
        the table's angular acceleration about the rotation's axis l (wdot_table . l)."""
        if not self.ramp_rate:
            return None
        w_s = np.array([self.ramp_rate.get(int(i), np.nan) for i in known])[r]
        on = np.isfinite(w_s)
        if not on.any():
            return None
        inv = np.where(on, 1.0 / np.where(on, w_s, 1.0) ** 2, 0.0)
        wdot = ctx.wdot_table[..., rows, :]
        thdd = wdot[..., 0] * l[:, 0] + wdot[..., 1] * l[:, 1] + wdot[..., 2] * l[:, 2]
        if ctx.wsq_table is not None:
            wsq = np.asarray(ctx.wsq_table)[..., rows]
        else:
            w = ctx.w_table[..., rows, :]
            wsq = w[..., 0] * w[..., 0] + w[..., 1] * w[..., 1] + w[..., 2] * w[..., 2]
        return (wsq * inv)[..., None], (thdd * inv)[..., None], on.astype(float)[:, None]

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
        return out + self._vertical_words(x, sigma)

    def _vertical_words(self, x, sigma) -> list[str]:
        """The same about vertical axes: along the axis per table axis and rate, across it per
        rotation group (its own frame), each said when it stands out (> 3 sigma), in mg."""
        x, sigma = np.asarray(x, float), np.asarray(sigma, float)
        axial0 = 6 * len(self.groups)
        across0 = axial0 + 2 * len(self.vertical_axial)
        if len(x) < across0 + 4 * len(self.vertical_across):
            return []
        out = []
        for n, (k, rate) in enumerate(self.vertical_axial):
            j = axial0 + 2 * n
            m, sm = rev.amplitude(x[j], x[j + 1], sigma[j], sigma[j + 1])
            parts = [f"{m:.3g} ± {sm:.2g} mg along its axis"] if m > 3 * sm else []
            seen = []
            for i, (k2, rate2, name) in enumerate(self.vertical_across):
                if (k2, rate2) != (k, rate):
                    continue
                b = across0 + 4 * i
                v, sg = x[b:b + 4], sigma[b:b + 4]
                ma, sa = rev.amplitude(np.hypot(v[0], v[1]), np.hypot(v[2], v[3]),
                                       float(np.hypot(sg[0], sg[1]) / np.sqrt(2)), float(np.hypot(sg[2], sg[3]) / np.sqrt(2)))
                if ma > 3 * sa:
                    seen.append(f"{ma:.3g} ± {sa:.2g} mg across it in the rotations from {name}'s start")
            parts += seen
            if not parts:
                continue
            which = f"table axis {k}" if k else "the table"
            out.append(f"{which} vibrates once per revolution at {rate:g} °/s about a vertical axis: "
                       f"{' and '.join(parts)}; a fault of the bench, not of the IMU, and not compensated: balance "
                       "the platter or load it symmetrically (across a vertical axis its direction is known only "
                       "from each rotation's own start, not the table's)")
        return out
