"""Rotation summaries computed chunk by chunk (station/estimate/summaries.py, CHUNK_SAMPLES) against
the same summaries computed with whole arrays (tests/summaries_reference.py, the code they replace):
equal to rounding, whatever the chunk size, for a steady and a rippling rate and a short sweep."""
import numpy as np
import pytest

from station.estimate import summaries
from summaries_reference import rotation_summary as reference_summary

RATE_HZ = 1000.0
EPS = np.finfo(float).eps


def rotation(n, *, rate_dps=30.0, ripple=0.0, seed=5):
    """A rotation segment about x: (t, accel, gyro, temp, angle_deg, gyro_sigma, gyro_bias).
    Jittered time stamps, white noise, a rate that ripples by ``ripple`` (relative) once a turn,
    gravity turning in the y-z plane with a second harmonic and an offset."""
    rng = np.random.default_rng(seed)
    t = 100.0 + np.arange(n) / RATE_HZ + rng.normal(0, 2e-6, n)
    omega = np.radians(rate_dps)
    phase = omega * (t - t[0]) + ripple * np.sin(omega * (t - t[0]))
    rate = np.gradient(phase, t)
    gyro = np.column_stack([np.degrees(rate), np.zeros(n), np.zeros(n)]) + [0.01, -0.02, 0.005]
    gyro += rng.normal(0, 0.01, (n, 3))
    accel = np.column_stack([0.05 + 0.0 * t, 9.8 * np.cos(phase) + 1e-3 * np.cos(2 * phase),
                             9.8 * np.sin(phase) - 2e-3 * np.sin(2 * phase)])
    accel += rng.normal(0, 0.01, (n, 3))
    temp = 25.0 + 1e-3 * (t - t[0])
    angle_deg = np.degrees(phase[-1] - phase[0]) * n / (n - 1)
    return t, accel, gyro, temp, angle_deg, np.full(3, 0.01), np.array([0.01, -0.02, 0.005])


def assert_equal_to_rounding(chunked, whole, n):
    """Every number of the two summaries equal to what the order of n additions can change
    (n eps relative to the largest value of each quantity, which the harmonic fit's Gram matrix,
    close to n/2 times the identity, does not amplify)."""
    for name, value in vars(whole).items():
        other = getattr(chunked, name)
        if isinstance(value, np.ndarray):
            scale = max(float(np.max(np.abs(value))), 1e-300)
            np.testing.assert_allclose(other, value, rtol=0, atol=4 * n * EPS * scale, err_msg=name)
        elif isinstance(value, float):
            assert other == pytest.approx(value, rel=4 * n * EPS, abs=1e-300, nan_ok=True), name
        else:
            assert other == value, name


@pytest.mark.parametrize("chunk", [7, 1000, 1 << 15])
@pytest.mark.parametrize("ripple", [0.0, 0.05])
def test_chunked_rotation_summary_equals_the_whole_array_one(monkeypatch, chunk, ripple):
    n = 36_001                          # 3 turns at 30 deg/s, not a multiple of any chunk size
    t, accel, gyro, temp, angle, sigma, bias = rotation(n, ripple=ripple)
    whole = reference_summary("rot", np.array([1.0, 0, 0]), 0, angle, t, accel, gyro, temp, sigma, bias)
    monkeypatch.setattr(summaries, "CHUNK_SAMPLES", chunk)
    chunked = summaries.rotation_summary("rot", np.array([1.0, 0, 0]), 0, angle, t, accel, gyro, temp,
                                         sigma, bias)
    assert_equal_to_rounding(chunked, whole, n)
    assert abs(chunked.accel_cos[1] - 9.8) < 0.01 and chunked.steady


