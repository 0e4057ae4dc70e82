"""Verdicts at their thresholds, from captures (issue 30 item 3): a fit whose reduced chi2 sits just
below and just above each threshold of station/estimate/verdict.py, and what the user sees on
both sides -- the exit status of `station estimate`, the calibration file, the report page.

* **fails**: a hidden effect the base model lacks (the accelerometers' second-order
  nonlinearity K2, sim_devices.truth, identical on the three axes) of a size chosen so that the
  reduced chi2 lands 2 % below and 2 % above the threshold.  The fit is linear in K2 near the
  solution, so chi2(K2) = chi2_0 + B K2 + C K2^2: C (the expected chi2 increase per (ug/g^2)^2,
  the noncentrality) and B (the cross term with this seed's noise, which is kept: the noise
  stream does not change with the effect's size) come from a +-100 ug/g^2 pair at the same seed.
  The quadratic's own error (the model's curvature) is checked: the realised reduced chi2 lies
  within 0.5 % of its target, well inside the 2 % margin.
* **noise overestimated**: a ripple at half the sample rate of amplitude kappa sigma on every
  channel (an ADC that alternates) leaves every segment's mean as it was and inflates the white
  noise estimated from first differences by (1 + 2 kappa^2): the reduced chi2 becomes
  chi2_0 / (1 + 2 kappa^2), and kappa is chosen to land 2 % on either side of 1 / 1.5.
* **not converged**: the solver made to stop (status "evaluation limit") where the step it would
  still take moves accel_scale_x by 0.9 % and by 1.1 % of its 1-sigma (the threshold is 1 %,
  verdict.REMAINING_STEP_SIGMA): at the minimum with a note, or not converged and exit 3.
"""
from __future__ import annotations

import hashlib
import json
import math
import shutil

import numpy as np
import pytest
import yaml
from scipy import stats

from sim_devices.truth import default_truth
from station.cli import main
from station.estimate import estimate_with, lsq
from solver_helpers import dense_solve_through, numpy_lm
from station.estimate.verdict import judge
from station.io.scheme import load_scheme
from station.simulate import dryrun



# The thresholds as documented (docs/calibration-file.md), not read from verdict.py: a threshold
# moved in the code (the planted 1.5 -> 4.0) must fail these tests, not move their targets.
P_FAIL = 1e-3
REDUCED_CHI2_FAIL = 1.5
REMAINING_STEP_SIGMA = 0.01

SCHEME = load_scheme("optimal9", {"dwell_s": 10.0, "rotation_s": 36.0})
SEED = 5
MARGIN = 0.02           # each side's distance from the threshold, in reduced chi2 (relative)
PROBE_K2 = 100.0        # ug/g^2: the +- pair that measures B and C (chi2 moves by ~50 %)


def truth_with(k2_ug_per_g2: float):
    truth = default_truth(SEED)
    truth.accel.nonlinearity_ug_per_g2 = np.full(3, float(k2_ug_per_g2))
    return truth


def verdict_of(truth) -> dict:
    cal, _ = estimate_with(dryrun.simulate_capture(SCHEME, truth, SEED), "lsq")
    judge(cal)
    return cal.fit["verdict"]


def fail_threshold(dof: float) -> float:
    """The reduced chi2 above which the fit fails: both p < P_FAIL and reduced > 1.5."""
    return max(REDUCED_CHI2_FAIL, stats.chi2.isf(P_FAIL, dof) / dof)


def overestimate_threshold(dof: float) -> float:
    """The reduced chi2 below which the noise is overestimated: P(below) < P_FAIL and < 1/1.5."""
    return min(1.0 / REDUCED_CHI2_FAIL, stats.chi2.ppf(P_FAIL, dof) / dof)


@pytest.fixture(scope="module")
def clean():
    v = verdict_of(truth_with(0.0))
    assert v["result"] == "passes"
    return v


