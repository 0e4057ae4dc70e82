"""temperature_bias: biases linear in temperature."""
from __future__ import annotations

import numpy as np

from station.core import units
from station.model.effect import Effect, Param

# the effects whose terms are in the square of (T - T_ref), library and unlisted: the designer
# places them on its timeline as dT^2 (station.design.information.temperature_power), and a
# capture reveals them only with each axis at three or more temperatures (diagnose's words:
# station.diagnose.unrevealed)
SQUARED_IN_TEMPERATURE = ("temperature_bias_quadratic", "accel_scale_temperature_squared",
                          "gyro_scale_temperature_squared")


class TemperatureReferenced(Effect):
    """An effect in the temperature's difference from a reference, the mean temperature of the
    static segments (shared by temperature_bias, scale_temperature and
    temperature_bias_quadratic, so that their terms are about the same point).  Not an effect of
    its own: no id."""
    needs = ("temperature",)
    state_fields = ("reference_c", "available")

    def __init__(self):
        self.reference_c = 0.0
        self.available = True

    def setup(self, summaries) -> None:
        temps = [st.temp_c for st in summaries.statics if st.temp_c is not None]
        self.available = bool(temps)
        self.reference_c = float(np.mean(temps)) if temps else 0.0

    def _dt(self, ctx):
        """(points, 1): T - T_ref (0 where the temperature is not known)."""
        dt = ctx.temp_c - self.reference_c
        return np.where(np.isfinite(dt), dt, 0.0)[:, None]


class TemperatureBias(TemperatureReferenced):
    id = "temperature_bias"
    title = "Accelerometer and gyro biases linear in temperature"
    physics = ("Bias drifts with the sensor's temperature (mechanical stress, electronics offsets), "
               "nearly linearly over a few degrees.  During warm-up the biases move although the "
               "attitude does not.")
    term = ("accel_raw += c_a (T - T_ref) (µg/°C); gyro_raw += c_g (T - T_ref) (°/h/°C); "
            "T_ref the mean temperature of the static segments")
    excited_by = "segments recorded at different temperatures (warm-up, or a run spanning a drift)"
    magnitudes = "10-100 µg/°C and 1-10 °/h/°C (MEMS), 1-10 µg/°C and 0.01-0.1 °/h/°C (FOG, quartz)"
    signature = ("static segments: residuals that follow the temperature, the same on repeated "
                 "attitudes recorded at different temperatures; both sensors")
    signature_variable = "temperature"
    complex_step = True
    state_fields = ("reference_c", "available", "factors")

    def __init__(self):
        super().__init__()
        self.factors = (1.0, 1.0)

    def setup(self, summaries) -> None:
        super().setup(summaries)
        self.factors = (summaries.accel_factor, summaries.gyro_factor)

    @property
    def params(self):
        return (tuple(Param(f"accel_bias_tempco_{a}", "ug/degC", 1.0, 30.0, 1000.0) for a in "xyz")
                + tuple(Param(f"gyro_bias_tempco_{a}", "deg/h/degC", 1.0, 3.0, 300.0) for a in "xyz"))

    # one parameter vector x (6,) or a batch X (B, 6) with a batch context (Effect.accel_batch)
    def accel(self, x, ctx):
        return self._dt(ctx) * x[..., None, :3] * units.UG_MPS2

    def gyro(self, x, ctx):
        return self._dt(ctx) * x[..., None, 3:] / 3600.0

    accel_batch, gyro_batch = accel, gyro

    def report(self, x, cov):
        """Compensation data: raw units per degree C, and the reference temperature."""
        return {"temperature_reference_c": self.reference_c,
                "accel_bias_tempco_raw_per_c": x[:3] * units.UG_MPS2 / self.factors[0],
                "gyro_bias_tempco_raw_per_c": x[3:] / 3600.0 / self.factors[1]}
