"""A quick subset of mutation testing in the suite (issue 30 item 6): mutmut's own mutants of the
honesty-critical lines — the verdict's thresholds and 1-sigma widening, the least-squares
covariance, the VectorNav decoder's CRC and header checks on both of its paths, the compensation's
inverse — each run against small checks here, in this process; the test fails if any survives.

The whole mutation run (benchmarks/mutation.py, docs/testing.md) takes minutes per module; this
costs a few seconds of CPU: mutmut generates the mutants of the named functions only (their source
cut out of the module), they are compiled once into a copy of the module's namespace, and mutmut's
trampolines pick the mutant from $MUTANT_UNDER_TEST, as in a mutmut run.  A mutant is killed when
a check fails or raises.  The checks are shown to pass on the original first; the number of
mutants selected is checked too (a function renamed would otherwise select none)."""
from __future__ import annotations

import ast
import difflib
import io
import re
import types

import numpy as np
import pytest
from mutmut.__main__ import write_all_mutants_to_file
from scipy import stats

from drivers.protocols import vectornav as V
from drivers.protocols import vectornav_binary as VB
from station.estimate import distributions, lsq, verdict
from station.model import compensate


def _mutate(module, names, pattern=None, equivalent=None):
    """(namespace, mutant names) for mutmut's mutants of the top-level functions and classes
    ``names`` of ``module``, on the lines that match ``pattern`` (every other line is given
    mutmut's ``# pragma: no mutate``: generating a mutant costs ~20-80 ms of CPU, rendering and
    parsing its whole function, so only the lines that matter are mutated)."""
    source = open(module.__file__, encoding="utf-8").read()
    tree = ast.parse(source)
    pieces = [ast.get_source_segment(source, node) for node in tree.body
              if isinstance(node, (ast.FunctionDef, ast.ClassDef)) and node.name in names]
    assert len(pieces) == len(names), f"{module.__name__}: not all of {names} found"
    lines = ("from __future__ import annotations\n\n" + "\n\n\n".join(pieces)).splitlines()
    if pattern is not None:
        lines = [line if re.search(pattern, line) or not line.strip() or line.rstrip().endswith(("\\", "("))
                 else line + "  # pragma: no mutate" for line in lines]
    snippet = "\n".join(lines) + "\n"
    out = io.StringIO()
    mutants, _ = write_all_mutants_to_file(out=out, source=snippet, filename=f"{module.__name__}.py")
    code = out.getvalue()
    ns = dict(vars(module))
    exec(compile(code, f"<mutmut's mutants of {module.__name__}>", "exec"), ns)
    if equivalent is not None:          # mutants shown equivalent (the reason with the pattern)
        defs = {node.name: ast.get_source_segment(code, node).splitlines()[1:] for node in ast.walk(ast.parse(code))
                if isinstance(node, ast.FunctionDef) and "__mutmut_" in node.name}
        mutants = [m for m in mutants if not any(
            re.search(equivalent, line) for line in difflib.ndiff(defs[m.rpartition("__mutmut_")[0] + "__mutmut_orig"],
                                                                   defs[m]) if line.startswith("+ "))]
    return ns, sorted(mutants)


def _survivors(monkeypatch, module, ns, names, check):
    monkeypatch.setenv("MUTANT_UNDER_TEST", "")
    check(ns)                               # the checks hold for the original
    alive = []
    for name in names:
        monkeypatch.setenv("MUTANT_UNDER_TEST", f"{module.__name__}.{name}")
        try:
            with np.errstate(all="ignore"):         # a mutant may overflow: that is its failure
                check(ns)
        except Exception:                   # noqa: BLE001 - a failed check or an error: killed
            continue
        alive.append(name)
    monkeypatch.setenv("MUTANT_UNDER_TEST", "")
    return alive


# ------------------------------------------------------------------------------ the verdict