@pytest.fixture(scope="module")
def k2_sizes(clean):
    """K2 (ug/g^2) that puts the reduced chi2 at the fail threshold x (1 -+ MARGIN)."""
    dof = clean["dof"]
    chi0 = clean["reduced_chi2"] * dof
    plus, minus = (verdict_of(truth_with(s * PROBE_K2)) for s in (1, -1))
    assert plus["dof"] == minus["dof"] == dof
    chi_p, chi_m = plus["reduced_chi2"] * dof, minus["reduced_chi2"] * dof
    C = (chi_p + chi_m - 2 * chi0) / (2 * PROBE_K2 ** 2)      # expected increase per (ug/g^2)^2
    B = (chi_p - chi_m) / (2 * PROBE_K2)
    assert C > 0
    sizes = {}
    for side in (-1, 1):
        target = fail_threshold(dof) * (1 + side * MARGIN) * dof
        sizes[side] = (-B + math.sqrt(B * B - 4 * C * (chi0 - target))) / (2 * C)
    return sizes


@pytest.fixture(scope="module")
def clean_capture(tmp_path_factory):
    """The clean recording (the noise tests copy it and add their ripple; the solver's test reads
    it as it is)."""
    return dryrun.record_scheme(SCHEME, truth_with(0.0), SEED, tmp_path_factory.mktemp("clean") / "cap")


def read_doc(path):
    return yaml.safe_load(path.read_text())


def page_of(capture, tmp_path, name):
    page = tmp_path / f"{name}.html"
    assert main(["report", str(capture), "--no-auto", "-o", str(page)]) == 0
    return page.read_text()


@pytest.mark.parametrize("side", [-1, 1], ids=["just-below", "just-above"])
def test_fails_at_its_threshold(tmp_path, capsys, clean, k2_sizes, side):
    k2 = k2_sizes[side]
    cap = dryrun.record_scheme(SCHEME, truth_with(k2), SEED, tmp_path / "cap")
    status = main(["estimate", str(cap)])
    doc = read_doc(cap / "calibration.yaml")
    v = doc["verdict"]
    threshold = fail_threshold(v["dof"])
    # the quadratic's aim: within 0.5 % of the target (a quarter of the margin)
    assert v["reduced_chi2"] == pytest.approx(threshold * (1 + side * MARGIN), rel=0.005), (k2, v)
    err = capsys.readouterr().err
    page = page_of(cap, tmp_path, "page")
    if side == 1:
        assert status == 3 and v["result"] == "fails"
        assert "exit status 3" in err
        assert doc["fit"]["sigma_scale"] == pytest.approx(math.sqrt(v["reduced_chi2"]), rel=1e-9)
        assert "fit verdict: fails" in page
    else:
        assert status == 0 and v["result"] == "passes"
        assert "sigma_scale" not in doc["fit"]
        assert "fit verdict: passes" in page
    # diagnose's own test (p alone) calls both sides a misfit; just below, it says that a
    # calibration from this fit passes, so that the two never seem to contradict
    capsys.readouterr()
    main(["diagnose", str(cap), "--json"])
    words = json.loads(capsys.readouterr().out)["verdict"]
    assert "does not explain the data" in words, words
    assert ("a calibration from this fit passes" in words) == (side == -1), words
    # accepted anyway: the file still says what the fit is
    assert main(["estimate", str(cap), "--accept-poor-fit", "-o", str(tmp_path / "accepted.yaml")]) == 0
    assert read_doc(tmp_path / "accepted.yaml")["verdict"]["result"] == v["result"]


# ------------------------------------------------------------------------ noise overestimated

