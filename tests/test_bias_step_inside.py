"""Issue 25, run 3: a bias step anywhere in time (inside a static or a rotation, not only at a
boundary between segments), its compensation on apply's clock, and the gyro anisoelastic term
at a MEMS size.  The goal harness's scheme (optimal9, 20 s statics, 36 s rotations at 100 °/s)
on the simulator (sim_devices, written independently of station.model)."""
import numpy as np
import pytest

import simhelpers
from station.estimate import lsq, profile
from station.model.bias_step import BiasStep, phase_weights, sample_share
from station.model.effect import SampleContext

GOAL = {"rate_dps": 100.0, "rotation_s": 36.0, "dwell_s": 20.0}


def summaries(seed=4, **hidden):
    truth, cap = simhelpers.mems_capture(seed, "optimal9", GOAL, **hidden)
    return truth, lsq.summarise(cap)


def reported(result, name):
    names, values, _, cov = lsq.reported(result, "m/s^2", "deg/s")
    i = names.index(name)
    return float(values[i]), float(np.sqrt(cov[i, i]))


def span_of(s, name):
    return next(x for x in BiasStep.segment_spans(s) if x["name"] == name)


@pytest.fixture(scope="module")
def accel_step():
    """The accelerometer y bias steps by +1500 µg at 400 s (the goal's accel_bias_step)."""
    return summaries(accel__bias_step=[0.0, 1500.0, 0.0], accel__bias_step_time_s=400.0)


def test_a_step_inside_a_rotation_is_located_inside_it_with_its_time_and_size(accel_step):
    """Run 2 offered only the boundaries between segments: the step 19 s into rotx_m was not kept
    and rotation_axis_offsets took part of it (reduced chi2 17 -> 2.6).  Now the profile splits
    each segment's samples: the step is located inside rotx_m, the fit passes, its size is within
    4 sigma of 1500 µg (sigma ~27 µg: the accelerometer's ~1 mg per-sample noise over the ~36,000
    samples on each side, with the attitudes' own parameters) and its time within 2 s of 400 s
    (the profile's 1-sigma range is ~1 s: the 36 s rotation's mean moves by 1500 µg / 36 s = 42
    µg per second of step time against its ~6 µg noise, the harmonics neglected in the profile)."""
    _, s = accel_step
    rotx_m = span_of(s, "rotx_m")
    effect = BiasStep()
    result = profile.fit_located(s, [effect])
    assert effect.segment == "rotx_m", effect.located_by
    t_capture = effect.step_time_s + effect.origin_s
    assert abs(t_capture - 400.0) < 2.0, effect.located_by
    assert rotx_m["first"] < effect.step_time_s < rotx_m["last"]
    value, sigma = reported(result, "accel_bias_step_y")
    assert abs(value - 1500.0) < 4 * sigma and sigma < 60.0, (value, sigma)
    assert result.chi2 / result.dof < 1.3, result.chi2 / result.dof
    # the words name the segment, the time into it and the 1-sigma range
    said = effect.words(np.array([0.0, value, 0.0, 0.0, 0.0, 0.0]), np.array([1.0, sigma, 1.0, 1.0, 1.0, 1.0]))
    assert said and "into rotx_m" in said[0] and "1σ" in said[0] and "µg" in said[0], said


@pytest.fixture(scope="module")
def gyro_step_located():
    """The gyro z bias steps by +50 °/h at 300 s, 5 s into pos09, located (profile.fit_located)."""
    _, s = summaries(gyro__bias_step=[0.0, 0.0, 50.0], gyro__bias_step_time_s=300.0)
    effect = BiasStep()
    return s, effect, profile.fit_located(s, [effect])


