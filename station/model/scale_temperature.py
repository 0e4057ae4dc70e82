"""scale_temperature: scale factors linear in temperature (accelerometers and gyros)."""
from __future__ import annotations


from station.model.effect import Param
from station.model.temperature import TemperatureReferenced


class ScaleTemperature(TemperatureReferenced):
    id = "scale_temperature"
    title = "Accelerometer and gyro scale factors linear in temperature (per axis)"
    physics = ("The scale factor drifts with the sensor's temperature (spring stiffness, magnet "
               "strength, reference voltage, drive amplitude), nearly linearly over a few degrees: "
               "the same attitude or rate reads a little more or less as the IMU warms, in "
               "proportion to the input.")
    term = ("accel_raw_i += s_a,i 1e-6 (T - T_ref) (K_a T_a f_p)_i (s_a in ppm/°C); "
            "gyro_raw_i += s_g,i 1e-6 (T - T_ref) (K_g T_g R_po w_p)_i (s_g in ppm/°C); "
            "T_ref the mean temperature of the static segments (temperature_bias's)")
    excited_by = ("segments recorded at different temperatures with large inputs: ±1 g statics "
                  "(accelerometers) and rotations (gyros) repeated across a warm-up")
    magnitudes = ("50-500 ppm/°C (MEMS gyros), 20-300 ppm/°C (MEMS accelerometers), 1-20 ppm/°C "
                  "(FOG, quartz)")
    signature = ("rotation segments: a gyro integral error proportional to the angle and to the "
                 "segment's temperature (the ± halves of a pair err in opposite directions, so it "
                 "is not an asymmetry; over several rates it is linear in the rate, so it is not a "
                 "rate-squared term); statics: an accelerometer error proportional to the gravity "
                 "along the axis and to the temperature, opposite at +1 g and -1 g.  Where the "
                 "warm-up visits +1 g and -1 g at different temperatures it is partly aliased with "
                 "temperature_bias")
    signature_variable = "temperature"
    complex_step = True
    @property
    def params(self):
        return (tuple(Param(f"accel_scale_tempco_{a}", "ppm/degC", 1.0, 30.0, 5000.0) for a in "xyz")
                # a MEMS gyro's typical size, the middle of its 50-500 ppm/degC (magnitudes): at 30
                # (an accelerometer's) a 2 degC warm-up, which sizes it to ~30 ppm/degC, left the gyros
                # held at 0 +/- 30 by the prior, a 300 ppm/degC scale slope was fitted as 85 and
                # --auto took a rate-squared term at one rate for it (benchmarks/diagnose_goal.py,
                # gyro_scale_tempco_2C and K3+gyro_scale_tempco)
                + tuple(Param(f"gyro_scale_tempco_{a}", "ppm/degC", 1.0, 150.0, 5000.0) for a in "xyz"))

    # one parameter vector x (p,) or a batch X (B, p) with a batch context (Effect.accel_batch):
    # the same arithmetic, the points' axis second to last
    def accel(self, x, ctx):
        return 1e-6 * x[..., None, :3] * self._dt(ctx) * (ctx.f_p @ ctx.accel_matrix.mT)

    def gyro(self, x, ctx):
        return 1e-6 * x[..., None, 3:] * self._dt(ctx) * (ctx.w_p @ ctx.gyro_matrix.mT)

    accel_batch, gyro_batch = accel, gyro
