"""Terms outside the library: a search over a dictionary of physical regressors.

When no effect of the library explains the residuals, each sensor axis may still carry a term
in a simple function of what the IMU experienced.  The dictionary, per output axis (the three
accelerometers in m/s^2 and the three gyros in deg/s; f the specific force in m/s^2 and w the
rate in deg/s, both in frame p; wd the table's angular acceleration in deg/s^2):

  accelerometers: f_j, f_j f_k, |f_j|, f_j^3, f_j T, f_j T^2;
  gyros: w_j, w_j^2, w_j |w_j|, w_j^3, w_j w_k, w_j f_k, wd_j, w_j T, w_j T^2, f_j, f_j f_k;
  both: T, T^2 (T = T - T_ref, deg C), dT/dt (deg C/s), time within the run (s), a step at each
  of the first segment boundaries.

A column is tested when part of it lies outside the fitted model, judged against its own length
(the regressors' units span twenty orders of magnitude).  Terms that leave the fit failing are
proposed but not carried into the calibration (they may stand in for what is still missing).

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
from station.diagnose.core import ALPHA, chi2_sf, fit_fails, outside_model
from station.estimate import lsq
from station.model.effect import Effect, Param
from station.model.raw_counts import counts_per_unit, in_capture_units

MAX_TERMS = 9
AX = "xyz"
SENSORS = (("accel", "accelerometer", "m/s^2"), ("gyro", "gyro", "deg/s"))
G0 = 9.80665
MAX_STEPS = 40            # steps at segment boundaries in the dictionary (the first boundaries)
ALIAS_COS = 0.95          # two terms whose columns (outside the model) are this alike: aliases
OUTSIDE_SHARE2 = 1e-8     # a column whose part outside the model is below 1e-4 of its length (squared: 1e-8)
                          # is the model's own (rounding of the projection is ~1e-8 of it at worst)


@dataclass(frozen=True)
class Regressor:
    key: str          # short name, used in parameter names
    text: str         # in words
    unit: str         # its unit
    code: str         # a numpy expression of f, w, wd, T, Tr, t, seg (each (N,3) or (N,))
    family: str = ""  # f, f2, ff, absf, f3, fT, w, w2, wabsw, w3, ww, wf, wT, wd, T, T2, Tr, t, step
    j: int = -1       # the axis (or first axis) of the variable it is made of
    k: int = -1       # the second axis of a product


def _f(j):
    return f"f_{AX[j]}"


def _w(j):
    return f"w_{AX[j]}"


def _accel_regressors() -> list[Regressor]:
    """The accelerometer's: functions of the specific force f (m/s^2) and the temperature."""
    out = [Regressor(f"f{AX[j]}", _f(j), "m/s^2", f"f[:, {j}]", "f", j) for j in range(3)]
    for j in range(3):
        for k in range(j, 3):
            out.append(Regressor(f"f{AX[j]}f{AX[k]}", f"{_f(j)}·{_f(k)}", "(m/s^2)^2",
                                 f"f[:, {j}] * f[:, {k}]", "f2" if j == k else "ff", j, k))
    out += [Regressor(f"absf{AX[j]}", f"|{_f(j)}|", "m/s^2", f"np.abs(f[:, {j}])", "absf", j) for j in range(3)]
    out += [Regressor(f"f{AX[j]}3", f"{_f(j)}³", "(m/s^2)^3", f"f[:, {j}] ** 3", "f3", j) for j in range(3)]
    out += [Regressor(f"f{AX[j]}T", f"{_f(j)}·(T - T_ref)", "(m/s^2) degC", f"f[:, {j}] * T", "fT", j)
            for j in range(3)]
    out += [Regressor(f"f{AX[j]}T2", f"{_f(j)}·(T - T_ref)²", "(m/s^2) degC^2", f"f[:, {j}] * T ** 2", "fT2", j)
            for j in range(3)]
    return out


def _gyro_regressors() -> list[Regressor]:
    """The gyro's: functions of the rate w (deg/s), the specific force and the temperature."""
    out = []
    for j in range(3):
        out += [Regressor(f"w{AX[j]}", _w(j), "deg/s", f"w[:, {j}]", "w", j),
                Regressor(f"w{AX[j]}2", f"{_w(j)}²", "(deg/s)^2", f"w[:, {j}] ** 2", "w2", j),
                Regressor(f"w{AX[j]}absw{AX[j]}", f"{_w(j)}·|{_w(j)}|", "(deg/s)^2",
                          f"w[:, {j}] * np.abs(w[:, {j}])", "wabsw", j),
                Regressor(f"w{AX[j]}3", f"{_w(j)}³", "(deg/s)^3", f"w[:, {j}] ** 3", "w3", j),
                Regressor(f"wd{AX[j]}", f"d{_w(j)}/dt", "deg/s^2", f"wd[:, {j}]", "wd", j),
                Regressor(f"w{AX[j]}T", f"{_w(j)}·(T - T_ref)", "(deg/s) degC", f"w[:, {j}] * T", "wT", j),
                Regressor(f"w{AX[j]}T2", f"{_w(j)}·(T - T_ref)²", "(deg/s) degC^2", f"w[:, {j}] * T ** 2", "wT2", j)]
    for j in range(3):
        for k in range(j + 1, 3):
            out.append(Regressor(f"w{AX[j]}w{AX[k]}", f"{_w(j)}·{_w(k)}", "(deg/s)^2",
                                 f"w[:, {j}] * w[:, {k}]", "ww", j, k))
    for j in range(3):
        for k in range(3):
            out.append(Regressor(f"w{AX[j]}f{AX[k]}", f"{_w(j)}·{_f(k)}", "(deg/s)(m/s^2)",
                                 f"w[:, {j}] * f[:, {k}]", "wf", j, k))
    out += [Regressor(f"f{AX[j]}", _f(j), "m/s^2", f"f[:, {j}]", "f", j) for j in range(3)]
    for j in range(3):
        for k in range(j, 3):
            out.append(Regressor(f"f{AX[j]}f{AX[k]}", f"{_f(j)}·{_f(k)}", "(m/s^2)^2",
                                 f"f[:, {j}] * f[:, {k}]", "f2" if j == k else "ff", j, k))
    return out


