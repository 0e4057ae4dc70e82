"""Issue 25, the rest of item 1 and item 5: a bias step located in time, a table encoder scale error,
a mounting offset per rotation axis and a table vibrating once per revolution, each hidden in the
simulator (sim_devices, written independently of station.model); and words for a failure that
--auto cannot mend.  Short schemes (optimal9: 6 s statics, 36 s rotations at 100 °/s)."""
import numpy as np
import pytest

import simhelpers
from effect_recovery import held_out_error
from station.diagnose import auto
from station.diagnose.core import SegmentResidual, diagnose, fit_fails
from station.diagnose.words import axis_patterns
from station.estimate import lsq, profile
from station.model.bias_step import BiasStep
from station.model.effect import SampleContext
from station.model.table_encoder_scale import TableEncoderScale

SHORT = {"rate_dps": 100.0, "rotation_s": 36.0, "dwell_s": 6.0}     # ten revolutions each way
NEW = ("bias_step", "table_encoder_scale", "rotation_axis_offsets")


def summaries(seed=3, overrides=None, **hidden):
    truth, cap = simhelpers.mems_capture(seed, "optimal9", overrides or SHORT, **hidden)
    return truth, lsq.summarise(cap)


def estimate_of(result, name):
    names, values, _, cov = lsq.reported(result, "m/s^2", "deg/s")
    i = names.index(name)
    return float(values[i]), float(np.sqrt(cov[i, i]))


# --- bias step -----------------------------------------------------------------------------

def test_a_gyro_bias_step_is_added_with_its_time_and_said_in_words():
    """The gyro z bias steps by +50 °/h at t = 300 s (between rotx_m, which ends at 291 s, and roty_p,
    which starts at 306 s).  --auto adds bias_step at the time the profile over the 17 boundaries
    locates, the fit then passes, and the step is said in words with its size and time.  Its size
    is checked against its own 1σ (4σ; ~2 °/h: the gyro's ~100 °/h per-sample noise over the
    ~30,000 samples on each side), the time to the boundary's gap (15 s).  (A step of the gyro about
    the axis of the rotations it falls beside, z before rotz, is aliased: that axis' Earth-rate
    component is a free parameter of the model; the profile lists the other boundary as likely.)"""
    from station.model.registry import EffectRegistry

    _, s = summaries(seed=4, gyro__bias_step=[0.0, 0.0, 50.0], gyro__bias_step_time_s=300.0)
    # the library without gyro_anisoelastic: with it, an IMU effect tried first, its means over the
    # revolutions about the horizontal axes (gyro offsets per rotation axis) are kept at step 1 and
    # dropped by the backward elimination once the step is in (the same end), but each fit of its 15
    # barely seen terms beside a time effect crept to the solver's limit (LM gaining ~0.01 of chi2
    # per 25 evaluations: 75 s of this test; issue 27).  The creep watch in chi2 units now takes 7 of
    # the 9 such fits to their minimum (9,270 -> 2,706 Jacobians), but two creep in dogbox too and
    # still reach the limit (~84 s of CPU in all on a loaded machine); here the step's own loop
    registry = EffectRegistry(entry_points=False, environment=False)
    registry.classes.pop("gyro_anisoelastic")
    steps, final = auto.run(s, discover=False, registry=registry)
    assert [e.id for e in final.result.model.effects] == ["bias_step"], [st.added for st in steps]
    step = next(st for st in steps if st.added == "bias_step")
    assert not fit_fails(final.result), final.verdict
    value, sigma = estimate_of(final.result, "gyro_bias_step_z")
    assert abs(value - 50.0) < 4 * sigma and sigma < 5.0, (value, sigma)
    effect = next(e for e in final.result.model.effects if e.id == "bias_step")
    assert abs(effect.step_time_s + effect.origin_s - 300.0) < 15.0, effect.located_by
    said = [c for c in step.caveats if c.startswith("gyro z bias steps by +")]
    assert said and f"at t = {effect.step_time_s + effect.origin_s:.0f} s" in said[0], step.caveats
    # no other axis' step is said (the accelerometers' and the other gyros' are within 3 sigma)
    assert len([c for c in step.caveats if "bias steps by" in c]) == 1, step.caveats


def test_a_step_between_the_statics_and_the_rotations_is_not_a_candidate():
    """With every static first and every rotation after, a step at that boundary is any offset the
    rotations share; the profile does not offer it (the words name it: test_diagnose_words)."""
    _, s = summaries()
    cands = BiasStep.candidate_times(s)
    assert cands and all(not (a == "pos09" and b == "rotx_p") for _, a, b in cands)
    assert ("rotx_p", "rotx_m") in {(a, b) for _, a, b in cands}


