"""The least-squares model against the simulated bench.

Bounds come from the model's own Fisher information evaluated with the true noise densities
(the Cramér-Rao bound, station.simulate.montecarlo.cramer_rao), never from a run of the estimator."""
import math

import numpy as np
import pytest
from scipy import stats

from sim_devices.bench import SimulatedBench
from station.simulate import montecarlo
from station.simulate import dryrun
from station.model.calibration import parameter_errors
from station.model.compensate import compensate
from station.estimate import lsq
from station.model import EFFECTS
from station.io.scheme import load_scheme

POSITIONS_M = np.array([[0.012, 0.004, -0.006], [-0.005, 0.009, 0.007], [0.006, -0.008, -0.014]])


def quiet(truth):
    truth.accel.noise_density = truth.gyro.noise_density = 0.0
    truth.bench.table_angle_error_arcsec = truth.bench.accel_disturbance_ug = 0.0
    return truth


def test_noise_free_fit_is_exact_and_chi2_zero():
    scheme, truth = load_scheme("optimal9"), quiet(dryrun.load_truth(None, 0))
    capture = dryrun.simulate_capture(scheme, truth, 4)
    capture_noise = dryrun.simulate_capture(scheme, montecarlo.make_truth(montecarlo.Settings()), 4)
    # the noise level is taken from the data; borrow a noisy one so the weights are finite
    s = lsq.summarise(capture)
    s_noise = lsq.summarise(capture_noise)
    s.accel_sigma, s.gyro_sigma, s.table_angle_sigma_deg = (s_noise.accel_sigma, s_noise.gyro_sigma,
                                                            2.0 / 3600)
    result = lsq.fit(s)
    cal = lsq.to_calibration(result, "m/s^2", "deg/s")
    for name, value, _, err, unit in parameter_errors(cal, dryrun.truth_calibration(truth)):
        sigma = cal.sigma[name] / value * 1e6 if unit == "ppm" else cal.sigma[name]
        assert abs(err) < 1e-3 * sigma, (name, err, sigma, unit)
    # noise would give about dof; what remains is the Earth rate seen in the gyro-tracked phase
    # of each turn (about Omega_E / rate rad), far below the noise
    assert result.chi2 < 1e-2 * result.dof
    lever_p = truth.paper_parameters()["C_pb"] @ truth.bench.lever_arm_m     # case axes -> frame p
    block = result.model.layout["mounting_offset"]
    sigma = np.sqrt(np.diag(result.covariance)[block])
    assert np.all(np.abs(result.x[block] - lever_p) < 1e-2 * sigma)


def test_spread_and_reported_sigma_match_the_cramer_rao_bound():
    runs = 24
    scheme = load_scheme("optimal9")
    settings = montecarlo.Settings(accel_noise_ug=100.0, gyro_noise_dph=0.03, table_angle_arcsec=2.0)
    names, errors, sigmas = montecarlo.run(scheme, settings, runs, first_seed=700)
    crlb = montecarlo.cramer_rao(scheme, settings)
    lo, hi = (math.sqrt(stats.chi2.ppf(q, runs) / runs) for q in (0.0005, 0.9995))
    for (name, _), col, bound, reported in zip(names, errors.T, crlb, sigmas.T):
        ratio = math.sqrt(np.mean(col**2)) / bound   # rms error over runs: unbiased and efficient
        assert lo < ratio < hi, f"{name}: rms error {ratio:.2f} x the bound, outside [{lo:.2f}, {hi:.2f}]"
        # the reported 1-sigma is the bound evaluated at the estimate; the bound itself moves a
        # little with each run's random table headings (the Earth rate seen at rest)
        assert abs(np.mean(reported) / bound - 1) < 0.05, name


def test_reduced_chi2_follows_its_distribution():
    scheme, truth = load_scheme("optimal9"), dryrun.load_truth(None, 0)
    chi2, dof = 0.0, 0
    for seed in range(30, 36):
        result = lsq.fit(lsq.summarise(dryrun.simulate_capture(scheme, truth, seed)))
        chi2 += result.chi2
        dof += result.dof
    assert stats.chi2.ppf(0.0005, dof) < chi2 < stats.chi2.ppf(0.9995, dof), (chi2, dof)


def size_effect_truth():
    truth = dryrun.load_truth(None, 0)
    truth.accel.noise_density, truth.gyro.noise_density = 150.0, 5.0      # MEMS
    truth.accel.position_m = POSITIONS_M
    return truth