def _shared_regressors(n_segments: int = 0) -> list[Regressor]:
    out = [Regressor("temp", "temperature (T - T_ref)", "degC", "T", "T"),
           Regressor("T2", "(T - T_ref)²", "degC^2", "T ** 2", "T2"),
           Regressor("temprate", "temperature rate dT/dt", "degC/s", "Tr", "Tr"),
           Regressor("time", "time within the run", "s", "t", "t")]
    out += [step_regressor(b) for b in range(1, min(n_segments, MAX_STEPS + 1))]
    return out


def step_regressor(b: int) -> Regressor:
    """1 from the segment of index b on (a step at the boundary before it), 0 before."""
    return Regressor(f"step{b}", f"a step at the start of segment {b}", "1", f"(seg >= {b}) * 1.0", "step", b)


def dictionary(sensor: str | None = None, n_segments: int = 0) -> list[Regressor]:
    """The regressors of ``sensor`` ("accel": functions of f and T; "gyro": of w, f and T; both
    also of time and steps at the first ``n_segments`` - 1 segment boundaries); None: every
    regressor either sensor has (for looking keys up)."""
    if sensor == "accel":
        return _accel_regressors() + _shared_regressors(n_segments)
    if sensor == "gyro":
        return _gyro_regressors() + _shared_regressors(n_segments)
    seen = {}
    for r in _accel_regressors() + _gyro_regressors() + _shared_regressors(n_segments):
        seen.setdefault(r.key, r)
    return list(seen.values())


def regressor(key: str) -> Regressor:
    if key.startswith("step"):
        return step_regressor(int(key[4:]))
    return {r.key: r for r in dictionary()}[key]


# what a term means, per family: (words with {i} the output axis and {j}, {k} the variable's axes,
# when the variable is the output's own axis; when it is another axis; natural unit; factor:
# natural value = coefficient (output unit per regressor unit) * factor)
_UG = 1e-6 * G0                      # m/s^2 per µg
PHYSICS = {
    ("accel", "f"): ("its scale factor (in the base model)", "its misalignment towards {j} (in the base model)", "ppm", 1e6),
    ("accel", "f2"): ("a second-order nonlinearity (K2)", "a term in the square of the force along {j}", "ug/g^2", G0 * 1e6),
    ("accel", "ff"): ("cross-axis coupling (K_{i}{o}, its input times the force along {o})",
                      "a term in the product of the forces along {j} and {k}", "ug/g^2", G0 * 1e6),
    ("accel", "absf"): ("a scale-factor asymmetry (|input|)", "a term in |f_{j}|", "ppm", 1e6),
    ("accel", "f3"): ("a third-order nonlinearity (K3)", "a term in the cube of the force along {j}", "ug/g^3", G0**2 * 1e6),
    ("accel", "fT"): ("its scale factor changes with temperature", "its misalignment towards {j} changes with temperature",
                      "ppm/degC", 1e6),
    ("accel", "fT2"): ("its scale factor changes with the square of the temperature",
                       "its misalignment towards {j} changes with the square of the temperature", "ppm/degC^2", 1e6),
    ("gyro", "w"): ("its scale factor (in the base model)", "its misalignment towards {j} (in the base model)", "ppm", 1e6),
    ("gyro", "w2"): ("its scale changes with the rate, even in its sign (w²)", "a term in the square of the rate about {j}",
                     "ppm/(deg/s)", 1e6),
    ("gyro", "wabsw"): ("its scale changes with the size of the rate, odd in its sign (w·|w|)",
                        "a term in w_{j}·|w_{j}|", "ppm/(deg/s)", 1e6),
    ("gyro", "w3"): ("a cubic rate nonlinearity (w³)", "a term in the cube of the rate about {j}", "ppm/(deg/s)^2", 1e6),
    ("gyro", "ww"): ("a term in the product of the rates about {j} and {k}", "a term in the product of the rates about {j} and {k}",
                     "ppm/(deg/s)", 1e6),
    ("gyro", "wf"): ("its scale changes with the specific force along {k}", "a term in the rate about {j} times the force along {k}",
                     "ppm/g", G0 * 1e6),
    ("gyro", "wd"): ("it responds to the angular acceleration (a time lag)", "it responds to the angular acceleration about {j}",
                     "ms", 1e3),
    ("gyro", "wT"): ("its scale factor changes with temperature", "its misalignment towards {j} changes with temperature",
                     "ppm/degC", 1e6),
    ("gyro", "wT2"): ("its scale factor changes with the square of the temperature",
                      "its misalignment towards {j} changes with the square of the temperature", "ppm/degC^2", 1e6),
    ("gyro", "f"): ("its bias changes with the specific force along {j} (g-sensitivity)",
                    "its bias changes with the specific force along {j} (g-sensitivity)", "deg/h/g", 3600 * G0),
    ("gyro", "f2"): ("an anisoelastic term (the square of the force along {j})",
                     "an anisoelastic term (the square of the force along {j})", "deg/h/g^2", 3600 * G0**2),
    ("gyro", "ff"): ("an anisoelastic term (the forces along {j} and {k})", "an anisoelastic term (the forces along {j} and {k})",
                     "deg/h/g^2", 3600 * G0**2),
}
_BIAS = {  # family: (words, accel unit, accel factor, gyro unit, gyro factor)
    "T": ("its bias changes with temperature", "ug/degC", 1 / _UG, "deg/h/degC", 3600.0),
    "T2": ("its bias changes with the square of the temperature", "ug/degC^2", 1 / _UG, "deg/h/degC^2", 3600.0),
    "Tr": ("its bias follows the rate of change of the temperature", "ug per degC/min", 1 / _UG / 60, "deg/h per degC/min",
           60.0),
    "t": ("its bias drifts with time", "ug/h", 3600 / _UG, "deg/h per hour", 3600.0**2),
    "step": ("its bias steps", "ug", 1 / _UG, "deg/h", 3600.0),
}


