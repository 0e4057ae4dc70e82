"""The noise model every data group is weighted with (station/estimate/noise_model.py, lsq.fit's
reweighting): the hand turns' 1-sigma estimated from their scatter, the bias moving between poses
when the poses' halves show it moving, both stated in the file, and the verdict taken on what is
left to test.  The references here share no code with the product: the simulated sessions'
drawn turn errors and bias walk (sim_devices/hand.py), and numpy's own sums."""
from __future__ import annotations

import numpy as np
from scipy import stats

from sim_devices.hand import hand_session
from sim_devices.truth import mems_truth
from station import cli
from station.estimate import estimate_capture
from station.estimate.noise_model import pose_instability
from station.estimate.summaries import StaticSummary
from station.model.calibration import parameter_errors
from station.simulate.dryrun import truth_calibration

from test_pose_check import import_session

BLOCKS = ("accel_scale", "accel_misalignment", "accel_bias", "gyro_scale", "gyro_misalignment", "gyro_bias")


def session(seed, turn_error_deg=0.0, gyro_walk_dph=0.0, tau_s=10.0):
    """An MPU-like gyro (20 deg/h/sqrt(Hz), 0.061 deg/s LSB), 16 hand poses."""
    truth = mems_truth(seed)
    truth.gyro.noise_density, truth.gyro.lsb = 20.0, 0.061
    hs = hand_session(truth, seed, poses=16, dwell_s=(2.5, 3.5), turn_s=(1.0, 1.8),
                      turn_error_deg=turn_error_deg, bias_instability=(0.0, gyro_walk_dph), bias_tau_s=tau_s)
    return truth, hs


def true_turn_sigma(hs) -> float:
    """The RMS, per direction across the up after each turn, of the turn errors drawn (deg)."""
    errors = hs.truth["turn_errors_deg"]
    ups = [C.apply([0.0, 0.0, 1.0]) for C in hs.attitudes[1:]]
    across = [e - (e @ u) * u for e, u in zip(errors, ups)]
    return float(np.sqrt(np.mean([a @ a for a in across]) / 2.0))


def z_scores(cal, truth, hs) -> np.ndarray:
    """(estimate - truth) / 1-sigma of the accelerometer and gyro blocks; the biases against the
    session's own bias (the truth's plus the walk's mean over the still samples)."""
    walk = hs.truth["bias_walk_mean"]
    out = []
    for name, value, true, err, unit in parameter_errors(cal, truth_calibration(truth)):
        if not name.startswith(BLOCKS) or name not in cal.sigma:
            continue
        if name.startswith("accel_bias"):
            err -= walk["xyz".index(name[-1])]
        elif name.startswith("gyro_bias"):
            err -= walk[3 + "xyz".index(name[-1])]
        sigma = cal.sigma[name] / true * 1e6 if "_scale_" in name else cal.sigma[name]
        out.append(err / sigma)
    return np.array(out)


def test_missed_turns_get_their_own_sigma_and_the_fit_passes(tmp_path):
    """Turns the gyro misses by 1 degree (per axis): their 1-sigma is estimated (within a band of
    the drawn errors' RMS across the up), stated in the file and on screen, the turns are left
    out of the test, the rest passes, the joint fit agrees with the poses alone and every
    parameter is within its 1-sigma of the truth (RMS of z over 3 sessions x 18 parameters:
    both sides checked, a 1-sigma too large fails like one too small)."""
    ratios, zs = [], []
    for seed in (1, 2, 3):
        truth, hs = session(seed, turn_error_deg=1.0)
        cal, _, _ = estimate_capture(import_session(tmp_path, hs, f"t{seed}"))
        fit = cal.fit
        turn = fit["noise_model"]["turn_angle_deg"]
        assert turn["source"] == "estimated" and turn["scatter_before"] > 10
        ratios.append(turn["sigma"] / true_turn_sigma(hs))
        assert fit["verdict"]["result"] == "passes" and fit["verdict"]["left_out"] == ["hand turn"]
        assert "turn angle" in fit["verdict"]["noise_model"]
        assert any(n.startswith("noise model: the hand turns miss by") for n in fit["notes"])
        assert fit["pose_check"]["result"] == "agree"
        zs.append(z_scores(cal, truth, hs))
    # each estimate rests on ~21 turn residuals (relative 1-sigma ~ 1/sqrt(2 * 21) = 0.15); the
    # gyro's parameters take up a share of the turns' misfit, so the mean sits a little below 1
    assert 0.7 < np.mean(ratios) < 1.15, ratios
    z = np.concatenate(zs)
    assert 0.6 < np.sqrt(np.mean(z**2)) < 1.4 and np.max(np.abs(z)) < 4.5, z