@pytest.mark.parametrize("seed", [3, 4])
def test_size_effect_positions_recovered_and_compensated(seed):
    scheme, truth = load_scheme("sizeeffect"), size_effect_truth()
    capture = dryrun.simulate_capture(scheme, truth, seed)
    without = lsq.estimate(capture)
    cal = lsq.estimate(capture, [EFFECTS["accel_lever_arm"]()])
    # the missing effect shows: the base model cannot explain the rotations
    assert without.fit["reduced_chi2"] > 100 and cal.fit["reduced_chi2"] < 1.5
    # rotations about body axes reveal each element's own-axis coordinate, only those
    for i, a in enumerate("xyz"):
        name = f"accel_position_{a}_{a}"
        value = dict((n, v) for n, v, _ in cal.extra_parameters)[name]
        assert abs(value - POSITIONS_M[i, i] * 1e3) < 3 * cal.sigma[name], (name, value, cal.sigma[name])
    assert any("not revealed by this capture" in note for note in cal.fit["notes"])

    # 200 deg/s about the vertical z axis, compensated: the reference point is on the axis
    bench = SimulatedBench(dryrun._mounted(truth, scheme), seed + 100)
    seg = bench.rotation([0, 0, 1], 200.0, 20.0, axis_elevation_deg=90.0)
    # at the reference point, on the axis: gravity alone, constant in body, expressed in frame p
    truth_f = truth.paper_parameters()["C_pb"] @ seg.truth["C_bn0"] @ [0.0, 0.0, bench.gravity_mps2]
    comp = {"accel_matrix": cal.accel_matrix, "accel_bias": cal.accel_bias,
            "gyro_matrix": cal.gyro_matrix, "gyro_bias": cal.gyro_bias}
    f_plain, _ = compensate(comp, seg.t, seg.accel, seg.gyro)
    f_comp, _ = compensate({**comp, **cal.compensation_extra}, seg.t, seg.accel, seg.gyro)
    n = len(seg.t)
    noise = truth.accel_noise_sigma / math.sqrt(n)                  # of the mean, per axis
    # allowed: the mean's noise plus the calibration's own error (scale 1e-4 g, bias 1e-4 g)
    allowed = 5 * noise + 3 * 1e-4 * bench.gravity_mps2
    error_plain = np.abs(f_plain.mean(axis=0) - truth_f)[:2]
    error_comp = np.abs(f_comp.mean(axis=0) - truth_f)[:2]
    assert error_plain.max() > 50 * allowed / 5                      # several mg without the effect
    assert error_comp.max() < allowed, (error_comp, allowed)


def test_apply_follows_the_temperature_with_temperature_coefficients(tmp_path):
    from station.io.calfile import read_calfile, write_calfile

    truth = dryrun.load_truth(None, 0)
    truth.accel.bias_tempco = np.array([60.0, -40.0, 50.0])         # µg/°C
    truth.temperature.warmup_delta_c = 6.0
    capture = dryrun.simulate_capture(load_scheme("optimal9"), truth, 3)
    write_calfile(tmp_path / "c.yaml", lsq.estimate(capture, [EFFECTS["temperature_bias"]()]), {})
    comp = read_calfile(tmp_path / "c.yaml")["compensation"]
    first = capture.segments[0].data                                  # pos01, cold
    warm = capture.segments[8].data                                   # pos09, warmed up
    g = capture.site.gravity_mps2
    noise = truth.accel_noise_sigma / math.sqrt(len(first.t))
    for data in (first, warm):
        f, _ = compensate(comp, data.t, data.accel, data.gyro, data.temp)
        # with the temperature column: gravity to within the noise and the calibration's own error
        assert abs(np.linalg.norm(f.mean(axis=0)) - g) < 5 * noise + 20e-6 * g
    # without it the warm attitude is off by the coefficient times the temperature change
    dT = warm.temp.mean() - comp["temperature_reference_c"]
    f_plain, _ = compensate(comp, warm.t, warm.accel, warm.gyro)
    f, _ = compensate(comp, warm.t, warm.accel, warm.gyro, warm.temp)
    assert np.linalg.norm(f_plain.mean(axis=0) - f.mean(axis=0)) == pytest.approx(
        np.linalg.norm(comp["accel_bias_tempco_raw_per_c"]) * abs(dT), rel=0.05)


@pytest.mark.parametrize("m, n, rank", [(303, 99, 99), (200, 60, 57), (40, 40, 40), (30, 45, 30)])
def test_the_lm_step_is_the_damped_least_squares_step(m, n, rank):
    """solver's Levenberg-Marquardt step (the SVD of R from the QR of [A f] where A is tall:
    solver._svd_projected) against the damped least squares solved another way: numpy's lstsq of
    [A; sqrt(lam) I] p = [-f; 0] with the lam the step reports (the minimum-norm Gauss-Newton
    step, lam = 0, where the radius holds it).  Columns scaled over 8 decades, some dependent
    (rank < n: the step drops their null space as the pseudo-inverse does), tall, square, wide;
    radii from inside the Gauss-Newton step's norm to outside it.  Agreement to 1e-9 of the
    step: both are backward stable, the condition number after scaling is ~1e3."""
    from station.estimate import solver

    rng = np.random.default_rng(m + n)
    A = rng.standard_normal((m, rank)) @ rng.standard_normal((rank, n)) * 10.0 ** rng.uniform(-4, 4, n)
    f = rng.standard_normal(m)
    diag = np.linalg.norm(A, axis=0)                      # the solver's column scaling
    As = A / diag
    gn = np.linalg.lstsq(As, -f, rcond=None)[0]
    for delta in np.array([1e-3, 0.3, 0.95, 3.0]) * np.linalg.norm(gn):
        s, Vt, uf = solver._svd_projected(As, f)
        p, lam = solver._step(s, Vt, uf, diag, delta, 0.0)
        ref = np.linalg.lstsq(np.vstack([As, math.sqrt(lam) * np.eye(n)]), np.concatenate([-f, np.zeros(n)]),
                              rcond=None)[0] if lam > 0 else gn
        assert np.linalg.norm(p - ref) < 1e-9 * np.linalg.norm(ref), (delta, lam, np.linalg.norm(p - ref))
        assert np.linalg.norm(p) <= 1.1 * delta if lam > 0 else np.linalg.norm(gn) <= 1.1 * delta
    # a Jacobian with an infinite entry: answered as the SVD of A answers it (not finite, no exception)
    As[0, 0] = np.inf
    s = solver._svd_projected(As, f)[0]
    assert not np.isfinite(s).all() and np.array_equal(s, np.linalg.svd(As, full_matrices=False)[1], equal_nan=True)
