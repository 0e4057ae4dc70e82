"""accel_nonlinearity: second-order scale factor of each accelerometer."""
from __future__ import annotations

from station.core import units
from station.model.effect import Effect, Param
from station.model.geometry import normalised


class AccelNonlinearity(Effect):
    id = "accel_nonlinearity"
    title = "Accelerometer second-order nonlinearity K2 (per axis)"
    physics = ("An accelerometer's output is not exactly proportional to its input: the pendulum's "
               "spring and the readout add a term in the square of the input.  It is the same sign "
               "for +1 g and -1 g, so it looks like a bias that depends on the attitude.")
    term = "accel_raw_i += K2_i (a_i / g0)^2 (µg), a_i the specific force along sensing axis i"
    excited_by = ("static attitudes with an axis at ±1 g and at 45° (0.5 g²), and rotations that "
                  "sweep gravity through every axis")
    magnitudes = ("100-2000 µg/g² (MEMS: 0.1-0.5 % of a ±2 to ±8 g range), 5-20 µg/g² (quartz "
                  "pendulum), < 5 µg/g² (navigation grade)")
    signature = ("accelerometer, every segment: an error even in the square of the input, the same "
                 "sign at +1 g and -1 g, half as large at 45°, a second harmonic in rotations")
    signature_variable = "gravity_along_axis"
    complex_step = True

    @property
    def params(self):
        return tuple(Param(f"accel_k2_{a}", "ug/g^2", 1.0, 100.0, 5000.0) for a in "xyz")

    def accel(self, x, ctx):
        """One parameter vector x (3,), or a batch X (B, 3) with a batch context (accel_batch)."""
        along = ctx.f_p @ normalised(ctx.accel_matrix).mT      # along each sensing direction
        return x[..., None, :] * units.UG_MPS2 * (along / units.STANDARD_GRAVITY) ** 2

    accel_batch = accel
