"""accel_cross_axis: accelerometer output in the product of its input and a cross-axis force."""
from __future__ import annotations

import numpy as np

from station.core import units
from station.model.effect import Effect, Param
from station.model.geometry import normalised

PAIRS = tuple((i, j) for i in range(3) for j in range(3) if i != j)


class AccelCrossAxis(Effect):
    id = "accel_cross_axis"
    title = "Accelerometer cross-axis nonlinearity: a_i f_j products (per axis pair)"
    physics = ("A pendulous accelerometer's proof mass swings under its own input, so a force "
               "across its axis then acts on it too: a term in the product of the input and the "
               "cross-axis component (the pendulum's cross-coupling).  It is second order, like "
               "K2, but zero with gravity along one axis.")
    term = ("accel_raw_i += C_ij (a_i / g0)(f_j / g0) (µg/g²), j != i, a_i along sensing axis i, "
            "f_j the component along axis j of frame p")
    excited_by = ("static attitudes with gravity shared between two axes (the 45° attitudes: "
                  "a_i f_j = 0.5 g²) against those with gravity along one axis (zero); rotations "
                  "about the diagonal axes")
    magnitudes = "100-3000 µg/g² (MEMS), 5-50 µg/g² (quartz pendulum), < 5 µg/g² (navigation grade)"
    signature = ("accelerometer, static segments: an error at the attitudes where gravity is shared "
                 "between two axes, zero at ±1 g on one axis, with the sign of the product; with "
                 "one 45° attitude per axis pair (optimal9) C_ij and C_ji of a pair share it with the "
                 "misalignments, and rotations about the diagonal axes separate them")
    signature_variable = "gravity_along_axis"
    complex_step = True

    @property
    def params(self):
        return tuple(Param(f"accel_cross_{'xyz'[i]}{'xyz'[j]}", "ug/g^2", 1.0, 100.0, 20000.0) for i, j in PAIRS)

    def accel(self, x, ctx):
        g = units.STANDARD_GRAVITY
        # x (6,), or a batch X (B, 6) with a batch context (accel_batch): the points' axis second to last
        along = ctx.f_p @ normalised(ctx.accel_matrix).mT / g       # a_i, g
        f = ctx.f_p / g
        rows = []
        for i in range(3):
            term = 0.0
            for k, (ii, j) in enumerate(PAIRS):
                if ii == i:
                    term = term + x[..., k, None] * f[..., j]
            rows.append(along[..., i] * term)
        return units.UG_MPS2 * np.stack(rows, axis=-1)

    accel_batch = accel