# Turns that follow the gyro add no term (session(11), no turn errors): checked in
# tests/test_pose_check.py's test_the_same_session_without_turn_errors_agrees, whose session is
# this one sample for sample (its coarse_session(turn_error_deg=0.0)): one estimate, not two.


def test_a_stated_turn_sigma_is_tested(tmp_path, capsys):
    """--turn-sigma-deg states the turns' 1-sigma: they are then tested with it.  Stated near the
    truth, the fit passes with the turns in the test; stated 20 times too small, it fails and the
    hand turns are named."""
    truth, hs = session(3, turn_error_deg=1.0)
    out = import_session(tmp_path, hs)
    cal, _, _ = estimate_capture(out, turn_sigma_deg=true_turn_sigma(hs))
    assert cal.fit["noise_model"]["turn_angle_deg"]["source"] == "stated"
    assert "left_out" not in cal.fit["verdict"] and cal.fit["verdict"]["result"] == "passes"
    capsys.readouterr()
    assert cli.main(["estimate", str(out), "-o", str(tmp_path / "c.yaml"), "--turn-sigma-deg", "0.05"]) == 3
    screen = " ".join(capsys.readouterr().err.split())
    assert "the hand turns (gravity after each turn) scatter" in screen
    assert cli.main(["estimate", str(out), "--turn-sigma-deg", "nan"]) == 2


def test_a_wandering_gyro_bias_is_measured_in_the_poses_and_weighted_between_them(tmp_path):
    """A gyro bias that wanders (150 deg/h, correlation time 2 s): the poses' half-means show it
    moving (the gyro's half-differences far above white), so the static gyro means are reweighted
    by their scatter between poses (stated: 'bias between poses'); the fit passes and every
    parameter is within its 1-sigma of the session's truth (z over 3 sessions, both sides)."""
    zs = []
    for seed in (1, 2, 3):
        truth, hs = session(seed, gyro_walk_dph=150.0, tau_s=2.0)
        cal, _, _ = estimate_capture(import_session(tmp_path, hs, f"w{seed}"))
        nm = cal.fit["noise_model"]
        assert "bias instability" in nm["terms"] and "bias between poses (static gyro)" in nm["terms"]
        assert min(nm["bias_instability"]["ratio_to_white"][3:]) > 3
        between = nm["between_poses"]["static gyro"]["sigma_degph"]
        assert 50 < between[0] < 250                       # the walk's 150 deg/h, seen over ~70 s
        assert cal.fit["verdict"]["result"] == "passes" and "static gyro" in cal.fit["verdict"]["left_out"]
        assert any(n.startswith("noise model: the gyro bias moves between the poses") for n in cal.fit["notes"])
        zs.append(z_scores(cal, truth, hs))
    z = np.concatenate(zs)
    assert 0.6 < np.sqrt(np.mean(z**2)) < 1.4 and np.max(np.abs(z)) < 4.5, z


def test_a_bias_that_wanders_on_one_axis_is_weighted_on_that_axis(tmp_path):
    """A gyro whose z bias alone wanders (300 deg/h, 2 s): the variance between the poses is
    estimated per sensor axis, so x and y keep their stated noise and z takes what its scatter
    says (before, one variance for the triad: each axis got a third of z's).  Seed 3: the poses'
    means scatter beyond their noise on z (seeds 1, 2 and 4 carry the walk within the poses'
    bias-instability term and need no more)."""
    truth, hs = session(3, gyro_walk_dph=(0.0, 0.0, 300.0), tau_s=2.0)
    cal, _, _ = estimate_capture(import_session(tmp_path, hs, "z-walk"))
    between = cal.fit["noise_model"]["between_poses"]["static gyro"]["sigma_degph"]
    assert between[0] == between[1] == 0.0 and 100.0 < between[2] < 450.0, between   # the walk's 300 deg/h
    assert cal.fit["verdict"]["result"] == "passes"
    z = z_scores(cal, truth, hs)
    assert np.max(np.abs(z)) < 4.5, z


