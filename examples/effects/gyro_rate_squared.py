"""An effect plugin: a gyro scale factor that grows with the rate (a rate-squared term).

Load it with ``station estimate CAPTURE --add examples/effects/gyro_rate_squared.py:GyroRateSquared``
(or ``--plugin`` to make it a candidate of ``station diagnose``); docs/effects.md explains each part.
"""
from station.model.effect import Effect, Param
from station.model.geometry import analytic_abs


class GyroRateSquared(Effect):
    id = "gyro_rate_squared"
    title = "Gyro scale factor growing with the rate (rate-squared term, per axis)"
    physics = ("The gyro's scale factor is not constant over its range: a term in the square of the "
               "input rate (signed, so that it is odd like the rate) bends the transfer curve.")
    term = "gyro_raw_i += q_i 1e-6 w_i |w_i| (q in ppm per deg/s; w_i the rate along gyro i, deg/s)"
    excited_by = "rotations at two or more rates about each gyro's axis"
    magnitudes = "1-20 ppm/(deg/s) (MEMS), < 0.1 ppm/(deg/s) (FOG, RLG)"
    signature = ("gyro, rotation segments: an integrated-rate error growing with the square of the "
                 "rate, opposite signs in the two directions")
    signature_variable = "rate_squared"
    complex_step = True         # gyro() is complex-analytic: |w| through analytic_abs, not np.abs

    @property
    def params(self):
        # name, unit, reported = internal * scale, typical size, largest plausible size
        return tuple(Param(f"gyro_rate2_{a}", "ppm/(deg/s)", 1.0, 5.0, 1000.0) for a in "xyz")

    def gyro(self, x, ctx):
        w = ctx.w_p @ ctx.gyro_matrix.T          # the rate along each gyro's sensing axis, deg/s
        return 1e-6 * x * w * analytic_abs(w)

