"""Terms outside the library: a search over a dictionary of physical regressors.

When no effect of the library explains the residuals, each sensor axis may still carry a term
in a simple function of what the IMU experienced.  The dictionary, per output axis (the three
accelerometers in m/s^2 and the three gyros in deg/s; f the specific force in m/s^2 and w the
rate in deg/s, both in frame p; wd the table's angular acceleration in deg/s^2):

  f_j, f_j f_k, |f_j|,  w_j, w_j^2, w_j |w_j|, w_j w_k, w_j f_k,  wd_j,
  temperature (T - T_ref, deg C) and its rate (deg C/s), time within the run (s), segment index.

Every term enters the model as one coefficient (output unit per regressor unit).  All the score
tests are taken at once from the Jacobian columns of one bank of terms (they are linear in their
coefficients), with the over-dispersion correction and a Holm correction over the whole
dictionary; the most significant is kept, the others are tested again with it projected out
(forward selection), and at most MAX_TERMS are proposed.  The proposal is then refitted as a
real effect (``TermsEffect``) so that its coefficients get a 1-sigma, and it is checked out of
sample like any other effect (station.diagnose.auto.judge).  ``plugin_source`` writes it as a
ready-to-edit plugin file (docs/effects.md).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from station.core.errors import UserError
from station.diagnose.core import ALPHA, chi2_sf, outside_model
from station.estimate import lsq
from station.model.effect import Effect, Param
from station.model.raw_counts import counts_per_unit, in_capture_units

MAX_TERMS = 6
AX = "xyz"
SENSORS = (("accel", "accelerometer", "m/s^2"), ("gyro", "gyro", "deg/s"))


@dataclass(frozen=True)
class Regressor:
    key: str          # short name, used in parameter names
    text: str         # in words
    unit: str         # its unit
    code: str         # a numpy expression of f, w, wd, T, Tr, t, seg (each (N,3) or (N,))


def dictionary() -> list[Regressor]:
    out = []
    for j in range(3):
        out.append(Regressor(f"f{AX[j]}", f"f_{AX[j]}", "m/s^2", f"f[:, {j}]"))
    for j in range(3):
        for k in range(j, 3):
            out.append(Regressor(f"f{AX[j]}f{AX[k]}", f"f_{AX[j]}·f_{AX[k]}", "(m/s^2)^2", f"f[:, {j}] * f[:, {k}]"))
    for j in range(3):
        out.append(Regressor(f"absf{AX[j]}", f"|f_{AX[j]}|", "m/s^2", f"np.abs(f[:, {j}])"))
    for j in range(3):
        out.append(Regressor(f"w{AX[j]}", f"w_{AX[j]}", "deg/s", f"w[:, {j}]"))
        out.append(Regressor(f"w{AX[j]}2", f"w_{AX[j]}²", "(deg/s)^2", f"w[:, {j}] ** 2"))
        out.append(Regressor(f"w{AX[j]}absw{AX[j]}", f"w_{AX[j]}·|w_{AX[j]}|", "(deg/s)^2",
                             f"w[:, {j}] * np.abs(w[:, {j}])"))
        out.append(Regressor(f"wd{AX[j]}", f"dw_{AX[j]}/dt", "deg/s^2", f"wd[:, {j}]"))
    for j in range(3):
        for k in range(j + 1, 3):
            out.append(Regressor(f"w{AX[j]}w{AX[k]}", f"w_{AX[j]}·w_{AX[k]}", "(deg/s)^2", f"w[:, {j}] * w[:, {k}]"))
    for j in range(3):
        for k in range(3):
            out.append(Regressor(f"w{AX[j]}f{AX[k]}", f"w_{AX[j]}·f_{AX[k]}", "(deg/s)(m/s^2)", f"w[:, {j}] * f[:, {k}]"))
    out += [Regressor("temp", "temperature (T - T_ref)", "degC", "T"),
            Regressor("temprate", "temperature rate", "degC/s", "Tr"),
            Regressor("time", "time within the run", "s", "t"),
            Regressor("segment", "segment index", "1", "seg")]
    return out


@dataclass(frozen=True)
class Term:
    sensor: str       # "accel" or "gyro"
    axis: int         # output axis 0..2
    regressor: Regressor

    @property
    def name(self) -> str:
        return f"term_{self.sensor}_{AX[self.axis]}_{self.regressor.key}"

    @property
    def out_unit(self) -> str:
        return "m/s^2" if self.sensor == "accel" else "deg/s"

    @property
    def unit(self) -> str:
        return f"{self.out_unit} per {self.regressor.unit}"

    def words(self, value: float, sigma: float | None = None) -> str:
        who = "accelerometer" if self.sensor == "accel" else "gyro"
        spread = "" if sigma is None else f" ± {sigma:.2g}"
        return (f"{AX[self.axis]} {who}: {value:+.3g}{spread} {self.out_unit} per {self.regressor.unit} "
                f"in {self.regressor.text}")


def _variables(ctx, reference_c: float) -> dict:
    n = len(ctx.f_p)
    temp = ctx.temp_c - reference_c
    return {"np": np, "f": ctx.f_p, "w": ctx.w_p, "wd": np.degrees(ctx.wdot_table),
            "T": np.where(np.isfinite(temp), temp, 0.0),
            "Tr": np.nan_to_num(ctx.column("temp_rate_c_per_s")),
            "t": np.nan_to_num(ctx.column("t_s")), "seg": np.nan_to_num(ctx.column("segment_index")),
            "_n": n}


class TermsEffect(Effect):
    """Terms of the dictionary as one effect: output axis += c * regressor."""

    id = "discovered_terms"
    title = "Terms found outside the library"
    physics = "Terms found by the regressor search of station diagnose; their physics is for you to name."
    signature_variable = ""
    state_fields = ("spec", "reference_c")

    def __init__(self, terms: list[Term] | None = None, reference_c: float = 0.0):
        self.terms = list(terms or [])
        self.reference_c = reference_c
        self.spec = [[t.sensor, t.axis, t.regressor.key] for t in self.terms]
        self._compile()

    def restore(self, state):
        super().restore(state)
        lookup = {r.key: r for r in dictionary()}
        self.terms = [Term(s, int(a), lookup[k]) for s, a, k in self.spec]
        self._compile()

    def _compile(self):
        self._code = {t.regressor.key: compile(t.regressor.code, "<term>", "eval") for t in self.terms}
        self.term = "; ".join(f"{t.sensor}_{AX[t.axis]} += c * {t.regressor.text}" for t in self.terms)
        self.needs = tuple(sorted({"temperature" for t in self.terms if t.regressor.key in ("temp", "temprate")}
                                  | {"time" for t in self.terms if t.regressor.key.startswith("wd")}))

    @property
    def params(self):
        return tuple(Param(t.name, t.unit, 1.0, float("inf"), float("inf")) for t in self.terms)

    def _term(self, x, ctx, sensor):
        out = np.zeros_like(ctx.f_p)
        v = _variables(ctx, self.reference_c)
        values = {}
        for k, t in enumerate(self.terms):
            if t.sensor != sensor or x[k] == 0.0:
                continue
            key = t.regressor.key
            if key not in values:
                values[key] = np.broadcast_to(eval(self._code[key], {"__builtins__": {}}, v), (len(out),))
            out[:, t.axis] += x[k] * values[key]
        return out

    def accel(self, x, ctx):
        return self._term(x, ctx, "accel") if any(t.sensor == "accel" for t in self.terms) else None

    def gyro(self, x, ctx):
        return self._term(x, ctx, "gyro") if any(t.sensor == "gyro" for t in self.terms) else None


@dataclass
class Found:
    term: Term
    chi2_drop: float          # predicted, nominal noise, given the terms found before it
    p_value: float            # Holm-corrected over the dictionary, over-dispersion-corrected
    value: float              # one-step estimate, output unit per regressor unit
    sigma: float


def _reference_c(s) -> float:
    temps = [st.temp_c for st in s.statics if st.temp_c is not None]
    return float(np.mean(temps)) if temps else 0.0


def searchable(s) -> tuple:
    """The SENSORS whose terms can be sized on this capture: not a raw gyro's without a nominal
    scale or a rotation with an encoder angle, nothing of a raw accelerometer's without a
    nominal scale or statics (station.model.raw_counts)."""
    try:
        _, n_g = counts_per_unit(s)
    except UserError:
        return ()
    return tuple(x for x in SENSORS if x[0] != "gyro" or n_g is not None)


def search(result, max_terms: int = MAX_TERMS) -> list[Found]:
    """Forward selection over the dictionary at the current fit (linearised score tests), on
    the sensors whose terms can be sized (``searchable``)."""
    model = result.model
    s = model.s
    reference = _reference_c(s)
    candidates = [Term(sensor, axis, reg) for sensor, _, _ in searchable(s) for axis in range(3) for reg in dictionary()]
    if not candidates:
        return []
    bank = in_capture_units(TermsEffect)(candidates, reference)      # counts on a raw capture
    extended = lsq.Model(s, [*model.effects, bank], model.attitudes, like=model)
    extended.priors = dict(model.priors)
    n = model.layout.size
    x = np.concatenate([result.x, np.zeros(len(candidates))])
    r = extended.residuals(x)
    cols = list(range(n, n + len(candidates)))
    Jc = extended.jacobian_columns(x, cols)             # d(residual)/d(coefficient)
    Jp = outside_model(result, Jc)
    m = len(candidates)
    data = model.data_rows if hasattr(model, "data_rows") else np.ones(len(r), bool)
    found: list[Found] = []
    chosen = []
    for _ in range(max_terms):
        # over-dispersion of what is left (the misfit shrinks as terms are taken)
        dof = result.dof - len(found)
        rss = float(r[data] @ r[data]) if len(data) == len(r) else float(r @ r)
        phi = max(rss / dof, 1.0) if dof > 0 and chi2_sf(rss, dof) < ALPHA / 10 else 1.0
        norms2 = np.einsum("ij,ij->j", Jp, Jp)
        usable = norms2 > 1e-12 * max(norms2.max(initial=0.0), 1e-300)
        g = Jp.T @ r
        lm = np.where(usable, g**2 / np.where(usable, norms2, 1.0), 0.0)
        lm[chosen] = 0.0
        k = int(np.argmax(lm))
        if lm[k] <= 0:
            break
        # Holm over the family: the step's rank among m - len(found) untested terms
        p = min(1.0, chi2_sf(lm[k] / phi, 1) * (m - len(found)))
        if p >= ALPHA:
            break
        c = -g[k] / norms2[k]
        found.append(Found(candidates[k], float(lm[k]), p, float(c), float(np.sqrt(phi / norms2[k]))))
        chosen.append(k)
        q = Jp[:, k] / np.sqrt(norms2[k])
        r = r - q * (q @ r)
        Jp = Jp - np.outer(q, q @ Jp)
    return found


def refit(summaries, result, found: list[Found]):
    """The model with the found terms added as one effect, refitted (values with 1-sigma)."""
    effect = in_capture_units(TermsEffect)([f.term for f in found], _reference_c(summaries))
    return lsq.fit(summaries, [*result.model.effects, effect], result.model.attitudes, like=result.model), effect


def plugin_source(effect: TermsEffect, values, sigmas, class_name: str = "DiscoveredTerms") -> str:
    """A ready-to-edit effect plugin with these terms (their fitted values in comments)."""
    lines = [
        f'"""Terms found by `station diagnose`: edit the id, the names and the physics, then',
        f"add it with  station estimate CAPTURE --add THIS_FILE.py:{class_name}",
        f"and compensate with  station apply CAL.yaml IN.csv -o OUT.csv --plugin THIS_FILE.py:{class_name}",
        "",
        "Found (value ± 1σ at the fit that proposed them):",
    ]
    for t, v, sg in zip(effect.terms, values, sigmas):
        lines.append(f"  {t.words(v, sg)}")
    lines += ['"""', "import numpy as np", "", "from station.model.effect import Effect, Param", "", "",
              f"class {class_name}(Effect):",
              '    id = "discovered_terms"          # an identifier of your choice',
              '    title = "Terms found outside the library"',
              '    physics = "Name the physics here."',
              f"    term = {effect.term!r}",
              '    excited_by = "the segments that revealed them"',
              '    magnitudes = "see the values above"',
              '    signature = "the residual pattern diagnose reported"',
              f"    needs = {tuple(effect.needs)!r}",
              f"    REFERENCE_C = {effect.reference_c!r}    # temperature reference, deg C", "",
              "    @property", "    def params(self):",
              "        # name, unit, reported = internal * scale, typical size, largest plausible size",
              "        return ("]
    for t, v in zip(effect.terms, values):
        typical = max(abs(float(v)), 1e-300)
        lines.append(f'            Param("{t.name}", "{t.unit}", 1.0, {typical:.3g}, {100 * typical:.3g}),')
    lines += ["        )", ""]
    for sensor in ("accel", "gyro"):
        idx = [k for k, t in enumerate(effect.terms) if t.sensor == sensor]
        if not idx:
            continue
        lines += [f"    def {sensor}(self, x, ctx):",
                  "        f, w = ctx.f_p, ctx.w_p                    # m/s^2 and deg/s, frame p",
                  "        wd = np.degrees(ctx.wdot_table)           # deg/s^2",
                  "        T = np.nan_to_num(ctx.temp_c - self.REFERENCE_C)",
                  '        Tr = np.nan_to_num(ctx.column("temp_rate_c_per_s"))',
                  '        t = np.nan_to_num(ctx.column("t_s"))',
                  '        seg = np.nan_to_num(ctx.column("segment_index"))',
                  "        out = np.zeros_like(f)"]
        for k in idx:
            t = effect.terms[k]
            lines.append(f"        out[:, {t.axis}] += x[{k}] * ({t.regressor.code})    # {t.regressor.text}")
        lines += ["        return out", ""]
    return "\n".join(lines).rstrip() + "\n"


