"""The vectorised residual of the least-squares model (all segments in one pass, effects called
once with the stacked sample points) against the per-segment formulation it replaced
(tests/lsq_reference.py), row by row, at random parameter vectors; and its Jacobian (complex
step) against central differences of that reference.

Tolerances: both residuals are whitened (unit noise per row) and computed from the same numbers
in a different order, so they differ by rounding only: 1e-9 of the row's size (at most ~1e4 here)
is ~1e5 times the double-precision rounding of the ~100 operations per row and ~1e-5 of the
noise.  The complex-step Jacobian has no subtraction error (exact to rounding; the hand turns to
first order about x, whose derivative is the exact one), so the difference is the central
differences' own error: truncation, h^2/6 times the third derivative with h = 1e-4 of each
parameter's size (measured: at most 8.3e-9 of a column's norm), plus rounding, eps D / h per
row, D the size of the whitened numbers that cancel in it (the data and the prediction, or the
phase points of a harmonic: up to ~1e8 for a gyro integral).  The tolerance is 1e-7 of the
column's norm plus 4 eps D / h, D the largest whitened prediction or datum of the same segment
and sensor (the residual of the same model with the data set to zero is minus its prediction).
It was 1e-4 of the column's norm plus 16 eps D / h_forward (h_forward = 1e-7 of the size) while
both Jacobians were forward differences: 1000 times tighter on the column's share, and the
rounding share 4000 times smaller (steps 1000 times larger)."""
from dataclasses import replace

import numpy as np
import pytest

from sim_devices.hand import hand_session
from sim_devices.truth import mems_truth
from station import cli
from station.estimate import lsq
from station.io.capture import read_capture
from station.io.scheme import load_scheme
from station.model import LIBRARY
from station.simulate import dryrun
from lsq_reference import PerSegmentModel

JACOBIAN_SHARE = 1e-7      # of a column's norm: the central differences' truncation (above)
ALL_EFFECTS = ("accel_lever_arm", "accel_nonlinearity", "gyro_g_sensitivity", "gyro_scale_asymmetry",
               "temperature_bias", "time_offset")


@pytest.fixture(scope="module")
def optimal9():
    truth = dryrun.load_truth(None, 0)
    truth.sample_rate_hz = 50.0
    return lsq.summarise(dryrun.simulate_capture(load_scheme("optimal9"), truth, 3))


@pytest.fixture(scope="module")
def hand(tmp_path_factory):
    """Short simulated hand sessions, imported without and with the site's latitude; the quiet
    gyro (2 deg/h/rtHz) sees the Earth turn in a pose, the MEMS one (19) does not."""
    tmp = tmp_path_factory.mktemp("hand")
    out = {}
    for gyro, noise in (("mems", None), ("quiet", 2.0)):
        truth = mems_truth(5)
        truth.gyro.noise_density = noise or truth.gyro.noise_density
        hs = hand_session(truth, 5, poses=10, dwell_s=(3.0, 3.5), turn_s=(1.0, 1.4))
        log = tmp / f"{gyro}.csv"
        np.savetxt(log, np.column_stack([hs.t, hs.accel, hs.gyro]), delimiter=",", header="t,ax,ay,az,gx,gy,gz",
                   comments="", fmt="%.10g")
        for name, extra in (("plain", []), ("latitude", ["--latitude-deg", f"{hs.truth['latitude_deg']:g}"])):
            assert cli.main(["import", "csv", str(log), "--preset", "station", "-o", str(tmp / f"{gyro}-{name}"),
                             "--gravity-mps2", str(hs.truth["gravity_mps2"])] + extra) == 0
            out[gyro, name] = lsq.summarise(read_capture(tmp / f"{gyro}-{name}"))
    return out


def random_x(model, rng):
    """The start plus a random step: 1e-3 of each parameter's size (1e-2 at least; the effects'
    typical size), so every term is away from zero and from the start."""
    x = model.x0.copy()
    step = 1e-3 * np.maximum(np.abs(x), 1e-2)
    for e in model.effects:
        sl = model.layout[f"effect:{e.id}"]
        step[sl] = [p.typical / p.scale for p in e.params]
    return x + step * rng.standard_normal(len(x))


def models(s, effects=(), attitudes="auto", priors=()):
    pair = []
    for cls in (lsq.Model, PerSegmentModel):
        m = cls(s, [LIBRARY[e]() for e in effects], attitudes)
        for c in priors:
            m.priors[c] = 0.5
        m.refresh()
        pair.append(m)
    return pair


def prediction(ref, x):
    """The reference model's residual with every datum set to zero: minus its whitened prediction."""
    s = ref.s
    zero = replace(s, statics=[replace(st, accel=0 * st.accel, gyro=0 * st.gyro) for st in s.statics],
                   rotations=[replace(r, **{k: 0 * getattr(r, k) for k in (
                       "accel_dc", "accel_cos", "accel_sin", "accel_cos2", "accel_sin2", "gyro_integral")})
                              for r in s.rotations])
    ref.s = zero
    try:
        return ref.residuals(x)
    finally:
        ref.s = s


def cancelling_size(ref, x, r):
    """Per row: the largest |whitened datum| or |whitened prediction| of its segment and sensor."""
    size = np.maximum(np.abs(r), np.abs(prediction(ref, x)))
    size = np.maximum(size, np.abs(r - prediction(ref, x)))
    keys = [(segment, quantity.split("_")[0]) for segment, _, quantity, _ in ref.row_labels(x)]
    largest = {}
    for k, v in zip(keys, size):
        largest[k] = max(largest.get(k, 0.0), v)
    return np.array([largest[k] for k in keys])


