"""Review of issue 28's fixramp28 merge (revramp): the summaries' merged columns of a recorded ramp
(6-9 the encoder's turned moments, 10-17 the ramp products of table_vibration's (5)) in both of
rotation_summary's paths -- the chunk loop's normal equations and a short sweep's SVD fallback --
with and without an accelerometer mask, across chunk boundaries."""
import numpy as np
import pytest

from station.estimate import summaries


def _ramp(n=2500, fs=200.0, rate=60.0, accel_dps2=40.0, rest_s=1.0, seed=3):
    """A rest, a ramp up and steady turns about x: (t, accel, gyro, angle_deg)."""
    t = np.arange(n) / fs
    w = np.minimum(accel_dps2 * np.clip(t - rest_s, 0.0, None), rate)
    turned = np.concatenate([[0.0], np.cumsum(0.5 * (w[1:] + w[:-1]) / fs)]) + 0.5 * w[0] / fs
    angle = turned[-1] + 0.5 * w[-1] / fs
    phase = np.radians(turned)
    rng = np.random.default_rng(seed)
    accel = np.column_stack([np.full(n, 0.1), 9.8 * np.cos(phase), -9.8 * np.sin(phase)]) + rng.normal(0, 0.01, (n, 3))
    gyro = np.column_stack([w, np.zeros(n), np.zeros(n)]) + rng.normal(0, 0.01, (n, 3))
    return t, accel, gyro, angle


@pytest.mark.parametrize("masked", [False, True])
@pytest.mark.parametrize("chunk, max_condition", [(None, None), (7, None), (333, None), (None, 0.0), (7, 0.0)])
def test_a_recorded_ramps_merged_columns_are_the_least_squares_harmonics_in_both_paths(monkeypatch, masked, chunk,
                                                                                        max_condition):
    """ramp_coef ([w^2, dw/dt] x [1, cos, sin, cos 2, sin 2 of the phase] x harmonic), turned_moments
    and the accelerometer's harmonics against numpy's lstsq on the samples kept, over the summary's
    own phase and rate (_ramp_fraction), sharing no column layout with rotation_summary: chunk sizes
    that split the window anywhere, the short sweep's SVD fallback forced (MAX_GRAM_CONDITION 0), a
    mask leaving out every 7th sample and a run of 100.  Equal to rounding (measured <= 2e-15 of
    each quantity's largest value): 1e-12."""
    t, accel, gyro, angle = _ramp()
    n, rate, sigma = len(t), 60.0, np.full(3, 0.01)
    keep = np.ones(n, bool)
    if masked:
        keep[::7] = False
        keep[1500:1600] = False
    if chunk is not None:
        monkeypatch.setattr(summaries, "CHUNK_SAMPLES", chunk)
    if max_condition is not None:
        monkeypatch.setattr(summaries, "MAX_GRAM_CONDITION", max_condition)
    s = summaries.rotation_summary("r", np.array([1.0, 0, 0]), 0, angle, t, accel, gyro, None, gyro_sigma_dps=sigma,
                                   accel_mask=(lambda phase, a: keep) if masked else None, steady_rate_dps=rate)
    assert s.rate_from_table and s.samples == int(keep.sum())
    fraction, table_rate = summaries._ramp_fraction(t, gyro, gyro.mean(axis=0), angle, rate, sigma)
    theta = np.radians(angle) * fraction
    basis = np.column_stack([np.ones(n), np.cos(theta), np.sin(theta), np.cos(2 * theta), np.sin(2 * theta)])
    w = np.radians(table_rate)
    wsq, wdot = w * w, np.gradient(w, t)
    wanted = np.column_stack([accel, wsq[:, None] * basis, wdot[:, None] * basis,
                              theta * basis[:, 1], theta * basis[:, 2], theta**2 * basis[:, 1], theta**2 * basis[:, 2]])
    ref = np.linalg.lstsq(basis[keep], wanted[keep], rcond=None)[0]          # (5 harmonics, 17)
    harmonics = np.stack([s.accel_dc, s.accel_cos, s.accel_sin, s.accel_cos2, s.accel_sin2])
    for name, have, want in (("accel", harmonics, ref[:, :3]),
                             ("ramp_coef", s.ramp_coef, np.stack([ref[:, 3:8].T, ref[:, 8:13].T])),
                             ("turned_moments", s.turned_moments, ref[:, 13:17].T),
                             ("rate_sq_coef", s.rate_sq_coef, ref[:, 3]), ("rate_dot_coef", s.rate_dot_coef, ref[:, 8])):
        np.testing.assert_allclose(have, want, rtol=0, atol=1e-12 * np.abs(want).max(), err_msg=name)
