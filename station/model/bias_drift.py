"""bias_drift: biases drifting linearly in time."""
from __future__ import annotations

import numpy as np

from station.core import units
from station.model.effect import Effect, Param


class BiasDrift(Effect):
    id = "bias_drift"
    title = "Accelerometer and gyro biases drifting linearly in time (per axis)"
    physics = ("After power-on the biases wander as the sensor settles (charging, stress relief, "
               "outgassing): over a run of minutes to hours the wander is close to a straight line "
               "in time, whatever the temperature does.")
    term = ("accel_raw += d_a (t - t_ref) (µg/h); gyro_raw += d_g (t - t_ref) (°/h per hour); t the "
            "time in the run (the fit counts it from the first segment's mean time, station apply "
            "from the first sample of the data it is given, t_ref moved by the difference, kept in "
            "the file), t_ref the statics' mean time: apply compensates a recording that starts "
            "where the capture started (the same time after power-on)")
    excited_by = ("static attitudes repeated at the start and the end of the run (the same attitude "
                  "at two times); a capture whose attitudes are each visited once spreads the drift "
                  "over the attitudes' own parameters")
    magnitudes = ("10-500 µg/h and 1-50 °/h per hour (MEMS in the first hour), < 10 µg/h and "
                  "< 0.1 °/h per hour (navigation grade)")
    signature = ("static segments: residuals that follow the time in the run, the same on repeated "
                 "attitudes; both sensors.  Where the temperature follows the time (a warm-up) it "
                 "is aliased with temperature_bias: only a capture whose temperature and time part "
                 "ways (a drift after the warm-up, or a temperature that goes back) tells them apart")
    signature_variable = "time"
    complex_step = True
    needs = ("time",)
    state_fields = ("reference_s", "apply_offset_s")

    def __init__(self):
        self.reference_s = 0.0
        self.apply_offset_s = 0.0      # the fit's clock's zero less the capture's first sample (s):
                                       #   station apply counts t from the first sample (0: files before it)

    def setup(self, summaries) -> None:
        # time as the fit sees it: from the earliest segment's mean time (station.estimate.lsq)
        segs = [x for x in (*summaries.statics, *summaries.rotations) if np.isfinite(x.t_mid_s)]
        t0 = min(x.t_mid_s for x in segs) if segs else 0.0
        statics = [st.t_mid_s - t0 for st in summaries.statics if np.isfinite(st.t_mid_s)]
        self.reference_s = float(np.mean(statics)) if statics else 0.0
        # apply's clock starts at the capture's first sample, half the first segment before t0 (10 s
        # with 20 s statics: 0.08 deg/h at 30 deg/h per hour, the same offset bias_step had)
        first = min((x.t_mid_s - 0.5 * x.duration_s for x in segs if np.isfinite(x.duration_s)), default=t0)
        self.apply_offset_s = float(max(t0 - first, 0.0))

    def time_shear(self) -> tuple:
        """(parameter, the base model's bias block, its axis, per second): a drift's term at time
        t is the bias' term times (t - t_ref) x this factor (its unit per the bias' internal unit:
        accelerometer m/s^2, gyro deg/s), so a segment recorded later by s seconds has the drift's
        Jacobian plus s x factor x the bias' (station/design/information.py: the designer places
        each candidate at its time in the designed scheme)."""
        return (tuple((f"accel_bias_drift_{a}", "accel_bias", i, units.UG_MPS2 / 3600.0) for i, a in enumerate("xyz"))
                + tuple((f"gyro_bias_drift_{a}", "gyro_bias", i, 1.0 / 3600.0 / 3600.0) for i, a in enumerate("xyz")))

    @property
    def params(self):
        return (tuple(Param(f"accel_bias_drift_{a}", "ug/h", 1.0, 100.0, 1e5) for a in "xyz")
                + tuple(Param(f"gyro_bias_drift_{a}", "deg/h/h", 1.0, 10.0, 1e4) for a in "xyz"))

    def _hours(self, ctx):
        reference = self.reference_s
        if getattr(ctx, "turned_s", None) is None:         # station apply: its clock, from the first sample
            reference += float(getattr(self, "apply_offset_s", 0.0) or 0.0)
        t = ctx.column("t_s") - reference
        return np.where(np.isfinite(t), t, 0.0)[:, None] / 3600.0

    # one parameter vector x (6,) or a batch X (B, 6) with a batch context (Effect.accel_batch)
    def accel(self, x, ctx):
        return self._hours(ctx) * x[..., None, :3] * units.UG_MPS2

    def gyro(self, x, ctx):
        return self._hours(ctx) * x[..., None, 3:] / 3600.0

    accel_batch, gyro_batch = accel, gyro