ARCSEC_PER_RAD = 648000.0 / np.pi
# a term in ANOTHER axis' input times the temperature is a misalignment (rad, for small angles:
# output unit per input unit) that changes with temperature: said in arc-seconds
OTHER_AXIS_UNIT = {"fT": ("arcsec/degC", ARCSEC_PER_RAD), "wT": ("arcsec/degC", ARCSEC_PER_RAD),
                   "fT2": ("arcsec/degC^2", ARCSEC_PER_RAD), "wT2": ("arcsec/degC^2", ARCSEC_PER_RAD)}


def meaning(sensor: str, axis: int, reg: Regressor) -> tuple[str, str, float]:
    """(what the term is in words, its natural unit, factor: natural value = coefficient * factor)."""
    if reg.family in _BIAS:
        words, ua, fa, ug, fg = _BIAS[reg.family]
        if reg.family == "step":
            words = f"its bias steps at the start of segment {reg.j}"
        return (words, ua, fa) if sensor == "accel" else (words, ug, fg)
    own, other, unit, factor = PHYSICS[(sensor, reg.family)]
    mine = reg.j == axis if reg.family not in ("ff",) else axis in (reg.j, reg.k)
    if sensor == "gyro" and reg.family == "wf":
        mine = reg.j == axis
    words = own if mine else other
    if not mine and reg.family in OTHER_AXIS_UNIT:
        unit, factor = OTHER_AXIS_UNIT[reg.family]
    o = reg.k if reg.j == axis else reg.j
    return words.format(i=AX[axis], j=AX[max(reg.j, 0)], k=AX[max(reg.k, 0)], o=AX[max(o, 0)]), unit, factor


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

    def meaning(self) -> tuple[str, str, float]:
        return meaning(self.sensor, self.axis, self.regressor)

    def natural(self, value: float) -> float:
        return value * self.meaning()[2]

    def words(self, value: float, sigma: float | None = None) -> str:
        """In words and natural units: "x gyro: its scale factor changes with temperature:
        +300 ± 8 ppm/degC (in w_x·(T - T_ref))"."""
        who = "accelerometer" if self.sensor == "accel" else "gyro"
        what, unit, factor = self.meaning()
        spread = "" if sigma is None else f" ± {abs(sigma * factor):.2g}"
        return f"{AX[self.axis]} {who}: {what}: {value * factor:+.3g}{spread} {unit} (in {self.regressor.text})"


TEMPERATURE_FAMILIES = ("T", "T2", "Tr", "fT", "wT", "fT2", "wT2")


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
        self.terms = [Term(s, int(a), regressor(k)) for s, a, k in self.spec]
        self._compile()

    def _compile(self):
        self._code = {t.regressor.key: compile(t.regressor.code, "<term>", "eval") for t in self.terms}
        self.term = "; ".join(f"{t.sensor}_{AX[t.axis]} += c * {t.regressor.text}" for t in self.terms)
        self.needs = tuple(sorted({"temperature" for t in self.terms if t.regressor.family in TEMPERATURE_FAMILIES}
                                  | {"time" for t in self.terms if t.regressor.family in ("wd", "Tr")}))

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

    def _term_batch(self, X, ctx, sensor):
        """_term of every row of X (B, terms) with a batch context (Effect.accel_batch): the
        regressors, elementwise in the points, on the B x N points flattened (the same numbers).
        A term no row carries is skipped, as _term skips it; in a row whose coefficient alone is 0
        it adds 0 x a finite regressor, which changes no number."""
        B, N = len(X), len(ctx)
        out = np.zeros_like(ctx.f_p)
        v, values = None, {}
        for k, t in enumerate(self.terms):
            if t.sensor != sensor:
                continue
            if not np.any(X[:, k] != 0.0):
                continue
            key = t.regressor.key
            if key not in values:
                if v is None:
                    v = _variables(ctx, self.reference_c)
                    v.update(f=ctx.f_p.reshape(-1, 3), w=ctx.w_p.reshape(-1, 3), wd=v["wd"].reshape(-1, 3),
                             T=np.tile(v["T"], B), Tr=np.tile(v["Tr"], B), t=np.tile(v["t"], B),
                             seg=np.tile(v["seg"], B), _n=B * N)
                values[key] = np.broadcast_to(eval(self._code[key], {"__builtins__": {}}, v), (B * N,)).reshape(B, N)
            out[:, :, t.axis] += X[:, k, None] * values[key]
        return out

    def accel(self, x, ctx):
        return self._term(x, ctx, "accel") if any(t.sensor == "accel" for t in self.terms) else None

    def gyro(self, x, ctx):
        return self._term(x, ctx, "gyro") if any(t.sensor == "gyro" for t in self.terms) else None

    def accel_batch(self, X, ctx):
        return self._term_batch(X, ctx, "accel") if any(t.sensor == "accel" for t in self.terms) else None

    def gyro_batch(self, X, ctx):
        return self._term_batch(X, ctx, "gyro") if any(t.sensor == "gyro" for t in self.terms) else None


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