def add_nyquist_ripple(capture, kappa: float) -> None:
    """Every channel of every segment: + kappa sigma (-1)^i, sigma its own white noise from first
    differences; the last sample of an odd count takes the other sign so every mean is kept."""
    doc = yaml.safe_load((capture / "manifest.yaml").read_text())
    for entry in doc["segments"]:
        path = capture / entry["file"]
        lines = path.read_text().splitlines()
        header = lines[0].split(",")
        table = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
        cols = [header.index(c) for c in ("ax", "ay", "az", "gx", "gy", "gz")]
        x = table[:, cols]
        a = kappa * np.std(np.diff(x, axis=0), axis=0) / math.sqrt(2)
        sign = np.where(np.arange(len(x)) % 2 == 0, 1.0, -1.0)
        if len(x) % 2:
            sign[-1] = 0.0
        table[:, cols] = x + sign[:, None] * a
        text = ",".join(header) + "\n" + "".join(",".join(f"{v:.15g}" for v in row) + "\n" for row in table)
        path.write_text(text)
        entry["sha256"] = hashlib.sha256(text.encode()).hexdigest()
    (capture / "manifest.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))


@pytest.mark.parametrize("side", [-1, 1], ids=["just-below", "just-above"])
def test_noise_overestimated_at_its_threshold(tmp_path, capsys, clean, clean_capture, side):
    dof = clean["dof"]
    target = overestimate_threshold(dof) * (1 + side * MARGIN)
    kappa = math.sqrt((clean["reduced_chi2"] / target - 1) / 2)
    cap = shutil.copytree(clean_capture, tmp_path / "cap")       # the clean recording, once per module
    add_nyquist_ripple(cap, kappa)
    status = main(["estimate", str(cap)])
    doc = read_doc(cap / "calibration.yaml")
    v = doc["verdict"]
    # the model chi2_0 / (1 + 2 kappa^2) holds to 1 % (the harmonics of a rotation see the ripple
    # slightly; the bias-instability test is unchanged): half the margin
    assert v["reduced_chi2"] == pytest.approx(target, rel=0.01), (kappa, v)
    assert status == 0                                    # kept, said, never an exit 3
    page = page_of(cap, tmp_path, "page")
    if side == -1:
        assert v["result"] == "noise overestimated" and "every 1-sigma is too large" in v["reason"]
        assert "fit verdict: noise overestimated" in page
    else:
        assert v["result"] == "passes"
        assert "fit verdict: passes" in page
    capsys.readouterr()


# ------------------------------------------------------------------------ not converged

def stopped_short(fraction: float):
    """A least_squares that solves, then reports stopping at its evaluation limit at a point
    from which the Gauss-Newton step moves the first parameter (accel_scale_x) by ``fraction``
    of its 1-sigma, and every other one by its regression on it (less)."""
    real = numpy_lm

    def solve(fun, x0, *args, jac=None, **kw):
        res = real(fun, x0, *args, jac=jac, **kw)
        J = jac(res.x)
        J = J.toarray() if hasattr(J, "toarray") else np.asarray(J)
        d = 1.0 / np.linalg.norm(J, axis=0)
        cov = d[:, None] * np.linalg.pinv((J * d).T @ (J * d)) * d[None, :]
        x = res.x + fraction * cov[:, 0] / math.sqrt(cov[0, 0])
        res.x, res.fun = x, fun(x)
        res.jac = jac(x)
        res.cost = 0.5 * float(res.fun @ res.fun)
        res.status = 0
        return res

    return solve


@pytest.mark.parametrize("side", [-1, 1], ids=["just-below", "just-above"])
def test_not_converged_at_its_threshold(tmp_path, monkeypatch, capsys, clean_capture, side):
    fraction = REMAINING_STEP_SIGMA * (1 + side * 0.1)
    monkeypatch.setattr(lsq, "_lm", dense_solve_through(stopped_short(fraction)))
    out = tmp_path / "cal.yaml"
    status = main(["estimate", str(clean_capture), "-o", str(out)])
    doc = read_doc(out)
    steps = doc["fit"]["remaining_step_sigma"]
    assert doc["fit"]["converged"] is False
    assert max(steps, key=steps.get) == "accel_scale_x"
    assert steps["accel_scale_x"] == pytest.approx(fraction, rel=0.02)   # the linear step: to 2 %
    monkeypatch.undo()
    page = tmp_path / "page.html"
    assert main(["report", str(clean_capture), "--cal", str(out), "--no-auto", "-o", str(page)]) == 0
    page = page.read_text()
    err = capsys.readouterr().err
    if side == 1:
        assert status == 3 and doc["verdict"]["result"] == "not converged"
        assert "the fit did not converge (exit status 3)" in err
        assert "fit verdict: not converged" in page
    else:
        assert status == 0 and doc["verdict"]["result"] == "passes"
        assert any("every parameter written is at the minimum" in n for n in doc["fit"]["notes"])
        assert "fit verdict: passes" in page
