"""Issue 28 item 3 (fifteenth session): `station run` records turns whose ramp is in the window on
the device twins over pseudo-terminals (the sequencer commands the rate inside the window and
places the table's reads on the IMU's clock: station/bench/ramp_angle.py); the review's items 1, 5
and 6: each window's angle carries its reads' placement (angle_sigma_deg) and the capture's fit
with a time offset is honest.  One capture (module fixture) for both tests: the run is the cost."""
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from sim_devices.truth import default_truth
from sim_devices.twins.serve import BenchOptions, BenchServer
from station.io.capture import read_capture

SPEED = 8.0
RATE, ACCEL = 100.0, 300.0
OFFSET_S = 0.005
CONFIG = f"""\
version: 1
table:
  axes: 3
  limits: [{{max_rate_dps: 300, max_accel_dps2: 300, move_rate_dps: 60, move_accel_dps2: 60, rate_accel_dps2: {ACCEL:g}}}]
run: {{operator: false, settle_s: 0.5, max_missing_fraction: 0.02, max_gap_s: 2.0, rerecord_attempts: 5}}
"""
# six statics, steady pairs about every axis (they determine the gyros) and a ramp up and a brake
# each way about z (they see the time offset): ~15 s on two loaded cores at speed 8
SCHEME = f"""\
name: ramps-fit
defaults: {{dwell_s: 1, rate_dps: {RATE:g}, rotation_s: 3.6}}
segments:
  - {{static: s0, up_body: [0, 0, 1]}}
  - {{static: s1, up_body: [0, 0, -1]}}
  - {{static: s2, up_body: [1, 0, 0]}}
  - {{static: s3, up_body: [-1, 0, 0]}}
  - {{static: s4, up_body: [0, 1, 0]}}
  - {{static: s5, up_body: [0, -1, 0]}}
  - {{rotation: up, axis_body: [0, 0, 1], record_ramp: start}}
  - {{rotation: down, axis_body: [0, 0, 1], record_ramp: end}}
  - {{rotation: stx, axis_body: [1, 0, 0]}}
  - {{rotation: sty, axis_body: [0, 1, 0]}}
  - {{rotation: stz, axis_body: [0, 0, 1]}}
"""


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """(the run's directory, its completed process): the scheme on the twins, 5 ms clock offset."""
    d = tmp_path_factory.mktemp("ramp_twins")
    (d / "station.yaml").write_text(CONFIG)
    (d / "s.yaml").write_text(SCHEME)
    truth = default_truth(11)
    truth.bench.time_offset_s = OFFSET_S
    with BenchServer(truth, BenchOptions(speed=SPEED, seed=11, axes=3, lossless=True)) as bench:
        proc = subprocess.run([sys.executable, "-m", "station.cli", "run", "--config", "station.yaml",
                               "--port", bench.imu_path, "--table-port", bench.table_path, "--scheme", "s.yaml",
                               "--out", "cap", "--no-history"], cwd=d, capture_output=True, text=True,
                              timeout=300)
    return d, proc


def test_the_twins_record_a_ramp_up_and_a_brake_with_their_rates_and_angles(run):
    """The manifest says which ramp each window keeps, the table's rates at its edges and the angle;
    the gyro's own integral over the window agrees with that angle within what the twins' scale
    error, the 5 ms clock offset and the placement of the reads allow: per read, its bracket (the IMU
    stamps before and after it, recorded in table_reads) times the rate; the mean of the reads
    is within the widest bracket of the truth, so |integral - angle - dt dw| <= |w| (widest
    bracket + one period) + 2000 ppm of the angle (the twin's gyro scale errors are ~1000 ppm)."""
    d, proc = run
    assert proc.returncode in (0, 3), proc.stderr[-2000:]    # the run's own estimate has no time offset
    capture = read_capture(d / "cap", load_data=True)
    ramps = {s.name: s for s in capture.segments if s.extra.get("record_ramp")}
    assert set(ramps) == {"up_p", "up_m", "down_p", "down_m"}
    assert all(s.status == "complete" for s in ramps.values())
    for name, s in ramps.items():
        kind = "start" if name.startswith("up") else "end"
        sign = np.sign(s.rate_dps)
        assert s.extra["record_ramp"] == kind and s.extra["ramp_accel_dps2"] == ACCEL
        edges = (s.extra["rate_start_dps"], s.extra["rate_end_dps"])
        assert (edges[0] == 0.0) == (kind == "start") and (edges[1] == 0.0) == (kind == "end")
        moving = edges[1] if kind == "start" else edges[0]
        assert abs(moving - sign * RATE) < 0.01
        g = s.data.gyro @ np.asarray(s.axis_body, float)
        rest, turning = (g[:3], g[-3:]) if kind == "start" else (g[-3:], g[:3])
        assert abs(rest.mean()) < 1.0 and abs(turning.mean() - sign * RATE) < 1.0
        integral = float(np.gradient(s.data.t) @ g)
        reads = np.array(s.extra["table_reads"], float)
        widest = float(np.max(reads[:, 3] - reads[:, 2]))
        dw = edges[1] - edges[0]
        bound = RATE * (widest + 1.0 / capture.imu.sample_rate_hz) + 2e-3 * abs(s.angle_deg)
        assert abs(integral - s.angle_deg - OFFSET_S * dw) < bound, (name, integral, s.angle_deg, bound)
        # the angle's own 1-sigma from the reads' placement: their brackets (w / sqrt 12, w one
        # to several periods) times the rate, so between a period's and the widest bracket's
        period = 1.0 / capture.imu.sample_rate_hz
        sigma = s.extra["angle_sigma_deg"]
        assert RATE * period / np.sqrt(12) <= sigma <= RATE * (widest + period), (name, sigma)
    # the window holds the turn at the rate (3.6 s: a revolution) and the ramp, the rest more or less
    assert all(abs(s.angle_deg) > 300.0 for s in ramps.values())
    assert Path(d / "cap" / "manifest.yaml").read_text().count("record_ramp") == 4
    assert yaml.safe_load((d / "cap" / "manifest.yaml").read_text())["format"] == "station-capture/1"


