"""table_encoder_scale: the table turns (1 + e) times the angle its encoder reads."""
from __future__ import annotations

import functools

import numpy as np

from station.model.effect import Effect, Param
from station.model.geometry import cross


FOURIER_ORDER = 4        # the turned time's harmonics kept (see turned_time)
DENSE = 720              # points per revolution its harmonics are computed from


def turned_time(angle_deg: float, duration_s: float, phases: int, power: int = 1) -> np.ndarray:
    """_turned_time, remembered: a capture's rotations share a few angles and durations, and every
    model of the capture (a diagnosis builds one per candidate) asks for each (a copy returned)."""
    return _turned_time(float(angle_deg), float(duration_s), int(phases), int(power)).copy()


@functools.lru_cache(maxsize=4096)
def _turned_time(angle_deg: float, duration_s: float, phases: int, power: int = 1) -> np.ndarray:
    """(phases,): the time since a rotation's start at each point of the model's phase grid
    (phase 2 pi j / phases of the encoder's angle from the start, mod 2 pi), averaged over the
    revolutions that point stands for (_mean_visit), over the mean rate A / duration, as its
    Fourier series to FOURIER_ORDER: a term t(p) g(p) with g of order <= 3 (gravity's turn times
    the harmonic basis) then projects on the harmonics exactly on a grid of 12 points (orders up
    to 11 average exactly) for whole revolutions, where t(p) itself is a sawtooth the grid
    would alias by 2-10 %.  ``power`` 2: the mean of the squared time instead (s^2)."""
    A = np.radians(angle_deg)
    if A == 0 or duration_s <= 0:
        return np.zeros(phases)
    dense = 2 * np.pi * np.arange(DENSE) / DENSE
    values = _mean_visit(A, dense, power)
    grid = 2 * np.pi * np.arange(phases) / phases
    out = np.full(phases, values.mean())
    for k in range(1, FOURIER_ORDER + 1):
        c, s = 2 * np.mean(values * np.cos(k * dense)), 2 * np.mean(values * np.sin(k * dense))
        out += c * np.cos(k * grid) + s * np.sin(k * grid)
    return out / (A / duration_s) ** power


def _mean_visit(A: float, p: np.ndarray, power: int = 1) -> np.ndarray:
    """The mean angle (rad; power 2: of its square) of the visits theta = p + 2 pi k within the arc
    [0, A] (or [A, 0]); a phase the arc never reaches (part of a revolution) takes the arc's
    nearer end."""
    if A > 0:
        n = np.floor((A - p) / (2 * np.pi)) + 1
        first, step = p, 2 * np.pi
        end = np.where(p - A < 2 * np.pi - p, A, 0.0)
    else:
        top = np.where(p == 0, 0.0, p - 2 * np.pi)
        n = np.floor((top - A) / (2 * np.pi)) + 1
        first, step = top, -2 * np.pi
        end = np.where(A - top < p, A, 0.0)
    if power == 1:
        return np.where(n >= 1, first + 0.5 * step * (n - 1), end)
    # the mean of (first + k step)^2 over k = 0 .. n-1
    m = np.maximum(n, 1)
    mean_sq = first**2 + first * step * (m - 1) + step**2 * (m - 1) * (2 * m - 1) / 6
    return np.where(n >= 1, mean_sq, end**2)


PHASES = 12               # the fit's phase grid (station.estimate.lsq.PHASES: its rows per rotation)
_GRID = 2 * np.pi * np.arange(PHASES) / PHASES
# the harmonic basis 1, cos, sin, cos 2, sin 2 at the grid's points, (PHASES, 5): values there whose
# uniform projection (the fit's: lsq.Model._harmonics) are the harmonics h are _BASIS @ h
_BASIS = np.column_stack([np.ones(PHASES), np.cos(_GRID), np.sin(_GRID), np.cos(2 * _GRID), np.sin(2 * _GRID)])


def arc_moments(angle_deg: float) -> np.ndarray:
    """(4, 5): the least-squares harmonics (1, cos, sin, cos 2, sin 2 of the phase, as the summaries
    fit a rotation's accelerometer over its arc) of theta cos theta, theta sin theta, theta^2 cos
    theta and theta^2 sin theta over a uniform turn theta in [0, A] (rad; A signed, whole revolutions
    or not).  Gravity turned further by e theta adds -e theta (l x f) + e^2 theta^2 / 2 l x (l x f)
    with f = cos p v - sin p (l x v): its harmonics are these moments times v and l x v, for any arc
    (issue 28, twenty-first session: the phase grid's uniform projection of the mean visit's angle
    is the least-squares fit for whole revolutions only; over 300 degrees it took 1000 ppm for 898
    +- 9)."""
    return _arc_moments(float(angle_deg)).copy()


