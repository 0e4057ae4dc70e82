"""A recorded ramp (record_ramp: start) whose window happens to turn a whole number of turns: the
turn is not uniform (it starts at rest and accelerates), so the Earth rate across its axis does not
average out over the whole turns, and the fit must model it (lsq._earth_rate_visible by the
window's own phase weights).  The review of the fifteenth session found the whole-turns rule of a
uniform turn applied to it: the Earth rate dropped, reduced chi2 864-1546 over four seeds."""
import numpy as np
from scipy.stats import chi2 as chi2_dist

from sim_devices.truth import default_truth
from station.estimate import lsq
from station.estimate.summaries import summarise
from station.io.scheme import scheme_from_text
from station.simulate import dryrun

# the dry run ramps at 50 deg/s^2: the ramp up to 189.842 deg/s turns 189.842^2 / (2 * 50) =
# 360.4 degrees, so a window of one steady turn after it is 719.8 degrees (2.000 turns, within
# the whole-turns rule's 1e-3)
RATE = 189.842
FACES = [[0, 0, 1], [0, 0, -1], [1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0]]
SCHEME = "name: ramps\ndefaults: {dwell_s: 2, rate_dps: %g, rotation_s: %.6f}\nsegments:\n" % (RATE, 360.0 / RATE) + \
    "".join(f"  - {{static: s{i}, up_body: {u}}}\n" for i, u in enumerate(FACES)) + """\
  - {rotation: up, axis_body: [1, 0, 0], record_ramp: start}
  - {rotation: upz, axis_body: [0, 0, 1], record_ramp: start}
  - {rotation: steady_x, axis_body: [1, 0, 0]}
  - {rotation: steady_y, axis_body: [0, 1, 0]}
  - {rotation: steady_z, axis_body: [0, 0, 1]}
"""


def test_a_ramp_window_of_whole_turns_keeps_the_earth_rate():
    cap = dryrun.simulate_capture(scheme_from_text(SCHEME, "ramps.yaml"), default_truth(1), 0)
    s = summarise(cap)
    ramps = [r for r in s.rotations if r.record_ramp]
    assert ramps and all(abs(abs(r.angle_deg) / 360.0 - 2.0) < 1e-3 for r in ramps), [r.angle_deg for r in ramps]
    for r in ramps:
        # its trace: Omega x |weights| = 0.0065 deg against the integral's noise ~2e-5 deg
        noise = np.max(s.gyro_sigma) * np.sqrt(r.duration_s / s.sample_rate_hz)
        assert np.degrees(lsq.EARTH_RATE_RAD) * np.hypot(*r.earth_weights_s) > 100 * noise
        assert lsq._earth_rate_visible(r, s), r.name
    result = lsq.fit(s, [])
    # the fit passes its own chi2 test at 0.1 % (with the Earth rate dropped: 864-1546 x dof)
    assert result.chi2 < chi2_dist.ppf(0.999, result.dof), (result.chi2, result.dof)
