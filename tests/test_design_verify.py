"""A design the estimator does not deliver is not proposed (issue 28): `station design` checks its
prediction with noisy dry runs estimated as `station montecarlo` estimates them
(designer.verify), and refuses a design whose errors are beyond the predicted 1σ."""
import numpy as np

from station.design import designer
from station.design.designer import Prediction, verify
from station.design.information import Noise
from station.io.scheme import load_scheme
from station.model.registry import EffectRegistry

NAMES = ["accel_scale_x", "accel_position_x_y", "accel_position_y_x"]


def _prediction():
    return Prediction("designed", 1000.0, NAMES, ["ppm", "mm", "mm"], np.array([10.0, 0.073, 0.073]),
                      np.array([True, True, True]))


def test_an_error_far_beyond_the_predicted_sigma_is_a_problem(monkeypatch):
    """The divergence found before (a size-effect design: Monte Carlo spread 701 mm against a
    predicted 0.073 mm): an estimate 2 m off in one noisy run is named, with its seed; the
    other runs' errors within the prediction are not."""
    def fake(scheme, ids, noise, seed, chamber=None, ramp_accel_dps2=None, warmup=None):
        errors = np.array([5.0, 0.05, -0.04]) if seed != 1002 else np.array([5.0, 2000.0, 0.05])
        return NAMES, errors, np.array([10.0, 0.07, 0.075]), []
    monkeypatch.setattr(designer, "verify_one", fake)
    effects = [EffectRegistry().create("accel_lever_arm")]
    v = verify(None, effects, Noise(), _prediction(), [1, 2], runs=4)
    assert not v.ok and len(v.problems) == 1, v.problems
    assert "accel_position_x_y" in v.problems[0] and "seed 1002" in v.problems[0]
    assert v.worst == "accel_position_x_y (seed 1002)" and v.worst_z > 1e4
    # held by its prior in a noisy run (a fit that does not see it) or its own 1σ far off: problems too
    def blind(scheme, ids, noise, seed, chamber=None, ramp_accel_dps2=None, warmup=None):
        return NAMES, np.array([5.0, 0.05, 0.0]), np.array([10.0, 0.07, 10.0]), \
            ["not revealed by this capture (...): accel_position_y_x"]
    monkeypatch.setattr(designer, "verify_one", blind)
    v = verify(None, effects, Noise(), _prediction(), [1, 2], runs=1)
    assert [p.split()[0] for p in v.problems] == ["accel_position_y_x"] and "not estimated" in v.problems[0]
    def wide(scheme, ids, noise, seed, chamber=None, ramp_accel_dps2=None, warmup=None):
        return NAMES, np.array([5.0, 0.05, 0.05]), np.array([10.0, 0.2, 0.07]), []
    monkeypatch.setattr(designer, "verify_one", wide)
    v = verify(None, effects, Noise(), _prediction(), [1, 2], runs=1)
    assert len(v.problems) == 1 and "the fit's own 1σ" in v.problems[0]


def test_an_honest_prediction_is_delivered():
    """The sizeeffect scheme shortened, with the size effect: the estimator's noiseless
    prediction and two noisy dry runs (seeds 1000, 1001) agree (errors within VERIFY_Z = 6
    predicted 1σ, the fits' own 1σ within a factor 2)."""
    from dataclasses import replace

    scheme = load_scheme("sizeeffect")
    scheme = replace(scheme, segments=tuple(replace(s, dwell_s=10.0) if s.kind == "static" else s
                                            for s in scheme.segments))
    effects = [EffectRegistry().create("accel_lever_arm")]
    p = designer.predict(scheme, effects, Noise())
    which = [i for i, n in enumerate(p.names) if n.startswith("accel_position_") and p.revealed[i]]
    assert which
    v = verify(scheme, effects, Noise(), p, which, runs=2)
    assert v.ok, v.problems
    assert 0.0 < v.worst_z < designer.VERIFY_Z


def test_the_noise_free_prediction_keeps_every_turn_the_noisy_estimate_keeps():
    """A noise-free turn repeats its extreme value once a revolution, the flat top of a rail to the
    data-fault scan: the predictions (station design, montecarlo's Cramér-Rao bound) left
    sizeeffect's 200 deg/s turns about y and z out as "x gyro at its rail" while a noisy run of
    the same scheme keeps them.  The noise-free capture is not scanned (its extra says
    noise_free), so the prediction is of every segment the estimator will use."""
    from station.design.information import model_of, quiet_truth
    from station.estimate.summaries import summarise
    from station.simulate import dryrun, montecarlo

    scheme = load_scheme("sizeeffect")
    turns = [s.name for s in scheme.segments if s.kind == "rotation"]
    model, _ = model_of(scheme, [], Noise(), quiet_truth(Noise()))
    assert [r.name for r in model.s.rotations] == turns
    noisy = summarise(dryrun.simulate_capture(scheme, montecarlo.make_truth(montecarlo.Settings()), 1000))
    assert [r.name for r in noisy.rotations] == turns


