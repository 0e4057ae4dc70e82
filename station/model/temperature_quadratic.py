"""temperature_bias_quadratic: the second-order term of the biases' temperature dependence."""
from __future__ import annotations


from station.core import units
from station.model.effect import Param
from station.model.temperature import TemperatureReferenced


class TemperatureBiasQuadratic(TemperatureReferenced):
    id = "temperature_bias_quadratic"
    title = "Accelerometer and gyro biases quadratic in temperature (the T² term)"
    physics = ("Over a wider temperature range the bias curve bends: the second-order term of its "
               "temperature dependence.  It is the T² term only, about the same reference as "
               "temperature_bias, so the two add (the linear term is temperature_bias's; alone, "
               "this effect says the slope is zero at T_ref).")
    term = ("accel_raw += c2_a (T - T_ref)^2 (µg/°C²); gyro_raw += c2_g (T - T_ref)^2 (°/h/°C²); "
            "T_ref the mean temperature of the static segments (temperature_bias's)")
    excited_by = ("segments recorded over a temperature range of several °C, with the same attitude "
                  "(or the same bias) repeated at three or more temperatures")
    magnitudes = ("1-20 µg/°C² and 0.05-2 °/h/°C² (MEMS), < 0.5 µg/°C² and < 0.01 °/h/°C² (FOG, "
                  "quartz)")
    signature = ("static segments: residuals that follow the square of the temperature's distance "
                 "from the mean (after the linear term is fitted: a bow, the ends of the warm-up "
                 "against its middle); both sensors.  Over a warm-up that is a function of time it "
                 "is aliased with any smooth drift in time")
    signature_variable = "temperature"
    complex_step = True
    @property
    def params(self):
        return (tuple(Param(f"accel_bias_tempco2_{a}", "ug/degC^2", 1.0, 5.0, 500.0) for a in "xyz")
                + tuple(Param(f"gyro_bias_tempco2_{a}", "deg/h/degC^2", 1.0, 0.5, 100.0) for a in "xyz"))

    def _dt2(self, ctx):
        return self._dt(ctx) ** 2

    # one parameter vector x (6,) or a batch X (B, 6) with a batch context (Effect.accel_batch)
    def accel(self, x, ctx):
        return self._dt2(ctx) * x[..., None, :3] * units.UG_MPS2

    def gyro(self, x, ctx):
        return self._dt2(ctx) * x[..., None, 3:] / 3600.0

    accel_batch, gyro_batch = accel, gyro
