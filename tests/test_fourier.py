"""The Fourier method (station/estimate/fourier.py) against synthetic sines and the simulated bench.

Tolerances come from the noise, never from a run of the estimator:
  * peak frequency: the first-order standard deviation of the three-bin interpolator, from the
    variance N sigma^2 of every DFT bin of white noise (bins uncorrelated with a rectangular
    window), checked with the chi-square band of a Monte Carlo std;
  * calibration: fourier.propagate, the first-order propagation of the noise densities through
    the spectral summaries (harmonic amplitudes 2 N^2/T, means N^2/T, mean rate from the phase
    noise of the tracked angle) and the algebraic solution; each error within 4.5 sigma;
  * low-grade gyro biases: the Earth rate along each shaft (at most |Omega_E|) goes into them
    through the bias row of the least-squares pseudo-inverse, bounded here, plus 4.5 sigma.
"""
import math

import numpy as np
import pytest
import yaml
from scipy import stats

from station.simulate import dryrun

from station.core import units
from station.model.calibration import parameter_errors
from station.io.capture import read_capture
from station.core.errors import UserError
from station.estimate import choose_method, estimate_capture, estimate_with, fourier, zhang2010
from station.io.scheme import load_scheme, parse_scheme

EARTH_DPH = units.EARTH_RATE_DPS * 3600


# --- the spectral peak -----------------------------------------------------------------------------

def candan_delta(y, n):
    """Candan's three-bin interpolator on bins y = (X_{k-1}, X_k, X_{k+1}) (test's own copy)."""
    c = math.tan(math.pi / n) / (math.pi / n)
    return c * np.real((y[0] - y[2]) / (2 * y[1] - y[0] - y[2]))


@pytest.mark.parametrize("k", [20, 80, 300])
def test_peak_interpolation_noise_free_multichannel(k):
    """Three channels of one tone at any sub-bin offset: frequency to 2e-4 bin, amplitude and
    phase to the leakage of the negative-frequency image, 1/(N sin(2 pi f/fs))."""
    fs, n = 100.0, 1000
    t = np.arange(n) / fs
    amp, ph = np.array([3.0, 1.0, 0.5]), np.array([0.3, 1.0, 2.0])
    for d in np.linspace(-0.5, 0.5, 11):
        f = (k + d) * fs / n
        peak = fourier.spectral_peak(amp * np.cos(2 * np.pi * f * t[:, None] + ph), fs)
        assert abs(peak.frequency_hz - f) * n / fs < 2e-4
        image = 1.0 / (n * math.sin(2 * math.pi * f / fs))
        assert np.abs(peak.amplitude - amp * np.exp(1j * ph)).max() <= amp.max() * (image + 2 * math.pi * 2e-4)


@pytest.mark.parametrize("d", [0.0, 0.25, 0.45])
def test_peak_interpolation_noise_matches_first_order_prediction(d):
    fs, n, k, a, sigma, trials = 100.0, 1000, 80, 1.0, 0.3, 400
    t = np.arange(n) / fs
    f = (k + d) * fs / n
    rng = np.random.default_rng(7)
    # prediction: linearise the interpolator in the three bins of the noise-free tone
    X = np.fft.rfft(a * np.cos(2 * np.pi * f * t + 0.4))[k - 1:k + 2]
    grad = []
    for i in range(3):
        for unit in (1.0, 1j):
            h = 1e-6 * abs(X[1])
            Xp, Xm = X.copy(), X.copy()
            Xp[i] += h * unit
            Xm[i] -= h * unit
            grad.append((candan_delta(Xp, n) - candan_delta(Xm, n)) / (2 * h))
    sigma_bins = math.sqrt(np.sum(np.square(grad)) * n * sigma ** 2 / 2)
    errs = []
    for _ in range(trials):
        x = a * np.cos(2 * np.pi * f * t + rng.uniform(0, 2 * np.pi)) + sigma * rng.standard_normal(n)
        errs.append((fourier.spectral_peak(x, fs).frequency_hz - f) * n / fs)
    lo, hi = (math.sqrt(stats.chi2.ppf(q, trials - 1) / (trials - 1)) for q in (0.0005, 0.9995))
    assert lo * sigma_bins < np.std(errs, ddof=1) < hi * sigma_bins
    assert abs(np.mean(errs)) < 4.5 * sigma_bins / math.sqrt(trials)
    crlb_bins = math.sqrt(6 / ((2 * math.pi) ** 2 * a ** 2 / (2 * sigma ** 2) * n * (n ** 2 - 1))) * n
    assert sigma_bins >= crlb_bins        # no estimator beats the Cramer-Rao bound