def failing_sensors(result) -> dict:
    """Per sensor, whether its own data rows carry a misfit: their whitened sum of squares
    against their share of the degrees of freedom (rows x dof / data rows), failing at the
    fit's own level (p below ALPHA / 10).  A misfit of the accelerometers leaks into the gyro
    rows only through the shared nuisances (attitudes, start phases), so the gyro terms are
    searched only when the gyro rows themselves fail, and the accelerometer's likewise:
    {"accel": (fails, rss, expected), "gyro": (...)}."""
    from station.diagnose.core import PRIOR_QUANTITIES

    labels = result.model.row_labels(result.x)
    r = result.model.residuals(result.x)
    data = np.array([q not in PRIOR_QUANTITIES for _, _, q, _ in labels])
    share = result.dof / max(int(data.sum()), 1)
    out = {}
    for sensor in ("accel", "gyro"):
        rows = np.array([q.startswith(sensor) for _, _, q, _ in labels]) & data
        n = int(rows.sum())
        rss = float(r[rows] @ r[rows])
        expected = n * share
        out[sensor] = (n > 0 and chi2_sf(rss, max(expected, 1.0)) < ALPHA / 10, rss, expected)
    return out


PREFERENCE = {  # within a group of aliases, the more physical term first (lower is preferred)
    "f2": 0, "ff": 0, "f3": 0, "absf": 0, "fT": 0, "w2": 0, "wabsw": 0, "w3": 0, "wT": 0, "f": 0, "w": 0,
    "fT2": 1, "wT2": 1,
    "wf": 1, "ww": 1, "wd": 1, "T": 1, "T2": 1, "Tr": 2, "t": 2, "step": 3}


def _rank(term: "Term") -> tuple:
    """Own-axis terms before terms in another axis' variable; temperature and its square before
    its rate, time and steps (a step or a drift in time is an event of this capture, not a
    property of the sensor that holds in the next one)."""
    reg = term.regressor
    own = term.axis in (reg.j, reg.k) or reg.family in _BIAS
    return (PREFERENCE.get(reg.family, 2), 0 if own else 1)


@dataclass
class Found:
    term: Term
    chi2_drop: float          # predicted, nominal noise, given the terms found before it
    p_value: float            # Holm-corrected over the dictionary, over-dispersion-corrected
    value: float              # one-step estimate, output unit per regressor unit
    sigma: float
    aliases: list = field(default_factory=list)   # (Term, cosine, what would separate them)