def check(new, ref, seed):
    rng = np.random.default_rng(seed)
    assert new.layout.blocks == ref.layout.blocks and np.array_equal(new.x0, ref.x0)
    for x in (new.x0, random_x(new, rng)):
        pieces_new, tags_new = new._pieces(x)
        pieces_ref, tags_ref = ref._pieces(x)
        assert tags_new == tags_ref
        r_new, r_ref = np.concatenate(pieces_new), np.concatenate(pieces_ref)
        np.testing.assert_allclose(r_new, r_ref, rtol=1e-9, atol=1e-9 * max(1.0, np.max(np.abs(r_ref))))
        J_new, (J_ref, h) = new.jacobian(x), ref.central_jacobian(x)
        D = cancelling_size(ref, x, r_ref)
        tolerance = JACOBIAN_SHARE * np.linalg.norm(J_ref, axis=0) + 4 * np.finfo(float).eps * np.outer(D, 1 / h)
        excess = np.abs(J_new - J_ref) / tolerance
        assert np.all(excess <= 1), (np.unravel_index(np.argmax(excess), excess.shape), np.max(excess))
    ref._column_groups()      # sets data_rows
    assert np.array_equal(new.data_rows, ref.data_rows)
    assert new.row_labels(new.x0) == ref.row_labels(ref.x0)


def test_table_scheme_with_latitude(optimal9):
    new, ref = models(optimal9)
    assert new.with_latitude and new.attitudes == "unknown"
    check(new, ref, 1)


def test_table_scheme_with_every_library_effect_and_priors(optimal9):
    new, ref = models(optimal9, ALL_EFFECTS, priors=(0, 30))
    check(new, ref, 2)


def test_table_scheme_without_latitude_attitudes_from_the_table(optimal9):
    s = lsq.Summaries(**{**optimal9.__dict__, "latitude_deg": None})
    new, ref = models(s, ("accel_nonlinearity", "gyro_g_sensitivity"), attitudes="table")
    assert not new.with_latitude and new.attitudes == "table"
    check(new, ref, 3)


def test_hand_turns_without_latitude(hand):
    new, ref = models(hand["mems", "plain"], ("accel_nonlinearity",))
    assert new.hands and not new.with_latitude and not new.hand_earth_vertical
    check(new, ref, 4)


def test_hand_turns_with_latitude_vertical_earth_rate_only(hand):
    new, ref = models(hand["mems", "latitude"])
    assert new.hands and not new.with_latitude and new.hand_earth_vertical
    check(new, ref, 5)


def test_hand_turns_with_latitude_full_attitudes(hand):
    new, ref = models(hand["quiet", "latitude"], ("gyro_g_sensitivity",))
    assert new.hands and new.with_latitude
    check(new, ref, 6)


def test_a_model_built_on_another_models_start_is_the_same_model(hand):
    """A candidate's score test builds its model on the fitted model's algebraic start
    (``Model(..., start=model.start)``): the same reference values and residuals as a model that
    made its own, and the start is not written to (its notes stay the start's: the hand turns'
    Earth-rate note is the model's, said once by each model)."""
    s = hand["mems", "latitude"]
    base = lsq.Model(s, [])
    notes = list(base.start.notes)
    shared = lsq.Model(s, [LIBRARY["accel_nonlinearity"]()], base.attitudes, start=base.start)
    own = lsq.Model(s, [LIBRARY["accel_nonlinearity"]()], base.attitudes)
    assert shared.start is base.start and base.start.notes == notes
    assert shared.notes == own.notes and sum("Earth rate" in n for n in shared.notes) == 1
    np.testing.assert_array_equal(shared.x0, own.x0)
    np.testing.assert_array_equal(shared.residuals(shared.x0), own.residuals(own.x0))


def test_a_model_like_another_takes_its_nuisances_and_is_the_same_model(hand, optimal9):
    """A candidate's score test builds its model ``like`` the fitted one (its start and initial
    nuisances taken, not computed again): the same start values and residuals as a model that
    computed its own; and its sparse Jacobian is its dense one."""
    for s in (hand["mems", "latitude"], hand["quiet", "latitude"], optimal9):
        base = lsq.Model(s, [])
        like = lsq.Model(s, [LIBRARY["accel_nonlinearity"]()], base.attitudes, like=base)
        own = lsq.Model(s, [LIBRARY["accel_nonlinearity"]()], base.attitudes)
        assert like.start is base.start and like.notes == own.notes
        np.testing.assert_array_equal(like.x0, own.x0)
        np.testing.assert_array_equal(like.residuals(like.x0), own.residuals(own.x0))
        x = random_x(like, np.random.default_rng(3))
        np.testing.assert_array_equal(like.sparse_jacobian(x).toarray(), own.jacobian(x))


def test_a_refit_like_another_fit_is_the_same_fit(optimal9, hand):
    """The add-and-refit loop refits ``like`` the model it adds to (its start and initial
    nuisances taken): the same solution and covariance as a fit that computed them."""
    for s in (optimal9, hand["quiet", "latitude"]):
        base = lsq.fit(s, [])
        effects = [LIBRARY["accel_nonlinearity"]()]
        like, own = lsq.fit(s, effects, like=base.model), lsq.fit(s, list(effects))
        np.testing.assert_allclose(like.x, own.x, rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(like.covariance, own.covariance, rtol=1e-9, atol=1e-300)
        assert like.chi2 == pytest.approx(own.chi2, rel=1e-12)
