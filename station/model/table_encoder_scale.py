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
            "time since the rotation's start at the point; "
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
    state_fields = ("table_axes", "position_of")

    def __init__(self):
        # one error per table axis when the capture records which axis turned each rotation
        # (``table_axis``, as a bench run writes it) and names more than one: each axis has its own
        # encoder and gearing; otherwise one error for the table (the axes are not told apart)
        self.table_axes = []          # the table axes with an error of their own ([]: one for the table)
        self.position_of = {}         # segment index -> position of its axis in table_axes

    def setup(self, summaries) -> None:
        steady = [r for r in summaries.rotations if r.steady]
        known = sorted({r.table_axis for r in steady if getattr(r, "table_axis", None) is not None})
        if len(known) > 1 and all(getattr(r, "table_axis", None) is not None for r in steady):
            self.table_axes = [int(k) for k in known]
            self.position_of = {int(r.index): known.index(r.table_axis) for r in steady}
        else:
            self.table_axes, self.position_of = [], {}

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
        turning = ctx.f_p - _segment_means(ctx.column("segment_index"), ctx.f_p)
        return _gravity_turned(e, turned, sq, ctx.w_table, turning) @ ctx.accel_matrix.T

    def gyro(self, x, ctx):
        if getattr(ctx, "turned_s", None) is None:
            return None
        e = self._per_row(x, ctx) * 1e-6
        e = e[:, None] if np.ndim(e) else e
        return e * (180.0 / np.pi) * ctx.w_table @ ctx.gyro_matrix.T    # (np.degrees: no complex step)

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
        return _gravity_turned(e, turned, sq, ctx.w_table, turning) @ ctx.accel_matrix.mT

    def gyro_batch(self, X, ctx):
        if getattr(ctx, "turned_s", None) is None:
            return None
        return self._per_point_batch(X, ctx) * (180.0 / np.pi) * ctx.w_table @ ctx.gyro_matrix.mT


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