def test_a_gyro_step_inside_a_static_is_located_there_and_apply_compensates_it_on_its_own_clock(gyro_step_located):
    """The gyro z bias steps by +50 °/h at 300 s, 5 s into pos09 (the goal's gyro_bias_step).  Run 2
    put it at the boundary pos08 -> pos09 (287.5 s) and apply counted that time from the first
    sample of its data without the fit's origin (the first segment's MEAN time, 10 s later): the
    held-out rotation that straddles 300 s was compensated 22 s early (41 ppm against a floor of
    13.9).  Now the step is located inside pos09 within 3 s (the profile's 1-sigma is ~2 s: the
    step moves pos09's mean by 50 °/h / 20 s = 2.5 °/h per second against its ~2.2 °/h noise) and
    apply's step falls at the same time on the capture's clock."""
    s, effect, result = gyro_step_located
    assert effect.segment == "pos09", effect.located_by
    t_capture = effect.step_time_s + effect.origin_s
    assert abs(t_capture - 300.0) < 3.0, effect.located_by
    value, sigma = reported(result, "gyro_bias_step_z")
    assert abs(value - 50.0) < 4 * sigma and sigma < 5.0, (value, sigma)
    # station apply on a recording that starts where the capture started (its first sample)
    t = effect.start_s + np.arange(0.0, 600.0, 0.01)
    ctx = SampleContext(f_p=np.zeros((len(t), 3)), w_p=np.zeros((len(t), 3)), w_table=np.zeros((len(t), 3)),
                        wdot_table=np.zeros((len(t), 3)), temp_c=np.full(len(t), np.nan),
                        accel_matrix=np.eye(3), gyro_matrix=np.eye(3), t_s=t - t[0])
    after = effect._after(ctx)[:, 0]
    first = t[np.argmax(after > 0)]
    assert abs(first - t_capture) <= 0.01, (first, t_capture)


def test_the_location_spread_is_kept_when_the_fit_refines_the_time_of_a_step_inside_a_segment(gyro_step_located):
    """Issue 28 review: refine_time moves the time of a step inside pos09 off the profile's split
    (276.0 -> 275.2 s on the fit's clock, chi2 167.0 -> 166.8); location_spread was then asked for
    a candidate the profile never had and returned None, so the spread of where the step may be
    was silently left out of the covariance of every step inside a segment the refinement moved.
    The spread belongs to the profile's candidate (the time's own 1-sigma is freed in the fit)."""
    s, effect, result = gyro_step_located
    located = [t for t, before, after in effect.profile_sizes if before == after == "pos09"]
    assert located and effect.step_time_s not in located, (located, effect.step_time_s)   # refined
    assert effect.location_spread is not None
    blocks, extra = effect.location_spread
    assert blocks[-1] == "effect:bias_step" and np.all(np.isfinite(extra))
    assert np.all(np.linalg.eigvalsh(extra) >= -1e-12 * max(np.abs(extra).max(), 1e-300))


def test_a_static_split_carries_the_share_of_its_samples_after_the_step():
    span = {"first": 10.0, "last": 29.99, "samples": 2000, "rotation": False, "angle_deg": 0.0}
    assert sample_share(span, 5.0) == 1.0 and sample_share(span, 40.0) == 0.0
    assert sample_share(span, 15.005) == pytest.approx(1499 / 2000)      # 501 samples before (10.00-15.00 s)
    assert sample_share(span, 29.995) == pytest.approx(0.0)


@pytest.mark.parametrize("angle_deg, step_fraction", [(3600.0, 0.53), (-3600.0, 0.3), (250.0, 0.6),
                                                      (-1234.0, 0.77)])
def test_a_rotation_split_projects_on_the_harmonics_as_the_samples_do(angle_deg, step_fraction):
    """The rotation's summaries are the mean and the first two harmonics of the samples over the
    encoder's angle; the model evaluates a term at 12 phase points and projects them.  The phase
    weights (the share of each phase's visits after the step, as a Fourier series to order 4) must
    give the harmonics of H(t - t_step) over the samples: checked against a least-squares
    projection of the samples themselves (10 revolutions at 100 Hz: 3600 samples; the residual
    difference is the series' truncation, < 2 % of the step)."""
    n, dur = 3600, 35.99
    t = np.linspace(0.0, dur, n)
    phi = np.radians(angle_deg) * t / dur
    step_s = step_fraction * dur
    H = (t >= step_s).astype(float)
    basis = np.column_stack([np.ones(n), np.cos(phi), np.sin(phi), np.cos(2 * phi), np.sin(2 * phi)])
    want = np.linalg.lstsq(basis, H, rcond=None)[0]
    span = {"first": 0.0, "last": dur, "samples": n, "rotation": True, "angle_deg": angle_deg}
    w = phase_weights(span, step_s, 12)
    grid = 2 * np.pi * np.arange(12) / 12
    gbasis = np.column_stack([np.ones(12), np.cos(grid), np.sin(grid), np.cos(2 * grid), np.sin(2 * grid)])
    got = np.linalg.lstsq(gbasis, w, rcond=None)[0]
    # the mean (the gyro integral's share and the accelerometers' mean) is the samples' share after
    # the step, whole revolutions or not (the phases' visits weigh their fractions); the
    # harmonics are compared for whole revolutions, where every phase is visited as often
    assert got[0] == pytest.approx(H.mean(), abs=2e-3)
    if abs(angle_deg) % 360.0 == 0.0:
        assert np.max(np.abs(got - want)) < 0.02, (got, want)


