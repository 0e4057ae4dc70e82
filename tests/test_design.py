"""station design (issue 28): the candidates' information is the estimator's own, the designed
scheme is an ordinary scheme that plan, run and montecarlo accept, and its predicted 1σ is what
repeated dry runs show (small candidate sets, few exchange passes: each test a few seconds)."""
import json
import math
import os
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import chi2

from station.cli import choices
from station.design import search
from station.design.candidates import Table, candidate_set, directions
from station.design.search import mountings_needed
from station.design.information import UNIT_DWELL_S, Noise, information, schur
from station.io.scheme import StaticSpec, load_scheme
from station.simulate import montecarlo

ROOT = Path(__file__).resolve().parents[1]
# (--verify-runs 0: these tests run station montecarlo on the design, the stronger check)
SMALL = ["--rates", "30,100", "--revolutions", "1", "--dwells", "10,30", "--passes", "3", "--verify-runs", "0"]


def station(*args, cwd=None, timeout=1200):
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    return subprocess.run([sys.executable, "-m", "station.cli", *map(str, args)], capture_output=True,
                          text=True, cwd=cwd, env=env, timeout=timeout)


def _ratio_bounds(runs: int, tests: int, alpha: float = 1e-3) -> tuple[float, float]:
    """Bounds of a sample std over its true σ with ``runs`` repetitions: (n-1) s²/σ² is χ² with
    n-1 degrees of freedom for normal errors; two-sided at ``alpha`` for all ``tests`` ratios
    together (Bonferroni: alpha / tests each), so an honest σ fails the test once in 1/alpha."""
    dof = runs - 1
    a = alpha / tests / 2.0
    return math.sqrt(chi2.ppf(a, dof) / dof), math.sqrt(chi2.ppf(1.0 - a, dof) / dof)


def test_information_is_the_estimators_cramer_rao_bound():
    """optimal9's own segments as candidates: the summed per-candidate information gives the
    1σ that station.simulate.montecarlo.cramer_rao (a full fit's covariance) gives.  Both are
    (J^T J)^-1 of the same model, J taken at the start here and at the fit's solution there (a
    noiseless capture: they differ by the start's error, ~1e-6 relative), so agreement to 1e-3
    relative is the nuisances' elimination being right (a nuisance held only by its prior
    dropped instead of eliminated made the accelerometer biases 5 % too small)."""
    scheme = load_scheme("optimal9")
    chunk, cands = [], []
    segs = list(scheme.segments)
    i = 0
    while i < len(segs):
        s = segs[i]
        if isinstance(s, StaticSpec):
            up = tuple(float(x) for x in s.up_body)
            chunk.append((("static", up), replace(s, dwell_s=UNIT_DWELL_S)))
            cands.append(search.Candidate(("static", up, s.dwell_s), "static", s.dwell_s, dwell_s=s.dwell_s, slot=up))
            i += 1
        else:
            key = (tuple(float(x) for x in s.axis_body), 0.0, abs(s.rate_dps), 5)
            chunk.append((key, (s, segs[i + 1])))
            cands.append(search.Candidate(key, "rotation", 2 * s.duration_s, axis=key[:2]))
            i += 2
    info = information([chunk], [], Noise())
    scorer = search.Scorer(info, cands, search.Criterion("D"), np.arange(21))
    mine = scorer.sigma(range(len(cands)))
    bound = montecarlo.cramer_rao(scheme, montecarlo.Settings())
    np.testing.assert_allclose(mine, bound, rtol=1e-3)
    # the incremental state (the search's) gives the same information as the sum
    state = search.State(scorer, range(len(cands)))
    np.testing.assert_allclose(state.information(), scorer.information(range(len(cands))), rtol=1e-12, atol=0)
    F = state.information(remove=(0,), add=())
    np.testing.assert_allclose(F, scorer.information(range(1, len(cands))), rtol=1e-9, atol=1e-9 * np.abs(F).max())


