"""gyro_scale_asymmetry: different scale factors for positive and negative rates."""
from __future__ import annotations

from station.model.effect import Effect, Param
from station.model.geometry import analytic_abs


class GyroScaleAsymmetry(Effect):
    id = "gyro_scale_asymmetry"
    title = "Gyro scale-factor asymmetry (per axis)"
    physics = ("The gyro's scale factor differs slightly between positive and negative rates, "
               "from the drive and sense electronics or the closed loop.  A ± rotation pair then "
               "gives unequal magnitudes although the table turned the same angle.")
    term = "gyro_raw_i += A_i 1e-6 |(K_g T_g R_po w)_i|  (scale k(1+A) for positive, k(1-A) for negative)"
    excited_by = "rotation pairs in both directions about each gyro's axis (fast rotations)"
    magnitudes = "100-1000 ppm (MEMS), 10-100 ppm (FOG), < 5 ppm (ring laser)"
    signature = ("gyro, rotation segments: the ± integrals differ in magnitude by a fraction of the "
                 "angle, same sign for every axis pair; nothing at rest")
    signature_variable = "signed_rate"
    complex_step = True

    @property
    def params(self):
        return tuple(Param(f"gyro_asym_{a}", "ppm", 1.0, 300.0, 20000.0) for a in "xyz")

    def gyro(self, x, ctx):
        """One parameter vector x (3,), or a batch X (B, 3) with a batch context (gyro_batch)."""
        return 1e-6 * x[..., None, :] * analytic_abs(ctx.w_p @ ctx.gyro_matrix.mT)

    gyro_batch = gyro
