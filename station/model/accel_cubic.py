"""accel_cubic: third-order scale factor (K3) of each accelerometer."""
from __future__ import annotations

from station.core import units
from station.model.effect import Effect, Param
from station.model.geometry import normalised


class AccelCubic(Effect):
    id = "accel_cubic"
    title = "Accelerometer third-order nonlinearity K3 (per axis)"
    physics = ("The pendulum's spring stiffens (or softens) and the readout saturates symmetrically, "
               "so the output gains a term in the cube of the input.  It is odd, like the scale "
               "factor: at ±1 g it is a scale-factor change, and only inputs of other sizes "
               "(gravity shared between axes) tell it from the scale factor.")
    term = "accel_raw_i += K3_i (a_i / g0)^3 (µg), a_i the specific force along sensing axis i"
    excited_by = ("static attitudes with gravity at ±1 g and at 45° on each axis (a_i^3 / a_i = 1 "
                  "against 0.5); rotations show it only through the tilted statics: 3/4 of it is "
                  "in the first harmonic (a scale factor) and 1/4 in a third harmonic")
    magnitudes = ("10-1000 µg/g³ (MEMS), 1-30 µg/g³ (quartz pendulum), < 1 µg/g³ (navigation "
                  "grade)")
    signature = ("accelerometer, static segments: an error odd in the input that the scale factor "
                 "absorbs at ±1 g and leaves at the 45° attitudes (a_i = 0.71 g: K3 (0.35 - 0.71) "
                 "= -0.35 K3); rotations: nothing the scale factor does not already give.  On a "
                 "capture with one tilted attitude per axis pair it is weakly determined; the "
                 "gravity-along-axis plot shows it")
    signature_variable = "gravity_along_axis"
    complex_step = True

    @property
    def params(self):
        return tuple(Param(f"accel_k3_{a}", "ug/g^3", 1.0, 100.0, 20000.0) for a in "xyz")

    def accel(self, x, ctx):
        """One parameter vector x (3,), or a batch X (B, 3) with a batch context (accel_batch)."""
        along = ctx.f_p @ normalised(ctx.accel_matrix).mT / units.STANDARD_GRAVITY   # g, per axis
        return x[..., None, :] * units.UG_MPS2 * along * along * along

    accel_batch = accel
