"""gyro_g_sensitivity: gyro output that depends on the specific force."""
from __future__ import annotations

import numpy as np

from station.core import units
from station.model.effect import Effect, Param


class GyroGSensitivity(Effect):
    id = "gyro_g_sensitivity"
    title = "Gyro g-sensitivity (3x3): rate error proportional to specific force"
    physics = ("A vibrating or rotating proof mass is pushed by acceleration as well as by rotation, "
               "so the gyro reads a false rate proportional to the specific force.  Each gyro can "
               "respond to the force along any of the three axes.")
    term = "gyro_raw_i += sum_j G_ij f_j / g0 (°/h), f in frame p"
    excited_by = ("static attitudes (gravity along each axis in turn) and rotations about "
                  "horizontal axes (gravity turning in the body)")
    magnitudes = ("10-300 °/h/g (consumer MEMS), 1-10 °/h/g (tactical MEMS and FOG), "
                  "< 0.1 °/h/g (ring laser)")
    signature = ("gyro, static segments: a bias that changes with the attitude, in proportion to "
                 "the gravity components; unexplained by the Earth rate")
    signature_variable = "gravity_along_axis"
    complex_step = True

    @property
    def params(self):
        return tuple(Param(f"gyro_g_sens_{i}{j}", "deg/h/g", 1.0, 30.0, 3000.0) for i in "xyz" for j in "xyz")

    def gyro(self, x, ctx):
        """One parameter vector x (9,), or a batch X (B, 9) with a batch context (gyro_batch)."""
        G = x.reshape(*x.shape[:-1], 3, 3) / 3600.0       # deg/s per g
        return (ctx.f_p / units.STANDARD_GRAVITY) @ G.mT

    gyro_batch = gyro