@pytest.mark.parametrize("effect_ids", [(), ("accel_nonlinearity",)])
def test_information_with_known_attitudes_is_the_estimators_covariance(effect_ids):
    """sizeeffect's own segments (six statics: the estimator takes the table's attitudes, known to
    its angle error, through one mounting rotation) as candidates of known attitude: the design's
    information gives the 1σ of station.simulate.montecarlo.cramer_rao -- the estimator's own fit
    of the noiseless capture and its covariance, attitudes as the estimator chooses them.  Both
    are (J^T J)^-1 of the same model at the same point (the noiseless fit's solution), so they
    agree to the solver's tolerance; measured 2.3e-3 at most (the gyro biases), so 1e-2.  Summing
    per-candidate information with each attitude's table prior scaled with the dwell as the data
    are (an attitude's prior is not data) misses by more: checked below, so the test can fail."""
    from station.model import LIBRARY

    scheme = load_scheme("sizeeffect")
    chunk, cands = [], []
    for s in scheme.segments:
        if isinstance(s, StaticSpec):
            up = tuple(float(x) for x in s.up_body)
            chunk.append((("static", up), replace(s, dwell_s=UNIT_DWELL_S)))
            cands.append(search.Candidate(("static", up, s.dwell_s), "static", s.dwell_s, dwell_s=s.dwell_s, slot=up))
        else:       # one direction each (pair: false), grouped by axis as the estimator groups them
            key = (tuple(float(x) for x in s.axis_body), float(s.axis_elevation_deg), s.rate_dps, 1)
            chunk.append((key, (s,)))
            cands.append(search.Candidate(key, "rotation", s.duration_s, axis=key[:2]))
    effects = [LIBRARY[e]() for e in effect_ids]
    info = information([chunk], effects, Noise(), centred=scheme.centred, attitudes="table")
    everything = range(len(cands))
    scorer = search.Scorer(info, cands, search.Criterion("D"), np.arange(len(info.parameters.names)))
    mine = scorer.sigma(everything)
    bound = montecarlo.cramer_rao(scheme, replace(montecarlo.Settings(), effects=effect_ids))
    assert len(mine) == len(bound) == 21 + sum(len(e.params) for e in effects)
    np.testing.assert_allclose(mine, bound, rtol=1e-2)
    # the attitudes' priors scaled with the dwell, as an unknown attitude's information is: wrong
    for i, c in enumerate(cands):
        if c.kind == "static":
            D, P = info.static_parts[c.key[:-1]]
            scorer.M[i] = schur((D + P / UNIT_DWELL_S) * c.dwell_s, info.shared)
    assert np.max(np.abs(scorer.sigma(everything) / bound - 1.0)) > 2e-2


def test_the_search_lengthens_a_static_paid_for_by_dropping_another():
    """One parameter, information per second of each static (attitude a: 1 at any dwell, b: 2,
    c: 0.8), a budget of 110 s.  Greedily per second: b 10 s, a 10 s, c 90 s (information
    20 + 10 + 72 = 102), the budget spent; no single exchange helps (a 100 s needs 90 s more than
    a 10 s frees), but a 100 s paid for by dropping c gives 20 + 100 = 120: the search finds it."""
    from station.design.information import Information, Parameters

    info = Information(1, Parameters(["p"], ["1"], np.array([0]), np.array([1.0]), np.array([np.inf])),
                       attitudes="table")
    rate = {"a": 1.0, "b": 2.0, "c": 0.8}
    for slot, r in rate.items():       # one attitude column, decoupled (its prior holds it)
        info.static_parts[("static", slot)] = (np.diag([r, 0.0]), np.diag([0.0, 1.0]))
    cands = [search.Candidate(("static", s, d), "static", d, dwell_s=d, slot=s)
             for s, d in (("a", 10.0), ("a", 100.0), ("b", 10.0), ("c", 90.0))]
    scorer = search.Scorer(info, cands, search.Criterion("A"), np.arange(1))
    result = search.exchange(scorer, 110.0, min_statics=1)
    assert sorted(result.chosen) == [1, 2]             # a 100 s and b 10 s
    assert result.value == pytest.approx(1.0 / 120.0)


