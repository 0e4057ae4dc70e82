"""Issue 25 item 1: the IMU remounted for every rotation (remount_per_segment, a bench nuisance), hidden
in the simulator (sim_devices: bench.remount_error_arcsec with remount_rotations, written
independently of station.model), found by --auto and recovered against the simulator's own
placements; no false alarm on a clean capture; a remount once per rotation axis is the base model's
(its axes and static attitudes are nuisances already).  Short schemes (optimal9: 6 s statics, two
revolutions each way at 100 °/s)."""
import numpy as np
import pytest

import simhelpers
from effect_recovery import held_out_error
from sim_devices.truth import mems_truth
from station.diagnose import auto
from station.diagnose.core import diagnose, fit_fails
from station.diagnose.holdout import judge, leave_one_segment_out
from station.estimate import lsq
from station.io.scheme import load_scheme
from station.model.effect import SampleContext
from station.model.remount import RemountPerSegment
from station.simulate import dryrun

SHORT = {"rate_dps": 100.0, "rotation_s": 7.2, "dwell_s": 6.0}       # two revolutions each way
REMOUNT = {"bench__remount_error_arcsec": 360.0, "bench__remount_rotations": True}
ARCSEC = np.pi / 180.0 / 3600.0


def capture(seed=3, **hidden):
    """(truth, summaries, each segment's simulated placement error, rad, frame b)."""
    truth = simhelpers.hide(mems_truth(0), **hidden)
    scheme = load_scheme("optimal9", SHORT)
    placements = {spec.name: seg.truth["remount_error_rad"]
                  for spec, seg, _ in dryrun._simulate(scheme, dryrun._bench(scheme, truth, seed))}
    return truth, lsq.summarise(dryrun.simulate_capture(scheme, truth, seed)), placements


@pytest.fixture(scope="module")
def remounted():
    truth, s, placements = capture(**REMOUNT)
    steps, final = auto.run(s)
    return truth, s, placements, steps, final


def test_auto_adds_the_placements_and_the_fit_passes(remounted):
    """0.1° (1σ per axis) placement errors: the gyros see each rotation's axis moved by
    ~0.1-0.5° (at 100 °/s a cross-axis rate of 0.2-0.9 °/s against a noise of the two-revolution
    integral's direction of ~6 arc-seconds): the fit fails by far and the words say the IMU was
    moved.  --auto adds remount_per_segment (first, as the words ask) and nothing else, and the fit
    then passes; the words name the rotations, largest first, in arc-seconds."""
    _, _, _, steps, final = remounted
    assert [st.added for st in steps] == ["remount_per_segment"], [st.added for st in steps]
    assert fit_fails(steps[0].before.result)
    assert any("was moved or remounted" in f for f in steps[0].before.failures)
    assert not fit_fails(final.result), final.verdict
    assert not any("was moved or remounted" in f for f in final.failures), final.failures
    said = [c for c in steps[0].caveats if c.startswith("the IMU was placed anew")]
    assert said, steps[0].caveats
    sizes = [float(p.split(" ")[1]) for p in said[0].split(": ", 1)[1].split("; ")[:-1]]
    assert sizes == sorted(sizes, reverse=True) and sizes[0] > 100.0, said


def test_each_placement_is_the_simulators(remounted):
    """Each rotation's fitted placement relative to the first about its axis is the simulator's
    (its placement's rotation vector less the reference's, into frame p by the truth's C_pb),
    across the axis (the part along it is gravity's start phase, the base model's psi): within 4
    times the fit's own 1σ (~6 arc-seconds per component over two revolutions; the second order of
    composing two 0.1° placements, |r1||r2|/2 ~ 0.1 arc-second, is far below it)."""
    truth, s, placements, _, final = remounted
    effect = next(e for e in final.result.model.effects if e.id == "remount_per_segment")
    names, values, _, cov = lsq.reported(final.result, "m/s^2", "deg/s")
    C_pb = truth.paper_parameters()["C_pb"]
    for k in effect.free:
        name, ref = effect.names[k], effect.names[(k[0], 0)]
        i = names.index(f"{name}_tilt_t1")
        t1, t2 = effect.basis[k]
        fitted = values[i] * t1 + values[i + 1] * t2
        true = C_pb @ (placements[name] - placements[ref]) / ARCSEC
        axis = C_pb @ next(r.axis_body for r in s.rotations if r.name == name)
        across = np.eye(3) - np.outer(axis, axis) / (axis @ axis)
        sigma = np.sqrt(cov[i, i] + cov[i + 1, i + 1])
        assert np.linalg.norm(across @ (fitted - true)) < 4 * sigma, (name, fitted, true, sigma)