def _verdict_checks(ns):
    """The thresholds (p < 0.001 and reduced chi2 > 1.5; P(below) < 0.001 and reduced chi2 <
    1/1.5) from either side at 400 and at 10 degrees of freedom, the p-values against
    scipy.stats, and the widening of every 1-sigma by sqrt(reduced chi2)."""
    def judged(chi2, dof):
        cal = types.SimpleNamespace(fit={"method": "lsq", "chi2": chi2, "dof": dof},
                                    sigma={"accel_scale_x": 2.0, "gyro_bias_z": 0.5})
        ns["_verdict"](cal)
        return cal
    for reduced, dof, result in ((1.49, 400, "passes"), (1.51, 400, "fails"), (1.6, 10, "passes"),
                                 (4.0, 10, "fails"), (0.67, 400, "passes"), (0.66, 400, "noise overestimated"),
                                 (0.2, 10, "passes"), (0.05, 10, "noise overestimated")):
        cal = judged(reduced * dof, dof)
        v = cal.fit["verdict"]
        assert v["result"] == result, (reduced, dof, v)
        assert v["reduced_chi2"] == pytest.approx(reduced, rel=1e-12) and v["dof"] == dof
        assert v["p_value"] == pytest.approx(stats.chi2.sf(reduced * dof, dof), rel=1e-9)
        widen = np.sqrt(reduced) if result == "fails" else 1.0
        assert cal.sigma == pytest.approx({"accel_scale_x": 2.0 * widen, "gyro_bias_z": 0.5 * widen}, rel=1e-12)
        if result == "fails":
            assert cal.fit["sigma_scale"] == pytest.approx(widen, rel=1e-12)
        else:
            assert "sigma_scale" not in cal.fit
        if result == "noise overestimated":
            assert v["p_below"] == pytest.approx(stats.chi2.cdf(reduced * dof, dof), rel=1e-9)
        if result == "fails":
            assert cal.fit["notes"][-1].startswith(f"the fit fails (reduced chi2 {reduced:.3g}): every 1-sigma")
    # at the thresholds themselves: "above 1.5", "below 1/1.5", "p below P_FAIL" are strict
    assert judged(600.0, 400).fit["verdict"]["result"] == "passes"           # reduced chi2 1.5 exactly
    assert judged(200.0, 300).fit["verdict"]["result"] == "passes"           # 2/3 exactly
    p_fail = ns["P_FAIL"]
    try:
        # (the verdict's own tails, station.estimate.distributions: scipy's to ~1e-15, not to the bit)
        ns["P_FAIL"] = float(distributions.chi2_sf(10, 40.0))    # reduced 4 at 10 dof: p exactly at P_FAIL
        assert judged(40.0, 10).fit["verdict"]["result"] == "passes"
        ns["P_FAIL"] = float(distributions.chi2_cdf(10, 0.5))    # reduced 0.05: P(below) exactly at P_FAIL
        assert judged(0.5, 10).fit["verdict"]["result"] == "passes"
    finally:
        ns["P_FAIL"] = p_fail
    # a pose-only accelerometer block keeps its own 1-sigma when the fit fails
    cal = types.SimpleNamespace(fit={"method": "lsq", "chi2": 4.0 * 400, "dof": 400,
                                     "pose_check": {"written": "pose-only accelerometers", "sigma_scale": 1.25}},
                                sigma={"accel_scale_x": 2.0, "gyro_bias_z": 0.5})
    ns["_verdict"](cal)
    assert cal.sigma == {"accel_scale_x": 2.0, "gyro_bias_z": 1.0}


def test_the_verdicts_thresholds_and_widening(monkeypatch):
    # the widening in verdict._verdict (verdict.chi2_verdict passes its thresholds on) ...
    ns, names = _mutate(verdict, ["chi2_verdict", "_verdict"],
                        r"P_FAIL|REDUCED_CHI2_FAIL|reduced = |scale = |cal.sigma = ")
    assert len(names) >= 8, len(names)
    assert _survivors(monkeypatch, verdict, ns, names, _verdict_checks) == []
    # ... and the rule itself, in distributions.chi2_verdict since the twenty-first session (lsq
    # asks it too, without an import cycle): its mutants reached through the same checks
    plain, _ = _mutate(verdict, ["chi2_verdict", "_verdict"], r"^$")
    rule, rule_names = _mutate(distributions, ["chi2_verdict"],
                               r"p_fail|reduced_fail|chi2_sf|chi2_cdf|reduced = |fails = |overestimated = |result = ")
    assert len(rule_names) >= 12, len(rule_names)
    monkeypatch.setattr(distributions, "chi2_verdict", rule["chi2_verdict"])
    assert _survivors(monkeypatch, distributions, plain, rule_names, _verdict_checks) == []


