"""The 2010 estimator against the simulated bench (two independent pieces of code).

Tolerances come from the noise and the scheme (first-order error propagation, derived in
docs/method-zhang2010.md), never from a run of the estimator:
  sigma_m   accelerometer mean over a dwell T_d, per axis: density / sqrt(T_d)
  accel scale sigma_m / (sqrt(2) g); bias sigma_m / sqrt(2); misalignment sqrt(7) sigma_m / g
  gyro scale  e = sqrt(2 sigma_angle^2 + 2 sigma_int^2) / swept, with sigma_int = density sqrt(T_r);
  gyro misalignment sqrt(6) e; gyro bias sigma_gm sqrt(diag((U^T U)^-1)), U the Earth-rate
  directions seen at the static attitudes.
"""
import math

import numpy as np
import pytest
from scipy import stats

from station.simulate import montecarlo

from station.simulate import dryrun
from station.model.calibration import parameter_errors
from station.estimate import zhang2010
from station.io.scheme import load_scheme

G0 = 9.80665
ARCSEC = math.radians(1 / 3600)


def quiet_truth(seed=0, accel_ug=0.0, gyro_dph=0.0, angle_arcsec=0.0):
    truth = dryrun.load_truth(None, seed)
    truth.accel.noise_density = accel_ug
    truth.gyro.noise_density = gyro_dph
    truth.bench.table_angle_error_arcsec = angle_arcsec
    truth.bench.accel_disturbance_ug = 0.0
    return truth


def errors_by_name(cal, truth):
    return {name: err for name, _, _, err, _ in parameter_errors(cal, dryrun.truth_calibration(truth))}


def predicted_sigma(scheme, truth, capture) -> dict:
    """1-sigma of each error from the noise densities and the scheme's timings."""
    g = capture.site.gravity_mps2
    statics = [s for s in scheme.segments if s.kind == "static"]
    rot = next(s for s in scheme.segments if s.kind == "rotation")
    sigma_m = truth.accel.noise_density * G0 * 1e-6 / math.sqrt(statics[0].dwell_s)   # m/s^2
    swept = 2 * abs(rot.rate_dps) * rot.duration_s                                     # deg
    sigma_int = truth.gyro.noise_density / 3600 * math.sqrt(rot.duration_s)             # deg
    sigma_ang = truth.bench.table_angle_error_arcsec / 3600                             # deg
    e = math.sqrt(2 * sigma_ang**2 + 2 * sigma_int**2) / swept
    w = np.array([s.data.gyro.mean(axis=0) for s in capture.complete("static")])
    U = w / np.linalg.norm(w, axis=1)[:, None]
    sigma_gm = truth.gyro.noise_density / math.sqrt(statics[0].dwell_s)                 # deg/h
    gyro_bias = sigma_gm * np.sqrt(np.diag(np.linalg.inv(U.T @ U)))
    out = {}
    for i, a in enumerate("xyz"):
        out[f"accel_scale_{a}"] = sigma_m / (math.sqrt(2) * g) * 1e6
        out[f"accel_bias_{a}"] = sigma_m / math.sqrt(2) / (G0 * 1e-6)
        out[f"gyro_scale_{a}"] = e * 1e6
        out[f"gyro_bias_{a}"] = gyro_bias[i]
    for n in ("yz", "zy", "zx"):
        out[f"accel_misalignment_{n}"] = math.sqrt(7) * sigma_m / g / ARCSEC
        out[f"gyro_misalignment_{n}"] = math.sqrt(6) * e / ARCSEC
    return out


def test_noise_free_dry_run_recovers_truth_exactly():
    """No noise, no table error: only the numerical floor and the unmodelled terms remain."""
    scheme, truth = load_scheme("optimal9"), quiet_truth()
    cal = zhang2010.estimate(dryrun.simulate_capture(scheme, truth, seed=3))
    err = errors_by_name(cal, truth)
    floor = {"scale": 1e-5, "misalignment": 1e-5, "accel_bias": 1e-5, "gyro_bias": 1e-4, "inter_triad": 1e-5}
    for name, e in err.items():
        key = next(k for k in floor if k in name)
        assert abs(e) < floor[key], f"{name}: error {e} above the numerical floor {floor[key]}"


