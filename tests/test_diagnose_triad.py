"""Diagnose's generality (issue 25's loop, fourteenth session; docs/diagnose.md): a gyro misfit that
lands in the accelerometer rows is named on the gyro (the term search scores both triads), the
gyro effects a warm-up scheme cannot reveal are said with their 1-sigma and the `station design
--from` command (station/diagnose/unrevealed.py), and those effects' forward model
(station/model/unlisted.py) agrees with the simulator's physics, written without it."""
import fnmatch

import numpy as np
import pytest

import simhelpers
from station.diagnose import terms, unrevealed
from station.diagnose.core import fit_fails
from station.estimate import lsq

# optimal9 with 20 s statics and ten revolutions at 100 deg/s, an 8 degC warm-up (tau 400 s): the
# goal harness' training (benchmarks/diagnose_goal.py, STD and WARM), seed 4 as there
SCHEME = {"rate_dps": 100.0, "rotation_s": 36.0, "dwell_s": 20.0}
WARM = {"temperature__warmup_delta_c": 8.0, "temperature__warmup_time_constant_s": 400.0}
TILT = [[20.0, -20.0], [20.0, 20.0], [-20.0, 20.0]]     # arcsec/degC; row i towards OTHER_AXES[i]
OTHER_AXES = ((1, 2), (0, 2), (0, 1))
T2 = [20.0, -15.0, 25.0]                                # ppm/degC^2
CASES = {"tilt": {"gyro__axis_tilt_tempco_arcsec_per_c": TILT}, "t2": {"gyro__scale_tempco2_ppm_per_c2": T2}}
MODEL = {"tilt": (), "t2": ("scale_temperature",)}     # what --auto adds on the goal harness' capture
_FITS: dict = {}


def _fit(name):
    """(summaries, base fit) of a case, made once for the module (each test only reads them)."""
    if name not in _FITS:
        _, cap = simhelpers.mems_capture(seed=4, overrides=SCHEME, **WARM, **CASES[name])
        from station.model import LIBRARY

        s = lsq.summarise(cap)
        _FITS[name] = (s, lsq.fit(s, [LIBRARY[e]() for e in MODEL[name]]))
    return _FITS[name]


def test_a_gyro_axis_tilting_with_temperature_is_named_on_the_gyro():
    """The misfit of gyro axes that tilt with temperature lands in the ACCELEROMETER rows (through
    the attitudes the rotations share with the statics) while the gyro rows pass; the search
    still names gyro misalignments that change with temperature, each within 4 sigma (the
    search's own, from the noise) of the simulator's tilt, and no accelerometer term."""
    s, res = _fit("tilt")
    failing = terms.failing_sensors(res)
    assert failing["accel"][0] and not failing["gyro"][0], failing
    found = terms.search(res, events=False)
    assert found
    for f in found:
        t = f.term
        assert t.sensor == "gyro" and t.regressor.family == "wT" and t.regressor.j != t.axis, t.name
        truth = TILT[t.axis][OTHER_AXES[t.axis].index(t.regressor.j)]
        value, sigma = t.natural(f.value), abs(t.natural(f.sigma))
        assert abs(value - truth) < 4 * sigma, (t.name, value, sigma, truth)
        assert "misalignment towards" in t.words(f.value, f.sigma) and "arcsec/degC" in t.words(f.value)


def test_the_other_triad_takes_the_misfit_only_when_clearly_better():
    """cross_triad: a term of a sensor whose rows pass is kept only when it explains more than the
    blamed sensor's best by the 1 % point of chi2 on one degree of freedom (6.63), times the
    over-dispersion."""
    acc = terms.Term("accel", 0, terms.regressor("fzT"))
    gyr = terms.Term("gyro", 2, terms.regressor("wxT"))
    kept = terms.cross_triad(np.array([26.6, 70.7]), [acc, gyr], ["accel"], 1.0)
    assert kept[1] == 70.7 and kept[0] == 26.6
    near = terms.cross_triad(np.array([26.6, 30.0]), [acc, gyr], ["accel"], 1.0)
    assert near[1] == 0.0 and near[0] == 26.6
    # over-dispersed 1.7x: a margin of 11.3; 26.6 + 11.3 > 35
    assert terms.cross_triad(np.array([26.6, 35.0]), [acc, gyr], ["accel"], 1.7)[1] == 0.0


def test_what_a_warm_up_scheme_cannot_reveal_is_said_with_its_1_sigma_and_the_design_command():
    """A gyro scale second order in temperature (20, -15, 25 ppm/degC^2) over the 8 degC warm-up:
    with the linear scale_temperature (what --auto adds) the fit passes, and the capture truly cannot tell it from zero (each true value within
    3 sigma of 0, the sigma from the capture's own score test); diagnose says so, with the
    rotations' temperature span, and names the scale that changes with the force too (every
    axis turned with no force along it).  The design command's effect loads as `--add` takes it
    and its `--reveal` pattern names its parameters."""
    from station.model.registry import EffectRegistry

    s, res = _fit("t2")
    assert not fit_fails(res)
    from station.diagnose.core import diagnose

    said = {u.spec.rsplit(":", 1)[1]: u for u in unrevealed.find(diagnose(res, exclude=EffectRegistry().ids()), s)}
    assert {"GyroScaleTemperatureSquared", "GyroScaleForce"} <= set(said), sorted(said)
    t2 = said["GyroScaleTemperatureSquared"].text
    sigmas = [said["GyroScaleTemperatureSquared"].sigmas[f"gyro_scale_tempco2_{a}"] for a in "xyz"]
    assert all(abs(v) < 3 * sg for v, sg in zip(T2, sigmas)), (T2, sigmas)
    assert "the rotations that turn each gyro axis span" in t2 and "ppm/degC^2" in t2
    assert "mean forces along it" in said["GyroScaleForce"].text
    for u in said.values():
        reg = EffectRegistry()
        (eid,) = reg.add(u.spec)
        names = [p.name for p in reg.create(eid).params]
        assert any(fnmatch.fnmatchcase(n, u.reveal.strip("'")) for n in names), (u.reveal, names)
    # a change with the temperature's square: no `--from` command (segments added at the capture's
    # temperatures cannot reveal it: the designer refused such proposals on the quick-start
    # capture), a new design at a chamber's setpoints instead; the force's scale keeps its command
    cmd = (lambda cap, effects, reveal: f"station design --from {cap} --add {effects[0]} --reveal {reveal[0]}")
    t2_after = unrevealed.after(said["GyroScaleTemperatureSquared"], "cap", cmd)
    assert "--from" not in t2_after and "chamber" in t2_after and t2_after.endswith("-o scheme.yaml")
    assert "station design --config station.yaml --add station.model.unlisted:GyroScaleTemperatureSquared" in t2_after
    assert "'worst:gyro_scale_tempco2_*'" in t2_after
    assert unrevealed.after(said["GyroScaleForce"], "cap", cmd).startswith(
        "; the segments that would reveal it: station design --from cap --add station.model.unlisted:GyroScaleForce")


