"""gyro_rate_nonlinearity: gyro terms in the square of the rate, even (w^2) and odd (w|w|)."""
from __future__ import annotations

from station.model.effect import Effect, Param
from station.model.geometry import analytic_abs


class GyroRateNonlinearity(Effect):
    id = "gyro_rate_nonlinearity"
    title = "Gyro scale factor changing with the rate: w² (even) and w|w| (odd) terms (per axis)"
    physics = ("The gyro's transfer curve bends over its range (the drive and sense loops, the "
               "readout's gain): an odd term w|w| is a scale factor that grows with the rate, the "
               "same relative change in both directions; an even term w² reads the same sign "
               "both ways, like an asymmetry that grows with the rate.")
    term = ("gyro_raw_i += 1e-6 (q_i r_i^2 + p_i r_i |r_i|), r_i = (K_g T_g R_po w_p)_i in °/s, "
            "q and p in ppm/(°/s) (at 100 °/s, 1 ppm/(°/s) is 100 ppm of the rate)")
    excited_by = ("rotations at two or more rates about each gyro's axis, both directions: at one "
                  "rate w² is an asymmetry and w|w| a scale factor")
    magnitudes = "0.5-20 ppm/(°/s) (MEMS), 0.01-0.5 ppm/(°/s) (FOG), < 0.01 ppm/(°/s) (ring laser)"
    signature = ("gyro, rotation segments: an integral error that grows with the square of the "
                 "rate; the ± halves of a pair err alike (w²) or oppositely (w|w|).  At a single "
                 "rate it is aliased with gyro_scale_asymmetry (w²) and the scale factor (w|w|): "
                 "diagnose then names the asymmetry")
    signature_variable = "rate_squared"
    complex_step = True

    @property
    def params(self):
        return (tuple(Param(f"gyro_rate_sq_even_{a}", "ppm/(deg/s)", 1.0, 1.0, 1000.0) for a in "xyz")
                + tuple(Param(f"gyro_rate_sq_odd_{a}", "ppm/(deg/s)", 1.0, 1.0, 1000.0) for a in "xyz"))

    def gyro(self, x, ctx):
        """One parameter vector x (6,), or a batch X (B, 6) with a batch context (gyro_batch)."""
        r = ctx.w_p @ ctx.gyro_matrix.mT                      # deg/s along each gyro
        return 1e-6 * (x[..., None, :3] * r * r + x[..., None, 3:] * r * analytic_abs(r))

    gyro_batch = gyro