def test_bias_step_in_estimate_is_located_by_the_profile():
    """estimate --add bias_step (no diagnosis): the time is located before the fit (profile.fit_located)."""
    _, s = summaries(seed=5, gyro__bias_step=[0.0, 0.0, 50.0], gyro__bias_step_time_s=300.0)
    effect = BiasStep()
    result = profile.fit_located(s, [effect])
    assert effect.located_by.startswith("located between"), effect.located_by
    assert abs(effect.step_time_s + effect.origin_s - 300.0) < 15.0
    value, sigma = estimate_of(result, "gyro_bias_step_z")
    assert abs(value - 50.0) < 4 * sigma


# --- table encoder scale ---------------------------------------------------------------------

@pytest.fixture(scope="module")
def encoder():
    truth, s = summaries(bench__encoder_scale_error_ppm=300.0)
    return truth, s, lsq.fit(s)


def test_the_encoder_scale_error_is_the_candidate_and_is_recovered(encoder):
    """The table turns 300 ppm more than its encoder says: the gyros' scale factors take it and the
    accelerometers' rotations do not fit (reduced chi2 ~ 18).  The score test names
    table_encoder_scale first; fitted, it comes back within 4σ (σ ~ 5.5 ppm, from the rotations'
    accelerometer harmonics) and the fit passes."""
    truth, s, base = encoder
    d = diagnose(base)
    assert d.candidates[0].effect == "table_encoder_scale" and d.candidates[0].significant
    with_it = lsq.fit(s, [TableEncoderScale()], like=base.model)
    value, sigma = estimate_of(with_it, "table_encoder_scale_error")
    assert abs(value - 300.0) < 4 * sigma and sigma < 10.0, (value, sigma)
    assert fit_fails(base) and not fit_fails(with_it)
    # held out: the gyro scale factors are those of the true angle again.  Without the effect their
    # error is ~ the 300 ppm the encoder hides (each axis alike); with it, within the fit's own
    # gyro-scale 1-sigma (~10 ppm) of the clean floor: under a third of the error without it
    before = held_out_error(base, truth).gyro_ppm
    after = held_out_error(with_it, truth).gyro_ppm
    assert before > 150.0 and after < before / 3, (before, after)


@pytest.mark.parametrize("angle_deg", [300.0, -200.0, 360.0, -720.0, 520.0])
def test_the_turned_gravity_projects_as_the_summaries_fit_it_over_any_arc(angle_deg):
    """The encoder's term on the fit's phase grid, projected as the fit projects it (uniformly),
    against a reference sharing no code with it: samples of a uniform turn whose gravity turns
    through (1 + e) times the encoder's angle (a rotation, not its expansion), their harmonics
    fitted over the arc by least squares (as the summaries do), less those at e = 0.  Over part of
    a revolution the grid's mean visit was not that fit: 1000 ppm on turns of 300 degrees came out
    898 +- 9 (reduced chi2 4.5; issue 28, twenty-first session).  Tolerance: the third order the
    term leaves out, (e theta)^3 / 6 g, 2e-7 g at e = 2000 ppm and 720 degrees, and the samples'
    discretisation (4,000 per revolution)."""
    from types import SimpleNamespace

    from scipy.spatial.transform import Rotation

    from station.model.table_encoder_scale import turned_time

    e_ppm, g, phases = 2000.0, 9.81, 12
    l = np.array([0.0, 0.0, 1.0])
    v = g * np.array([0.8, -0.6, 0.0])                       # gravity across the axis at the start
    kappa = 0.3                                              # and along it (does not turn)
    A = np.radians(angle_deg)
    n = int(4000 * max(1.0, abs(angle_deg) / 360.0))
    theta = A * (np.arange(n) + 0.5) / n                     # the encoder's angle at each sample
    basis = np.column_stack([np.ones(n), np.cos(theta), np.sin(theta), np.cos(2 * theta), np.sin(2 * theta)])

    def harmonics(scale):       # the body sees gravity turned by -scale theta about l
        f = Rotation.from_rotvec(-np.outer(scale * theta, l)).apply(v) + kappa * l
        return np.linalg.lstsq(basis, f, rcond=None)[0]

    expected = harmonics(1.0 + 1e-6 * e_ppm) - harmonics(1.0)
    # the fit's context: PHASES points, gravity at the grid's phases, one rotation (segment 7)
    p = 2 * np.pi * np.arange(phases) / phases
    f_p = kappa * l + np.outer(np.cos(p), v) - np.outer(np.sin(p), np.cross(l, v))
    rate = A / 30.0
    ctx = SampleContext(f_p=f_p, w_p=np.zeros((phases, 3)), w_table=np.outer(np.full(phases, rate), l),
                        wdot_table=np.zeros((phases, 3)), temp_c=np.full(phases, np.nan), accel_matrix=np.eye(3),
                        gyro_matrix=np.eye(3), segment_index=np.full(phases, 7.0),
                        turned_s=turned_time(angle_deg, 30.0, phases), turned_sq_s2=turned_time(angle_deg, 30.0, phases, 2))
    effect = TableEncoderScale()
    effect.setup(SimpleNamespace(rotations=[SimpleNamespace(index=7, steady=True, angle_deg=angle_deg, table_axis=None)]))
    term = effect.accel(np.array([e_ppm]), ctx)
    grid = np.column_stack([np.ones(phases), np.cos(p), np.sin(p), np.cos(2 * p), np.sin(2 * p)])
    got = (grid * np.array([1.0, 2.0, 2.0, 2.0, 2.0])).T / phases @ term       # the fit's projection
    tolerance = (1e-6 * e_ppm * abs(A)) ** 3 / 6 * g + 1e-7 * g
    np.testing.assert_allclose(got, expected, rtol=0, atol=tolerance)
    assert np.abs(expected).max() > 100 * tolerance       # the term itself is far above it