ANISO = [[0.0, 0.0, 20.0, 30.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0, 0.0, 40.0], [0.0, 0.0, 0.0, 0.0, -35.0, 0.0]]


@pytest.fixture(scope="module")
def aniso_fits():
    """Summaries with the goal's anisoelastic term, the fit without it and the fit with it."""
    from station.model.registry import EffectRegistry

    _, s = summaries(gyro__anisoelastic_dph_per_g2=ANISO)
    base = lsq.fit(s)
    return s, base, lsq.fit(s, [EffectRegistry().create("gyro_anisoelastic")], like=base.model)


def test_the_out_of_sample_check_keeps_a_real_anisoelastic_term_and_refuses_it_on_a_clean_capture(aniso_fits):
    """Run 2's leave-one-segment-out score (the squared deleted residuals) rose with the true
    anisoelastic term (on the goal harness's capture: 720 -> 807, rotxz_m alone 22 -> 225, a segment of leverage ~0.9 whose
    extrapolation the 1/(1-h)^2 weighting let outweigh the others) and --auto refused it, though
    `estimate --add gyro_anisoelastic` took the held-out gyro error from 51 to 20 ppm.  The
    predictive chi2 (the deleted residuals against their own covariance, plus its log-determinant)
    falls with it (420 -> 344); on a clean capture of the same scheme and seed the same term,
    fitted to noise alone, raises it (296 -> 342): the check stays a check."""
    from station.diagnose.holdout import leave_one_segment_out
    from station.model.registry import EffectRegistry

    _, base, with_it = aniso_fits
    before, after = leave_one_segment_out(base).common_score(leave_one_segment_out(with_it))
    assert after < before - 20.0, (before, after)
    _, clean = summaries()
    base = lsq.fit(clean)
    noise_fit = lsq.fit(clean, [EffectRegistry().create("gyro_anisoelastic")], like=base.model)
    before, after = leave_one_segment_out(base).common_score(leave_one_segment_out(noise_fit))
    assert after > before, (before, after)


def test_a_gyro_anisoelastic_term_of_a_mems_size_is_estimated_not_held_by_its_prior(aniso_fits):
    """The goal's gyro_anisoelastic (20-40 °/h/g²): run 2 held every one of its 15 parameters at
    0 ± 2 °/h/g² (its 'typical' size was the bottom of the MEMS range, below what 20 s statics
    resolve, ~4-9 °/h/g², so the fit called them blind), the fit kept a reduced chi2 of 1.37 and
    --auto did not keep it (12 % of the excess).  With a typical size of 10 °/h/g² (MEMS: 1-50)
    the capture estimates them: the truth's x: 20 F_z² + 30 F_x F_y, y: 40 F_y F_z, z: -35 F_x F_z
    are xx = yy = -20 (F_z² = 1 - F_x² - F_y² at rest), xy = 30 on x, yz = 40 on y, xz = -35 on z,
    each within 4 sigma, and the fit passes."""
    _, _, result = aniso_fits
    assert not [n for n in result.model.unobservable if n.startswith("gyro_aniso")], result.model.unobservable
    truth = {"x_xx": -20.0, "x_yy": -20.0, "x_xy": 30.0, "y_yz": 40.0, "z_xz": -35.0}
    for name in ("x_xx", "x_yy", "x_xy", "x_xz", "x_yz", "y_xx", "y_yy", "y_xy", "y_xz", "y_yz",
                 "z_xx", "z_yy", "z_xy", "z_xz", "z_yz"):
        value, sigma = reported(result, f"gyro_aniso_{name}")
        assert abs(value - truth.get(name, 0.0)) < 4 * sigma and sigma < 10.0, (name, value, sigma)
    assert result.chi2 / result.dof < 1.2, result.chi2 / result.dof
