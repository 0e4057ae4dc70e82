"""The effects' batch forms (Effect.accel_batch, gyro_batch: every row of a Jacobian batch in one
call, twentieth session) against their per-row forms, through the fit's residuals: every library
effect, real rows and complex-step rows, also scaled to a raw capture's counts
(raw_counts.InCaptureUnits); the same numbers in the same order, so equal bit for bit.  A plugin
that subclasses a library effect and overrides accel alone keeps its override."""
import numpy as np
import pytest

from station.estimate import lsq
from station.io.scheme import load_scheme
from station.model import LIBRARY
from station.model.lever_arm import AccelLeverArm
from station.model.nonlinearity import AccelNonlinearity
from station.model.raw_counts import in_capture_units
from station.model.table_encoder_scale import TableEncoderScale
from station.model.table_wobble import TableWobble
from station.simulate import dryrun

B = 4


@pytest.fixture(scope="module")
def optimal9():
    truth = dryrun.load_truth(None, 0)
    truth.sample_rate_hz = 50.0
    return lsq.summarise(dryrun.simulate_capture(load_scheme("optimal9"), truth, 3))


def rows(model, seed=1):
    """B parameter vectors: the start plus 1e-3 and each effect's parameters at a typical size."""
    rng = np.random.default_rng(seed)
    X = model.x0 + 1e-3 * rng.standard_normal((B, len(model.x0)))
    for e in model.effects:
        sl = model.layout[f"effect:{e.id}"]
        X[:, sl] = [p.typical / p.scale for p in e.params] * rng.standard_normal((B, sl.stop - sl.start))
    return X


def per_row(model, X, monkeypatch):
    with monkeypatch.context() as m:
        m.setattr(lsq, "_own_term_batch", lambda effect, name: None)
        return model._residuals_batch(X)


@pytest.mark.parametrize("scaled", [False, True])
def test_every_library_effects_batch_form_is_its_per_row_form(optimal9, monkeypatch, scaled):
    effects = [in_capture_units(cls)() for cls in LIBRARY.values()]
    model = lsq.Model(optimal9, effects)
    if scaled:      # as on a raw capture: the matrices over the nominal scales, the terms times them
        for e in model.effects:
            e._counts_per_unit = (2.0, 3.0)
    X = rows(model)
    Xc = X + 1e-20j * np.eye(B, len(X[0]), k=model.layout["effect:accel_nonlinearity"].start)
    batched = [e.id for e in model.effects if lsq._own_term_batch(e, "accel") or lsq._own_term_batch(e, "gyro")]
    assert len(batched) >= 10
    for x in (X, Xc):
        np.testing.assert_array_equal(model._residuals_batch(x), per_row(model, x, monkeypatch))
    # each batch form's term reaches the residuals: without it they change
    for e in effects if not scaled else ():
        if e.id in batched and e.id != "time_offset":
            alone = lsq.Model(optimal9, [in_capture_units(type(e).__mro__[2])()])
            x = rows(alone)
            zero = x.copy()
            zero[:, alone.layout[f"effect:{e.id}"]] = 0.0
            assert not np.array_equal(alone._residuals_batch(x), alone._residuals_batch(zero)), e.id


class Doubled(AccelNonlinearity):
    """A plugin: the library's K2 term, twice (accel overridden alone)."""

    def accel(self, x, ctx):
        return 2.0 * super().accel(x, ctx)


def test_a_subclass_overriding_accel_alone_keeps_its_override(optimal9, monkeypatch):
    plugin = lsq.Model(optimal9, [in_capture_units(Doubled)()])
    library = lsq.Model(optimal9, [in_capture_units(AccelNonlinearity)()])
    assert lsq._own_term_batch(plugin.effects[0], "accel") is None
    assert lsq._own_term_batch(library.effects[0], "accel") is not None
    X = rows(plugin)
    mine = plugin._residuals_batch(X)
    np.testing.assert_array_equal(mine, per_row(plugin, X, monkeypatch))
    assert not np.array_equal(mine, library._residuals_batch(X))


def test_diagnoses_discovered_terms_batch_form_is_its_per_row_form(optimal9, monkeypatch):
    """station diagnose's TermsEffect: every regressor of both sensors on its own axis, some rows'
    coefficients 0 (the per-row form skips those terms)."""
    from station.diagnose.terms import Term, TermsEffect, dictionary

    terms = [Term(sensor, k % 3, r) for sensor in ("accel", "gyro")
             for k, r in enumerate(dictionary(sensor, n_segments=len(optimal9.statics) + len(optimal9.rotations)))]
    model = lsq.Model(optimal9, [in_capture_units(TermsEffect)(terms, 20.0)])
    assert lsq._own_term_batch(model.effects[0], "accel") is not None
    rng = np.random.default_rng(2)
    X = model.x0 + 1e-3 * rng.standard_normal((B, len(model.x0)))
    sl = model.layout["effect:discovered_terms"]
    X[:, sl] = 1e-9 * rng.standard_normal((B, sl.stop - sl.start)) * (rng.random((B, sl.stop - sl.start)) < 0.7)
    X[:, sl.start] = 0.0            # a term no row carries
    np.testing.assert_array_equal(model._residuals_batch(X), per_row(model, X, monkeypatch))


class MirroredArms(AccelLeverArm):
    """A plugin: the library's size effect with its elements' positions mapped its own way
    (``positions`` overridden alone: a helper accel calls and the batch form did not)."""
    id = "mirrored_lever_arm"

    def positions(self, x):
        p = super().positions(x)
        return p + p[::-1]


class SteeperWobble(TableWobble):
    """A plugin: the library's wobble with its lean three times (``_lean`` overridden alone)."""
    id = "steeper_wobble"

    def _lean(self, x, index):
        l, w, lxw = super()._lean(x, index)
        return l, 3.0 * w, 3.0 * lxw


class GearedEncoder(TableEncoderScale):
    """A plugin: the library's encoder scale error in units of 5 ppm (``_per_row`` overridden alone)."""
    id = "geared_encoder_scale"

    def _per_row(self, x, ctx):
        return 5.0 * super()._per_row(x, ctx)


@pytest.mark.parametrize("plugin", [MirroredArms, SteeperWobble, GearedEncoder], ids=lambda c: c.__name__)
def test_a_subclass_overriding_a_helper_of_accel_alone_keeps_its_override(optimal9, monkeypatch, plugin):
    """The review of batch27: a plugin overriding a method the per-row term calls but the batch
    form does not (its own arithmetic) lost its override in the fit (silently: station apply, row
    by row, kept it); such a subclass is called row by row."""
    mine = lsq.Model(optimal9, [in_capture_units(plugin)()])
    library = lsq.Model(optimal9, [in_capture_units(plugin.__mro__[1])()])
    X = rows(mine)
    ours = mine._residuals_batch(X)
    np.testing.assert_array_equal(ours, per_row(mine, X, monkeypatch))
    assert not np.array_equal(ours, library._residuals_batch(X))