@pytest.mark.parametrize("ramp", ["start", "end"])
def test_a_recorded_ramps_turned_gravity_is_fitted_over_its_own_samples(ramp):
    """A recorded ramp's window is no uniform turn (a rest and a ramp at one end spend more samples
    at their phases): the summaries keep the window's own least-squares moments of the turned
    angle (RotationSummary.turned_moments) and the effect projects to them.  Reference: the
    summaries of samples whose gravity turns through (1 + e) times the table's angle (a rotation),
    less those at e = 0.  Before, the uniform turn's mean visit: 5000 ppm on ramp-recorded turns
    of one revolution at 10 deg/s (the brake recorded) came out 5043 +- 9 (chi2 5,240 on 92, 179
    at e = 0); now the fit at 5000 ppm has the chi2 and the offset of the one at e = 0.  Tolerance:
    the third order left out, (e theta)^3 / 6 g, and rounding."""
    from types import SimpleNamespace

    from scipy.spatial.transform import Rotation

    from station.estimate.summaries import rotation_summary
    from station.model.table_encoder_scale import turned_time

    e_ppm, g, fs, rate, accel_dps2, rest_s, steady_s = 5000.0, 9.81, 100.0, 30.0, 50.0, 0.5, 12.0
    ramp_s = rate / accel_dps2
    n = int(round((rest_s + ramp_s + steady_s) * fs))
    t = np.arange(n) / fs
    # the table's angle (the encoder's, deg) and rate: rest, ramp, steady (start); time-reversed (end)
    u = t if ramp == "start" else t[-1] - t
    moving = np.clip(u - rest_s, 0.0, None)
    w = np.where(moving < ramp_s, accel_dps2 * moving, rate)
    angle = np.where(moving < ramp_s, 0.5 * accel_dps2 * moving**2, 0.5 * rate * ramp_s + rate * (moving - ramp_s))
    if ramp == "end":
        angle = angle[0] - angle
    total = angle[-1] - angle[0] + 0.5 * (w[0] + w[-1]) / fs      # the window's (half a sample at each end)
    angle = angle - angle[0] + 0.5 * w[0] / fs                       # from the window's start
    l = np.array([0.0, 0.0, 1.0])
    v = g * np.array([0.6, 0.8, 0.0])
    gyro = np.outer(w, l)

    def summary(scale):
        f = Rotation.from_rotvec(-np.outer(scale * np.radians(angle), l)).apply(v) + 0.2 * l
        return rotation_summary("r", (0.0, 0.0, 1.0), 0, total, t, f, gyro, None, steady_rate_dps=rate)

    base, turned = summary(1.0), summary(1.0 + 1e-6 * e_ppm)
    assert base.turned_moments is not None
    expected = np.array([turned.accel_dc - base.accel_dc, turned.accel_cos - base.accel_cos,
                         turned.accel_sin - base.accel_sin, turned.accel_cos2 - base.accel_cos2,
                         turned.accel_sin2 - base.accel_sin2])
    phases = 12
    p = 2 * np.pi * np.arange(phases) / phases
    # the fit's gravity on its grid: the base summary's own first harmonic (v and l x v)
    f_p = 0.2 * l + np.outer(np.cos(p), base.accel_cos) + np.outer(np.sin(p), base.accel_sin)
    grid = np.column_stack([np.ones(phases), np.cos(p), np.sin(p), np.cos(2 * p), np.sin(2 * p)])
    # the table's rate on the grid as the fit takes it: the summary's harmonics of it (rad/s)
    ctx = SampleContext(f_p=f_p, w_p=np.zeros((phases, 3)), w_table=np.outer(grid @ base.rate_coef, l),
                        wdot_table=np.zeros((phases, 3)), temp_c=np.full(phases, np.nan), accel_matrix=np.eye(3),
                        gyro_matrix=np.eye(3), segment_index=np.full(phases, 7.0),
                        turned_s=turned_time(total, t[-1] + 1 / fs, phases),
                        turned_sq_s2=turned_time(total, t[-1] + 1 / fs, phases, 2))
    base.index = 7
    effect = TableEncoderScale()
    effect.setup(SimpleNamespace(rotations=[base]))
    term = effect.accel(np.array([e_ppm]), ctx)
    got = (grid * np.array([1.0, 2.0, 2.0, 2.0, 2.0])).T / phases @ term
    tolerance = (1e-6 * e_ppm * np.radians(total)) ** 3 / 6 * g + 1e-9 * g
    np.testing.assert_allclose(got, expected, rtol=0, atol=tolerance)
    assert np.abs(expected).max() > 100 * tolerance
    # the gyros: the fit's turn is the points' mean rate times T, and they turned (1 + e) A: the
    # term adds e A (deg) -- not e times the rate's harmonics on the grid, whose mean over a ramp's
    # window is not A / T (here 1.6 % above: 0.5 s at rest and 0.6 s of ramp in 13.1 s)
    turn = effect.gyro(np.array([e_ppm]), ctx).mean(axis=0) * base.duration_s
    np.testing.assert_allclose(turn, 1e-6 * e_ppm * total * l, rtol=1e-9, atol=1e-12)