def _statics(rng, n_poses, samples, sigma, walk_sigma=0.0, drift=0.0):
    """Static summaries whose half-differences are drawn here: white noise over each half, plus
    a bias that differs between the halves by N(0, 2 walk_sigma^2), plus a drift's change."""
    out = []
    for j in range(n_poses):
        n = int(samples[j])
        h = n // 2
        duration = n / 100.0
        d = (sigma * np.sqrt(2.0 / h) * rng.standard_normal(6) + np.sqrt(2.0) * walk_sigma * rng.standard_normal(6)
             - drift * duration / 2.0)
        out.append(StaticSummary(f"p{j}", None, np.zeros(3), np.zeros(3), n, duration, None, half_diff=d))
    return out


def test_half_differences_under_white_noise_add_nothing_and_a_walk_is_sized():
    """pose_instability on half-differences drawn here: under white noise alone the pooled test's
    p-values are uniform (a false term in P_TERM / 2 of sessions per sensor) and no variance is
    added; with a walk of 5 sigma-of-a-half-mean the variance comes out within its sampling band."""
    rng = np.random.default_rng(5)
    sigma = np.array([1e-3, 1e-3, 1e-3, 0.05, 0.05, 0.05])
    ps, added = [], 0
    for _ in range(300):
        samples = rng.integers(200, 400, 20)
        inst = pose_instability(_statics(rng, 20, samples, sigma), sigma)
        ps.extend(inst.sensor_p.tolist())
        added += int(np.any(inst.variance > 0))
    # a (discrete) p-value below 0.05 in at most 5 % of the tests (+3 sigma of the binomial count)
    assert np.mean(np.array(ps) < 0.05) < 0.05 + 3 * np.sqrt(0.05 * 0.95 / len(ps))
    assert added <= 3               # 600 sensor tests at P_TERM / 2 = 5e-4 each: 0.3 expected
    walk = 5.0 * sigma * np.sqrt(2.0 / 300)
    estimates = []
    for _ in range(40):
        samples = rng.integers(250, 350, 30)
        inst = pose_instability(_statics(rng, 30, samples, sigma, walk_sigma=walk), sigma)
        assert np.all(inst.sensor_p < 1e-6)
        estimates.append(inst.variance / walk**2)
    # each estimate: (the median of 30 draws of 26 chi2(1), over chi2(1)'s median 0.455) - 1, over
    # 25.  The sample median's 1-sigma is sqrt(1/4 / 30) / f(0.455) (f the chi2(1) density there,
    # 0.4723): 0.193, 0.42 of the median; times 26/25: 0.44.  The mean of 40 within 4 of its 1-sigma
    spread = np.sqrt(0.25 / 30) / stats.chi2(1).pdf(0.454936) / 0.454936 * 26 / 25
    assert np.all(np.abs(np.mean(estimates, axis=0) - 1.0) < 4 * spread / np.sqrt(40)), np.mean(estimates, axis=0)


def test_one_pose_that_jumps_is_not_noise():
    """A bias step inside one pose (its halves 30 sigma apart on every axis): a fault or an
    effect of that pose, not a noise every pose shares: no term."""
    rng = np.random.default_rng(9)
    sigma = np.array([1e-3, 1e-3, 1e-3, 0.05, 0.05, 0.05])
    statics = _statics(rng, 16, rng.integers(200, 400, 16), sigma)
    statics[5].half_diff = statics[5].half_diff + 30 * sigma * np.sqrt(2.0 / 150)
    inst = pose_instability(statics, sigma)
    assert np.all(inst.variance == 0.0) and np.all(inst.sensor_p > 1e-3)


def test_a_steady_drift_is_an_effect_not_noise():
    """Half-differences that follow the pose's length (a bias drifting steadily, 20 sigma over a
    pose) are taken out and named; what is left is white: no term."""
    rng = np.random.default_rng(8)
    sigma = np.array([1e-3, 1e-3, 1e-3, 0.05, 0.05, 0.05])
    samples = rng.integers(150, 600, 20)
    drift = np.array([0, 0, 0, 0.0, 0.0, 20 * 0.05 * np.sqrt(2.0 / 150) / 1.5])   # gyro z, per s
    inst = pose_instability(_statics(rng, 20, samples, sigma, drift=drift), sigma)
    assert [(a, n) for a, n, _, _ in inst.follows] == [("gyro z", "drift")]
    assert np.all(inst.variance == 0.0)