def test_the_calibration_reaches_the_clean_floor(remounted):
    """Held out (noise-free samples of the truth at random attitudes and rates): with the
    placements in the model the calibration is the clean capture's, within 2x its error (the
    goal of issue 25) in the accelerometers and the gyros."""
    truth, _, _, _, final = remounted
    clean_truth, s0, _ = capture()
    floor = held_out_error(lsq.fit(s0), clean_truth)
    after = held_out_error(final.result, truth)
    assert after.accel_ug < 2 * floor.accel_ug and after.gyro_ppm < 2 * floor.gyro_ppm, (after, floor)


def test_no_false_alarm_on_a_clean_capture():
    """Nothing remounted: remount_per_segment is not a significant candidate, and added all the
    same (12 parameters that can absorb some noise) the out-of-sample rule of --auto (holdout.judge)
    refuses it or the fit already passed without it; --auto adds nothing."""
    _, s, _ = capture(seed=5)
    base = lsq.fit(s)
    d = diagnose(base)
    cand = next(c for c in d.candidates if c.effect == "remount_per_segment")
    assert not cand.significant, (cand.p_value_corrected, cand.predicted_chi2_drop)
    steps, final = auto.run(s, discover=False)
    assert steps == [] and not fit_fails(final.result), final.verdict


def test_a_remount_per_axis_is_the_base_models():
    """The IMU remounted once for each rotation axis (bench.remount_axes, 0.1° 1σ; the statics
    placed anew too): each axis' direction and each static's attitude are nuisances of the base
    model, so the fit passes without any effect, nothing is a candidate, and the held-out error is
    the clean capture's (the same seed and noise: within 2 %, what the placements change in the
    axes' determination)."""
    truth, s, _ = capture(bench__remount_error_arcsec=360.0, bench__remount_axes=True)
    result = lsq.fit(s)
    assert not fit_fails(result)
    assert not [c.effect for c in diagnose(result).candidates if c.significant]
    clean_truth, s0, _ = capture()
    floor, got = held_out_error(lsq.fit(s0), clean_truth), held_out_error(result, truth)
    assert got.accel_ug < 1.02 * floor.accel_ug and got.gyro_ppm < 1.02 * floor.gyro_ppm, (got, floor)


def test_apply_compensates_nothing_and_the_state_round_trips():
    """A bench nuisance: outside the fit (no turned_s) no term; state() restores the placements."""
    _, s, _ = capture()
    e = RemountPerSegment()
    e.setup(s)
    assert len(e.params) == 2 * (len(s.rotations) - s.groups)
    ctx = SampleContext(f_p=np.ones((4, 3)), w_p=np.ones((4, 3)), w_table=np.ones((4, 3)),
                        wdot_table=np.zeros((4, 3)), temp_c=np.full(4, np.nan), accel_matrix=np.eye(3),
                        gyro_matrix=np.eye(3), segment_index=np.full(4, float(s.rotations[1].index)))
    x = np.full(len(e.params), 1e-3)
    assert e.accel(x, ctx) is None and e.gyro(x, ctx) is None
    back = RemountPerSegment()
    back.restore(e.state())
    assert back.free == e.free and back.placement_of == e.placement_of and back.names == e.names
    assert [p.name for p in back.params] == [p.name for p in e.params]


def test_a_gyro_bias_step_before_the_rotations_is_not_a_remount(monkeypatch):
    """The gyro bias steps by 300 °/h after the statics (which all come first), before rotx_p: the
    rotations' bias is then off by 300 °/h = 0.083 °/s, which the sign-corrected integrals of a ±
    pair carry in opposite directions: their axes differ by 2 b T / A = 2 · 0.083 · 7.2 / 720 rad =
    0.095° (beyond 0.05° and 5σ), as a remount's would, but gravity's plane in the accelerometers
    does not move: the words do not say the IMU was moved (they would without the accelerometers'
    check), so --auto does not try remount_per_segment there."""
    from station.diagnose import words

    _, s0, _ = capture(seed=7)
    p = next(r for r in s0.rotations if r.name == "rotx_p")
    before = p.t_mid_s - 0.5 * p.duration_s - 2.0
    assert all(st.t_mid_s < before for st in s0.statics)
    _, s, _ = capture(seed=7, gyro__bias_step=[0.0, 300.0, 300.0], gyro__bias_step_time_s=before)
    result = lsq.fit(s)
    assert not any("rotx_p and rotx_m" in w for w in words._moved_axes(result))
    monkeypatch.setattr(words, "_accelerometers_agree", lambda *a: True)
    assert any("rotx_p and rotx_m" in w for w in words._moved_axes(result))
