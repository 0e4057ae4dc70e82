"""Issue 28, seventeenth session: a recorded ramp is checked against the IMU as statics and steady
turns are (station/bench/steadiness.py ramp_disagreement): the gyro's own angle over the window
(its bias from the window's rest, its scale from the turns at the rate) against the table's, within
Z of their 1-sigma (the window's angle_sigma_deg, the gyro's noise) and the time offset allowed.
Here the table's position reads at the rate are misplaced by SLIP_DEG in the first recording (an
encoder that slipped): the window's angle is off by that, the recording is kept aside with the
IMU's words and recorded again; the second one agrees.  Before, it was written complete, off by
the slip.  In process on the twins, as tests/test_ramp_hold.py."""
import numpy as np

from station.io.capture import read_capture
from test_ramp_hold import SPEED, run_ramp
from test_ramp_late_command import gyro_agrees

#: the encoder's slip (deg).  The IMU's check refuses a window beyond Z = 6 of its 1-sigma
#: (steadiness.ramp_disagreement), whose largest part is the window's own angle_sigma_deg: the rate
#: times the spread of its reads' moments on the IMU's clock, the host's latency between its looks
#: at the stream and the table's answers, in device time (times the twins' speed): it grows with
#: the host's load.  A slip far beyond it on a loaded host: 150 deg, the most a slip can put a
#: window's angle off is 180 (before, 60: under load at speed 8 angle_sigma_deg reached 9-62 deg at
#: 100 deg/s and a 60 or a 150 deg slip was rightly written complete, within the check's limit;
#: docs/twins.md "A slipped encoder under load")
SLIP_DEG = 150.0
#: the twins' speed while the slipped recording is made (run_ramp's is 8): the same host latency is
#: an eighth of the device time, angle_sigma_deg an eighth (4-6 deg under that load, limits 31-41
#: deg against the slip's 150; at speed 2, 7-16 deg, limits 46-99 deg, and once accepted under a
#: load of 15-21)
SLIP_SPEED = 1.0


class Slipped:
    """The table driver; between the first recording's own command (the ramp up, set_rate without
    the driver's wait) and the next command, every position reads SLIP_DEG ahead, and the twins'
    clock runs at SLIP_SPEED (the recording's reads placed on the IMU's clock within the host's
    latency times that speed, not run_ramp's 8: see SLIP_SPEED)."""

    def __init__(self, inner, bench):
        self.inner, self.bench, self.state = inner, bench, "before"

    def __getattr__(self, name):
        return getattr(self.inner, name)

    def set_rate(self, axis, rate_dps, **kw):
        if self.state == "slipping":
            self.state = "done"
            self.bench.clock.set_speed(SPEED)
        elif self.state == "before" and not kw.get("wait", True):
            self.state = "slipping"
            self.bench.clock.set_speed(SLIP_SPEED)
        return self.inner.set_rate(axis, rate_dps, **kw)

    def read_positions_deg(self):
        pos = np.array(self.inner.read_positions_deg(), float)
        return (pos + SLIP_DEG) % 360.0 if self.state == "slipping" else pos


def test_a_ramp_the_imu_disagrees_with_is_recorded_again(tmp_path):
    made = []
    seq = run_ramp(tmp_path, "start", lambda table, bench: made.append(Slipped(table, bench)) or made[-1])
    assert made[0].state == "done"
    assert (tmp_path / "cap" / "r.csv.incomplete").is_file(), list((tmp_path / "cap").iterdir())
    said = seq.console.file.getvalue()
    assert "the IMU's gyro turned" in said and "kept aside, recording it again" in said, said[-3000:]
    # the second recording agrees with the gyro (the twins' truth: a reference sharing no code with
    # the check) within 5 x its 1-sigma (test_ramp_late_command.gyro_agrees)
    r = next(s for s in read_capture(tmp_path / "cap", load_data=True).segments if s.status == "complete")
    imu, angle, bound = gyro_agrees(r)
    assert abs(imu - angle) < bound, (imu, angle, bound)