def test_a_short_sweep_takes_the_svd_solver_and_still_agrees(monkeypatch):
    """A 3-degree sweep: the harmonic basis is nearly collinear (Gram condition far above
    MAX_GRAM_CONDITION), so the whole-basis SVD solve is used, as before."""
    n = 100
    t, accel, gyro, temp, angle, sigma, bias = rotation(n)
    whole = reference_summary("rot", np.array([1.0, 0, 0]), 0, angle, t, accel, gyro, temp, sigma, bias)
    monkeypatch.setattr(summaries, "CHUNK_SAMPLES", 16)
    chunked = summaries.rotation_summary("rot", np.array([1.0, 0, 0]), 0, angle, t, accel, gyro, temp,
                                         sigma, bias)
    # the SVD solution of an ill-conditioned basis: agreement to rounding times its condition
    for name in ("accel_dc", "accel_cos", "accel_sin", "gyro_integral", "rate_coef"):
        np.testing.assert_allclose(getattr(chunked, name), getattr(whole, name), rtol=1e-6, atol=1e-9,
                                   err_msg=name)
    assert chunked.samples == whole.samples == n


@pytest.mark.parametrize("chunk", [7, 1 << 15])
def test_static_noise_sums_chunk_by_chunk_equal_the_whole_array_ones(monkeypatch, chunk):
    """The statics' white noise (half the sum of squared first differences) chunk by chunk."""
    rng = np.random.default_rng(2)
    x = rng.normal([0.1, -0.2, 9.8], 0.01, (50_001, 3))
    monkeypatch.setattr(summaries, "CHUNK_SAMPLES", chunk)
    whole = np.sum(np.diff(x, axis=0) ** 2, axis=0) / 2
    np.testing.assert_allclose(summaries._half_sum_sq_diff(x), whole, rtol=4 * len(x) * EPS, atol=0)
    assert summaries._half_sum_sq_diff(x[:1]).tolist() == [0.0, 0.0, 0.0]


@pytest.mark.parametrize("turns", [200.0 / 360.0, 1.5, 3.0])
def test_the_fits_whitening_of_a_rotations_harmonics_is_their_noise(turns):
    """Over part of a revolution the harmonic coefficients are correlated and far less certain
    than over whole ones (200 degrees: the basis' Gram condition 186): the fit whitens them by
    the square root of the arc's Gram matrix (RotationSummary.gram), which over 400 noise
    realisations gives whitened coefficients of unit covariance (the whole-revolution weights
    gave variances up to ~100 at 200 degrees, and the optimal9 fit of such rotations a reduced
    chi2 of 20).  Tolerance: a variance estimated from 400 draws scatters by sqrt(2/400) = 0.07."""
    from station.estimate.lsq import _harmonic_whitening

    rng = np.random.default_rng(11)
    n, sigma = 2000, 0.01
    t = np.arange(n) / 100.0
    phase = np.radians(turns * 360.0) * t / t[-1]
    clean = np.column_stack([0.05 + 0 * t, 9.8 * np.cos(phase), 9.8 * np.sin(phase)])
    gyro = np.column_stack([np.full(n, turns * 360.0 / t[-1]), np.zeros(n), np.zeros(n)])
    truth = summaries.rotation_summary("r", np.array([1.0, 0, 0]), 0, turns * 360.0 * n / (n - 1), t, clean,
                                       gyro, None)
    whitened = []
    for _ in range(400):
        s = summaries.rotation_summary("r", np.array([1.0, 0, 0]), 0, turns * 360.0 * n / (n - 1), t,
                                       clean + rng.normal(0, sigma, (n, 3)), gyro, None)
        diff = np.array([s.accel_dc - truth.accel_dc, s.accel_cos - truth.accel_cos, s.accel_sin - truth.accel_sin,
                         s.accel_cos2 - truth.accel_cos2, s.accel_sin2 - truth.accel_sin2])      # (5, 3)
        whitened.append(_harmonic_whitening(s.gram) @ diff[:, 1] * np.sqrt(n) / sigma)
    cov = np.cov(np.array(whitened).T)
    assert np.all(np.abs(np.diag(cov) - 1.0) < 0.25) and np.all(np.abs(cov - np.diag(np.diag(cov))) < 0.25), cov
    if turns < 1:
        assert np.linalg.cond(truth.gram) > 100


