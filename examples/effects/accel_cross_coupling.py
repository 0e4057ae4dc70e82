"""An effect plugin: accelerometer cross-coupling, a term in the product of two input components.

Load it with ``--add examples/effects/accel_cross_coupling.py:AccelCrossCoupling`` or ``--plugin``.
"""
import numpy as np

from station.model.effect import Effect, Param

G0 = 9.80665          # m/s^2 per g
UG = G0 * 1e-6        # m/s^2 per µg
PAIRS = [(i, j) for i in range(3) for j in range(3) if i != j]


class AccelCrossCoupling(Effect):
    id = "accel_cross_coupling"
    title = "Accelerometer cross-coupling: a_i a_j terms (per axis pair)"
    physics = ("A pendulous accelerometer's proof mass tilts under its own input, so a force across "
               "its axis couples in proportion to the product of the two components.")
    term = "accel_raw_i += C_ij (f_i / g0)(f_j / g0) (µg/g²), j != i, f in frame p"
    excited_by = "static attitudes with two axes sharing gravity (45° tilts, diagonal positions)"
    magnitudes = "100-3000 µg/g² (MEMS), < 20 µg/g² (quartz pendulum)"
    signature = ("accelerometer, static segments: an error at the attitudes where gravity is shared "
                 "between two axes, zero at ±1 g on one axis")
    signature_variable = "gravity_along_axis"
    complex_step = True         # accel() is complex-analytic (products and sums only)

    @property
    def params(self):
        return tuple(Param(f"accel_cross_{'xyz'[i]}{'xyz'[j]}", "ug/g^2", 1.0, 100.0, 20000.0) for i, j in PAIRS)

    def accel(self, x, ctx):
        f = ctx.f_p / G0
        out = np.zeros(ctx.f_p.shape, np.result_type(ctx.f_p, x))     # complex under complex step
        for k, (i, j) in enumerate(PAIRS):
            out[:, i] += x[k] * UG * f[:, i] * f[:, j]
        return out