# --- the method on the simulated bench ---------------------------------------------------------------

def truth_for(*, accel_ug, gyro_dph, drift=0.0, rate_hz=100.0, seed=0):
    truth = dryrun.load_truth(None, seed)
    truth.sample_rate_hz = rate_hz
    truth.accel.noise_density = accel_ug
    truth.gyro.noise_density = gyro_dph
    truth.bench.rate_drift_fraction = drift
    return truth


def errors_of(cal, truth):
    return {name: err for name, _, _, err, _ in parameter_errors(cal, dryrun.truth_calibration(truth))}


def predicted(scheme, truth, variant):
    quiet = truth_for(accel_ug=0.0, gyro_dph=0.0, drift=truth.bench.rate_drift_fraction,
                      rate_hz=truth.sample_rate_hz)
    quiet.accel, quiet.gyro = truth.accel.__class__(**{**truth.accel.__dict__, "noise_density": 0.0}), \
        truth.gyro.__class__(**{**truth.gyro.__dict__, "noise_density": 0.0})
    s = fourier.summarise(dryrun.simulate_capture(scheme, quiet, seed=0))
    return fourier.propagate(s, variant, truth.accel.noise_density * units.UG_MPS2,
                             truth.gyro.noise_density / 3600, truth.sample_rate_hz)


def earth_bias_bound(capture, cal):
    """Largest low-grade gyro bias error (deg/h, per axis) the Earth rate along the shafts can
    cause: the bias row of the pseudo-inverse of [w_p^T, 1] times |Omega_E| along each shaft."""
    axes = np.array([cal.fit["segments"][s.name]["axis_p"] for s in capture.complete("rotation")])
    rates = np.array([cal.fit["segments"][s.name]["mean_rate_dps"] for s in capture.complete("rotation")])
    c = np.linalg.pinv(np.column_stack([axes * rates[:, None], np.ones(len(axes))]))[3]
    return EARTH_DPH * np.abs(c) @ np.abs(axes)


def test_noise_free_with_rate_drift_recovers_truth():
    """20 % rate drift, a 5 cm lever arm, no noise: only the numerical floor (1e-2 ppm, arcsec,
    ug, deg/h) remains, except the low-grade gyro biases, which carry the Earth rate by design."""
    scheme = load_scheme("screwdriver", {"rotation_s": 20.0})
    truth = truth_for(accel_ug=0.0, gyro_dph=0.0, drift=-0.2)
    capture = dryrun.simulate_capture(scheme, truth, seed=3)
    for variant in ("low", "high"):
        cal = fourier.estimate(capture, variant)
        for name, e in errors_of(cal, truth).items():
            if variant == "low" and name.startswith("gyro_bias"):
                continue
            # the floor: the tracked angle converges to 1e-7 rad, ~1e-9 of 40 revolutions
            assert abs(e) < 1e-2, f"{variant}: {name}: {e} (ppm, arcsec, ug or deg/h)"
    assert cal.fit["method"] == "fourier" and cal.fit["variant"] == "high"
    seg = cal.fit["segments"]["shaftx_p"]
    n = 2000                                   # 20 s at 100 Hz; the rate at the last sample:
    assert seg["rate_range_dps"][0] == pytest.approx(720.0 * (1 - 0.2 * (n - 1) / n), rel=1e-7)
    assert seg["rate_range_dps"][1] == pytest.approx(720.0, rel=1e-7)
    assert seg["mean_rate_dps"] == pytest.approx(720.0 * (1 - 0.1 * (n - 1) / n), rel=1e-9)


