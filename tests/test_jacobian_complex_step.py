"""The fit's Jacobian by complex step (station/estimate/lsq.py, Model.jacobian): with every
library effect it equals central differences of the residual; an effect that is not
complex-step safe (a plugin) makes the model fall back to forward differences, whether it says
so (no ``complex_step = True``) or betrays itself (a cast to float, a real term).

Tolerance of complex step against central differences: the complex-step columns are exact to
rounding (no difference is taken), so the difference is the central differences' own error:
truncation h^2/6 f''' (h = 1e-4 of each parameter's size: ~1e-8 of a column) plus rounding,
eps D / h per row, D the size of the whitened numbers that cancel in the row (its datum and its
prediction; tests/test_lsq_vectorised.cancelling_size).  The bound is 1e-6 of the column's norm
plus 4 eps D / h.  Forward differences (the fallback) are held to the bound of
tests/test_lsq_vectorised.py: 1e-4 of the column's norm plus 16 eps D / h_forward."""
from pathlib import Path

import numpy as np
import pytest

from station.estimate import lsq
from station.io.scheme import load_scheme
from station.model import LIBRARY
from station.model.effect import Effect, Param
from station.model.raw_counts import in_capture_units
from station.model.registry import EffectRegistry
from station.simulate import dryrun
from lsq_reference import PerSegmentModel
from test_lsq_vectorised import cancelling_size, random_x

EPS = np.finfo(float).eps
EXAMPLES = Path(__file__).resolve().parents[1] / "examples" / "effects"


@pytest.fixture(scope="module")
def optimal9():
    truth = dryrun.load_truth(None, 0)
    truth.sample_rate_hz = 50.0
    return lsq.summarise(dryrun.simulate_capture(load_scheme("optimal9"), truth, 3))


def central(model, x, relative=1e-4):
    h = relative * model._sizes(x)
    J = np.empty((len(model.residuals(x)), len(x)))
    for c in range(len(x)):
        xp, xm = x.copy(), x.copy()
        xp[c] += h[c]
        xm[c] -= h[c]
        J[:, c] = (model.residuals(xp) - model.residuals(xm)) / (2 * h[c])
    return J, h


def excess(model, effects, x, J, h, column_share, rounding):
    """max |J - central| / tolerance (below 1: within it)."""
    Jc, hc = central(model, x)
    ref = PerSegmentModel(model.s, effects)
    D = cancelling_size(ref, x, ref.residuals(x))
    tolerance = column_share * np.linalg.norm(Jc, axis=0) + rounding * EPS * np.outer(D, 1 / h)
    tolerance += 4 * EPS * np.outer(D, 1 / hc)
    return np.max(np.abs(J - Jc) / tolerance)


@pytest.mark.parametrize("effect_id", sorted(LIBRARY))
def test_every_library_effect_is_complex_step_safe(optimal9, effect_id):
    effects = [in_capture_units(LIBRARY[effect_id])()]
    model = lsq.Model(optimal9, effects)
    x = random_x(model, np.random.default_rng(7))
    J = model.jacobian(x)
    assert model.complex_step, "a library effect fell back to forward differences"
    assert excess(model, effects, x, J, np.inf, 1e-6, 0.0) <= 1
    sl = model.layout[f"effect:{effect_id}"]
    cols = list(range(sl.start, sl.stop))
    np.testing.assert_array_equal(model.jacobian_columns(x, cols), J[:, cols])     # the score test's path


def test_every_library_effect_at_once(optimal9):
    effects = [LIBRARY[e]() for e in sorted(LIBRARY)]
    model = lsq.Model(optimal9, effects)
    x = random_x(model, np.random.default_rng(8))
    J = model.jacobian(x)
    assert model.complex_step
    assert excess(model, effects, x, J, np.inf, 1e-6, 0.0) <= 1


@pytest.mark.parametrize("spec", ["accel_cross_coupling.py:AccelCrossCoupling", "gyro_rate_squared.py:GyroRateSquared"])
def test_the_example_plugins_are_complex_step_safe(optimal9, spec):
    """docs/effects.md's examples declare complex_step = True: it must be true."""
    registry = EffectRegistry(entry_points=False, environment=False)
    (eid,) = registry.add(str(EXAMPLES / spec))
    effects = [registry.create(eid)]
    model = lsq.Model(optimal9, effects)
    x = random_x(model, np.random.default_rng(10))
    J = model.jacobian(x)
    assert model.complex_step
    assert excess(model, effects, x, J, np.inf, 1e-6, 0.0) <= 1


class GyroRateSquaredAbs(Effect):
    """A plugin as people write it: np.abs, no complex_step declared."""
    id = "plugin_rate_squared"

    @property
    def params(self):
        return tuple(Param(f"rate2_{a}", "ppm/(deg/s)", 1.0, 5.0, 1000.0) for a in "xyz")

    def gyro(self, x, ctx):
        w = ctx.w_p @ ctx.gyro_matrix.T
        return 1e-6 * x * w * np.abs(w)


class ClaimsSafeButCasts(GyroRateSquaredAbs):
    """Says it is safe, then casts to float (TypeError under complex step)."""
    id = "plugin_casts"
    complex_step = True

    def gyro(self, x, ctx):
        return super().gyro(np.array([float(v) for v in x]), ctx)


class ClaimsSafeButReal(GyroRateSquaredAbs):
    """Says it is safe, then returns a real array (the imaginary part dropped)."""
    id = "plugin_real"
    complex_step = True

    def gyro(self, x, ctx):
        return np.abs(super().gyro(x, ctx))


class ClaimsSafeIntegralReal(Effect):
    """A clock offset on the gyro integrals (as time_offset) that says it is safe, then drops the
    imaginary part with .real."""
    id = "plugin_integral_real"
    complex_step = True

    @property
    def params(self):
        return (Param("clock_ms", "ms", 1e3, 3.0, 200.0),)

    def integral(self, x, rotation):
        return x[0].real * (rotation.gyro_end - rotation.gyro_start)


@pytest.mark.parametrize("plugin", [GyroRateSquaredAbs, ClaimsSafeButCasts, ClaimsSafeButReal, ClaimsSafeIntegralReal])
def test_an_unsafe_plugin_falls_back_to_forward_differences(optimal9, plugin):
    effects = [LIBRARY["accel_nonlinearity"](), plugin()]
    model = lsq.Model(optimal9, effects)
    x = random_x(model, np.random.default_rng(9))
    x[model.layout[f"effect:{plugin.id}"]] = 1.0      # w |w| with w of either sign in the rotations
    J = model.jacobian(x)
    assert not model.complex_step and model.jacobian_method == f"forward differences ({plugin.id})"
    assert excess(model, effects, x, J, lsq.FORWARD_STEP * model._sizes(x), 1e-4, 16) <= 1
    # had complex step been trusted, the Jacobian would be wrong: np.abs gives the modulus
    if plugin is GyroRateSquaredAbs:
        model._unsafe = []
        model._last_jacobian = None
        assert excess(model, effects, x, model.jacobian(x), np.inf, 1e-6, 0.0) > 1


def test_complex_step_is_the_default_of_the_base_model(optimal9):
    model = lsq.Model(optimal9, [])
    model.jacobian(model.x0)
    assert model.complex_step and model.jacobian_method == "complex step"