@functools.lru_cache(maxsize=4096)
def _arc_moments(angle_deg: float) -> np.ndarray:
    A = np.radians(angle_deg)
    if A == 0:
        return np.zeros((4, 5))
    m = max(DENSE, int(DENSE * np.ceil(abs(A) / (2 * np.pi))))
    theta = A * (np.arange(m) + 0.5) / m                   # midpoints: the samples of a uniform turn
    basis = np.stack([np.ones(m), np.cos(theta), np.sin(theta), np.cos(2 * theta), np.sin(2 * theta)])
    gram = basis @ basis.T / m
    rhs = np.stack([theta * np.cos(theta), theta * np.sin(theta),
                    theta**2 * np.cos(theta), theta**2 * np.sin(theta)]) @ basis.T / m      # (4, 5)
    return np.linalg.lstsq(gram, rhs.T, rcond=1e-12)[0].T


class TableEncoderScale(Effect):
    id = "table_encoder_scale"
    title = "Table encoder scale error: the table turns (1 + e) times the angle its encoder reads"
    physics = ("A gear or belt drive, an encoder disc off its centre or a wrong count per revolution make the "
               "table turn a little more (or less) than its encoder says.  The gyros see the true rate, so "
               "their scale factors take the error (all alike) unless something else knows the angle: the "
               "accelerometers do, because gravity turns through the true angle in the body; over n "
               "revolutions read as whole, the last e n revolutions are extra, which leaves a mean and a "
               "second harmonic of gravity in every rotation.  It is a property of the bench, not of the "
               "IMU: station apply compensates nothing for it.")
    term = ("rotations only (the fit's phase grid): f_true(theta) = f(theta (1 + e 1e-6)), i.e. accel_raw += "
            "M_a (-e' t_turn (w_table x f) + e'^2/2 t_turn^2 w_table x (w_table x f)), e' = e 1e-6, t_turn the "
            "time since the rotation's start at the point (t_turn w_table = theta, the encoder's angle); on a steady "
            "rotation's grid its harmonics are the least-squares fit over its arc (arc_moments), whole revolutions "
            "or not; "
            "gyro_raw += e 1e-6 M_g w_table (the true rate); centripetal terms' 2e change neglected")
    excited_by = ("rotations about any axis with the accelerometers across gravity (the mean and second harmonic "
                  "of gravity over the revolutions); the gyros alone cannot tell it from their scale factors")
    magnitudes = "< 1 ppm (optical encoders on the axis), 10-100 ppm (gear or belt drives), 1000 ppm and more (a wrong gear ratio)"
    signature = ("accelerometer, rotation segments: a mean and a twice-per-revolution residual of gravity in "
                 "every rotation, growing with the number of revolutions' phase error e 360° n; gyro scale "
                 "factors all off by e alike (the sum of the three scale errors moves, their differences "
                 "do not)")
    signature_variable = "signed_rate"
    complex_step = True
    state_fields = ("table_axes", "position_of", "moments_of")

    def __init__(self):
        # one error per table axis when the capture records which axis turned each rotation
        # (``table_axis``, as a bench run writes it) and names more than one: each axis has its own
        # encoder and gearing; otherwise one error for the table (the axes are not told apart)
        self.table_axes = []          # the table axes with an error of their own ([]: one for the table)
        self.position_of = {}         # segment index -> position of its axis in table_axes
        self.moments_of = {}          # segment index -> (arc_moments, |A| / T rad/s): setup

    def setup(self, summaries) -> None:
        steady = [r for r in summaries.rotations if r.steady]
        known = sorted({r.table_axis for r in steady if getattr(r, "table_axis", None) is not None})
        if len(known) > 1 and all(getattr(r, "table_axis", None) is not None for r in steady):
            self.table_axes = [int(k) for k in known]
            self.position_of = {int(r.index): known.index(r.table_axis) for r in steady}
        else:
            self.table_axes, self.position_of = [], {}
        # each steady rotation's arc moments, by segment index: a recorded ramp's from its samples
        # (RotationSummary.turned_moments), a uniform turn's over its arc (arc_moments)
        self.moments_of = {}
        for r in steady:
            sampled = getattr(r, "turned_moments", None)
            # and the encoder's mean rate over the window, |A| / T (rad/s): the gyros' turn is (1 + e) A
            rate = abs(np.radians(r.angle_deg)) / r.duration_s if getattr(r, "duration_s", 0.0) > 0 else None
            if sampled is not None:
                self.moments_of[int(r.index)] = (np.asarray(sampled, float), rate)
            elif getattr(r, "angle_deg", 0.0):
                self.moments_of[int(r.index)] = (arc_moments(r.angle_deg), rate)

    @property
    def params(self):
        if self.table_axes:
            return tuple(Param(f"table_encoder_scale_error_axis{k}", "ppm", 1.0, 10.0, 20000.0)
                         for k in self.table_axes)
        return (Param("table_encoder_scale_error", "ppm", 1.0, 10.0, 20000.0),)

    def words(self, x, sigma) -> list[str]:
        out = []
        for n in range(len(x)):
            if abs(x[n]) <= 3 * sigma[n]:
                continue
            which = f"table axis {self.table_axes[n]}" if self.table_axes else "the table"
            out.append(f"{which} turns {x[n]:+.3g} ± {sigma[n]:.2g} ppm {'more' if x[n] > 0 else 'less'} than its "
                       "encoder reads (its gearing or encoder scale): the gyro scale factors in this calibration are "
                       "of the true angle; check the axis' angle against a reference (a polygon and autocollimator)")
        return out

    def _per_row(self, x, ctx):
        """The error (ppm) of every row: its rotation's table axis' (one error for the table when
        the axes are not told apart)."""
        if not self.table_axes:
            return x[0]
        index = ctx.column("segment_index")
        pos = np.array([self.position_of.get(int(i), 0) if np.isfinite(i) else 0 for i in index])
        return x[pos]

    def accel(self, x, ctx):
        turned = getattr(ctx, "turned_s", None)
        if turned is None:           # station apply: the bench's error is not the IMU's
            return None
        # gravity turned further by delta = e theta: f -> f + sin(delta) (f x l) + (cos(delta) - 1) f_perp,
        # to second order (delta reaches 1° over 10 revolutions at 300 ppm: its square 60 µg), with
        # theta l = t_turn w_table and f_perp = -(l x (l x f))
        # only gravity turns with the table's angle: the body-fixed part of f (the centripetal and
        # tangential acceleration of the mounting offset, and gravity along the axis) is each
        # rotation's mean over its phase points, taken out first (a rotation's points share its
        # segment index)
        e = self._per_row(x, ctx) * 1e-6
        e = e[:, None] if np.ndim(e) else e
        sq = getattr(ctx, "turned_sq_s2", None)
        sq = np.asarray(turned, float) ** 2 if sq is None else np.asarray(sq, float)
        index = ctx.column("segment_index")
        turning = ctx.f_p - _segment_means(index, ctx.f_p)
        out = _gravity_turned(e, turned, sq, ctx.w_table, turning)
        return self._on_arcs(out, e, index, turning) @ ctx.accel_matrix.T

    def gyro(self, x, ctx):
        if getattr(ctx, "turned_s", None) is None:
            return None
        e = self._per_row(x, ctx) * 1e-6
        e = e[:, None] if np.ndim(e) else e
        w = self._mean_rate_on_arcs(ctx.w_table, ctx.column("segment_index"))
        return e * (180.0 / np.pi) * w @ ctx.gyro_matrix.T    # (np.degrees: no complex step)

    # --- every row of X (B, p) with a batch context at once (Effect.accel_batch): the same numbers
    def _per_point_batch(self, X, ctx):
        """(B, N or 1, 1): each row's error (ppm, times 1e-6) at every point."""
        if not self.table_axes:
            return (X[:, 0] * 1e-6)[:, None, None]
        index = ctx.column("segment_index")
        pos = np.array([self.position_of.get(int(i), 0) if np.isfinite(i) else 0 for i in index])
        return (X[:, pos] * 1e-6)[..., None]

    def accel_batch(self, X, ctx):
        turned = getattr(ctx, "turned_s", None)
        if turned is None:
            return None
        e = self._per_point_batch(X, ctx)
        sq = getattr(ctx, "turned_sq_s2", None)
        sq = np.asarray(turned, float) ** 2 if sq is None else np.asarray(sq, float)
        index = ctx.column("segment_index")
        turning = ctx.f_p - np.stack([_segment_means(index, f) for f in ctx.f_p])
        out = _gravity_turned(e, turned, sq, ctx.w_table, turning)
        return self._on_arcs(out, e, index, turning) @ ctx.accel_matrix.mT

    def gyro_batch(self, X, ctx):
        if getattr(ctx, "turned_s", None) is None:
            return None
        w = self._mean_rate_on_arcs(ctx.w_table, ctx.column("segment_index"))
        return self._per_point_batch(X, ctx) * (180.0 / np.pi) * w @ ctx.gyro_matrix.mT


    def _on_arcs(self, out, e, index, turning):
        """``out`` (.., N, 3) with each steady rotation's PHASES points replaced by values whose
        uniform projection is the least-squares harmonics of the turned gravity over its arc
        (arc_moments): v and l x v from the turning part's first harmonic on the grid, l the
        fit's axis (the phase p turns about +l, signed like the angle: f = cos p v - sin p (l x v)).
        A rotation whose points are not the grid's keeps the mean visit's form (out)."""
        rows = self._arc_rows(index)
        if rows is None:
            return out
        idx, moments = rows
        T = turning[..., idx, :]                                              # (.., R, PHASES, 3)
        v = 2.0 / PHASES * np.einsum("k,...kc->...c", np.cos(_GRID), T)         # (.., R, 3)
        u = -2.0 / PHASES * np.einsum("k,...kc->...c", np.sin(_GRID), T)        # l x v
        if np.ndim(e) == 0:
            er = e
        elif np.shape(e)[-2] == 1:                  # one error for the table, per row of a batch
            er = e[..., None]
        else:                                       # each point's axis' error: its rotation's
            er = e[..., idx[:, 0], :][..., None]                                # (.., R, 1, 1)
        Qc, Qs, Q2c, Q2s = (moments[:, j, :, None] for j in range(4))          # (R, 5, 1)
        h = (-er * (Qc * u[..., None, :] + Qs * v[..., None, :])
             + 0.5 * er * er * (Q2s * u[..., None, :] - Q2c * v[..., None, :]))   # (.., R, 5, 3)
        out = np.array(out, dtype=np.result_type(out, h), copy=True)
        out[..., idx, :] = _BASIS @ h
        return out

    def _mean_rate_on_arcs(self, w, index):
        """The table rate ``w`` (.., N, 3) with each steady rotation's points at the encoder's mean
        rate |A| / T along the points' mean direction: the fit takes the gyros' turn from the
        points' mean times T, which over a recorded ramp's window (a rest and a ramp: the rate's
        harmonics on the grid average 0.11 % above A / T at 10 deg/s) is not the angle; the gyros
        turn (1 + e) A exactly (issue 28, twenty-first session)."""
        rows = self._arc_rows(index)
        if rows is None:
            return w
        idx = rows[0]
        rate = np.array([self.moments_of[int(k)][1] or 0.0 for k in np.asarray(index, float)[idx[:, 0]]])
        m = w[..., idx, :].mean(axis=-2)                                       # (.., R, 3)
        norm = np.sqrt(np.sum(m * m, axis=-1, keepdims=True))                 # (complex step: no abs)
        unit = np.divide(m, norm, out=np.zeros_like(m), where=norm.real > 0)
        out = np.array(w, dtype=np.result_type(w, unit), copy=True)
        out[..., idx, :] = (rate[:, None] * unit)[..., None, :]
        return out

    def _arc_rows(self, index):
        """(rows (R, PHASES), moments (R, 4, 5)) of the rotations with arc moments whose
        PHASES points the context holds in phase order, or None."""
        if not self.moments_of or index is None:
            return None
        index = np.asarray(index, float)
        keys = np.array(sorted(self.moments_of), float)
        sel = np.flatnonzero(np.isin(index, keys))
        if not len(sel):
            return None
        found, inverse, counts = np.unique(index[sel], return_inverse=True, return_counts=True)
        if np.any(counts != PHASES):
            return None
        order = np.argsort(inverse, kind="stable")
        idx = sel[order].reshape(len(found), PHASES)
        moments = np.array([self.moments_of[int(k)][0] for k in found])
        return idx, moments