@pytest.mark.parametrize("seed", [21, 22])
def test_mems_noise_and_drift_within_predicted_bounds(seed):
    """The issue's case: MEMS noise (150 ug/sqrt(Hz), 10 deg/h/sqrt(Hz), 100 Hz), 60 s per
    direction, the rate falling 20 % in every rotation."""
    scheme = load_scheme("screwdriver")
    truth = truth_for(accel_ug=150.0, gyro_dph=10.0, drift=-0.2)
    sigma = predicted(scheme, truth, "low")
    capture = dryrun.simulate_capture(scheme, truth, seed)
    cal = fourier.estimate(capture, "low")
    bound = earth_bias_bound(capture, cal)
    for name, e in errors_of(cal, truth).items():
        extra = bound["xyz".index(name[-1])] if name.startswith("gyro_bias") else 0.0
        assert abs(e) < 4.5 * sigma[name] + extra, f"{name}: error {e}, sigma {sigma[name]}"
    for a in "xyz":                                # the targets, far inside
        assert 4.5 * sigma[f"accel_scale_{a}"] < 1000 and 4.5 * sigma[f"gyro_scale_{a}"] < 2000


def test_high_variant_estimates_earth_rate_along_shafts():
    """Tactical noise, steady rate: the high-grade variant takes the Earth rate out of the gyro
    biases (errors within 4.5 sigma of the noise alone), and what it found along each shaft is
    no larger than the Earth rate itself."""
    scheme = load_scheme("screwdriver", {"rotation_s": 30.0})
    truth = truth_for(accel_ug=100.0, gyro_dph=0.03)
    capture = dryrun.simulate_capture(scheme, truth, seed=5)
    sigma = predicted(scheme, truth, "high")
    high = fourier.estimate(capture, "high")
    for name, e in errors_of(high, truth).items():
        assert abs(e) < 4.5 * sigma[name], f"{name}: error {e}, sigma {sigma[name]}"
    along = high.fit["earth_rate_along_shaft_dph"]
    assert len(along) == 4
    assert all(abs(v) < EARTH_DPH + 4.5 * max(sigma[f"gyro_bias_{a}"] for a in "xyz") for v in along.values())
    low = fourier.estimate(capture, "low")
    low_err = np.array([errors_of(low, truth)[f"gyro_bias_{a}"] for a in "xyz"])
    assert np.all(np.abs(low_err) < earth_bias_bound(capture, low) + 4.5 * np.array(
        [sigma[f"gyro_bias_{a}"] for a in "xyz"]))
    assert any("Earth rate is neglected" in n for n in low.fit["notes"])


def test_tilted_shaft_elevation_estimated():
    """A screwdriver clamped 10 deg nose-up in every mounting: the specific force along the
    shaft is g sin(10 deg); the method finds the elevation and keeps the scale factors."""
    doc = yaml.safe_load(open(load_scheme.__globals__["resources"].files("schemes")
                              .joinpath("screwdriver.yaml")))
    for entry in doc["segments"]:
        entry["axis_elevation_deg"] = 10.0
    doc["defaults"]["rotation_s"] = 20.0
    scheme = parse_scheme(doc, "tilted", {})
    truth = truth_for(accel_ug=0.0, gyro_dph=0.0)
    cal = fourier.estimate(dryrun.simulate_capture(scheme, truth, seed=4))
    assert cal.fit["shaft_elevation_deg"] == pytest.approx(10.0, abs=0.01)
    for name, e in errors_of(cal, truth).items():
        if not name.startswith("gyro_bias"):
            assert abs(e) < 1e-3, f"{name}: {e}"


# --- what the method refuses ----------------------------------------------------------------------

def test_three_mountings_assume_a_horizontal_shaft_and_two_are_refused():
    truth = truth_for(accel_ug=0.0, gyro_dph=0.0)
    base = yaml.safe_load(load_scheme.__globals__["resources"].files("schemes")
                          .joinpath("screwdriver.yaml").read_text())
    base["defaults"]["rotation_s"] = 10.0
    three = parse_scheme({**base, "segments": base["segments"][:3]}, "three", {})
    cal = fourier.estimate(dryrun.simulate_capture(three, truth, seed=2))
    assert any("taken as horizontal" in n for n in cal.fit["notes"])
    assert abs(errors_of(cal, truth)["accel_scale_x"]) < 1e-3
    two = parse_scheme({**base, "segments": base["segments"][:2]}, "two", {})
    with pytest.raises(UserError, match="at least 3 mountings"):
        fourier.estimate(dryrun.simulate_capture(two, truth, seed=2))