def test_a_kind_the_noisy_runs_refuse_gives_way_to_the_other(monkeypatch):
    """--statics any: both kinds' designs are fitted by the estimator; the better is verified
    first and, refused (as the unknown-attitude size-effect design at 1500 s was in the
    thirteenth session: every turn about a vertical axis, noisy fits ending at a reduced chi-square
    of 1e7), gives way to the other kind's, which is verified and written.  (verify is replaced by
    one that refuses the first design it is shown: the real refusal takes four noisy dry runs.)"""
    from station.bench.config import load_config

    shown = []

    def refuse_first(scheme, effects, noise, prediction, which, runs=4, first_seed=1000, executor=None, chamber=None,
                     ramp_accel_dps2=None, warmup=None):
        shown.append(scheme)
        problems = ["accel_position_x_y: error 1.11e+03 mm in the noisy run of seed 1000"] if len(shown) == 1 else []
        return designer.Verification(runs, 1e4 if problems else 1.5, "accel_position_x_y (seed 1000)", problems)

    monkeypatch.setattr(designer, "verify", refuse_first)
    said = []
    # (600 s and one exchange pass: both kinds designed, the same give-way; 3.1 s of CPU against
    # 5.0 s at 1200 s and two passes)
    d = designer.design(load_config(None, env={}), [], Noise(), 600.0, "D", rates_dps=(30.0, 100.0),
                        revolutions=(1,), dwells_s=(10.0, 30.0), max_passes=1, compare=(), verify_runs=2,
                        statics="any", progress=said.append)
    assert len(shown) == 2 and d.verification.ok
    assert d.scheme is shown[1] and d.scheme is not shown[0]
    assert any("refused" in s and "the other kind's next" in s for s in said), said


def test_a_design_of_unknown_attitudes_turns_about_two_level_axes():
    """The 1,500 s size-effect design of unknown attitudes had all its 26 turn pairs about
    vertical axes; its noisy fits ended at a reduced chi-square of 1e7 (seeds 1000, 1002) and the
    same design with two pairs made level did not (docs/design.md, thirteenth session).  A design
    of unknown attitudes now turns about at least MIN_LEVEL_AXES body axes with the table axis
    level, whatever the criterion would choose (here: D of the base model, whose search alone
    chose them too, and the size effect's positions, which it did not)."""
    from station.bench.config import load_config
    from station.design.search import MIN_LEVEL_AXES
    from station.io.scheme import RotationSpec

    # (600 s: 3.5 s of CPU for the two designs against 4.8 s at 900 s; with MIN_LEVEL_AXES set to 0
    # both designs turn about no level axis at 600 s as at 900 s: the test can fail)
    for effects, criterion in (([], "D"), ([EffectRegistry().create("accel_lever_arm")], "worst:accel_position_*")):
        d = designer.design(load_config(None, env={}), effects, Noise(), 600.0, criterion, rates_dps=(100.0, 200.0),
                            revolutions=(1,), dwells_s=(10.0, 30.0), max_passes=1, compare=(), verify_runs=0,
                            statics="unknown")
        level = {tuple(np.round(s.axis_body, 6)) for s in d.scheme.segments
                 if isinstance(s, RotationSpec) and s.axis_elevation_deg == 0.0}
        assert d.attitudes == "unknown" and len(level) >= MIN_LEVEL_AXES, (criterion, level)


def test_a_design_with_an_effect_outside_the_library_is_verified_not_a_traceback():
    """The designer's noisy dry runs with a plugin effect (station/model/unlisted.py, as diagnose's
    chamber-design command adds it): station montecarlo takes library ids only, and given the id
    every verification run raised KeyError (a traceback of `station design`); now the run is
    estimated with the effect's instance and its parameters come back by name, as a library
    effect's do."""
    import numpy as np

    from station.io.scheme import scheme_from_text
    from station.model.unlisted import GyroScaleTemperatureSquared

    faces = [[0, 0, 1], [0, 0, -1], [1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0]]
    text = "name: small\ndefaults: {dwell_s: 2, rate_dps: 90, rotation_s: 4}\nsegments:\n" + "".join(
        f"  - {{static: s{i}, up_body: {u}}}\n" for i, u in enumerate(faces)) + "".join(
        f"  - {{rotation: r{a}, axis_body: {v}}}\n" for a, v in zip("xyz", [[1, 0, 0], [0, 1, 0], [0, 0, 1]]))
    effect = GyroScaleTemperatureSquared()
    names, errors, sigmas, notes = designer.verify_one(scheme_from_text(text, "small.yaml"), (effect,), Noise(), 1000)
    wanted = [p.name for p in effect.params]
    assert names[-len(wanted):] == wanted and len(errors) == len(sigmas) == len(names)
    # each estimated (a finite error and 1σ), or -- since the eighteenth session -- not revealed by
    # the capture (held by its prior, not written: no error, an infinite 1σ, named in the notes)
    held = " ".join(n for n in notes if n.startswith("not revealed by this capture"))
    for n, e, s in zip(wanted, errors[-len(wanted):], sigmas[-len(wanted):]):
        if n in held:
            assert np.isnan(e) and np.isinf(s), (n, e, s)
        else:
            assert np.isfinite(e) and np.isfinite(s) and s > 0, (n, e, s)