def search(result, max_terms: int = MAX_TERMS, sensors=None, events: bool = True) -> list[Found]:
    """Forward selection over the dictionary at the current fit (linearised score tests), on
    the sensors whose terms can be sized (``searchable``), when a sensor's own rows fail
    (``failing_sensors``) or the fit fails: both triads are scored, and a term of a sensor whose
    rows pass is taken only when it is clearly the better account (``cross_triad``);
    ``sensors`` overrides.  At each step the most significant term is
    taken, unless a more physical term (``_rank``) is its alias — the two columns, outside the
    model and the terms taken before, alike to ALIAS_COS, so that this capture cannot tell them
    apart: then that one, and the others are listed as its aliases with what would separate
    them.  ``events``: whether a drift in time or a step at a segment boundary may be taken
    (after the physical terms, while the fit still fails)."""
    model = result.model
    s = model.s
    reference = _reference_c(s)
    blamed = None                 # the sensors whose own rows fail (None: ``sensors`` given)
    if sensors is None:
        failing = failing_sensors(result)
        blamed = [x for x, _, _ in searchable(s) if failing[x][0]]
        # the other triad's terms are searched too when a sensor fails: a misfit of one sensor
        # reaches the other's rows through the shared attitudes (a gyro axis that tilts with
        # temperature failed the ACCELEROMETER rows, 250 against 141, its own 65 against 43,
        # and was named an accelerometer misalignment changing with temperature); which triad
        # carries it is decided by the score (cross_triad), not by where the misfit landed
        sensors = [x for x, _, _ in searchable(s)] if blamed else []
        if not blamed and fit_fails(result):
            # the fit fails with no sensor's rows failing on their own (the misfit split between
            # them: seed 3 of the tilting gyro axes, reduced chi2 1.37): both triads, on the score
            sensors, blamed = [x for x, _, _ in searchable(s)], None
    n_seg = _segment_count(s)
    candidates = [Term(sensor, axis, reg) for sensor in sensors for axis in range(3)
                  for reg in dictionary(sensor, n_seg)]
    if not candidates:
        return []
    bank = in_capture_units(TermsEffect)(candidates, reference)      # counts on a raw capture
    bank.id = "term_search_bank"        # beside discovered terms already in the model
    extended = lsq.Model(s, [*model.effects, bank], model.attitudes, like=model)
    extended.priors = dict(model.priors)
    n = model.layout.size
    x = np.concatenate([result.x, np.zeros(len(candidates))])
    r = extended.residuals(x)
    cols = list(range(n, n + len(candidates)))
    Jc = extended.jacobian_columns(x, cols)             # d(residual)/d(coefficient)
    Jp = outside_model(result, Jc)
    # a column is usable when a part of it lies outside the fitted model, judged against its OWN
    # length: the regressors' units differ by twenty orders of magnitude (w³ in (deg/s)^3 against
    # dT/dt in degC/s), so a threshold relative to the largest column of the dictionary threw
    # away every small-unit regressor (a gyro bias in dT/dt was never tested)
    own2 = np.einsum("ij,ij->j", Jc, Jc)
    m = len(candidates)
    data = model.data_rows if hasattr(model, "data_rows") else np.ones(len(r), bool)
    found: list[Found] = []
    chosen = []
    # a drift in time or a step at a segment boundary is an event of this capture, not a property
    # of the sensor that holds in the next one: searched only once the physical terms are
    # exhausted and the fit still fails
    is_event = np.array([c.regressor.family in ("t", "step") for c in candidates])
    events_too = False
    while len(found) < max_terms:
        # over-dispersion of what is left (the misfit shrinks as terms are taken)
        dof = result.dof - len(found)
        rss = float(r[data] @ r[data]) if len(data) == len(r) else float(r @ r)
        phi = max(rss / dof, 1.0) if dof > 0 and chi2_sf(rss, dof) < ALPHA / 10 else 1.0
        norms2 = np.einsum("ij,ij->j", Jp, Jp)
        usable = (norms2 > OUTSIDE_SHARE2 * own2) & (own2 > 0.0)
        g = Jp.T @ r
        lm = np.where(usable, g**2 / np.where(usable, norms2, 1.0), 0.0)
        lm[chosen] = 0.0
        if not events_too:
            lm[is_event] = 0.0
        if blamed is not None and len(blamed) < len(sensors):
            lm = cross_triad(lm, candidates, blamed, phi)
        k = int(np.argmax(lm))
        # Holm over the family: the step's rank among m - len(found) untested terms
        p = min(1.0, chi2_sf(lm[k] / phi, 1) * (m - len(found))) if lm[k] > 0 else 1.0
        if p >= ALPHA:
            if events and not events_too and phi > 1.0:
                events_too = True         # the physical terms leave the fit failing: events may
                continue                  #   explain the rest
            break
        # its aliases: columns alike to ALIAS_COS that explain nearly as much
        unit = Jp / np.sqrt(np.where(usable, norms2, 1.0))
        cos = np.where(usable, unit.T @ unit[:, k], 0.0)
        group = [a for a in np.flatnonzero(np.abs(cos) >= ALIAS_COS) if a not in chosen and lm[a] > 0]
        best = min(group, key=lambda a: (_rank(candidates[a]), -lm[a]))
        if best != k:
            cos = np.where(usable, unit.T @ unit[:, best], 0.0)
            k = best
        aliases = [(candidates[a], float(cos[a]), separates(candidates[k], candidates[a]))
                   for a in sorted(group, key=lambda a: -abs(cos[a])) if a != k][:3]
        c = -g[k] / norms2[k]
        found.append(Found(candidates[k], float(lm[k]), p, float(c), float(np.sqrt(phi / norms2[k])), aliases))
        chosen.append(k)
        q = Jp[:, k] / np.sqrt(norms2[k])
        r = r - q * (q @ r)
        Jp = Jp - np.outer(q, q @ Jp)
    return found


def cross_triad(lm, candidates, blamed, phi: float) -> np.ndarray:
    """The score statistics with the terms of a sensor whose own rows pass (not ``blamed``)
    kept only when the best of them explains more than the best term of the blamed sensors by
    the 1 % point of chi2 on one degree of freedom (after the over-dispersion): the misfit is
    the blamed sensor's unless the other triad's physics is clearly the better account of it.
    An accelerometer K3 once took gyro w·|w| stand-ins that explained part of it; gyro axes
    tilting with temperature (each 20 arcsec/degC towards both others) leave their misfit in the
    accelerometer rows through the attitudes, and its w_x·T on the z gyro explains 70.7 where
    the best accelerometer term (f_z·T on x) explains 26.6."""
    from scipy.special import chdtri

    lm = np.array(lm, dtype=float)
    mine = np.array([c.sensor in blamed for c in candidates])
    if not mine.any() or mine.all():
        return lm
    best_mine = float(lm[mine].max())
    margin = chdtri(1, ALPHA) * max(phi, 1.0)
    others = ~mine & (lm > 0)
    if float(lm[others].max(initial=0.0)) <= best_mine + margin:
        lm[~mine] = 0.0
    return lm


OWN_COS = 0.999          # a term this alike to what an effect's parameters can do is that effect's own


