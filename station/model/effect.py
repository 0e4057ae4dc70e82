"""What an effect of the measurement model provides: the ``Effect`` interface.

An effect adds parameters and additive terms to the raw outputs the model predicts (the forward
model).  The same terms, evaluated at the compensated quantities, give its compensation: ``station
apply`` subtracts them by a fixed-point iteration (station/model/compensate.py), so an effect needs
no separate inverse unless it wants an exact one.  Effects can come from the library
(station/model/), from a Python file given to ``--add path/file.py:ClassName`` or from an installed
package's entry point (group ``station.effects``); docs/effects.md walks through writing one.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from station.model.geometry import cross


@dataclass(frozen=True)
class Param:
    name: str
    unit: str                 # the unit the value is reported in
    scale: float              # reported value = internal value * scale
    typical: float            # a typical magnitude (reported unit): below it, a capture that
                              #   cannot resolve it (1-sigma above) does not reveal it
    plausible: float          # the largest magnitude (reported unit) plausible for any IMU


@dataclass
class SampleContext:
    """Quantities at the sample points where the model predicts raw outputs.

    All arrays have N rows; frame p; specific force in m/s^2, rates in deg/s (w_p, the
    inertial rate the gyros sense) and rad/s (w_table, the table rate relative to the Earth,
    and its derivative wdot_table in rad/s^2).  The N points may come from many segments (the
    least-squares fit passes every static and every rotation's phase points in one call;
    segment_index says which): a term is computed point by point.
    """
    f_p: np.ndarray           # specific force at the IMU reference point
    w_p: np.ndarray           # inertial angular rate, deg/s
    w_table: np.ndarray       # table rate relative to the Earth, rad/s
    wdot_table: np.ndarray    # its time derivative, rad/s^2
    temp_c: np.ndarray        # temperature, deg C (NaN when not recorded)
    accel_matrix: np.ndarray  # current K_a T_a (rows: scale times sensing direction), 3x3
    gyro_matrix: np.ndarray   # current K_g T_g R_po, 3x3
    t_s: np.ndarray | None = None          # time since the start of the run, s (None: unknown)
    segment_index: np.ndarray | None = None  # index of the segment in the capture (None: unknown)
    temp_rate_c_per_s: np.ndarray | None = None  # rate of change of the temperature, deg C/s
    turned_s: np.ndarray | None = None     # the fit only: time since a rotation's start at its phase
                                           #   point (mean over the revolutions it stands for; 0 at
                                           #   statics), for effects of the table's angle; None in apply
    turned_sq_s2: np.ndarray | None = None  # the fit only: the mean of that time's square, s^2
    offset_m: np.ndarray | None = None     # the fit only: (N, 3) the model's mounting offset from the
                                           #   rotation axis at each point, m, frame p (0 at statics)
    wsq_table: np.ndarray | None = None    # the fit only: (N,) the table rate's square as the fit's rows
                                           #   take it, rad^2/s^2 (0 at statics): over a recorded ramp
                                           #   the square's own harmonics, not the square of the rate's;
                                           #   a batch context's (N,) or (B, N) (a window shift per row)
    axis_table: np.ndarray | None = None   # the fit only: (N, 3) the rotation's unit axis, frame p (0 at
                                           #   statics); a batch context's (B, N, 3)
    ramp_products: np.ndarray | None = None  # the fit only: (N, 2, 5) at a recorded ramp's phase points
                                           #   the values of w^2 and dw/dt times 1, cos p, sin p, cos 2p,
                                           #   sin 2p as the fit's rows take them (from the window's own
                                           #   harmonics of each product, RotationSummary.ramp_coef: not
                                           #   the product of w^2's harmonics with cos p), rad^2/s^2 and
                                           #   rad/s^2; NaN elsewhere; None without such a ramp.  Shared
                                           #   by a batch context's rows (a recorded ramp's rate shape is
                                           #   not scaled by a window shift)

    def __len__(self) -> int:
        """N, the points (also of a batch context, whose f_p is (B, N, 3): Effect.accel_batch)."""
        return self.f_p.shape[-2]

    def column(self, name: str) -> np.ndarray:
        """An optional quantity as an (N,) array; NaN where it is not known."""
        v = getattr(self, name)
        return np.full(len(self), np.nan) if v is None else np.broadcast_to(np.asarray(v, float), (len(self),))

    def centripetal(self, d) -> np.ndarray:
        """w x (w x d) at every point, m/s^2 (``d``: (3,), (N, 3), or a batch's (B, N, 3), m): the
        centripetal acceleration of a point ``d`` off the rotation axis.  In the fit it is
        wsq_table l x (l x d), with the square of the rate the rows take (the base model's own
        mounting offset's): over a recorded ramp the square of the rate's five harmonics is not the
        harmonics of its square, and an offset's 20 mm at 100 deg/s left a ramp window's harmonics
        1.5x their noise (issue 28, twentieth session, branch vib28).  Elsewhere (station apply, a
        context without them) the cross products of w_table."""
        if self.wsq_table is None or self.axis_table is None:
            return cross(self.w_table, cross(self.w_table, d))
        l = self.axis_table
        return np.asarray(self.wsq_table)[..., None] * cross(l, cross(l, d))     # (N,) or a batch's (B, N)


class Effect:
    """Base class: an effect adds parameters and additive terms to the raw outputs."""

    id = ""
    title = ""
    physics = ""              # two sentences
    term = ""                 # its term in the measurement equation
    excited_by = ""           # which segments reveal it
    magnitudes = ""           # typical sizes, consumer MEMS to navigation grade
    signature = ""            # what its residuals look like when it is missing
    signature_variable = ""   # what to plot its residuals against: rate_squared, temperature,
                              #   gravity_along_axis, signed_rate, rate_change, time
    named_by: tuple[str, ...] = ()   # phrases of diagnose's words that name it (station.diagnose.words):
                              #   --auto tries it first when the failure says one of them
    needs: tuple[str, ...] = ()   # inputs its compensation needs beyond the samples:
                              #   "temperature" (a temp column), "time" (time stamps: rates of change)
    state_fields: tuple[str, ...] = ()   # attributes set by setup() that the compensation needs;
                              #   written to the calibration file and restored by restore()
    complex_step = False      # True: accel/gyro/integral are complex-analytic in x and in ctx's
                              #   f_p, w_p, w_table, wdot_table, accel_matrix, gyro_matrix (no abs,
                              #   norm, comparison, float(), real part or in-place write into a
                              #   float array on them), so the fit's Jacobian may be taken by
                              #   complex step; False: by forward differences (docs/effects.md)

    def setup(self, summaries) -> None:
        """Decide the parameters this capture can carry (e.g. a gauge choice)."""

    @property
    def params(self) -> tuple[Param, ...]:
        return ()

    def accel(self, x: np.ndarray, ctx: SampleContext) -> np.ndarray | None:
        """Additive term of the raw accelerometer output (m/s^2 before unit conversion)."""
        return None

    def gyro(self, x: np.ndarray, ctx: SampleContext) -> np.ndarray | None:
        """Additive term of the raw gyro output (deg/s before unit conversion)."""
        return None

    # --- optional: the terms of a whole batch of parameter vectors at once -------------------
    # The fit evaluates its residuals for B parameter vectors at a time (the Jacobian's columns).
    # An effect may give the terms of all of them in one call: X is (B, p); ctx is a SampleContext
    # whose f_p, w_p, w_table, wdot_table, offset_m and axis_table are (B, N, 3), wsq_table (N,) or
    # (B, N), and accel_matrix, gyro_matrix (B, 3, 3), one per row of X, the other fields (the
    # points' temperature, time, segment index, ...) shared, (N,); the result is (B, N, 3) or None, row n equal to accel(X[n], ctx of row n).
    # The fit uses it where the class that defines accel (gyro) defines accel_batch (gyro_batch)
    # too, so a subclass overriding accel alone keeps its override (estimate.lsq._own_term_batch),
    # and no subclass redefines a method of that class (a helper accel calls: batch_form); else it
    # calls accel row by row.  An effect without a term returns None from both.
    def accel_batch(self, X: np.ndarray, ctx: SampleContext) -> np.ndarray | None:
        """accel() of every row of X (B, p) at once: (B, N, 3) (see above)."""
        return None

    def gyro_batch(self, X: np.ndarray, ctx: SampleContext) -> np.ndarray | None:
        """gyro() of every row of X (B, p) at once: (B, N, 3) (see above)."""
        return None

    def batch_term(self, name: str):
        """The batch form the fit may call for ``name`` ("accel" or "gyro"): the class that defines
        the term (first in the method resolution order) defines ``name + "_batch"`` too; else None
        (the fit calls the term row by row)."""
        return batch_form(self, name, type(self).__mro__)

    def integral(self, x: np.ndarray, rotation) -> np.ndarray | None:
        """Additive term of a rotation segment's gyro integral (deg before unit conversion)."""
        return None

    def window_shift_s(self, x: np.ndarray):
        """The time (s) by which the samples' window is shifted against the encoder's, when
        integral() is that shift times the change of the measured rate across the window
        (time_offset); None: no such term.  The measured rate's change includes the Earth rate's
        across the axis, whose integral the estimator already takes over the samples' own phases
        (the window the samples cover): the estimator takes that share out of the term."""
        return None

    def notes(self) -> tuple[str, ...]:
        """Sentences for the calibration's fit.notes about what setup() decided (e.g. parameters a
        convention fixes, so that they are not mistaken for ones the capture failed to reveal)."""
        return ()

    def report(self, x: np.ndarray, cov: np.ndarray | None) -> dict:
        """Extra content for the calibration file's compensation block, for other programs
        (e.g. the element positions of the size effect); station itself uses state()."""
        return {}

    # --- compensation ---------------------------------------------------------------------
    def state(self) -> dict:
        """What setup() decided that the terms depend on, as plain numbers and lists."""
        out = {}
        for name in self.state_fields:
            v = getattr(self, name)
            out[name] = np.asarray(v).tolist() if isinstance(v, (np.ndarray, tuple, list)) else v
        return out

    def restore(self, state: dict) -> None:
        """Undo state(): set the attributes the terms depend on (from a calibration file)."""
        for name in self.state_fields:
            if name in state:
                setattr(self, name, state[name])

    def compensate_time(self, x: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Time stamps corrected for this effect (e.g. a clock offset); most effects leave them."""
        return t


def batch_form(effect: Effect, name: str, classes):
    """``effect``'s ``name + "_batch"`` (bound) when the first of ``classes`` that defines ``name``
    or its batch form defines the batch form and no class before it redefines one of its methods
    (a helper ``name`` calls that the batch form may not: a plugin overriding the lever arm's
    ``positions`` alone lost it in the fit, review of batch27); else None (row by row)."""
    classes = tuple(classes)
    for at, cls in enumerate(classes):
        own = vars(cls)
        if name in own or f"{name}_batch" in own:
            batch = own.get(f"{name}_batch")
            if batch is None or (cls is not Effect and _redefined(classes[:at], cls)):
                return None
            return batch.__get__(effect, type(effect))
    return None


@functools.lru_cache(maxsize=1024)
def _redefined(subclasses: tuple, cls: type) -> bool:
    """Whether one of ``subclasses`` defines a method or property that ``cls`` or a base of it has."""
    methods = {k for c in cls.__mro__[:-1] for k, v in vars(c).items()
               if callable(v) or isinstance(v, (property, staticmethod, classmethod))}
    return any(k in methods for c in subclasses for k in vars(c))
