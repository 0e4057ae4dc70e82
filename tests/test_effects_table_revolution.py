"""Issue 25 item 1: the table's own once-per-revolution faults as library nuisances (bench = True,
nothing compensated), each hidden in the simulator (sim_devices, written independently of
station.model: world.wobbling_table, world.table_vibration_enu): a platter whose axis wobbles
(table_wobble) and a table that vibrates once per revolution (table_vibration_once_per_rev).
Short schemes (optimal9: 6 s statics, ten revolutions each way at 100 °/s), seed 4.

Tolerances: every estimate is checked against its own 1σ from the fit's covariance (4σ: a test
that fails by chance once in 16,000 runs per value); a phase against the amplitude's relative 1σ
(σ_φ = σ_b / b rad, the same 4σ).  The held-out IMU error is checked against the clean capture's of
the same seed, scheme and IMU (the floor) within the goal's 2x."""
import numpy as np
import pytest

import simhelpers
from effect_recovery import held_out_error
from station.diagnose import auto
from station.diagnose.core import diagnose, fit_fails
from station.estimate import lsq
from station.model import table_revolution
from station.model.table_vibration import TableVibration
from station.model.table_wobble import TableWobble

SHORT = {"rate_dps": 100.0, "rotation_s": 36.0, "dwell_s": 6.0}
OURS = ("table_wobble", "table_vibration_once_per_rev")


def captured(**hidden):
    truth, cap = simhelpers.mems_capture(4, "optimal9", SHORT, **hidden)
    return truth, lsq.summarise(cap)


def reported(result, prefix):
    names, values, _, cov = lsq.reported(result, "m/s^2", "deg/s")
    return {n: (float(v), float(np.sqrt(cov[i, i]))) for i, (n, v) in enumerate(zip(names, values))
            if n.startswith(prefix)}


@pytest.fixture(scope="module")
def clean():
    truth, s = captured()
    return truth, s, diagnose(lsq.fit(s))


@pytest.fixture(scope="module")
def wobble():
    return captured(bench__wobble_arcsec=30.0, bench__wobble_phase_deg=60.0)


@pytest.fixture(scope="module")
def vibration():
    return captured(bench__vibration_mg=[1.0, 0.5, 0.5], bench__vibration_phase_deg=30.0)


def test_a_wobble_is_fitted_with_its_size_and_phase(wobble):
    """30 arc-seconds, its lean 60° from gravity across the axis at the rotations' start: the fit with
    table_wobble passes (without it reduced chi2 ~2) and finds both, each within 4 sigma."""
    _, s = wobble
    result = lsq.fit(s, [TableWobble()])
    assert not fit_fails(result), result.chi2 / result.dof
    p = reported(result, "table_wobble")
    (bv, sv), (bu, su) = p["table_wobble_along_gravity"], p["table_wobble_across_gravity"]
    b, sb = table_revolution.amplitude(bv, bu, sv, su)
    assert abs(b - 30.0) < 4 * sb and sb < 5.0, (b, sb)
    phase = np.degrees(np.arctan2(bu, bv))
    assert abs(phase - 60.0) < 4 * np.degrees(sb / b), phase


def test_over_part_of_a_revolution_the_lean_shows_in_the_gyro_angle_too():
    """240° at 300 °/s: the lean's rate across the axis, 2 b w turning once per revolution, no longer
    averages out of the gyro integral (2 (sin A (l x w) - (1 - cos A) w): ~0.03° for 60″), and with it
    the fit passes and finds b (cos 40°, sin 40°) within 4 sigma; with that term's sign flipped it
    did not (reduced chi2 1.2, the lean's sign reversed), without it the fit failed (9.2)."""
    _, s = captured_with({"rate_dps": 300.0, "rotation_s": 0.8, "dwell_s": 6.0},
                         bench__wobble_arcsec=60.0, bench__wobble_phase_deg=40.0)
    result = lsq.fit(s, [TableWobble()])
    assert not fit_fails(result), result.chi2 / result.dof
    p = reported(result, "table_wobble")
    for name, want in (("table_wobble_along_gravity", 60.0 * np.cos(np.radians(40.0))),
                       ("table_wobble_across_gravity", 60.0 * np.sin(np.radians(40.0)))):
        got, sigma = p[name]
        assert abs(got - want) < 4 * sigma and sigma < 5.0, (name, got, sigma, want)