def within(result, effect, found_terms) -> list[float]:
    """For each term, how much of its column (outside the fitted model) lies in what ``effect``'s
    parameters can change: 1 when the effect contains the term (the same physics)."""
    model = result.model
    n = model.layout.size

    def columns(extra):
        ext = lsq.Model(model.s, [*model.effects, extra], model.attitudes, like=model)
        ext.priors = dict(model.priors)
        x = np.concatenate([result.x, np.zeros(ext.layout.size - n)])
        return outside_model(result, ext.jacobian_columns(x, list(range(n, ext.layout.size))))

    bank = in_capture_units(TermsEffect)(list(found_terms), _reference_c(model.s))
    bank.id = "term_search_bank"
    E, T = columns(effect), columns(bank)
    u, sv, _ = np.linalg.svd(E, full_matrices=False)
    u = u[:, sv > 1e-8 * sv[0]] if len(sv) and sv[0] > 0 else u[:, :0]
    norms = np.maximum(np.linalg.norm(T, axis=0), 1e-300)
    return [float(v) for v in np.linalg.norm(u.T @ T, axis=0) / norms]


def _segment_count(s) -> int:
    idx = [q.index for q in [*s.statics, *s.rotations] if getattr(q, "index", None) is not None]
    return int(max(idx)) + 1 if idx else 0


_VARIABLE = {"f": "force", "f2": "force", "ff": "force", "absf": "force", "f3": "force", "fT": "force_temp",
             "fT2": "force_temp", "wT2": "rate_temp",
             "w": "rate", "w2": "rate", "wabsw": "rate", "w3": "rate", "ww": "rate", "wf": "rate_force",
             "wd": "rate_change", "wT": "rate_temp", "T": "temp", "T2": "temp", "Tr": "temp_rate",
             "t": "time", "step": "time"}


def separates(a: Term, b: Term) -> str:
    """The segments that would tell term a from term b (the capture could not)."""
    fa, fb = a.regressor.family, b.regressor.family
    pair = {fa, fb}
    va, vb = _VARIABLE.get(fa, ""), _VARIABLE.get(fb, "")
    if pair <= {"w", "w2", "wabsw", "w3", "ww"}:
        if pair & {"w2"} and pair & {"wabsw", "w"}:
            return "rotations in both directions (+ and -) about each axis"
        return "rotations at three or more rates about each axis, in both directions"
    if pair <= {"f", "f2", "ff", "absf", "f3"}:
        return "statics with gravity at ±1 g and at 45° and 35° to each axis (inputs of other sizes)"
    if "temp" in (va, vb) or "time" in (va, vb) or "temp_rate" in (va, vb):
        if {va, vb} <= {"temp", "time", "temp_rate"}:
            if pair == {"T", "T2"}:
                return "the same attitudes at three or more temperatures"
            if pair == {"T", "Tr"}:
                return ("a temperature that peaks and cools (on one exponential warm-up dT/dt = (T_end - T)/tau "
                        "exactly): a cool-down after the warm-up, or a change of the ambient")
            return ("a temperature that does not follow the time (a cool-down after the warm-up, or the "
                    "statics repeated at a steady temperature)")
        return "the same attitudes and rotations repeated at another temperature, at a steady temperature"
    if pair <= {"fT", "fT2", "T", "T2"} or pair <= {"wT", "wT2", "T", "T2"}:
        if len(pair & {"fT", "fT2", "wT", "wT2"}) == 2:
            return "the same attitudes and rotations at three or more steady temperatures"
    if {va, vb} & {"rate_temp", "force_temp"}:
        return ("the same rotations (or statics) repeated at another temperature, and rotations at two "
                "rates at one temperature")
    if {va, vb} & {"rate_force", "rate_change"}:
        return "rotations about horizontal and vertical axes at several rates"
    return "attitudes, rates or temperatures this capture does not have"


def refit(summaries, result, found: list[Found]):
    """The model with the found terms added as one effect (merged with the terms already in it),
    refitted (values with 1-sigma)."""
    old = [t for e in result.model.effects if isinstance(e, TermsEffect) for t in e.terms]
    effect = in_capture_units(TermsEffect)([*old, *(f.term for f in found)], _reference_c(summaries))
    others = [e for e in result.model.effects if not isinstance(e, TermsEffect)]
    return lsq.fit(summaries, [*others, effect], result.model.attitudes, like=result.model), effect


def in_model(result):
    """(TermsEffect, values, sigmas) of the terms in a fitted model, or None."""
    effect = next((e for e in result.model.effects if isinstance(e, TermsEffect)), None)
    if effect is None:
        return None
    names, values, _, cov = lsq.reported(result, "m/s^2", "deg/s")
    at = {n: i for i, n in enumerate(names)}
    idx = [at[t.name] for t in effect.terms]
    return effect, [float(values[i]) for i in idx], [float(np.sqrt(cov[i, i])) for i in idx]


def _param_name(t: Term) -> str:
    return f"{t.sensor}_{AX[t.axis]}_{t.regressor.key}"


