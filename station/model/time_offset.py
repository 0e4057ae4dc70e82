"""time_offset: the IMU's clock against the table's."""
from __future__ import annotations

import numpy as np

from station.model.effect import Effect, Param


class TimeOffset(Effect):
    id = "time_offset"
    title = "Time offset between the IMU's time stamps and the table's encoder"
    physics = ("The IMU stamps its samples with its own clock and the table reads its encoder with "
               "another; a latency between them shifts the window over which the gyro is "
               "integrated against the one over which the table measured the angle.  While the "
               "rate is constant the shift changes nothing; where the rate changes it does.")
    term = ("gyro_integral += dt (w_end - w_start): the samples cover the encoder window shifted "
            "by dt (positive: the sample stamped t was taken at t + dt on the table's clock, i.e. "
            "the IMU's stamps run behind)")
    excited_by = ("rotation segments whose rate differs at their start and end (ramps, rate "
                  "ripple, a rate that drifts); a constant-rate capture cannot reveal it")
    magnitudes = "1-10 ms (USB and serial links, buffered MEMS), < 0.1 ms (hardware-synchronised)"
    signature = ("gyro, rotation segments: an integral error proportional to the change of rate "
                 "across the segment; zero for steady rotations")
    signature_variable = "rate_change"
    complex_step = True

    @property
    def params(self):
        return (Param("time_offset", "ms", 1e3, 3.0, 200.0),)

    def compensate_time(self, x, t):
        """The sample stamped t was taken at t + x[0] on the table's clock (the sign of the integral
        term: the samples selected by their stamps in the encoder window [t0, t1] cover the table
        times [t0 + dt, t1 + dt], whose integral is the window's plus dt (w(t1) - w(t0)))."""
        return t + x[0]

    def integral(self, x, rotation):
        return x[0] * (rotation.gyro_end - rotation.gyro_start)

    def integral_batch(self, X, rotations):
        """integral() of every row of X (B, 1) and every rotation at once, (B, R, 3): the fit's
        residuals call it for each batch of the Jacobian (lsq.Model._blocks), B x R calls of
        integral() before (the nineteenth session: 11 s of the 37 s of CPU of
        tests/test_ramp_placement_scatter.py)."""
        change = np.array([r.gyro_end - r.gyro_start for r in rotations], float).reshape(len(rotations), 3)
        return X[:, :1, None] * change[None, :, :]

    def window_shift_s(self, x):
        """The integral term is the window's shift times the measured rate's change, the Earth
        rate's included; the estimator's Earth term is over the samples' own phases, already
        shifted, so it takes the Earth's share of the change out (lsq.Model: else counted twice,
        and across the axis that pulled the offset toward 0, issue 28, nineteenth session)."""
        return x[0]