def test_apply_compensates_nothing_for_the_table():
    """A bench property: outside the fit (no turned_s in the context) the effect has no term."""
    e = TableEncoderScale()
    ctx = SampleContext(f_p=np.ones((4, 3)), w_p=np.ones((4, 3)), w_table=np.ones((4, 3)),
                        wdot_table=np.zeros((4, 3)), temp_c=np.full(4, np.nan), accel_matrix=np.eye(3),
                        gyro_matrix=np.eye(3))
    assert e.accel(np.array([300.0]), ctx) is None and e.gyro(np.array([300.0]), ctx) is None


# --- a mounting offset per rotation axis ------------------------------------------------------

def test_a_mounting_offset_of_its_own_per_axis_is_found_and_named():
    """The IMU is 20 mm further (along z) from the axis that turns it about y than from the others:
    at 100 °/s that is 1.75² · 0.02 = 61 mm/s² = 6.2 mg of centripetal acceleration in roty's mean,
    against ~260 µg noise of a 36 s rotation's mean.  rotation_axis_offsets is significant; fitted,
    the offset comes back within 4σ and the fit passes; its words name the rotations."""
    _, s = summaries(bench__axis_offsets_m=[[0.0, 0.0, 0.0], [0.0, 0.0, 0.02], [0.0, 0.0, 0.0]])
    base = lsq.fit(s)
    d = diagnose(base)
    # (a bench nuisance is ranked after the IMU's significant effects: it can hold the size effect too)
    assert "rotation_axis_offsets" in [c.effect for c in d.candidates if c.significant]
    registry = simhelpers.registry_without()
    effect = registry.create("rotation_axis_offsets")
    result = lsq.fit(s, [effect], like=base.model)
    assert not fit_fails(result)
    group = next(r.group for r in s.rotations if r.name == "roty_p")
    value, sigma = estimate_of(result, f"axis{group}_offset_z")
    assert abs(value - 20.0) < 4 * sigma and sigma < 1.0, (value, sigma)
    names, values, _, cov = lsq.reported(result, "m/s^2", "deg/s")
    own = [i for i, n in enumerate(names) if n.startswith("axis")]
    words = effect.words(np.array([values[i] for i in own]), np.sqrt(np.diag(cov)[own]))
    assert any("roty_p, roty_m" in w and "along z" in w for w in words), words


