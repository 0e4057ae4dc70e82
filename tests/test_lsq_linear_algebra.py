"""The fit's linear algebra (issue 27, docs/performance.md "Fifteenth session: the fit's linear
algebra"): the Jacobian at the solution is factorised once, and what is read from it -- the
at-minimum test's Gauss-Newton gain, the covariance and null space, the noise groups' leverages
-- is what the separate factorisations gave.

Tolerances: the Gauss-Newton gain by lstsq is chi2 - ||r + J d||^2, a difference of two sums
of ~chi2 whose rounding is ~1e-15 chi2 per row (300 rows: < 1e-12 chi2); through the SVD it is
||U_k^T r||^2, rounded ~1e-15 relative to itself.  So they agree within 1e-12 chi2 + 1e-9 of
the gain (far below the decision's 1e-4 / 1e-6 chi2 units, far above rounding).  The leverages
from the kept SVD are the same LAPACK call on the same matrix: equal to the last bit.
"""
from __future__ import annotations

import traceback

import numpy as np
import pytest

from station import api
from station.estimate import lsq, noise_groups
from station.io.capture import read_capture


@pytest.fixture(scope="module")
def summaries(tmp_path_factory):
    path = api.simulate("optimal9", tmp_path_factory.mktemp("la") / "c", seed=3, dwell_s=5.0, rotation_s=5.0)
    return lsq.summarise(read_capture(path))


@pytest.fixture(scope="module")
def fitted(summaries):
    return lsq.fit(summaries)


def _lstsq_gain(J, r):
    return lsq._gauss_newton_gain(type("R", (), {"fun": r, "jac": J})())


def test_the_gain_read_from_the_svd_is_lstsqs(summaries, fitted):
    """Far from the minimum (the start: the gain is most of chi2) and at it (the gain ~0)."""
    model = lsq.Model(summaries, [])
    for m, x in ((model, model.x0), (fitted.model, fitted.x)):
        J, r = m.jacobian(x), m.residuals(x)
        svd = lsq._ScaledSVD(J)
        chi2 = float(r @ r)
        ours, ref = svd.gauss_newton_gain(r), _lstsq_gain(J, r)
        assert abs(ours - ref) <= 1e-12 * chi2 + 1e-9 * ref, (ours, ref, chi2)
        # through _gauss_newton_gain: the SVD is read only when it is of that very Jacobian
        res = type("R", (), {"fun": r, "jac": J})()
        assert lsq._gauss_newton_gain(res, svd) == ours
        other = J * (1.0 + 2.0**-40)            # another matrix: lstsq's own factorisation
        assert lsq._gauss_newton_gain(type("R", (), {"fun": r, "jac": other})(), svd) == _lstsq_gain(other, r)
    start_gain = _lstsq_gain(model.jacobian(model.x0), model.residuals(model.x0))
    assert start_gain > 1.0                     # (the start is not at the minimum: the test sees a gain)


def test_the_leverages_from_the_solutions_svd_are_the_same_to_the_last_bit(fitted):
    model, x = fitted.model, fitted.x
    J = model.jacobian(x)
    kept = lsq._solution_svd(model, J)
    assert kept is not None                     # _solve kept the SVD of this very matrix
    np.testing.assert_array_equal(noise_groups.leverages(J, kept), noise_groups.leverages(J))
    assert lsq._solution_svd(model, J * (1.0 + 2.0**-40)) is None     # another matrix: its own SVD
    assert lsq._solution_svd(model, None) is None


def test_the_solutions_jacobian_is_factorised_once(summaries, monkeypatch):
    """Outside the solver's own steps, the Jacobian at the solution is factorised by one SVD:
    the at-minimum test, the covariance, the null space and the noise groups' leverages all
    read it (three factorisations before: lstsq, the covariance's SVD, the leverages' SVD)."""
    calls = []
    for name in ("svd", "lstsq", "qr", "eigh"):
        real = getattr(np.linalg, name)

        def counted(a, *args, _real=real, _name=name, **kwargs):
            where = traceback.extract_stack(limit=2)[0].filename
            calls.append((_name, np.shape(a), where))
            return _real(a, *args, **kwargs)
        monkeypatch.setattr(np.linalg, name, counted)
    result = lsq.fit(summaries)
    lsq.to_calibration(result, "m/s^2", "deg/s")
    shape = result.model.jacobian(result.x).shape
    outside = [c for c in calls if c[1] == shape and not c[2].endswith("solver.py")]
    assert [c[0] for c in outside] == ["svd"], outside