@pytest.fixture(scope="module")
def fitted(run):
    """The run's capture fitted with --add time_offset as station estimate fits it (the API's
    estimate, in this process): (the Estimate, its calibration file's content)."""
    from station import api

    d, _ = run
    est = api.estimate(d / "cap", add=["time_offset"])
    est.save(d / "cal.yaml")
    return est, yaml.safe_load((d / "cal.yaml").read_text())


def test_the_fit_of_a_ramp_capture_with_a_time_offset_is_honest(fitted):
    """Issue 28 review items 1, 5 and 6: the capture fitted with --add time_offset.  Each window's
    angle carries its reads' placement on the IMU's clock (tens of ms of bracket at 100 deg/s:
    about a degree), written as angle_sigma_deg and weighted so; before, every window was weighted
    as the encoder's 2" (the review's capture: reduced chi2 813).  Honest: the rotations' gyro
    integrals -- the rows the windows' angles weigh -- scatter as their stated noise says: their
    chi2 lies between chi2's 0.05 % and 99.95 % points for their redundancy (a 1-sigma too small
    fails above, too large below).  The whole fit's verdict is not asserted: on the twins the 3.6 s
    steady turns' accelerometer harmonics scatter 1.08-1.29 x their noise from run to run (the
    twins' timing under load, not the ramp windows: CI at load ~3 failed the whole fit at 1.49
    where three runs at load 2 gave 1.05-1.23); the file says so when it fails."""
    from scipy.stats import chi2 as chi2_dist

    _, cal = fitted
    # the steady turns' and the ramps' gyro integrals (the ramps a group of their own since the
    # eighteenth session: four windows keep their stated 1-sigma, too few to estimate it)
    groups = [g for g in cal["fit"]["noise_groups"] if g["group"] in ("rotation gyro", "ramp gyro")]
    ramp = next(g for g in groups if g["group"] == "ramp gyro")
    assert ramp["rows"] == 12 and ramp["placement_k"] == 1.0 and not ramp["placement_estimated"], ramp
    gyro = {"chi2": sum(g["chi2"] for g in groups), "redundancy": sum(g["redundancy"] for g in groups)}
    low, high = chi2_dist.ppf([0.0005, 0.9995], gyro["redundancy"])
    assert low < gyro["chi2"] < high, groups
    assert "time_offset" in cal["effects"]


def test_the_time_offset_of_a_ramp_capture_is_held_by_its_prior_and_its_data_say_the_twins_5_ms(fitted):
    """Issue 28, seventeenth session ("the time offset's bias", docs/design.md): the fitted offset
    came out ~0.6 ms for the twins' 5 ms, 1.7 of its 1-sigma low in every run.  Not a half sample
    (the dry run recovers 0, 5 and 10 ms at 50, 100 and 200 Hz within 0.013 ms): the four ramp
    windows, their angles placed within 1-3 deg on the IMU's clock, give the offset a 1-sigma of
    ~6 ms of their own, above its typical 3 ms, so the fit holds it at 0 +/- 3 ms by a prior and
    says so; what it writes is that posterior, pulled toward 0 by the data's weight in it
    ((1/6^2) / (1/6^2 + 1/3^2) ~ 0.2: ~1 ms expected for 5).  The file must say it is not revealed
    and, since the eighteenth session (a calibration never lies), not write it: not under
    parameters, named in fit.not_determined, compensated at its nominal 0.  The posterior stays in
    the estimate (Estimate.held), and the data's own estimate -- that value and 1-sigma less the
    prior (a Gaussian prior of width p on the parameter alone: information 1/s^2 - 1/p^2, value
    x / (s^2 info)) -- must lie within 4 of its own 1-sigma of the twins' 5 ms.  Without the prior
    (a fit that takes the offset as revealed at ~6 ms) the note is missing, the offset written and
    the 1-sigma above 3 ms: fails."""
    from station.model.time_offset import TimeOffset

    est, cal = fitted
    held = [n for n in cal["fit"]["notes"] if n.startswith("not revealed by this capture")]
    assert held and held[0].endswith(": time_offset"), cal["fit"]["notes"]
    assert "time_offset" not in cal["parameters"] and "time_offset" in cal["fit"]["not_determined"]
    entry = next(e for e in cal["compensation"]["effects"] if e["id"] == "time_offset")
    assert entry["parameters"] == {"time_offset": 0.0} and entry["not_determined"] == ["time_offset"]
    typical = TimeOffset().params[0].typical
    value, sigma = est.held["time_offset"].value, est.held["time_offset"].sigma
    assert sigma < typical, (value, sigma)
    info = 1.0 / sigma ** 2 - 1.0 / typical ** 2
    own_value, own_sigma = value / (sigma ** 2 * info), info ** -0.5
    assert abs(own_value - OFFSET_S * 1e3) < 4.0 * own_sigma, (value, sigma, own_value, own_sigma)
