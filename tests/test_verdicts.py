"""The verdicts of their own (issue 24 item 7): "not converged" and "noise overestimated",
besides "passes" / "fails" / "untested"; in the file, on screen, in `show`, on the report page
and in the exit status.

The thresholds are checked on both sides with the chi-square distribution itself (scipy.stats,
which the product does not use: an independent reference for the tail probabilities)."""
from __future__ import annotations

import math

import numpy as np
import pytest
import yaml
from scipy import stats

from station.estimate import estimate_with, lsq
from solver_helpers import dense_solve_through, numpy_lm
from station.estimate.verdict import P_FAIL, REDUCED_CHI2_FAIL, UNUSABLE, fit_fails, judge
from station.io.scheme import load_scheme
from station.simulate import dryrun
from sim_devices.truth import default_truth



DOF = 400


def _judged(chi2, dof=DOF, converged=True):
    """The verdict of a fit with this chi2 and dof (on the truth's calibration: any will do)."""
    from station.estimate.verdict import _verdict

    cal = dryrun.truth_calibration(default_truth(1))
    cal.fit = {"method": "lsq", "chi2": chi2, "dof": dof, "converged": converged}
    cal.sigma = {}
    _verdict(cal)
    return cal.fit["verdict"]


@pytest.mark.parametrize("side", [-1, 1])
def test_noise_overestimated_at_its_threshold(side):
    """Just inside and just outside the lower tail: chi2 at the P_FAIL quantile of chi2(DOF)
    (the reduced value there, 0.80 for 400 dof, is above 1/1.5: so use fewer dof where the
    quantile is below 1/1.5 too)."""
    dof = 40                                              # the 1e-3 quantile: reduced chi2 0.44 < 1/1.5
    q = stats.chi2.ppf(P_FAIL, dof)
    assert q / dof < 1 / REDUCED_CHI2_FAIL
    v = _judged(q * (1 - side * 0.02), dof)
    assert v["result"] == ("noise overestimated" if side == 1 else "passes")
    if side == 1:
        assert "every 1-sigma is too large" in v["reason"]


def test_a_low_chi2_within_the_reduced_band_passes():
    """With many degrees of freedom a reduced chi2 of 0.85 is improbable (p below 1e-3) but close
    to 1: it is not called an overestimate (the second condition, reduced < 1/1.5)."""
    dof = 5000
    chi2 = 0.85 * dof
    assert stats.chi2.cdf(chi2, dof) < P_FAIL
    assert _judged(chi2, dof)["result"] == "passes"


@pytest.mark.parametrize("side", [-1, 1])
def test_fails_at_its_threshold(side):
    dof = 40
    q = stats.chi2.isf(P_FAIL, dof)                       # reduced 2.0 > 1.5: the p-value decides
    assert q / dof > REDUCED_CHI2_FAIL
    v = _judged(q * (1 + side * 0.02), dof)
    assert v["result"] == ("fails" if side == 1 else "passes")


def test_not_converged_wins_over_any_chi2():
    for chi2 in (0.3 * DOF, DOF, 10 * DOF):
        v = _judged(chi2, converged=False)
        assert v["result"] == "not converged" and "stopped at its evaluation limit" in v["reason"]
    assert "not converged" in UNUSABLE


def _capture(seed=5):
    truth = default_truth(seed)
    scheme = load_scheme("optimal9", {"dwell_s": 20.0, "rotation_s": 36.0})
    return truth, dryrun.simulate_capture(scheme, truth, seed)


def test_alternating_samples_make_the_noise_overestimated():
    """A ripple at half the sample rate (a chopper-stabilised sensor, an ADC that alternates)
    inflates the white noise estimated from first differences (var of the difference / 2 gains
    2 a^2) while every segment's mean is untouched: the residuals are then far smaller than the
    stated noise.  The estimate says so (reduced chi2 about sigma^2 / (sigma^2 + 2 a^2))."""
    truth, capture = _capture()
    for seg in capture.segments:
        d = seg.data
        n = len(d.t)
        sign = np.where(np.arange(n) % 2 == 0, 1.0, -1.0)[:, None]
        a_acc = 3.0 * np.std(np.diff(d.accel, axis=0), axis=0) / math.sqrt(2)   # a = 3 sigma
        a_gyr = 3.0 * np.std(np.diff(d.gyro, axis=0), axis=0) / math.sqrt(2)
        d.accel[:] = d.accel + sign * a_acc
        d.gyro[:] = d.gyro + sign * a_gyr
        if n % 2:                                         # keep every mean exactly as it was
            d.accel[-1] -= a_acc
            d.gyro[-1] -= a_gyr
    cal, _ = estimate_with(capture, "lsq")
    judge(cal)
    v = cal.fit["verdict"]
    assert v["result"] == "noise overestimated", v
    assert v["reduced_chi2"] < 0.5                        # 1 / (1 + 2 * 9) = 0.05 for white parts
    assert not fit_fails(cal)


def test_an_unconverged_fit_is_said_and_exits_3(tmp_path, monkeypatch, capsys):
    """A fit stopped at its evaluation limit far from its minimum: the file says "not converged",
    `estimate` exits 3, `show` says it.  One stopped at its limit with every written parameter
    at the minimum (the step left below 1 % of each 1-sigma) passes, with a note."""
    from station.cli import main

    truth, _ = _capture()
    cap = tmp_path / "cap"
    dryrun.record_scheme(load_scheme("optimal9", {"dwell_s": 20.0, "rotation_s": 36.0}), truth, 5, cap)
    real = numpy_lm

    def one_evaluation_from_afar(fun, x0, *args, **kw):
        kw["max_nfev"] = 1          # no step taken: x is the start, 1e-3 from the minimum in every
        return real(fun, x0 + 1e-3, *args, **kw)     # coordinate (1000 ppm in a scale factor)

    monkeypatch.setattr(lsq, "_lm", dense_solve_through(one_evaluation_from_afar))
    assert main(["estimate", str(cap), "--method", "lsq"]) == 3
    captured = capsys.readouterr()
    assert "fit not converged" in captured.out and "the fit did not converge (exit status 3)" in captured.err
    doc = yaml.safe_load((cap / "calibration.yaml").read_text())
    assert doc["verdict"]["result"] == "not converged"
    assert main(["show", str(cap / "calibration.yaml")]) == 0
    assert "fit not converged" in capsys.readouterr().out
    assert main(["estimate", str(cap), "--method", "lsq", "--accept-poor-fit", "-o", str(tmp_path / "c2.yaml")]) == 0
    doc = yaml.safe_load((cap / "calibration.yaml").read_text())
    assert max(doc["fit"]["remaining_step_sigma"].values()) > 1.0

    def two_evaluations(*args, **kw):           # from the algebraic start: at the minimum
        kw["max_nfev"] = 2
        return real(*args, **kw)

    monkeypatch.setattr(lsq, "_lm", dense_solve_through(two_evaluations))
    assert main(["estimate", str(cap), "--method", "lsq"]) == 0
    doc = yaml.safe_load((cap / "calibration.yaml").read_text())
    assert doc["verdict"]["result"] == "passes" and doc["fit"]["converged"] is False
    assert max(doc["fit"]["remaining_step_sigma"].values()) < 0.01
    assert any("every parameter written is at the minimum" in n for n in doc["fit"]["notes"])
    monkeypatch.undo()
    assert main(["estimate", str(cap), "--method", "lsq"]) == 0
    doc = yaml.safe_load((cap / "calibration.yaml").read_text())
    assert doc["verdict"]["result"] == "passes" and doc["fit"]["converged"] is True