def test_candidates_on_a_one_axis_table_need_remounts(tmp_path):
    """A 1-axis table (vertical axis) reaches one "up" per right-angle mounting: the 6 faces; the
    20 askew attitudes each on a fixture of their own (an operator step each); it turns only
    about the vertical (elevation 90)."""
    from station.bench.config import load_config
    from station.design.candidates import FIXTURE_BIT

    path = tmp_path / "one.yaml"
    path.write_text("table:\n  axes: 1\n")
    table = Table(load_config(str(path)))
    cands, chunks, notes, masks = candidate_set(table, rates_dps=(30.0,), revolutions=(1,), dwells_s=(10.0,))
    statics = [(c, m) for c, m in zip(cands, masks) if c.kind == "static"]
    faces = {c.slot for c, m in statics if m < 1 << FIXTURE_BIT}
    assert len(faces) == 6 and all(sum(abs(x) > 0 for x in u) == 1 for u in faces)
    assert len(statics) == 26 == len(directions())
    assert {c.axis[1] for c in cands if c.kind == "rotation"} == {90.0}
    assert mountings_needed([m for _, m in statics]) == 26
    # unattended: the configured mounting only, one up
    path.write_text("table:\n  axes: 1\nrun:\n  operator: false\n")
    cands, *_ = candidate_set(Table(load_config(str(path))), rates_dps=(30.0,), revolutions=(1,), dwells_s=(10.0,))
    assert len([c for c in cands if c.kind == "static"]) == 1


def test_design_is_a_scheme_that_plan_and_run_accept_and_montecarlo_confirms(tmp_path, capsys):
    """The designed scheme (a small candidate set) within its budget as the compiler times it;
    `station plan` and `station run --sim` accept it; `station montecarlo` on it gives the
    predicted 1σ as its Cramér-Rao bound, and the spread of its repeated estimates is that 1σ
    within the χ² spread of a sample std (_ratio_bounds)."""
    # (a 700 s budget: 670 s designed, D-efficiency 2.1 against optimal9 at that duration; its ten
    # dry runs 3.8 s of CPU against 5.4 s for the 900 s budget's 858 s design: the same checks.
    # plan and run in this process (the same code as the command's after the interpreter's start;
    # their processes' exit status is tested in test_cli*.py); design and montecarlo as processes)
    budget = 700
    out = tmp_path / "designed.yaml"
    done = station("design", "--duration", budget, "-o", out, "--compare", "optimal9", "--json", *SMALL)
    assert done.returncode == 0, done.stderr[-3000:]
    report = json.loads(done.stdout)
    assert report["duration_s"] <= budget
    # both kinds searched (the default --statics any), the better by the estimator's fit kept and said
    assert "statics of unknown attitude: criterion" in done.stderr and "statics of table attitude: criterion" in done.stderr
    assert report["static_attitudes"] in ("unknown", "table")
    from station.cli import main

    capsys.readouterr()
    assert main(["plan", "--scheme", str(out)]) == 0
    plan_out = capsys.readouterr().out
    total = float(plan_out.split("total: ")[1].split(" s")[0])
    assert abs(total - report["duration_s"]) < 1.0
    assert main(["run", "--scheme", str(out), "--sim", "--out", str(tmp_path / "cap")]) == 0
    assert (tmp_path / "cap" / "calibration.yaml").exists()
    # a design at optimal9's duration beats optimal9's criterion (D-efficiency above 1)
    assert report["builtins"][0]["efficiency"] > 1.0
    runs = 10       # (the bounds widen with fewer runs: _ratio_bounds)
    mc = station("montecarlo", "--scheme", out, "--runs", runs, "--json")
    assert mc.returncode == 0, mc.stderr[-2000:]
    rows = json.loads(mc.stdout)["parameters"]
    predicted = {p["name"]: p["sigma"] for p in report["designed"]["parameters"]}
    # the same bound: the estimator's fit of the same noiseless capture (attitudes as the
    # estimator chooses them from nine statics on: unknown), 1e-3 relative
    for r in rows:
        assert r["crlb"] == pytest.approx(predicted[r["name"]], rel=1e-3), r["name"]
    low, high = _ratio_bounds(runs, len(rows))
    ratios = np.array([r["std"] / predicted[r["name"]] for r in rows])
    assert np.all((ratios > low) & (ratios < high)), (low, high, dict(zip([r["name"] for r in rows], ratios)))


