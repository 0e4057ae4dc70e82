"""Issue 28 item 1 (sixteenth session): `station design --add time_offset` took 111.5 s of CPU
because every noiseless fit of a chunk with ramp windows about vertical axes tried each axis'
"other crossing" (lsq._other_crossing) as a whole fit.  About an axis that is also turned in whole
turns (no Earth-rate phase) the tilt is pinned by their gyro integrals and there is no other
crossing; and a ramp window's Earth factor is its own weights', not a uniform turn's."""
import numpy as np

from sim_devices.truth import default_truth
from station.estimate import lsq
from station.estimate.summaries import summarise
from station.io.scheme import scheme_from_text
from station.simulate import dryrun

FACES = "".join(f"  - {{static: s{i}, up_body: {u}}}\n" for i, u in enumerate(
    [[0, 0, 1], [0, 0, -1], [1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [1, 1, 1], [-1, 1, 0], [0, 1, -1]]))


def _model(turns: str):
    truth = default_truth(1)
    truth.accel.noise_density = truth.gyro.noise_density = 0.0
    truth.bench.accel_disturbance_ug = truth.bench.table_angle_error_arcsec = 0.0
    text = ("name: c\ndefaults: {dwell_s: 2, rate_dps: 100, rotation_s: 3.6}\nsegments:\n" + FACES + turns)
    capture = dryrun.simulate_capture(scheme_from_text(text, "c.yaml"), truth, 3)
    capture.extra["noise_free"] = True
    s = summarise(capture, table_angle_arcsec=2.0)
    s.accel_sigma = np.full(3, 1e-3 * 9.80665)          # 100 ug/sqrt(Hz) at 100 Hz
    s.gyro_sigma = np.full(3, 0.03 * 10 / 3600.0)        # 0.03 deg/h/sqrt(Hz) at 100 Hz
    return lsq.Model(s, [], attitudes="unknown")


RAMP = "  - {rotation: up, axis_body: [0, 0, 1], axis_elevation_deg: 90, record_ramp: start}\n"
STEADY = "  - {rotation: steady, axis_body: [0, 0, 1], axis_elevation_deg: 90}\n"


def test_whole_turns_about_the_axis_pin_its_tilt_no_other_crossing():
    """With a steady whole-turn pair about the same vertical axis the reflected point misfits the
    whole turns' integrals (A d, d ~ 12 urad: chi2 ~1e5 above, noise-free): no flip is tried.
    Without it (the ramp pair alone) the other crossing is a start, and it fits the gyro
    integrals: its chi2 is within the accelerometers' price of the tilt (a few units), not 1e5."""
    model = _model(RAMP + STEADY)
    group = model.s.rotations[[r.name for r in model.s.rotations].index("up_p")].group
    x = lsq._solve(model, model.x0)[0]
    assert lsq._other_crossing(model, x, group) is None
    alone = _model(RAMP)
    x = lsq._solve(alone, alone.x0)[0]
    other = lsq._other_crossing(alone, x, 0)
    assert other is not None
    r0, r1 = alone.residuals(x), alone.residuals(other)
    # noise-free: the two crossings fit the ramp windows' integrals exactly, the accelerometers see
    # the ~12 urad tilt at ~20 urad/sqrt(N) -- a chi2 of order one; a uniform turn's factor for the
    # ramp windows put the reflected point 1e4-1e5 of chi2 away
    assert r1 @ r1 - r0 @ r0 < 100.0