# --- once per revolution ----------------------------------------------------------------------

def test_a_table_vibrating_once_per_revolution_is_named():
    """The table base accelerates by 1 mg along its axis once per revolution (and 0.5 mg across):
    gravity has no turning part along the axis, so the rotations' first harmonic along their own
    axis stands out (~1 mg against ~370 µg noise per harmonic component of a 36 s rotation)."""
    _, s = summaries(bench__vibration_mg=[1.0, 0.5, 0.5])
    d = diagnose(lsq.fit(s))
    said = [f for f in d.failures if "once per revolution along the rotation's own axis" in f]
    assert said and "vibration or imbalance of the table" in said[0], d.failures


# --- clean captures: no false alarm -----------------------------------------------------------

@pytest.mark.parametrize("rate, seconds", [(10.0, 36.0), (10.0, 20.0), (300.0, 12.0), (300.0, 0.8)])
def test_clean_captures_raise_no_alarm(rate, seconds):
    """Whole (10 °/s for 36 s: one turn; 300 °/s for 12 s: ten) and partial revolutions (200° at
    10 °/s, 240° at 300 °/s): the fit passes, none of the new effects is a significant candidate,
    and no bench word is said."""
    _, s = summaries(overrides={"rate_dps": rate, "rotation_s": seconds, "dwell_s": 6.0})
    d = diagnose(lsq.fit(s))
    assert not fit_fails(d.result), d.verdict
    assert not [c.effect for c in d.candidates if c.effect in NEW and c.significant]
    assert not [f for f in d.failures if "once per revolution" in f or "a step in time" in f]


# --- words for a failure --auto cannot mend ---------------------------------------------------

def test_a_failure_that_auto_cannot_mend_is_told_in_words(encoder):
    """The encoder's error with table_encoder_scale taken out of the library: --auto ends failing.
    The account says what was tried and the share of the excess chi2 each explained, where the
    misfit is (per axis, per segment kind, per revolution) and what each axis' residual follows; it
    is in the JSON and on the report page, and the verdict names a pattern, not only "no candidate"."""
    from station.cli.diagnose import _summary_lines
    from station.diagnose.as_json import to_json
    from station.diagnose.report import ReportInput, render

    _, s, _ = encoder
    # the table's once-per-revolution vibration out too: its part across the axis (a constant and a
    # second harmonic in gravity's frame) is what an encoder scale error leaves in the accelerometers,
    # so without table_encoder_scale it takes part of it (reduced chi2 44.7 -> 3.6, still failing)
    steps, final = auto.run(s, registry=simhelpers.registry_without("table_encoder_scale", "table_vibration_once_per_rev"),
                            discover=False)
    assert fit_fails(final.result)
    account = final.account
    tried = [line for line in account if line.startswith(("tried ", "added "))]
    assert tried and all("% of the excess chi2" in line for line in tried), account
    assert any(line.startswith("the library's other candidates would explain at most") for line in account)
    per_axis = next(line for line in account if line.startswith("the misfit per axis"))
    assert "accelerometer" in per_axis
    kinds = next(line for line in account if line.startswith("the misfit per segment kind"))
    assert kinds.startswith("the misfit per segment kind: rotation segments")     # 97 % in the rotations
    assert any(line.startswith("per revolution, the rotations' accelerometer misfit is") for line in account)
    assert sum(line.startswith("the residual of accelerometer") for line in account) >= 2
    # the verdict names a pattern or the terms that would explain part of it, never "no candidate" alone
    assert ("outside the library the residuals follow" in final.verdict if final.proposal is not None
            else "the residual of accelerometer" in final.verdict), final.verdict
    assert to_json(final, steps)["failure_account"] == account
    assert any(line.startswith("why it still fails: tried ") for line in _summary_lines(final))
    figures = {"residuals_per_segment.svg": b"<svg xmlns='http://www.w3.org/2000/svg'/>"}
    page = render(ReportInput(title="t", first=steps[0].before if steps else final, steps=steps, final=final),
                  figures)
    assert "Why it still fails" in page and "of the excess chi2" in page


class _Seg:
    def __init__(self, name, t, rate, n, temp=None):
        self.name, self.t_mid_s, self.rate_dps, self.samples, self.temp_c = name, t, rate, n, temp
        self.steady = True


class _Model:
    def __init__(self, statics, rotations, sigma):
        self.s = type("S", (), {"statics": statics, "rotations": rotations, "accel_sigma": np.full(3, 0.01),
                                "gyro_sigma": np.full(3, sigma), "accel_raw": False, "gyro_raw": False})()