def test_a_vibration_is_fitted_along_and_across_the_axis(vibration):
    """1 mg along the axis, 0.5 mg towards gravity across it and 0.5 mg across both, at 30° of the
    table's angle: a(theta) = cos(theta + 30°) A = cos theta P + sin theta Q, P = cos 30° A,
    Q = -sin 30° A; each of the six within 4 sigma (~0.012 mg), the fit passing (without: ~57)."""
    _, s = vibration
    result = lsq.fit(s, [TableVibration()])
    assert not fit_fails(result), result.chi2 / result.dof
    p = reported(result, "table_vibration")
    A = np.array([1.0, 0.5, 0.5])
    want = dict(zip([f"table_vibration_100dps_{d}_{h}" for h in ("cos", "sin") for d in ("axis", "gravity", "third")],
                    np.concatenate([np.cos(np.radians(30)) * A, -np.sin(np.radians(30)) * A])))
    for name, value in want.items():
        got, sigma = p[name]
        assert abs(got - value) < 4 * sigma and sigma < 0.05, (name, got, sigma, value)


def test_auto_adds_the_wobble_says_it_in_arcseconds_and_writes_it_in_the_notes(wobble):
    """--auto: the words name a wobbling platter, so table_wobble is tried first; it is kept, the fit
    passes, and its size is said (step and calibration notes): a finding for the lab."""
    _, s = wobble
    steps, final = auto.run(s, discover=False)
    assert [st.added for st in steps] == ["table_wobble"], [st.added for st in steps]
    assert not fit_fails(final.result), final.verdict
    said = [c for c in steps[0].caveats if "wobbles" in c and "arc-seconds" in c]
    assert said, steps[0].caveats
    notes = lsq.to_calibration(final.result, "m/s^2", "deg/s").fit["notes"]
    assert any("the table wobbles" in n for n in notes), notes


def test_auto_adds_the_vibration_first_and_the_imu_error_reaches_the_floor(vibration, clean):
    """--auto on the vibrating table: the words' "once per revolution along the rotation's own axis"
    puts table_vibration_once_per_rev first; the fit then passes and the IMU's held-out error is
    within 2x that of the clean capture's calibration (same seed, scheme and IMU)."""
    truth, s = vibration
    d = diagnose(lsq.fit(s))
    assert [c.effect for c in auto.named_in_words(d.candidates, d, auto.EffectRegistry())] == \
        ["table_vibration_once_per_rev"]
    steps, final = auto.run(s, discover=False)
    assert steps and steps[0].added == "table_vibration_once_per_rev", [st.added for st in steps]
    assert not fit_fails(final.result), final.verdict
    assert any("vibrates once per revolution" in c and "mg along its axis" in c for c in steps[0].caveats)
    after, floor = held_out_error(final.result, truth), held_out_error(clean[2].result, clean[0])
    assert after.accel_ug < 2 * floor.accel_ug, (after, floor)


def test_a_clean_capture_raises_no_alarm(clean):
    """Neither effect is significant on a clean capture (the score test, Holm-corrected over the
    library), and each one-step estimate is within 4 sigma of zero."""
    _, s, d = clean
    cands = {c.effect: c for c in d.candidates}
    for eid in OURS:
        assert not cands[eid].significant, (eid, cands[eid].p_value_corrected)
        # the one-step estimates (the score test's) are noise: each within 4 sigma of zero
        for name, v, sg in zip(cands[eid].names, cands[eid].estimate, cands[eid].sigma):
            assert abs(v) < 4 * sg, (name, v, sg)