def test_design_for_the_size_effect_is_confirmed_by_montecarlo(tmp_path):
    """A model with the size effect, worst 1σ of the accelerometers' positions: the design reveals
    the positions (optimal9 at the same duration does not, at its 10 deg/s), and `station
    montecarlo --add accel_lever_arm` on it shows the predicted 1σ (_ratio_bounds)."""
    out = tmp_path / "size.yaml"
    # (--statics table: the kind the default `any` keeps here, by the estimator's fit, searched
    # alone: half the time; the unknown-attitude kind's design at 1500 s, every turn about a
    # vertical axis, was one the estimator refused on some noisy runs, "does not determine the
    # accelerometers", which --verify-runs caught: a finding of 2026-11-27; since the thirteenth
    # session such designs turn about two level axes too, and pass: docs/design.md.  A 700 s
    # budget: 18 scheme entries (32 segments), the positions' 1sigma 0.046 mm, revealed, optimal9
    # at 700 s revealing none; a fit of the montecarlo below takes ~0.6 s of CPU against ~3 s for
    # the 1500 s design's 70 segments: the whole test 10 s of CPU instead of 37, the same checks.
    # Since 2026-11-27 (trimB) a 450 s budget: 434 s designed, the positions' 1sigma 0.083 mm, all
    # six revealed, optimal9 at 434 s revealing none; the ten dry runs 3.9 s of CPU against 5.0 s)
    done = station("design", "--duration", 450, "-o", out, "--add", "accel_lever_arm",
                   "--criterion", "worst:accel_position_*", "--compare", "optimal9", "--json",
                   "--rates", "100,200", "--revolutions", "1", "--dwells", "10,30", "--passes", "2",
                   "--verify-runs", "0", "--statics", "table")
    assert done.returncode == 0, done.stderr[-3000:]
    report = json.loads(done.stdout)
    params = report["designed"]["parameters"]
    positions = [p for p in params if p["name"].startswith("accel_position_")]
    assert positions and all(p["revealed"] for p in positions)
    assert set(report["builtins"][0]["design_reveals_beyond"]) & {p["name"] for p in positions}
    runs = 10       # (the bounds widen with fewer runs: _ratio_bounds)
    mc = station("montecarlo", "--scheme", out, "--runs", runs, "--add", "accel_lever_arm", "--json")
    assert mc.returncode == 0, mc.stderr[-2000:]
    rows = {r["name"]: r for r in json.loads(mc.stdout)["parameters"]}
    low, high = _ratio_bounds(runs, len(positions))
    for p in positions:
        r = rows[p["name"]]
        assert r["crlb"] == pytest.approx(p["sigma"], rel=1e-2), p["name"]
        assert low < r["std"] / p["sigma"] < high, (p["name"], r["std"], p["sigma"], low, high)


@pytest.mark.parametrize("args, words, process", [
    (["--criterion", "worst:no_such_*"], "no parameter of this model matches no_such_*", True),
    (["--criterion", "E"], "--criterion must be D, A or worst", False),
    (["--duration", "100"], "fewer than 6 static attitudes", False),
    (["--add", "no_such_effect"], "unknown effect", False),
    (["--compare", "nonesuch"], "not built-in schemes", False),
])
def test_bad_input_is_one_line_and_status_2(tmp_path, capsys, args, words, process):
    """One case through a process of its own (the command's exit status, no traceback on its
    stderr), the others through station.cli.main in this one (the same code after the
    interpreter's start: 0.4-0.8 s of CPU and 1.5-4 s of wall a process at a load of 16)."""
    base = ["design", "--duration", "1200", "-o", tmp_path / "x.yaml", *SMALL]
    if "--duration" in args:
        base = ["design", "-o", tmp_path / "x.yaml", *SMALL]
    if process:
        done = station(*base, *args)
        status, stderr = done.returncode, done.stderr
    else:
        from station.cli import main

        status, stderr = main([str(a) for a in (*base, *args)]), capsys.readouterr().err
    assert status == 2, stderr
    lines = [ln for ln in stderr.splitlines() if not ln.startswith("design:")]
    assert len(lines) == 1 and words in lines[0], stderr
    assert "Traceback" not in stderr
    assert not (tmp_path / "x.yaml").exists()


def test_choices_copy_the_criteria():
    assert choices.DESIGN_CRITERIA == search.CRITERIA