# ------------------------------------------------------------------------------ the covariance

def _covariance_checks(ns):
    rng = np.random.default_rng(3)
    J = rng.standard_normal((40, 5)) * np.logspace(-4, 4, 5)
    np.testing.assert_allclose(ns["covariance"](J), np.linalg.inv(J.T @ J), rtol=1e-9, atol=0)
    J0 = np.insert(J, 2, 0.0, axis=1)
    cov = ns["covariance"](J0)
    assert np.max(np.abs(cov[2])) < 1e-12 * np.max(np.abs(cov))
    np.testing.assert_allclose(np.delete(np.delete(cov, 2, 0), 2, 1), np.linalg.inv(J.T @ J), rtol=1e-9)
    q, _ = np.linalg.qr(rng.standard_normal((30, 3)))
    for eps, kept, null in ((4e-13, True, True), (2e-14, False, True), (4e-9, True, False), (1e-10, True, True)):
        svd = ns["_ScaledSVD"](np.column_stack([q[:, 0], q[:, 0] + eps * q[:, 1], 3.0 * q[:, 2]]))
        c = svd.covariance()
        assert (c[0, 0] > 1e15) == kept and c[2, 2] == pytest.approx(1 / 9.0, rel=1e-6)
        assert svd.null_columns() == ([0, 1] if null else [])
    aliased = np.column_stack([q[:, 0], q[:, 0] + 4e-13 * q[:, 1], 3.0 * q[:, 2]])
    assert ns["covariance"](aliased)[0, 0] > 1e15 > 1.0 > ns["covariance"](aliased, np.array([1.0, 1.0, 1e-6]))[0, 0]
    svd = ns["_ScaledSVD"](J0, np.r_[np.linalg.norm(J0, axis=0)[:2], 0.0, np.linalg.norm(J0, axis=0)[3:]])
    assert svd.norms[2] == 1.0 and svd.null_columns() == [2]
    # the Gauss-Newton gain read from the SVD (the at-minimum test): |J dx|^2 of the least-squares
    # step dx of J dx = r, as lstsq gives it, also with a null column
    r = rng.standard_normal(40)
    for M in (J, J0):
        dx = np.linalg.lstsq(M, r, rcond=None)[0]
        assert ns["_ScaledSVD"](M).gauss_newton_gain(r) == pytest.approx(float((M @ dx) @ (M @ dx)), rel=1e-9)


def test_the_least_squares_covariance(monkeypatch):
    ns, names = _mutate(lsq, ["_ScaledSVD", "covariance"], r"norms|svd|keep|return|null")
    assert len(names) >= 15, len(names)
    assert _survivors(monkeypatch, lsq, ns, names, _covariance_checks) == []


# ------------------------------------------------------------------------------ the decoder

def _decoder_checks(ns):
    """A frame with one payload byte changed, in a read of 600 frames (the vectorised path) and
    of 20 (frame by frame): never decoded, counted once, every other frame decoded."""
    layout = V.STATION_LAYOUT
    for n in (600, 20):
        t = np.arange(n) * 1_000_000
        data = bytearray(VB.encode_frames(layout, t, np.tile([0.1, 0.2, 9.8], (n, 1)),
                                          np.tile([0.01, -0.02, 0.03], (n, 1)), np.full(n, 25.0)))
        bad = n // 2
        data[bad * layout.frame_length + len(layout.header) + 3] ^= 0x10
        dec = ns["VectorNavDecoder"](layout)
        out = dec.feed(bytes(data))
        assert dec.frames == n - 1 and dec.checksum_errors == 1, (n, dec.frames, dec.checksum_errors)
        np.testing.assert_array_equal(out.t_s, np.delete(t, bad) * 1e-9)
        clean = ns["VectorNavDecoder"](layout)
        assert len(clean.feed(VB.encode_frames(layout, t, np.zeros((n, 3)), np.zeros((n, 3)), np.zeros(n)))) == n
        assert clean.checksum_errors == 0 and clean.resyncs == 0