@pytest.mark.parametrize("seed", [11, 12, 13])
def test_paper_noise_errors_within_predicted_bounds(seed):
    scheme = load_scheme("optimal9")
    truth = quiet_truth(accel_ug=100.0, gyro_dph=0.03, angle_arcsec=2.0)
    capture = dryrun.simulate_capture(scheme, truth, seed)
    err = errors_by_name(zhang2010.estimate(capture), truth)
    sigma = predicted_sigma(scheme, truth, capture)
    for name, s in sigma.items():
        assert abs(err[name]) < 4.5 * s, f"{name}: error {err[name]:.4g} > 4.5 sigma ({s:.4g})"
    # inter-triad: driven by the accelerometer calibration error, no larger than its misalignment
    for a in "xyz":
        assert abs(err[f"inter_triad_{a}"]) < 4.5 * sigma["accel_misalignment_yz"]


def test_error_spread_matches_noise_over_seeded_runs():
    """Over 30 runs the std of each error lies in the 99.9 % chi-square band of the prediction."""
    runs = 30
    scheme = load_scheme("optimal9")
    settings = montecarlo.Settings(accel_noise_ug=100.0, gyro_noise_dph=0.03,
                                   table_angle_arcsec=2.0, accel_disturbance_ug=0.0)
    settings.method = "zhang2010"
    names, errors, _ = montecarlo.run(scheme, settings, runs, first_seed=500)
    truth = montecarlo.make_truth(settings)
    sigma = predicted_sigma(scheme, truth, dryrun.simulate_capture(scheme, truth, 500))
    lo, hi = (math.sqrt(stats.chi2.ppf(q, runs - 1) / (runs - 1)) for q in (0.0005, 0.9995))
    for (name, _), col in zip(names, errors.T):
        ratio = col.std(ddof=1) / (sigma.get(name) or sigma["accel_misalignment_yz"])
        if name.startswith("inter_triad"):
            assert ratio < hi, f"{name}: spread {ratio:.2f} x the accel misalignment sigma"
        else:
            assert lo < ratio < hi, f"{name}: spread {ratio:.2f} x predicted, outside [{lo:.2f}, {hi:.2f}]"
        # and no bias: the mean error is within 4 standard errors of zero
        assert abs(col.mean()) < 4 * col.std(ddof=1) / math.sqrt(runs), f"{name}: biased"


@pytest.mark.parametrize("accel_unit, a_per_si, gyro_unit, g_per_si", [
    ("g", 1 / G0, "rad/s", math.pi / 180),
    ("raw", 1000.0, "raw", 50.0),
])
def test_manifest_units_are_honoured(accel_unit, a_per_si, gyro_unit, g_per_si):
    """The same data declared in other units give the same compensation into m/s^2 and deg/s."""
    scheme, truth = load_scheme("optimal9"), quiet_truth(accel_ug=100.0, gyro_dph=0.03, angle_arcsec=2.0)
    capture = dryrun.simulate_capture(scheme, truth, seed=21)
    reference = zhang2010.estimate(capture)
    for seg in capture.segments:
        seg.data.accel = seg.data.accel * a_per_si
        seg.data.gyro = seg.data.gyro * g_per_si
    capture.imu.accel_unit, capture.imu.gyro_unit = accel_unit, gyro_unit
    cal = zhang2010.estimate(capture)
    np.testing.assert_allclose(cal.accel_matrix * a_per_si, reference.accel_matrix, rtol=1e-9)
    np.testing.assert_allclose(cal.gyro_matrix * g_per_si, reference.gyro_matrix, rtol=1e-9)
    np.testing.assert_allclose(cal.accel_bias / a_per_si, reference.accel_bias, rtol=1e-7, atol=1e-12)
    np.testing.assert_allclose(cal.gyro_bias / g_per_si, reference.gyro_bias, rtol=1e-7, atol=1e-12)
    if accel_unit == "raw":   # the scale factor carries the unit
        np.testing.assert_allclose(cal.accel_scale, reference.accel_scale * a_per_si, rtol=1e-9)
    else:                     # dimensionless, the same number
        np.testing.assert_allclose(cal.accel_scale, reference.accel_scale, rtol=1e-9)