@dataclass
class Proposal:
    """Terms found outside the library, refitted, and checked out of sample."""
    found: list               # Found, in the order they were selected
    effect: TermsEffect
    values: list              # refitted, output unit per regressor unit
    sigmas: list
    chi2_before: float
    chi2_after: float
    reduced_after: float
    holdout_before: float
    holdout_after: float
    kept: bool                # passes the checks an added effect must pass (auto.judge)
    reason: str
    redundant: list = field(default_factory=list)   # (effect, why): added before, not needed with the terms

    def lines(self) -> list[str]:
        return [t.words(v, sg) for t, v, sg in zip(self.effect.terms, self.values, self.sigmas)]


def propose(diagnosis, summaries) -> Proposal | None:
    """Search, refit, judge; None when no term of the dictionary is significant."""
    from station.diagnose.core import diagnose
    from station.diagnose.holdout import judge, leave_one_segment_out

    result = diagnosis.result
    found = search(result)
    if not found:
        return None
    after_result, effect = refit(summaries, result, found)
    names, values, units_, cov = lsq.reported(after_result, "m/s^2", "deg/s")
    own = {t.name for t in effect.terms}
    idx = [i for i, n in enumerate(names) if n in own]
    after = diagnose(after_result, exclude=[e for e in _all_ids()])
    ok, reason, _, cv_b, cv_a = judge(diagnosis, after, leave_one_segment_out(result),
                                      leave_one_segment_out(after_result))
    return Proposal(found, effect, [float(values[i]) for i in idx], [float(np.sqrt(cov[i, i])) for i in idx],
                    diagnosis.chi2, after.chi2, after.reduced_chi2, cv_b, cv_a, ok, reason)


def _all_ids():
    from station.model.registry import EffectRegistry

    return EffectRegistry().ids()