def test_column_means_are_numpys_to_the_last_bit():
    """summaries._column_means (np.mean's sum over the count, without its Python layer: issue 27)
    gives np.mean's numbers bit for bit: any length (numpy's pairwise sum switches at 8 and 128
    values), strided columns, large and small magnitudes, another dtype."""
    rng = np.random.default_rng(27)
    for n in (1, 2, 7, 8, 9, 127, 128, 129, 1000, 10007, 70001):
        for scale in (1e-3, 1.0, 1e6):
            x = rng.normal(5.0, 1.0, (n, 3)) * scale
            for view in (x, x[::2], x[:, ::-1]):
                expected = np.array([view[:, k].mean() for k in range(view.shape[1])])
                assert summaries._column_means(view).tobytes() == expected.tobytes()
    ints = rng.integers(-1000, 1000, (500, 3))
    np.testing.assert_array_equal(summaries._column_means(ints), ints.mean(axis=0))


def test_a_recorded_ramps_turned_moments_are_summed_chunk_by_chunk_too():
    """A recorded ramp's turned moments (RotationSummary.turned_moments, table_encoder_scale; issue
    28) are the least-squares harmonics of theta cos, theta sin, theta^2 cos, theta^2 sin over the
    window's samples.  Taken with whole arrays (the phase, its basis, four columns and lstsq's
    copies) a 4 kHz, 10-minute ramp-recorded turn's summary peaked at 309 MB of temporaries
    against 115 MB without them, and took 3 times the CPU (review of enc28): they are summed
    with the accelerometer's, CHUNK_SAMPLES at a time.  Here 240,000 samples (4 kHz, 60 s; a 1 s
    rest, a ramp at 50 deg/s^2, 10 deg/s): the summary's temporaries stay under three times the
    accelerometer array (nine float64 columns of the segment's length: the ramp's phase, its
    gyro-derived rate and turn, the Earth weights' phase and their temporaries, 2.0 measured);
    the moments are the whole-array least-squares fit's (reference: numpy's lstsq on the samples'
    own phases, sharing no code) to rounding."""
    import tracemalloc

    fs, rate, accel_dps2, rest_s, n = 4000.0, 10.0, 50.0, 1.0, 240_000
    t = np.arange(n) / fs
    moving = np.clip(t - rest_s, 0.0, None)
    w = np.minimum(accel_dps2 * moving, rate)
    turned = np.concatenate([[0.0], np.cumsum(0.5 * (w[1:] + w[:-1]) / fs)]) + 0.5 * w[0] / fs
    angle = turned[-1] + 0.5 * w[-1] / fs
    phase = np.radians(turned)
    rng = np.random.default_rng(3)
    accel = np.column_stack([np.full(n, 0.1), 9.8 * np.cos(phase), -9.8 * np.sin(phase)])
    accel += rng.normal(0, 0.01, (n, 3))
    gyro = np.column_stack([w, np.zeros(n), np.zeros(n)]) + rng.normal(0, 0.01, (n, 3))
    tracemalloc.start()
    try:
        s = summaries.rotation_summary("ramp", np.array([1.0, 0, 0]), 0, angle, t, accel, gyro, None,
                                       gyro_sigma_dps=np.full(3, 0.01), steady_rate_dps=rate)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert s.turned_moments is not None and s.rate_from_table
    assert peak < 3 * accel.nbytes, (peak / 1e6, accel.nbytes / 1e6)
    # the reference: the summary's own phase is the gyro's, close to the true one; the moments of
    # the true phase differ from it by the phase's error, so compare over the same phases: those
    # the summary took are not exposed, hence the true phase and a tolerance of its error
    theta = np.radians(angle) * (turned / angle)
    basis = np.column_stack([np.ones(n), np.cos(theta), np.sin(theta), np.cos(2 * theta), np.sin(2 * theta)])
    wanted = np.column_stack([theta * basis[:, 1], theta * basis[:, 2], theta**2 * basis[:, 1], theta**2 * basis[:, 2]])
    reference = np.linalg.lstsq(basis, wanted, rcond=None)[0].T
    np.testing.assert_allclose(s.turned_moments, reference, rtol=0, atol=1e-3 * np.abs(reference).max())