@pytest.mark.parametrize("rate, seconds", [(10.0, 20.0), (300.0, 0.8)])
def test_partial_revolutions_raise_no_alarm(rate, seconds):
    """Part of a revolution (200° at 10 °/s, 240° at 300 °/s), where the harmonics are correlated and
    the wobble's lean shows in the gyro integral too: neither effect is a significant candidate."""
    _, s = captured_with({"rate_dps": rate, "rotation_s": seconds, "dwell_s": 6.0})
    d = diagnose(lsq.fit(s))
    assert not fit_fails(d.result), d.verdict
    assert not [c.effect for c in d.candidates if c.effect in OURS and c.significant]


def captured_with(overrides, **hidden):
    truth, cap = simhelpers.mems_capture(4, "optimal9", overrides, **hidden)
    return truth, lsq.summarise(cap)


def test_nothing_fixes_the_frame_about_a_vertical_axis(wobble):
    """A rotation about the vertical has no gravity across it: the wobble gets no parameter there
    (its lean is a tilt of the axis, which the fit's gravity angle per axis group takes); the
    vibration (sixteenth session) gets its part along the axis per table axis and rate and its part
    across per axis group, in a frame fixed to the case (station/model/table_vibration.py)."""
    _, s = wobble
    import copy

    vertical = copy.deepcopy(s)
    for r in vertical.rotations:       # gravity all along the axis: no first harmonic
        r.accel_dc = r.accel_dc + np.linalg.norm(r.accel_cos) * np.asarray(r.axis_body)
        r.accel_cos, r.accel_sin = 0 * r.accel_cos, 0 * r.accel_sin
    assert table_revolution.frames(vertical) == {}
    wobble_effect, vibration_effect = TableWobble(), TableVibration()
    wobble_effect.setup(vertical)
    assert wobble_effect.params == ()
    vibration_effect.setup(vertical)
    groups = len({r.group for r in vertical.rotations if r.steady})
    names = [p.name for p in vibration_effect.params]
    assert len(names) == 2 + 4 * groups and all(n.startswith("table_vibration_vertical_100dps_") for n in names)
    assert len(table_revolution.frames(s)) == len([r for r in s.rotations if r.steady])


def test_an_encoder_scale_error_is_not_taken_for_a_vibration():
    """An encoder that reads 300 ppm short leaves a constant and a second harmonic across the axis
    in gravity's frame, which the vibration's part across the axis can take too (aliased); the
    encoder's error is an effect of the library ranked before the bench's nuisances and its words
    do not name a vibration along the axis, so --auto keeps table_encoder_scale and the fit passes."""
    _, s = captured(bench__encoder_scale_error_ppm=300.0)
    steps, final = auto.run(s, discover=False)
    assert [st.added for st in steps] == ["table_encoder_scale"], [st.added for st in steps]
    assert not fit_fails(final.result), final.verdict


def test_a_named_wobble_is_tried_again_once_the_other_cause_is_in_the_model():
    """A 30″ wobble beside gyro g-sensitivity (10-40 °/h/g; 20 s statics, as the goal's case
    wobble+g_sens): the words name the wobble, so it is tried first, but before g-sensitivity is in
    the model it explains only part of the failure and is not kept; it stays open (named by the
    words), and after g-sensitivity is added it is tried again, kept, and the fit passes."""
    gsens = [[30.0, -20.0, 10.0], [15.0, 40.0, -25.0], [-10.0, 20.0, 35.0]]
    _, s = captured_with({"rate_dps": 100.0, "rotation_s": 36.0, "dwell_s": 20.0},
                         bench__wobble_arcsec=30.0, gyro__g_sensitivity_dph_per_g=gsens)
    steps, final = auto.run(s, discover=False)
    assert sorted(st.added for st in steps) == ["gyro_g_sensitivity", "table_wobble"], [st.added for st in steps]
    assert not fit_fails(final.result), final.verdict
    assert "table_wobble" not in [r.effect for r in final.rejected]