def test_the_words_give_the_slope_in_units_and_its_share():
    """Segment means of gyro x that grow with the signed rate by 0.8 °/h per °/s (plus white noise of
    their own 1 sigma): the words say "grows with rate", the slope in °/h per °/s within 4 of its
    sigmas, and the share of the misfit.  The slope's 1 sigma: the gyro mean's noise sigma/sqrt(N)
    = 0.1 °/s / 100 = 3.6 °/h per segment, over 24 rotations at ±20..±300 °/s (rate RMS ~165 °/s):
    3.6 / (165 sqrt 24) = 0.0045 °/h per °/s."""
    rng = np.random.default_rng(2)
    sigma, n = 0.1, 10000                       # deg/s per sample, samples per segment
    rates = np.repeat(np.linspace(20.0, 300.0, 12), 2) * np.tile([1, -1], 12)
    statics = [_Seg(f"s{i}", 10.0 * i, 0.0, n) for i in range(6)]
    rotations = [_Seg(f"r{i}", 100.0 + 10 * i, r, n) for i, r in enumerate(rates)]
    segs = []
    for seg in statics + rotations:
        u = np.array([0.8 / 3600 * seg.rate_dps, 0.0, 0.0]) + rng.normal(0, sigma / np.sqrt(n), 3)   # deg/s
        values = {(q, a): float(u[i] / (sigma / np.sqrt(n)))
                  for i, a in enumerate("xyz") for q in (("gyro",) if seg in statics else ("gyro_integral",))}
        segs.append(SegmentResidual(seg.name, "static" if seg in statics else "rotation", 0.0, {}, values))
    result = type("R", (), {"model": _Model(statics, rotations, sigma)})()
    found = axis_patterns(result, segs)
    assert [p["axis"] for p in found] == ["x"] and found[0]["variable"] == "rate", found
    assert abs(found[0]["slope"] * 3600 - 0.8) < 4 * 0.0045, found[0]
    said = found[0]["words"]
    assert said.startswith("the residual of gyro x grows with rate: +")
    assert abs(float(said.split(": ")[1].split(" °/h")[0]) - 0.8) < 4 * 0.0045, said
    assert "°/h per °/s" in found[0]["words"] and "% of its misfit" in found[0]["words"]


def test_one_revolution_turns_about_tilted_axes_reveal_the_encoder_scale_error():
    """Review of enc28 (issue 28): nine statics and one 360-degree turn about each case axis at 10
    deg/s, the table axis 30 degrees above the horizontal, the encoder 1000 ppm short.  The
    accelerometers reveal e to ~10 ppm, about the effect's typical size (10 ppm): the fit judged it
    blind at its start (1-sigma above the typical size), held it at 0 +- 10 ppm by a prior, and,
    the newcomer's prior never being released (_contradicted_priors), came out 481 +- 7 ppm (chi2
    4,899 on 93) -- the issue's "about half" (data 1000 +- 10 against a prior 0 +- 10).  The same
    on level turns of 300 degrees with the brake recorded for 1 seed in 12 (seed 7: 498 +- 7, chi2
    5,156/93), and on a three-axis table with 300, -500, 1000 ppm per axis (82, -206, 352).  At
    noise x 0.01 (1-sigma 0.1 ppm: not held) 1000.2 +- 0.1: the term is right, the prior is not.
    Expected: recovered within 4 sigma of its own 1-sigma and not held."""
    from sim_devices.truth import mems_truth
    from station.io.scheme import scheme_from_text
    from station.simulate import dryrun

    head = "name: t\ndefaults: {dwell_s: 20.0, rate_dps: 10.0, rotation_s: 36.0}\nsegments:\n"
    rotations = simhelpers.THREE_ROTATIONS.replace("]}", "], axis_elevation_deg: 30}")
    scheme = scheme_from_text(head + simhelpers.NINE_STATICS + rotations, "t")
    truth = simhelpers.hide(mems_truth(0), bench__encoder_scale_error_ppm=1000.0)
    s = lsq.summarise(dryrun.simulate_capture(scheme, truth, 3))
    base = lsq.fit(s, [])
    result = lsq.fit(s, [TableEncoderScale()], like=base.model)
    value, sigma = estimate_of(result, "table_encoder_scale_error")
    assert "table_encoder_scale_error" not in result.model.unobservable, (value, sigma, result.chi2, result.dof)
    assert abs(value - 1000.0) < 4 * sigma, (value, sigma, result.chi2, result.dof)
