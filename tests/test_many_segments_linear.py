"""estimate and diagnose linear in the segments (issue 27 item 4): each step that was quadratic
(a rows x rows matrix, a projection per candidate time, a set per boundary, an N x N SVD factor)
is now linear, and gives what the quadratic step gave.  Times and memory are measured in
benchmarks/perf_many_segments.py (whole processes), not here; these tests check the numbers.

Tolerances: the linear bias-step profile and the per-candidate projections are the same algebra
in another order (sums over segments instead of one projection per candidate): they differ by
rounding, amplified by the condition of the projected 6 x 6 Gram matrix (~1e4 here), so 1e-7 of
the largest score (one score is ~1 to 1e3 chi2; 1e-7 of it is far below the 0.01 that would move a
located step).  Bincount means and the indicator-matrix means add the same numbers in another
order: 1e-12 relative.  The sparse Jacobian built as CSC is the same matrix as the dense one
entry for entry (the same values put in other containers): exactly equal."""
import subprocess
import sys

import numpy as np
import pytest

from station.estimate import lsq, profile
from station.io.scheme import load_scheme
from station.model import bias_step
from station.model.bias_step import BiasStep
from station.model.table_encoder_scale import _segment_means
from station.simulate import dryrun


@pytest.fixture(scope="module")
def summaries():
    truth = dryrun.load_truth(None, 0)
    truth.sample_rate_hz = 50.0
    return lsq.summarise(dryrun.simulate_capture(load_scheme("optimal9"), truth, 11))


def test_the_linear_bias_step_profile_gives_every_candidates_projection(summaries, monkeypatch):
    monkeypatch.setattr(lsq, "LARGE_MODEL", 0)          # optimal9 on the large model's path
    result = lsq.fit(summaries)
    assert result.model.is_large
    taken = []
    linear_path = profile._bias_like_profile_linear
    monkeypatch.setattr(profile, "_bias_like_profile_linear", lambda *a: taken.append(linear_path(*a)) or taken[-1])
    linear = profile._bias_like_profile(result, BiasStep())
    assert taken and taken[0] is not None                 # the linear path, not its fallback
    monkeypatch.setattr(profile, "LINEAR_PROFILE_COLUMNS", -1)     # the candidates one at a time
    one_by_one = profile._bias_like_profile(result, BiasStep())
    assert len(linear) == len(one_by_one) >= 5
    assert [p[:3] for p in linear] == [p[:3] for p in one_by_one]
    a, b = (np.array([p[3] for p in prof]) for prof in (linear, one_by_one))
    assert np.max(np.abs(a - b)) <= 1e-7 * np.max(np.abs(b))
    assert np.argmax(a) == np.argmax(b)


def test_a_large_models_sparse_jacobian_is_the_dense_one_also_in_batches(summaries, monkeypatch):
    monkeypatch.setattr(lsq, "LARGE_MODEL", 0)
    model = lsq.Model(summaries, [])
    x = model.x0 + 1e-4
    dense = model.jacobian(x)
    sparse = model.sparse_jacobian(x)
    assert sparse.format == "csr" and sparse.has_sorted_indices
    assert np.array_equal(sparse.toarray(), dense)
    monkeypatch.setattr(lsq, "BATCH_VALUES", 1)        # one perturbed vector a batch
    batched = lsq.Model(summaries, []).sparse_jacobian(x)
    assert np.array_equal(batched.toarray(), dense)


def _indicator_means(index, f):
    same = (index[:, None] == index[None, :]).astype(float)
    return (same / same.sum(axis=1, keepdims=True)) @ f


@pytest.mark.parametrize("complex_", [False, True])
def test_segment_means_by_bincount_are_the_indicator_matrixs(complex_):
    rng = np.random.default_rng(3)
    index = rng.integers(0, 9, 200).astype(float)
    f = rng.normal(size=(200, 3)) + (1j * rng.normal(size=(200, 3)) if complex_ else 0.0)
    got = _segment_means(index, f)
    assert got.dtype == f.dtype
    np.testing.assert_allclose(got, _indicator_means(index, f), rtol=1e-12, atol=1e-14)
    index[:5] = np.nan                  # a segment not known: NaN, as the indicator matrix gave
    got = _segment_means(index, f)
    assert np.all(np.isnan(got[:5]))
    np.testing.assert_allclose(got[5:], _indicator_means(index[5:], f[5:]), rtol=1e-12, atol=1e-14)


class _Seg:
    def __init__(self, name, t):
        self.name, self.t_mid_s, self.duration_s = name, t, 1.0


class _Summaries:
    def __init__(self, kinds):
        self.statics = [_Seg(f"s{i}", 2.0 * i) for i, k in enumerate(kinds) if k]
        self.rotations = [_Seg(f"r{i}", 2.0 * i) for i, k in enumerate(kinds) if not k]


def _candidates_with_sets(kinds):
    """candidate_times as it was: a set of each side at every boundary."""
    static = list(kinds)
    m = bias_step.MIN_SIDE
    return [k for k in range(m, len(static) - m + 1)
            if not (len(set(static[:k])) == 1 and len(set(static[k:])) == 1 and static[0] != static[-1])]


def test_the_bias_steps_candidate_times_are_those_the_sets_gave():
    rng = np.random.default_rng(5)
    cases = [[True] * 6 + [False] * 4, [False] * 3 + [True] * 7, [True] * 8, [True, False] * 5, []]
    cases += [list(rng.integers(0, 2, rng.integers(1, 16)).astype(bool)) for _ in range(300)]
    for kinds in cases:
        got = BiasStep.candidate_times(_Summaries(kinds))
        want = _candidates_with_sets(kinds) if len(kinds) >= 2 * bias_step.MIN_SIDE else []
        assert [b for _, _, b in got] == [("s" if kinds[k] else "r") + str(k) for k in want], kinds


def test_the_ellipsoid_of_many_statics_takes_no_n_by_n_factor(monkeypatch):
    from station.estimate import zhang2010

    seen = []
    svd = np.linalg.svd

    def spy(a, full_matrices=True, **kw):
        seen.append((a.shape, full_matrices))
        return svd(a, full_matrices=full_matrices, **kw)

    monkeypatch.setattr(np.linalg, "svd", spy)
    rng = np.random.default_rng(2)
    up = rng.normal(size=(5000, 3))
    up /= np.linalg.norm(up, axis=1, keepdims=True)
    L, b = zhang2010.fit_accelerometers(9.8 * up * 1.01 + 0.05, 9.8)
    np.testing.assert_allclose(b, 0.05 * np.ones(3), atol=1e-9)
    assert seen and all(not full for shape, full in seen if shape[0] > shape[1])


@pytest.mark.parametrize("command", ["estimate", "diagnose"])
def test_running_out_of_memory_is_one_line_and_exit_2(tmp_path, command):
    """A MemoryError (numpy's, from an allocation of 10^16 doubles, as an estimate far too large
    for the machine raised) is one line naming the command, not a traceback."""
    code = ("import sys, numpy as np; from station import api; from station.cli import console_main\n"
            f"def big(*a, **k): return np.empty((10**8, 10**8))\n"
            f"api.{command} = big\n"
            f"sys.argv = ['station', '{command}', {str(tmp_path)!r}]; sys.exit(console_main())")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 2, r.stderr
    assert "Traceback" not in r.stderr
    lines = [line for line in r.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith(f"station {command}: out of memory"), r.stderr