def _gravity_turned(e, turned, sq, w, turning):
    """The change of the turning part of f when the table turned further by e theta (second order:
    accel()'s comment): -e t (w x f) + e^2/2 t^2 w x (w x f), one row's points or a batch's."""
    wxf = cross(w, turning)
    return -e * np.asarray(turned, float)[:, None] * wxf + 0.5 * e * e * sq[:, None] * cross(w, wxf)


def _segment_means(index: np.ndarray, f: np.ndarray) -> np.ndarray:
    """Each row's mean of f over the rows of its segment (``index``; NaN where the segment is not
    known), real or complex: sums by segment (bincount), in time and memory linear in the rows
    (a rows x rows indicator matrix was 1.6 GB at 4,000 segments)."""
    f = np.asarray(f)
    finite = np.isfinite(index)
    out = np.full(f.shape, np.nan, dtype=np.result_type(f, float))
    if not finite.any():
        return out
    _, inv = np.unique(index[finite], return_inverse=True)
    counts = np.bincount(inv).astype(float)
    rows = f[finite]
    means = np.empty((len(counts), f.shape[1]), dtype=out.dtype)
    for k in range(f.shape[1]):
        col = rows[:, k]
        m = np.bincount(inv, weights=col.real, minlength=len(counts))
        if np.iscomplexobj(col):
            m = m + 1j * np.bincount(inv, weights=col.imag, minlength=len(counts))
        means[:, k] = m / counts
    out[finite] = means[inv]
    return out