def test_the_vectornav_decoders_checks_on_both_paths(monkeypatch):
    ns, names = _mutate(VB, ["VectorNavDecoder"], r"crc|VECTORISE_FROM|checksum_errors|ok |return k|return j")
    assert len(names) >= 8, len(names)
    assert _survivors(monkeypatch, VB, ns, names, _decoder_checks) == []


# ------------------------------------------------------------------------------ compensation

def _compensation_checks(ns):
    """Raw samples made from a known f, w by the forward model written out here, compensated
    back, with and without a small effect term."""
    rng = np.random.default_rng(1)
    Ma, Mg = np.eye(3) + 0.02 * rng.standard_normal((3, 3)), np.eye(3) + 0.02 * rng.standard_normal((3, 3))
    fa, fg = 9.80665, 180.0 / np.pi
    comp = {"raw_units": {"accel": "g", "gyro": "rad/s"}, "accel_matrix": fa * np.linalg.inv(Ma),
            "gyro_matrix": fg * np.linalg.inv(Mg), "accel_bias": np.array([0.01, -0.02, 0.03]),
            "gyro_bias": np.array([0.001, 0.002, -0.003])}
    t = np.arange(20) * 0.01
    f = np.array([1.0, -2.0, 9.0]) + 0.5 * rng.standard_normal((20, 3))
    w = np.array([5.0, -20.0, 90.0]) + 0.5 * rng.standard_normal((20, 3))

    class Square:
        def compensate_time(self, x, t):
            return t

        def accel(self, x, ctx):
            return 1e-4 * ctx.f_p ** 2 + 1e-3 * ctx.f_p @ (ctx.accel_matrix - np.eye(3)).T

        def gyro(self, x, ctx):
            return 1e-5 * ctx.w_p ** 2 + 1e-3 * ctx.w_p @ (ctx.gyro_matrix - np.eye(3)).T
    assert ns["factors"]({"raw_units": {"accel": "raw", "gyro": "raw"}}) == (1.0, 1.0)
    assert ns["factors"]({"raw_units": {}}) == (1.0, 1.0)
    da_true = 1e-4 * f ** 2 + 1e-3 * f @ (Ma - np.eye(3)).T
    dw_true = 1e-5 * w ** 2 + 1e-3 * w @ (Mg - np.eye(3)).T
    for effects, da, dw in (([], 0.0, 0.0), ([(Square(), None)], da_true, dw_true)):
        ar = (f @ Ma.T + da) / fa + comp["accel_bias"]
        gr = (w @ Mg.T + dw) / fg + comp["gyro_bias"]
        _, f2, w2 = ns["compensate_with_effects"](comp, effects, t, ar, gr)
        np.testing.assert_allclose(f2, f, rtol=1e-10, atol=1e-9)
        np.testing.assert_allclose(w2, w, rtol=1e-10, atol=1e-8)


def test_the_compensation_inverts_the_forward_model(monkeypatch):
    # np.asarray(raw, None) is np.asarray(raw, float) for the samples apply reads (floats, or integer
    # counts made float by the bias subtracted next): equivalent
    ns, names = _mutate(compensate, ["factors", "compensate_with_effects"], r"_bias|inv\(|@|factor\(",
                        equivalent=r"np\.asarray\((accel|gyro)_raw,( None)?\)")
    assert len(names) >= 15, len(names)
    assert _survivors(monkeypatch, compensate, ns, names, _compensation_checks) == []
