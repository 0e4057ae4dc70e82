"""accel_lever_arm: the size effect (Zhang et al. 2017, eqs. 10-17 and 21-24)."""
from __future__ import annotations

import numpy as np

from station.model.geometry import cross
from station.model.effect import Effect, Param

AXES = "xyz"


class AccelLeverArm(Effect):
    id = "accel_lever_arm"
    title = "Size effect: each accelerometer senses at its own position"
    physics = ("The three accelerometers are not at one point: each sits millimetres from the IMU's "
               "reference point, so under rotation each senses its own centripetal w x (w x p_i) "
               "and tangential dw/dt x p_i acceleration.")
    term = "accel_raw_i += (K_a T_a)_i . (dw/dt x p_i + w x (w x p_i))"
    excited_by = ("rotation segments, growing with the square of the rate; rotations about tilted "
                  "or diagonal axes reveal the components across each sensing axis")
    magnitudes = ("element offsets 1-5 mm in navigation-grade units, 5-15 mm in tactical and "
                  "consumer MEMS boards; at 200 deg/s, 10 mm gives 12 mg")
    signature = ("accelerometer, rotation segments only: a constant offset growing with the square "
                 "of the rate, the same sign in both directions, different on each axis")
    signature_variable = "rate_squared"
    complex_step = True
    needs = ("time",)
    state_fields = ("free",)

    def __init__(self):
        self.free = [(i, c) for i in range(3) for c in range(3)]   # (element, coordinate) estimated

    def setup(self, summaries) -> None:
        # With the mounting offset unknown, a common translation of all three elements is the
        # offset itself: fix each element's coordinate along its own axis to define the
        # reference point (the point whose x is the x element's x, and so on).
        known = summaries.mounting_offset_m is not None
        self.free = [(i, c) for i in range(3) for c in range(3) if known or i != c]

    def notes(self) -> tuple[str, ...]:
        """What the convention fixes: said as such, not as something the capture failed to reveal."""
        fixed = [f"accel_position_{AXES[i]}_{AXES[i]}" for i in range(3) if (i, i) not in self.free]
        if not fixed:
            return ()
        return (f"{', '.join(fixed)}: 0 by convention, not estimated: with the mounting offset unknown, "
                "a shift common to the three accelerometers is the offset itself, so no capture can "
                "reveal them; each element's coordinate along its own axis defines the reference point "
                "(give the offset, table.imu_offset_m, to estimate them)",)

    @property
    def params(self):
        return tuple(Param(f"accel_position_{AXES[i]}_{AXES[c]}", "mm", 1e3, 10.0, 50.0) for i, c in self.free)

    def positions(self, x: np.ndarray) -> np.ndarray:
        p = np.zeros((3, 3), dtype=np.result_type(x, float))     # complex under complex step
        for (i, c), v in zip(self.free, x):
            p[i, c] = v
        return p

    def accel(self, x, ctx):
        p = self.positions(x)
        wd = ctx.wdot_table
        out = np.empty(ctx.f_p.shape, np.result_type(ctx.f_p, ctx.accel_matrix, ctx.w_table, p))
        for i in range(3):
            a = cross(wd, p[i]) + ctx.centripetal(p[i])
            out[:, i] = a @ ctx.accel_matrix[i]
        return out

    def accel_batch(self, X, ctx):
        """accel() of every row of X (B, p) with a batch context (Effect.accel_batch)."""
        p = np.zeros((len(X), 3, 3), dtype=np.result_type(X, float))
        for k, (i, c) in enumerate(self.free):
            p[:, i, c] = X[:, k]
        wd = ctx.wdot_table
        out = np.empty(ctx.f_p.shape, np.result_type(ctx.f_p, ctx.accel_matrix, ctx.w_table, p))
        for i in range(3):
            pi = p[:, None, i, :]
            a = cross(wd, pi) + ctx.centripetal(pi)
            out[..., i] = (a @ ctx.accel_matrix[:, i, :, None])[..., 0]
        return out

    def report(self, x, cov):
        return {"accel_lever_arm_m": self.positions(x)}