def test_the_unlisted_effects_follow_the_simulators_physics():
    """The forward model of station/model/unlisted.py against sim_devices' (written without it) on
    the same inputs: the scale terms agree to rounding (1e-9 of their size); the tilt to the
    simulator's exact geometry, whose renormalised unit vector differs from the small-angle term
    by (theta_1^2 + theta_2^2)/2 of the rate along the axis, theta at most 20 arcsec/degC x
    8 degC = 7.8e-4 rad: 6e-7 x 300 deg/s = 1.8e-4 deg/s, allowed 1.5x that."""
    from sim_devices.truth import G_STANDARD, TriadTruth, _outside_library
    from station.model.effect import SampleContext
    from station.model.unlisted import (AccelScaleTemperatureSquared, GyroMisalignmentTemperature, GyroScaleForce,
                                        GyroScaleTemperatureSquared)

    rng = np.random.default_rng(1)
    n = 200
    w = rng.uniform(-300.0, 300.0, (n, 3))                  # deg/s
    f = rng.uniform(-1.0, 1.0, (n, 3)) * G_STANDARD          # m/s^2
    dT = rng.uniform(-8.0, 8.0, (n, 1))
    ctx = SampleContext(f_p=f, w_p=w, w_table=np.radians(w), wdot_table=np.zeros((n, 3)), temp_c=25.0 + dT[:, 0],
                        accel_matrix=np.eye(3), gyro_matrix=np.eye(3))
    S = np.array([[0.0, 300.0, -200.0], [150.0, 400.0, 0.0], [0.0, -250.0, 300.0]])
    theta = np.max(np.abs(TILT)) * np.max(np.abs(dT)) * np.pi / 648000.0       # rad
    tilt_tol = 1.5 * theta**2 * np.max(np.abs(w))                               # deg/s
    for effect, x, truth in (
            (GyroScaleTemperatureSquared(), np.array(T2), TriadTruth(scale_tempco2_ppm_per_c2=T2)),
            (GyroMisalignmentTemperature(), np.ravel(TILT), TriadTruth(axis_tilt_tempco_arcsec_per_c=TILT)),
            (GyroScaleForce(), S.ravel(), TriadTruth(scale_g_ppm_per_g=S)),
            (AccelScaleTemperatureSquared(), np.array(T2), TriadTruth(scale_tempco2_ppm_per_c2=T2))):
        effect.reference_c = 25.0
        sim = _outside_library(truth, [w, w, w], dT, None, None, 1.0, f_case=f / G_STANDARD)
        model = effect.gyro(x, ctx)
        if isinstance(effect, AccelScaleTemperatureSquared):
            sim, model = _outside_library(truth, [f, f, f], dT, None, None, 1.0), effect.accel(x, ctx)
        size = np.max(np.abs(sim))
        assert size > 0.0
        tol = tilt_tol if isinstance(effect, GyroMisalignmentTemperature) else 1e-9 * size
        assert np.max(np.abs(model - sim)) < tol, (effect.id, np.max(np.abs(model - sim)), tol)
        assert np.max(np.abs(model)) > 100 * tol         # the test can fail: the term is far above it


@pytest.fixture(scope="module", autouse=True)
def _drop_fits():
    yield
    _FITS.clear()


def test_the_unlisted_effects_are_complex_step_safe():
    """They declare complex_step: their Jacobian columns (the score test's path) agree with central
    differences as the library's do (tests/test_jacobian_complex_step.py's check, all four at once
    on its 50 Hz optimal9; a share of 1e-6 of each column, its tolerance for the library)."""
    import test_jacobian_complex_step as jcs
    from station.io.scheme import load_scheme
    from station.model.raw_counts import in_capture_units
    from station.model.unlisted import UNLISTED
    from station.simulate import dryrun

    truth = dryrun.load_truth(None, 0)
    truth.sample_rate_hz = 50.0
    truth.temperature.warmup_delta_c = 8.0           # the temperature terms need a temperature that moves
    s = lsq.summarise(dryrun.simulate_capture(load_scheme("optimal9"), truth, 3))
    effects = [in_capture_units(cls)() for cls in UNLISTED.values()]
    model = lsq.Model(s, effects)
    x = jcs.random_x(model, np.random.default_rng(7))
    J = model.jacobian(x)
    assert model.complex_step, "an unlisted effect fell back to forward differences"
    assert jcs.excess(model, effects, x, J, np.inf, 1e-6, 0.0) <= 1