def plugin_source(effect: TermsEffect, values, sigmas, class_name: str = "DiscoveredTerms",
                  aliases=(), discovered_by: str = "station diagnose --auto") -> str:
    """A working effect plugin with these terms: each parameter in its natural unit (ppm/degC,
    ug/g^3, deg/h/degC^2 ...), on the sensor it was found on, its compensation (``station apply``
    subtracts the same terms, docs/effects.md), the temperature reference decided from the
    capture like the library's temperature effects, and a self-test (``python FILE.py`` or
    pytest) that the compensation removes the terms at typical inputs."""
    terms = list(effect.terms)
    uses_abs = any(t.regressor.family in ("absf", "wabsw") for t in terms)
    uses_seg = any(t.regressor.family == "step" for t in terms)
    who = {"accel": "accelerometer", "gyro": "gyro"}
    what = []
    for t in terms:
        m = t.meaning()[0]
        if m not in what:
            what.append(m)
    sensors = sorted({who[t.sensor] for t in terms})
    title = f"{' and '.join(sensors)}: {'; '.join(what)} (found outside the library)"
    lines = [
        f'"""{title}.',
        "",
        f"Found by `{discovered_by}` (value ± 1σ at the fit that found them):",
    ]
    lines += [f"  {t.words(v, sg)}" for t, v, sg in zip(terms, values, sigmas)]
    if aliases:
        lines += ["", "What that capture could not tell them from (and what would):"]
        lines += [f"  {a}" for a in aliases]
    if uses_seg:
        lines += ["", "A step at a segment boundary is an event of that capture: `station apply` does not",
                  "know the segments of the data it is given and compensates the level before the step."]
    lines += [
        "",
        f"Add it:      station estimate CAPTURE --add THIS_FILE.py:{class_name} -o CAL.yaml",
        f"Compensate:  station apply CAL.yaml IN.csv -o OUT.csv --plugin THIS_FILE.py:{class_name}",
        "Check it:    python THIS_FILE.py   (or pytest THIS_FILE.py)",
        "Rename the id, the parameters and the physics as you like (docs/effects.md).",
        '"""',
        "import numpy as np",
        "",
        "from station.model.effect import Effect, Param",
        "",
        "G0 = 9.80665                # m/s^2 per g",
        "",
        "",
        f"class {class_name}(Effect):",
        f'    id = "discovered_terms"',
        f"    title = {title!r}",
        f"    physics = {('; '.join(f'{AX[t.axis]} {who[t.sensor]}: {t.meaning()[0]}' for t in terms) + '.')!r}",
        f"    term = {'; '.join(f'{t.sensor}_{AX[t.axis]} += {_param_name(t)} [{t.meaning()[1]}] / {t.meaning()[2]:.10g} * {t.regressor.text}' for t in terms)!r}",
        f"    excited_by = {'the segments that revealed them (see the aliases above for what separates them)'!r}",
        f"    magnitudes = {('found: ' + '; '.join(f'{_param_name(t)} {t.natural(v):+.3g} {t.meaning()[1]}' for t, v in zip(terms, values)))!r}",
        f"    signature = {'the residual pattern station diagnose reported'!r}",
        f"    needs = {tuple(effect.needs)!r}",
        '    state_fields = ("reference_c",)',
        f"    complex_step = {not uses_abs}",
        "",
        "    def __init__(self):",
        f"        self.reference_c = {float(effect.reference_c)!r}     # T_ref, deg C",
        "",
        "    def setup(self, summaries):",
        "        # T_ref: the mean temperature of the static segments (the library's temperature effects')",
        "        temps = [st.temp_c for st in summaries.statics if st.temp_c is not None]",
        "        self.reference_c = float(np.mean(temps)) if temps else 0.0",
        "",
        "    @property",
        "    def params(self):",
        "        # name, unit, reported = internal * scale, typical size, largest plausible size",
        "        return (",
    ]
    for t, v in zip(terms, values):
        typical = max(abs(t.natural(float(v))), 1e-300)
        lines.append(f'            Param("{_param_name(t)}", "{t.meaning()[1]}", 1.0, {typical:.3g}, {100 * typical:.3g}),')
    lines += [
        "        )",
        "",
        "    def _variables(self, ctx):",
        "        f, w = ctx.f_p, ctx.w_p                      # m/s^2 and deg/s, frame p",
        "        wd = np.degrees(ctx.wdot_table)             # deg/s^2",
        "        T = np.nan_to_num(ctx.temp_c - self.reference_c)   # deg C from T_ref",
        '        Tr = np.nan_to_num(ctx.column("temp_rate_c_per_s"))',
        '        t = np.nan_to_num(ctx.column("t_s"))',
        '        seg = np.nan_to_num(ctx.column("segment_index"))',
        "        return f, w, wd, T, Tr, t, seg",
        "",
    ]
    for sensor in ("accel", "gyro"):
        idx = [k for k, t in enumerate(terms) if t.sensor == sensor]
        if not idx:
            continue
        lines += [f"    def {sensor}(self, x, ctx):",
                  f"        # the {who[sensor]} outputs' terms, {'m/s^2' if sensor == 'accel' else 'deg/s'}",
                  "        f, w, wd, T, Tr, t, seg = self._variables(ctx)",
                  "        out = np.zeros(f.shape, dtype=np.result_type(x, f))"]
        for k in idx:
            t = terms[k]
            unit, factor = t.meaning()[1], t.meaning()[2]
            lines.append(f"        out[:, {t.axis}] += x[{k}] / {factor:.10g} * ({t.regressor.code})"
                         f"    # {AX[t.axis]} {who[sensor]}: {t.meaning()[0]} [{unit}]")
        lines += ["        return out", ""]
    found = ", ".join(f"{t.natural(float(v))!r}" for t, v in zip(terms, values))
    lines += [
        "",
        f"FOUND = np.array([{found}])     # the values found, in the units of params",
        "",
        "",
        "def test_compensation_removes_the_terms():",
        '    """The terms at typical inputs (1 g along and across the axes, 100 deg/s, T_ref + 3 to 9 degC',
        '    warming at 1.5 degC/s: every term is exercised, temperature and its rate too)',
        '    are added to ideal outputs and station apply\'s compensation takes them out again."""',
        "    from station.model.compensate import compensate_with_effects",
        "",
        f"    e = {class_name}()",
        "    e.reference_c = 25.0",
        "    n = 400",
        "    t = np.arange(n) * 0.01",
        "    phase = np.radians(100.0) * t",
        "    up = np.column_stack([np.cos(phase), np.sin(phase), np.ones(n)]) / np.sqrt(2.0)",
        "    f = G0 * up                                   # gravity turning across x and y, half along z",
        "    w = np.column_stack([100.0 * np.ones(n), -60.0 * np.ones(n), 30.0 * np.ones(n)])",
        "    temp = 28.0 + 1.5 * t                         # warming at 1.5 degC/s: T_ref + 3 to + 9 degC",
        "    comp = {\"accel_matrix\": np.eye(3), \"gyro_matrix\": np.eye(3), \"accel_bias\": np.zeros(3),",
        "            \"gyro_bias\": np.zeros(3)}",
        "    from station.model.effect import SampleContext",
        "",
        "    w_rad = np.radians(w)",
        "    ctx = SampleContext(f_p=f, w_p=w, w_table=w_rad, wdot_table=np.gradient(w_rad, t, axis=0), temp_c=temp,",
        "                        accel_matrix=np.eye(3), gyro_matrix=np.eye(3), t_s=t,",
        "                        temp_rate_c_per_s=np.gradient(temp, t))     # as station apply computes it",
        "    da = e.accel(FOUND, ctx) if hasattr(e, \"accel\") else None",
        "    dw = e.gyro(FOUND, ctx) if hasattr(e, \"gyro\") else None",
        "    raw_a = f + (0.0 if da is None else da)",
        "    raw_w = w + (0.0 if dw is None else dw)",
        "    _, f_c, w_c = compensate_with_effects(comp, [(e, FOUND)], t, raw_a, raw_w, temp)",
        "    size_a = np.max(np.abs(raw_a - f)) + 1e-12",
        "    size_w = np.max(np.abs(raw_w - w)) + 1e-12",
        "    assert np.max(np.abs(f_c - f)) < 1e-3 * size_a + 1e-9, (np.max(np.abs(f_c - f)), size_a)",
        "    assert np.max(np.abs(w_c - w)) < 1e-3 * size_w + 1e-9, (np.max(np.abs(w_c - w)), size_w)",
        "    return size_a, size_w",
        "",
        "",
        'if __name__ == "__main__":',
        "    a, g = test_compensation_removes_the_terms()",
        '    print(f"ok: terms of {a / G0 * 1e6:.3g} ug and {g * 3600:.3g} deg/h at typical inputs are compensated")',
    ]
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
    after: object = None      # the Diagnosis with the terms (no library candidates ranked)
    h_after: object = None    # its leave-one-segment-out Holdout
    share: float | None = None

    def lines(self) -> list[str]:
        new = {f.term.name for f in self.found}
        return [t.words(v, sg) for t, v, sg in zip(self.effect.terms, self.values, self.sigmas) if t.name in new]

    def alias_lines(self) -> list[str]:
        """What the capture cannot tell each chosen term from, and what would."""
        out = []
        for f in self.found:
            if f.aliases:
                names = ", ".join(f"{t.regressor.text} ({'accelerometer' if t.sensor == 'accel' else 'gyro'} "
                                  f"{AX[t.axis]}, alike to {abs(c):.3f})" for t, c, _ in f.aliases)
                out.append(f"{f.term.regressor.text} on the {AX[f.term.axis]} "
                           f"{'accelerometer' if f.term.sensor == 'accel' else 'gyro'} cannot be told here from "
                           f"{names}: {f.aliases[0][2]} would separate them")
        return out


