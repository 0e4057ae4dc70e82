"""Effects on captures in raw counts: every effect's terms scaled to counts by the nominal scale.

An effect is written in physical units: its terms are m/s^2 (accelerometer) and deg/s (gyro), and
it reads the forward matrices K_a T_a and K_g T_g R_po as dimensionless (about the identity).  On a
capture whose accelerometer or gyro unit is ``raw`` (capture format: arbitrary output units) the
fit's matrices carry the unit (counts per m/s^2, counts per deg/s) and its terms must be counts.
``in_capture_units(cls)`` gives an effect class a subclass that, on such a capture, shows the
effect the matrices divided by the nominal scale n and multiplies its terms by n (forward model):

    accel_counts += n_a * accel_term(x; f_p, w_p, K_a T_a / n_a, ...)     n_a: counts per m/s^2
    gyro_counts  += n_g * gyro_term(x; f_p, w_p, K_g T_g R_po / n_g, ...)  n_g: counts per deg/s

so that every library effect and every plugin works unchanged on raw captures, with its parameters
in their physical units.  They are relative to the nominal scale, exactly as on a capture in m/s^2
and deg/s from a sensor whose scale factor is off by the same amount: a true scale 1 % away from
n makes a K2 or an asymmetry 1 % away from its value in true units, far below their 1σ in practice.

n: the manifest's nominal scale when given (``imu.accel_nominal_mps2_per_count``,
``imu.gyro_nominal_dps_per_count``, inverted); otherwise from the data: the accelerometer's, the
statics' mean |a| (counts) over the local gravity (biases average out over the attitudes); the
gyro's, the rotations' mean |integral| (counts s) over |encoder angle| (deg).  n is part of the
effect's state (``raw_counts_per_unit``), so the calibration file carries it to ``station apply``,
which compensates with the same n.  For captures in physical units n = 1 and nothing changes.
Terms on a rotation's gyro integral (``Effect.integral``) are built from the rotation's own
samples, already in the capture's units, and are left alone.
"""
from __future__ import annotations

import copy
import dataclasses
import functools

import numpy as np

from station.core.errors import UserError
from station.model.effect import batch_form

STATE_KEY = "raw_counts_per_unit"     # [counts per m/s^2, counts per deg/s]


def counts_per_unit(summaries) -> tuple[float, float | None]:
    """(n_a counts per m/s^2, n_g counts per deg/s) of a capture's summaries; 1.0 for an output in
    physical units (the summaries are then in m/s^2 and deg/s already); n_g None when a raw gyro
    has neither a nominal scale nor a rotation with an encoder angle."""
    n_a = 1.0
    if getattr(summaries, "accel_raw", False):
        n_a = summaries.accel_nominal
        if n_a is None:
            norms = [float(np.linalg.norm(st.accel)) for st in summaries.statics]
            n_a = float(np.mean(norms)) / summaries.gravity_mps2 if norms else None
        if not n_a or not np.isfinite(n_a):
            raise UserError("a raw accelerometer capture without a nominal scale "
                            "(imu.accel_nominal_mps2_per_count) or static segments: effects cannot be sized")
    n_g = 1.0
    if getattr(summaries, "gyro_raw", False):
        n_g = summaries.gyro_nominal
        if n_g is None:
            ratios = [float(np.linalg.norm(r.gyro_integral)) / abs(r.angle_deg)
                      for r in summaries.rotations if abs(r.angle_deg) > 0]
            n_g = float(np.mean(ratios)) if ratios else None
        if n_g is not None and not (n_g > 0 and np.isfinite(n_g)):
            n_g = None
    return n_a, n_g


class InCaptureUnits:
    """Mixin placed before an effect class (see ``in_capture_units``)."""

    _counts_per_unit: tuple = (1.0, 1.0)

    def _scaled(self) -> bool:
        return tuple(self._counts_per_unit) != (1.0, 1.0)

    def setup(self, summaries) -> None:
        self._counts_per_unit = counts_per_unit(summaries)
        if self._scaled():
            # the unit factors an effect may use (m/s^2 and deg/s per output unit) become the nominal ones
            summaries = copy.copy(summaries)
            summaries.accel_factor = 1.0 / self._counts_per_unit[0]
            if self._counts_per_unit[1] is not None:
                summaries.gyro_factor = 1.0 / self._counts_per_unit[1]
        super().setup(summaries)

    def _physical(self, ctx):
        n_a, n_g = self._counts_per_unit
        return dataclasses.replace(ctx, accel_matrix=np.asarray(ctx.accel_matrix) / n_a,
                                   gyro_matrix=np.asarray(ctx.gyro_matrix) / (n_g or 1.0))

    def accel(self, x, ctx):
        if not self._scaled():
            return super().accel(x, ctx)
        return self._in_counts("accel", super().accel(x, self._physical(ctx)))

    def gyro(self, x, ctx):
        if not self._scaled():
            return super().gyro(x, ctx)
        return self._in_counts("gyro", super().gyro(x, self._physical(ctx)))

    def batch_term(self, name: str):
        """The wrapped class's batch form of accel or gyro, its terms scaled as accel() and gyro()
        scale them; None where the class has none (or a class before this mixin defines the term)."""
        mro = type(self).__mro__
        here = mro.index(InCaptureUnits)
        if any(name in vars(c) or f"{name}_batch" in vars(c) for c in mro[:here]):
            return batch_form(self, name, mro[:here])
        inner = batch_form(self, name, mro[:here] + mro[here + 1:])     # a subclass' methods checked too
        if inner is None or not self._scaled():
            return inner
        return functools.partial(self._scaled_batch, name, inner)

    def _scaled_batch(self, name, inner, X, ctx):
        return self._in_counts(name, inner(X, self._physical(ctx)))

    def _in_counts(self, name, term):
        """A term in physical units (accel or gyro; one row or a batch) in the capture's counts."""
        if term is None:
            return None
        if name == "accel":
            return self._counts_per_unit[0] * np.asarray(term)
        if self._counts_per_unit[1] is None:
            raise UserError(f"effect {self.id!r}: a raw gyro capture without a nominal scale "
                            "(imu.gyro_nominal_dps_per_count) or a rotation with an encoder angle: its "
                            "gyro term cannot be sized")
        return self._counts_per_unit[1] * np.asarray(term)

    def state(self) -> dict:
        out = super().state()
        if self._scaled():
            out = dict(out)
            out[STATE_KEY] = [float(self._counts_per_unit[0]),
                              None if self._counts_per_unit[1] is None else float(self._counts_per_unit[1])]
        return out

    def restore(self, state: dict) -> None:
        state = dict(state)
        n = state.pop(STATE_KEY, None)
        if n is not None:
            if not (isinstance(n, list) and len(n) == 2 and isinstance(n[0], (int, float)) and n[0] > 0
                    and (n[1] is None or (isinstance(n[1], (int, float)) and n[1] > 0))
                    and np.all(np.isfinite([v for v in n if v is not None]))):
                raise ValueError(f"{STATE_KEY} must be two positive numbers (counts per m/s^2, per deg/s)")
            self._counts_per_unit = (float(n[0]), None if n[1] is None else float(n[1]))
        super().restore(state)


@functools.cache
def in_capture_units(cls: type) -> type:
    """``cls`` with its terms scaled to the capture's output units (counts for a raw capture)."""
    if issubclass(cls, InCaptureUnits):
        return cls
    return type(cls.__name__, (InCaptureUnits, cls),
                {"__module__": cls.__module__, "__qualname__": cls.__qualname__, "__doc__": cls.__doc__})