def test_hand_turns_refused():
    scheme = load_scheme("screwdriver", {"rotation_s": 2.0})      # 4 revolutions
    capture = dryrun.simulate_capture(scheme, truth_for(accel_ug=150.0, gyro_dph=10.0), seed=1)
    with pytest.raises(UserError, match=r"shaftx_p.*revolutions.*at least 10"):
        fourier.estimate(capture)


def test_vertical_shaft_refused():
    doc = {"name": "v", "defaults": {"rate_dps": 720.0, "rotation_s": 10.0},
           "segments": [{"rotation": f"r{i}", "axis_body": ax, "encoder": False, "axis_elevation_deg": 90}
                        for i, ax in enumerate([[1, 0, 0], [0, 1, 0], [0, 0, 1]])]}
    capture = dryrun.simulate_capture(parse_scheme(doc, "v", {}), truth_for(accel_ug=150.0, gyro_dph=10.0), 1)
    with pytest.raises(UserError, match="vertical"):
        fourier.estimate(capture)


def test_wrong_direction_in_manifest_is_reported_and_the_data_used():
    scheme = load_scheme("screwdriver", {"rotation_s": 10.0})
    truth = truth_for(accel_ug=0.0, gyro_dph=0.0)
    capture = dryrun.simulate_capture(scheme, truth, seed=6)
    reference = fourier.estimate(capture)
    capture.segments[0].rate_dps = -capture.segments[0].rate_dps
    flipped = fourier.estimate(capture)
    assert any(n.startswith("shaftx_p: the accelerometers show a positive rotation") for n in flipped.fit["notes"])
    np.testing.assert_allclose(flipped.gyro_scale, reference.gyro_scale, rtol=1e-12)


def test_unknown_variant_refused():
    with pytest.raises(UserError, match="variant"):
        fourier.estimate(None, "medium")


# --- dispatch -----------------------------------------------------------------------------------

def test_auto_selection_and_zhang2010_refusal(tmp_path):
    truth = truth_for(accel_ug=100.0, gyro_dph=0.03)
    screw = dryrun.record_scheme(load_scheme("screwdriver", {"rotation_s": 10.0}), truth, 1, tmp_path / "s")
    capture = read_capture(screw)
    assert choose_method(capture) == "fourier"
    with pytest.raises(UserError, match="no angle_deg; the 2010 method needs the encoder angle"):
        zhang2010.estimate(capture)
    cal, _, provenance = estimate_capture(screw)                  # default: auto
    assert provenance["method"] == "fourier" and cal.fit["method"] == "fourier"
    cal, method = estimate_with(capture, "fourier-high")
    assert method == "fourier-high" and cal.fit["variant"] == "high"

    optimal = dryrun.simulate_capture(load_scheme("optimal9", {"rotation_s": 36.0, "dwell_s": 10.0}), truth, 1)
    assert choose_method(optimal) != "fourier"          # every rotation has its encoder angle
    cal, method = estimate_with(optimal, "zhang2010")
    assert method == "zhang2010" and cal.fit["method"] == "zhang2010"
    with pytest.raises(UserError, match="unknown estimation method"):
        estimate_with(optimal, "kalman")


def test_run_screwdriver_end_to_end(tmp_path):
    from station import cli

    out = tmp_path / "run"
    assert cli.main(["run", "--scheme", "screwdriver", "--sim", "--out", str(out), "--rotation-s", "10"]) == 0
    doc = yaml.safe_load((out / "calibration.yaml").read_text())
    assert doc["provenance"]["method"] == "fourier" and doc["fit"]["variant"] == "low"
    assert doc["fit"]["rotation_segments"] == 8 and doc["fit"]["mountings"] == 4