def propose(diagnosis, summaries, h_before=None, events: bool = True) -> Proposal | None:
    """Search, refit, judge (the stop rule of --auto: station.diagnose.holdout.judge); None when
    no term of the dictionary is significant.  ``h_before``: the leave-one-segment-out Holdout
    of the diagnosis' fit, when already computed."""
    from station.diagnose.core import diagnose
    from station.diagnose.holdout import judge, leave_one_segment_out

    result = diagnosis.result
    found = search(result, events=events)
    if not found:
        return None
    after_result, effect = refit(summaries, result, found)
    _, values, sigmas = in_model(after_result)
    after = diagnose(after_result, exclude=[e for e in _all_ids()])
    h_after = leave_one_segment_out(after_result)
    ok, reason, share, cv_b, cv_a = judge(diagnosis, after, h_before or leave_one_segment_out(result), h_after)
    if ok and fit_fails(after.result):
        # terms chosen from some hundred columns that leave the fit failing are likely stand-ins
        # for what is still missing: a gyro scale that follows the specific force (invisible to
        # the gyro rows of whole turns) failed the accelerometer rows through the shared
        # attitudes, and accelerometer terms that took 62 % of the excess raised the held-out
        # accelerometer error 0.017 -> 0.106 mg.  Proposed and emitted (marked), not carried.
        ok = False
        reason = (f"the terms explain {100 * (share or 0.0):.0f} % of the excess chi2 but leave the fit failing "
                  f"(reduced chi2 {after.reduced_chi2:.3g}): they may stand in for what is still missing (a "
                  "misfit of one sensor reaches the other's rows through the shared attitudes), so they are not "
                  "carried into the calibration")
    return Proposal(found, effect, values, sigmas, diagnosis.chi2, after.chi2, after.reduced_chi2, cv_b, cv_a, ok,
                    reason, after=after, h_after=h_after, share=share)


def _all_ids():
    from station.model.registry import EffectRegistry

    return EffectRegistry().ids()
