"""A whole design: candidates on the table, their information, the search, the scheme file, the
compiled time checked against the budget, each parameter's 1σ predicted by the estimator's own
fit of the designed scheme, and the same for every built-in table scheme stretched or shrunk to
the same compiled time."""
from __future__ import annotations

import copy
import math
import time
from dataclasses import dataclass, field, replace

import numpy as np
import yaml

from station.bench.compile import compile_scheme
from station.bench.plan import Chamber
from station.core.errors import UserError
from station.design import candidates as cand_mod
from station.design.information import Noise, information, model_of, quiet_truth, ramp_accel_of
from station.design.search import (MIN_LEVEL_AXES, MIN_STATICS, MIN_STATICS_TABLE, MAX_STATICS_TABLE, Scorer,
                                   parse_criterion,
                                   timed_exchange)
from station.io.scheme import Scheme, StaticSpec, load_scheme
from station.simulate.montecarlo import GEOMETRY_SEEDS

BUILTIN_TABLE_SCHEMES = ("optimal9", "chatfield18", "traditional24", "sizeeffect")
BUDGET_ROUNDS = 6          # search again with the budget less the compiled excess, at most this often
VERIFY_RUNS = 4            # noisy dry runs of the designed scheme through the estimator (verify)
# an error beyond this many predicted 1σ in a verification run: the estimator does not deliver
# the prediction.  For an honest 1σ the error is normal: P(|z| > 6) = 2e-9 per parameter, so
# 4 runs x 40 parameters raise a false alarm once in 3 million designs
VERIFY_Z = 6.0
# the estimator's own 1σ in a verification run against the predicted: beyond this factor either
# way the fit is not the one predicted (a parameter it held by its prior, a solver stopped
# short, a noise model that widened everything: the noise's own scatter of a 1σ estimated from
# a few hundred degrees of freedom is a few per cent)
VERIFY_SIGMA_FACTOR = 2.0
# the simulated bench's geometries (headings of the statics, headings and rolls of the rotation
# axes: random in every dry run, unknown to the estimator) each prediction is averaged over
# (predict), the same as station montecarlo's bound: one geometry is one draw, off the mean
# spread by up to 40 % for the gyro biases' bound (the temperature design of the twelfth
# session: 1.28x for gyro x over the Monte Carlo's geometries)
# (GEOMETRY_SEEDS, imported above from station.simulate.montecarlo: the designed scheme's own
# prediction; the kinds' and the built-ins' comparison at one geometry, seed 0, for the CPU)


@dataclass
class Prediction:
    """Each reported parameter's 1σ for a scheme, by the estimator's fit of its noiseless capture."""
    scheme: str
    duration_s: float              # compiled time on the table
    names: list
    units: list
    sigma: np.ndarray
    revealed: np.ndarray           # bool: determined by the fit (not aliased, effects below typical)
    note: str = ""
    covariance: np.ndarray | None = None     # reported units


@dataclass
class Design:
    scheme: Scheme
    text: str                      # the scheme file
    criterion: str
    value: float
    duration_s: float              # compiled
    budget_s: float
    prediction: Prediction
    builtins: list                 # Prediction per built-in scheme at the same duration
    search_sigma: np.ndarray       # the search's own 1σ (the candidates' information summed)
    candidates: int
    evaluations: int
    passes: int
    seconds: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)
    verification: Verification | None = None   # noisy dry runs through the estimator (verify)
    attitudes: str = "unknown"     # the statics' attitudes as the estimator takes them: "unknown" | "table"


def reported_names(effects) -> list:
    """The reported parameters' names (lsq._reported_index's order) of the base model and effects."""
    names = []
    for block, suffixes in (("accel_scale", "xyz"), ("accel_misalignment", ("yz", "zy", "zx")),
                            ("gyro_scale", "xyz"), ("gyro_misalignment", ("yz", "zy", "zx")),
                            ("accel_bias", "xyz"), ("gyro_bias", "xyz"), ("inter_triad", "xyz")):
        names += [f"{block}_{s}" for s in suffixes]
    return names + [p.name for e in effects for p in e.params]


def geometry_of(config) -> dict | None:
    t = config.table
    g = {"axes_intersect": bool(t.axes_intersect)}
    if t.level_arcsec is not None:
        g["level_arcsec"] = float(t.level_arcsec)
    return g


def predict(scheme: Scheme, effects: list, noise: Noise, config=None, duration_s: float = math.nan,
            plan=None, seeds=(0,), appended=(), times=None, temperatures=None) -> Prediction:
    """The estimator's 1σ of every reported parameter (scale factors in ppm) for ``scheme``: its
    capture simulated without noise, summarised with the noise stated, fitted as ``station
    estimate`` fits (attitudes as the estimator chooses them, blind effect parameters held by
    their priors and said to be not revealed).  Its covariance is the Cramér-Rao bound that
    station/simulate/montecarlo.py computes, for any model.

    ``seeds``: the simulated bench's geometries it is computed at (each static's heading, each
    rotation axis' heading and roll, drawn at random by the simulator for every run: unknown to
    the estimator, as a real table's azimuths are), the covariance their mean -- the expected
    spread of repeated runs, which draw a new geometry each (E over the geometry of the
    estimator's covariance).  One geometry alone is one draw: a static's heading decides which
    horizontal direction of the gyro bias its Earth rate hides, and the gyro biases' and their
    temperature coefficients' bound moved by up to 40 % from draw to draw (docs/design.md,
    thirteenth session).  ``appended``: segment names recorded later by ``run --append``, or
    {name: N} for the N-th extension's (station design --from's extension of a capture already
    extended: its rotations axis groups of their own per extension, as the estimator reads the
    capture then; information.model_of).  ``times``: {segment name: mean sample time, s} in place
    of the simulated bench's (information.model_of: station design --from's capture timeline);
    ``temperatures``: {segment name: mean temperature, degC} likewise."""
    from station.estimate import lsq

    truth = quiet_truth(noise, config)
    if plan is not None and not plan.manual:
        elevation = {s.spec.name: float(s.elevation_deg) for s in plan.steps
                     if type(s).__name__ == "Rotate" and getattr(s, "spec", None) is not None}
        scheme = replace(scheme, segments=tuple(replace(sp, axis_elevation_deg=elevation[sp.name])
                                                if sp.name in elevation else sp for sp in scheme.segments))
    covs, revealed = [], None
    for seed in seeds:
        model, _ = model_of(scheme, effects, noise, truth, None, seed=seed,
                            chamber=config.chamber if config is not None else None, appended=appended,
                            ramp_accel_dps2=ramp_accel_of(config), warmup=config.warmup if config is not None else None,
                            times=times, temperatures=temperatures)
        result = lsq.fit(model.s, [copy.deepcopy(e) for e in effects])
        names, index, factors, units_ = lsq._reported_index(result, "m/s^2", "deg/s")
        factors, units_ = np.array(factors, float), list(units_)
        for k, n in enumerate(names):
            if "_scale_" in n and units_[k] == "1":
                factors[k], units_[k] = 1e6, "ppm"
        covs.append(result.covariance_of(index) * np.outer(factors, factors))
        blind = (set(result.model.unobservable)
                 | {n for n, c in zip(names, index) if int(c) in set(result.rank_deficient)})
        r = np.array([n not in blind for n in names])
        revealed = r if revealed is None else revealed & r
    cov = np.mean(covs, axis=0)
    sigma = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    return Prediction(scheme.name, duration_s, names, units_, sigma, revealed, covariance=cov)


@dataclass
class Verification:
    runs: int
    worst_z: float                 # the largest |error| / predicted 1σ over the runs and parameters
    worst: str                     # where: "name (seed N)"
    problems: list                 # sentences: what the estimator did not deliver

    @property
    def ok(self) -> bool:
        return not self.problems


def verify_one(scheme: Scheme, effects: tuple, noise: Noise, seed: int, chamber=None,
               ramp_accel_dps2: float | None = None, warmup=None) -> tuple:
    """One noisy dry run of ``scheme`` estimated as ``station montecarlo`` estimates it (the same
    function, station.simulate.montecarlo.run_one): (names, errors, the fit's own 1σ, the fit's
    notes), errors and 1σ in the prediction's units (scale factors in ppm).  ``effects``: the
    library's ids, or effect instances where the model has one the library has not (a plugin,
    station/model/unlisted.py: montecarlo.effect_settings).  ``ramp_accel_dps2``: the configured
    table's recorded ramps (information.ramp_accel_of), as the prediction and the dry run take
    them (before: the dry run's default 50 deg/s^2 whatever the table).  ``warmup``: the configured
    warm-up (station.yaml warmup:), waited for before the first segment as the prediction does."""
    from station.simulate import montecarlo

    settings = replace(noise.settings(), effects=tuple(effects), chamber=chamber, ramp_accel_dps2=ramp_accel_dps2,
                       warmup=warmup)
    return montecarlo.run_one(scheme, settings, seed)


def _map(executor, fn, items) -> list:
    """[fn(item) for item in items] on a Dask cluster's workers (``executor``: its client's
    executor, `station design --scheduler`), else each in a forked child on this machine's cores."""
    if executor is None:
        from station.core.forked import map_in_children

        return map_in_children(fn, items)
    return list(executor.map(fn, list(items)))


def verify(scheme: Scheme, effects: list, noise: Noise, prediction: Prediction, which,
           runs: int = VERIFY_RUNS, first_seed: int = 1000, executor=None, chamber=None,
           ramp_accel_dps2: float | None = None, warmup=None) -> Verification:
    """Does the estimator deliver the prediction?  ``runs`` noisy dry runs of the designed scheme
    (seeds first_seed, ...: the first runs `station montecarlo` makes) estimated as it does;
    for every criterion parameter ``which`` (the prediction's indices) the error must be within
    VERIFY_Z predicted 1σ and the fit's own 1σ within VERIFY_SIGMA_FACTOR of the predicted, and
    a parameter predicted revealed must not be held by its prior.  The prediction is the
    estimator's covariance at the noiseless capture; what it leaves out is what the estimator
    does with noise: a start the solver does not converge from, a direction the noiseless fit
    sees and a noisy one does not, a noise model or reweighting the designed segments set off."""
    from station.simulate.montecarlo import effect_settings

    # the library's effects by id (what a Dask worker unpickles without the user's files); a model
    # with another effect by its instances
    ids = effect_settings(effects)
    results = _map(executor, lambda seed: verify_one(scheme, ids, noise, seed, chamber, ramp_accel_dps2, warmup),
                   [first_seed + k for k in range(runs)])
    problems, worst_z, worst = [], 0.0, ""
    for k, (names, errors, sigmas, notes) in enumerate(results):
        seed = first_seed + k
        at = {n: i for i, n in enumerate(names)}
        blind = " ".join(n for n in notes if n.startswith("not revealed"))
        for i in which:
            n = prediction.names[i]
            if n not in at or not prediction.revealed[i]:
                continue
            err, sig, pred = errors[at[n]], sigmas[at[n]], prediction.sigma[i]
            if not (np.isfinite(err) and np.isfinite(sig)) or n in blind:
                problems.append(f"{n} not estimated in the noisy run of seed {seed} (predicted 1σ {pred:.3g} "
                                f"{prediction.units[i]})")
                continue
            z = abs(err) / pred
            if z > worst_z:
                worst_z, worst = z, f"{n} (seed {seed})"
            if z > VERIFY_Z:
                problems.append(f"{n}: error {err:.3g} {prediction.units[i]} in the noisy run of seed {seed}, "
                                f"{z:.3g} x the predicted 1σ {pred:.3g}")
            elif not (1.0 / VERIFY_SIGMA_FACTOR <= sig / pred <= VERIFY_SIGMA_FACTOR):
                problems.append(f"{n}: the fit's own 1σ {sig:.3g} {prediction.units[i]} in the noisy run of seed "
                                f"{seed}, {sig / pred:.3g} x the predicted {pred:.3g}")
    return Verification(runs, worst_z, worst, problems)


def _segments_of(chosen, cands, masks=None, chamber=None, order=None) -> list:
    """The scheme's segment entries (YAML) and specs, level by level of a chamber (the first
    segment of each setpoint says ``chamber_c``), mounting by mounting as the time model covers
    them (timeline.cover: the compiler then remounts as often as the model counts), within a
    mounting the statics first, then the rotations -- or in the search's ``order``
    (search.order_search: the sequence on the timeline a temperature design chose)."""
    from station.design.timeline import written_order

    sequence = [cands[i] for i in written_order(chosen, cands, masks, chamber, order)]
    entries, specs = [], []
    setpoint = None
    for c in sequence:
        level = getattr(c, "level", None)
        tag = "" if level is None else f"_{_num(level)}C".replace("-", "m").replace(".", "p")
        sets = level is not None and level != setpoint
        setpoint = level if level is not None else setpoint
        if c.kind == "static":
            up = c.key[1]
            name = f"up_{cand_mod.name_of(up)}{tag}"
            entry = {"static": name, "up_body": [_num(x) for x in _integer_vector(up)], "dwell_s": c.dwell_s}
            spec = cand_mod.static_spec(up, c.dwell_s, name)
            if sets:
                entry["chamber_c"] = _num(level)
                spec = replace(spec, chamber_c=float(level))
            entries.append(entry)
            specs.append(spec)
            continue
        axis, e, rate, rev = c.key[:4]
        ramp = cand_mod.ramp_of(c.key)
        name = f"rot_{cand_mod.name_of(axis)}_e{e:g}_{rate:g}dps_{rev}rev{tag}" + (f"_ramp{ramp}" if ramp else "")
        entry = {"rotation": name, "axis_body": [_num(x) for x in _integer_vector(axis)], "rate_dps": rate,
                 "rotation_s": rev * 360.0 / rate}
        if e:
            entry["axis_elevation_deg"] = e
        if ramp:
            entry["record_ramp"] = ramp
        pair = cand_mod.rotation_pair(axis, e, rate, rev, name, record_ramp=ramp)
        if sets:
            entry["chamber_c"] = _num(level)
            pair = (replace(pair[0], chamber_c=float(level)), pair[1])
        entries.append(entry)
        specs.extend(pair)
    return entries, specs


def chamber_levels(config, effects=(), setpoints=None) -> tuple:
    """The chamber levels a design's candidates are offered at: the room's (None) and the end of
    the configured chamber's range farther from the room (the widest temperature span for one
    ramp; both ends tripled the candidates and the search's CPU: docs/design.md, fourteenth
    session); (None,) without a chamber.  A model with a term in the temperature's square
    (information.squared_in_temperature: temperature_bias_quadratic, the unlisted scale factors
    in T^2) is offered the setpoint half way between the room and that end as well: a parabola
    needs three temperatures, and the ends and the middle of the span are where its coefficient
    is best determined (the D-optimal design of a quadratic on an interval); the warm-up's 2 degC
    at the room are one of them, not two.  The search chooses which levels the design uses, each
    paid for by its chamber step (chamber_cost).  ``setpoints``: the user's (`station design
    --setpoints`), each within the chamber's range (UserError naming the one that is not)."""
    from station.design.information import squared_in_temperature

    c = config.chamber
    if setpoints is not None:
        if c is None:
            raise UserError("--setpoints: no temperature chamber is configured (station.yaml chamber:)")
        for x in setpoints:
            if not c.in_range(x):
                raise UserError(f"--setpoints: {x:g} °C is outside the chamber's range "
                                f"{c.range_c[0]:g}..{c.range_c[1]:g} °C")
        return (None,) + tuple(sorted({float(x) for x in setpoints if abs(float(x) - c.ambient_c) >= 1e-9}))
    if c is None:
        return (None,)
    far = max(c.range_c, key=lambda x: abs(x - c.ambient_c))
    if abs(far - c.ambient_c) < 1e-9:
        return (None,)
    if squared_in_temperature(effects):
        middle = round(0.5 * (c.ambient_c + far), 1)
        return (None, float(middle), float(far))
    return (None, float(far))


def chamber_cost(config):
    """levels -> the seconds their chamber steps cost on the table, as the compiler counts them
    (station/bench/compile.py _chamber_step: the operator's time, the ramp, the settling), the
    setpoints visited in the written order (timeline.level_rank); None without a chamber."""
    c = config.chamber
    if c is None:
        return None
    from station.core.chamber import order_levels

    def cost(levels) -> float:
        total, at = 0.0, c.ambient_c
        for level in order_levels([x for x in levels if x is not None], c.ambient_c):
            total += config.run.operator_s + c.step_s(at, level)
            at = level
        return total

    return cost


def _integer_vector(v) -> tuple:
    """A cube direction as small integers ((1, 1, 0) for (0.707, 0.707, 0)): the scheme reader
    normalises it."""
    v = np.asarray(v, float)
    m = np.min(np.abs(v[np.abs(v) > 1e-9]))
    return tuple(np.round(v / m).astype(int).tolist())


def _num(x):
    return int(x) if float(x).is_integer() else float(x)


def scheme_text(name: str, entries: list, header: list, centred: bool = False) -> str:
    doc = {"name": name, "title": "designed by station design", "reference": "docs/design.md"}
    if centred:
        doc["centred"] = True
    doc["segments"] = entries
    body = yaml.safe_dump(doc, sort_keys=False, default_flow_style=None, width=120)
    return "".join(f"# {line}\n" if line else "#\n" for line in header) + body


def scaled(scheme: Scheme, config, target_s: float) -> tuple[Scheme, float, object]:
    """``scheme`` with its dwells and rotation lengths (whole revolutions, at least one) scaled so
    that its compiled time on the table is as near ``target_s`` as it can be: (scheme, compiled
    time, plan)."""
    plan = compile_scheme(scheme, config)
    overhead = plan.duration_s - sum(s.duration_s for s in scheme.segments)

    def stretched(f):
        segs = []
        for s in scheme.segments:
            if isinstance(s, StaticSpec):
                segs.append(replace(s, dwell_s=max(1.0, s.dwell_s * f)))
            else:
                rev = max(1, round(abs(s.rate_dps) * s.duration_s * f / 360.0))
                segs.append(replace(s, duration_s=rev * 360.0 / abs(s.rate_dps)))
        return replace(scheme, segments=tuple(segs))

    def total(f):
        return overhead + stretched(f).duration_s

    lo, hi = 1e-3, 1e3
    for _ in range(60):
        mid = math.sqrt(lo * hi)
        lo, hi = (mid, hi) if total(mid) < target_s else (lo, mid)
    out = stretched(lo)
    # the rotations are whole revolutions (a step in the time): the statics take the rest
    statics = sum(sp.duration_s for sp in out.segments if isinstance(sp, StaticSpec))
    rest = target_s - overhead - (out.duration_s - statics)
    if statics > 0 and rest > 0:
        g = rest / statics
        out = replace(out, segments=tuple(replace(sp, dwell_s=max(1.0, sp.dwell_s * g))
                                          if isinstance(sp, StaticSpec) else sp for sp in out.segments))
    plan = compile_scheme(out, config)
    return out, plan.duration_s, plan


def design(config, effects: list, noise: Noise, budget_s: float, criterion: str = "D", *,
           setpoints=None, progress=None, **kw) -> Design:
    """The design (module doc; the arguments _design's).  With several chamber setpoints offered
    by chamber_levels' own choice (a term in the temperature's square: the middle of the span
    too), a design using more than one that the noisy dry runs refuse gives way to the design
    with the far end alone, searched and verified in turn, and a note says so (fifteenth
    session: the two-setpoint temperature_bias_quadratic design's noisy fits did not converge in
    9 of 24 runs -- the estimator's start with the table's angle noise, not the design's
    information -- the one-setpoint design's did: docs/design.md).  Setpoints the user names are
    kept as named."""
    say = progress or (lambda text: None)
    d = _design(config, effects, noise, budget_s, criterion, setpoints=setpoints, progress=progress, **kw)
    v = d.verification
    offered = chamber_levels(config, effects, setpoints)
    used = {sp.chamber_c for sp in d.scheme.segments if getattr(sp, "chamber_c", None) is not None}
    if setpoints is not None or v is None or v.ok or len(offered) <= 2 or len(used) <= 1:
        return d
    far = offered[-1]                   # (None, the middle, the far end: chamber_levels)
    say(f"the design at {', '.join(f'{x:g} C' for x in sorted(used))} was refused by its noisy dry runs "
        f"({v.problems[0]}); searching again with the chamber at {far:g} C alone")
    one = _design(config, effects, noise, budget_s, criterion, setpoints=(far,), progress=progress, **kw)
    one.notes.insert(0, f"the design setting the chamber to {', '.join(f'{x:g} C' for x in sorted(used))} "
                        f"(criterion {d.value:.4g}) was not delivered by the estimator in "
                        f"{v.runs} noisy dry runs ({len(v.problems)} problem(s), the first: {v.problems[0]}); "
                        f"this one sets it to {far:g} C alone (--setpoints names the setpoints)")
    for key, value in d.seconds.items():
        one.seconds[key] = one.seconds.get(key, 0.0) + value
    return one


def _design(config, effects: list, noise: Noise, budget_s: float, criterion: str = "D", *,
            rates_dps=cand_mod.DEFAULT_RATES_DPS, revolutions=cand_mod.DEFAULT_REVOLUTIONS,
            dwells_s=cand_mod.DEFAULT_DWELLS_S, max_passes: int = 20, name: str = "designed",
            compare=BUILTIN_TABLE_SCHEMES, progress=None, centred: bool = False,
            verify_runs: int = VERIFY_RUNS, executor=None, statics: str = "any", setpoints=None) -> Design:
    """The design (module doc).  ``progress(text)``: told what is being done.  ``centred``: the
    IMU is to be mounted with its reference point on the table's axes (the scheme says
    ``centred: true``; the mounting offset is then known, as in the sizeeffect scheme).
    ``executor``: a Dask client's executor (`station design --scheduler`): the predictions of the
    design and of the built-in schemes, and the verification's dry runs, run on its workers.
    ``statics``: the kinds of design searched ("unknown": nine or more statics of unknown attitude;
    "table": six to eight of the table's attitude; "any": both, the better kept).  ``setpoints``:
    the chamber setpoints the candidates are offered at (degC; None: chamber_levels' choice)."""
    say = progress or (lambda text: None)
    seconds = {}
    t0 = time.perf_counter()
    fixed = (config.run.operator_s if config.run.operator else 0.0)
    w = config.warmup
    fixed += max(w.duration_s, w.max_s or 0.0) if w.temp_slope_c_per_h is not None else w.duration_s
    parse_criterion(criterion, reported_names(effects))          # bad input before the work
    levels = chamber_levels(config, effects, setpoints)
    table = cand_mod.Table(config)
    least = fixed + MIN_STATICS_TABLE * table.static_s(min(dwells_s))
    if least > budget_s:
        raise UserError(f"a budget of {budget_s:.0f} s holds fewer than {MIN_STATICS_TABLE} static attitudes on "
                        f"this table (the least: {least:.0f} s with the shortest dwell, {min(dwells_s):g} s)")
    say("candidates on the table (gimbal kinematics)")
    cands, chunks, notes, masks = cand_mod.candidate_set(table, rates_dps, revolutions, dwells_s,
                                                         levels=levels,
                                                         ramps=any(e.id == "time_offset" for e in effects))
    if not any(c.kind == "rotation" for c in cands):
        raise UserError("the table can turn about none of the candidate axes (a continuous axis is needed)")
    remount_s = config.run.operator_s if config.run.operator else 0.0
    # the two kinds of design the estimator fits: nine or more statics of unknown attitude, or
    # six to eight of the table's attitudes (known to its angle error, one mounting: the
    # estimator's one mounting rotation), each searched over its own information
    kinds = []
    unknown_ok = (sum(1 for c in cands if c.kind == "static" and c.dwell_s == min(dwells_s)) >= MIN_STATICS
                  and fixed + MIN_STATICS * table.static_s(min(dwells_s)) <= budget_s)
    if unknown_ok and statics in ("any", "unknown"):
        kinds.append(("unknown", list(range(len(cands))), masks, MIN_STATICS, None, MIN_LEVEL_AXES))
    # with a chamber, "any" searches the unknown-attitude kind only (the minute of CPU: the
    # candidates are doubled; the known-attitude kind's design was the worse, 0.166 against
    # 0.148 µg/°C: docs/design.md, fourteenth session)
    table_kind = statics == "table" or (statics == "any" and (config.chamber is None or not kinds))
    one = one_mounting(cands, masks) if table_kind else None
    if one is not None:
        kinds.append(("table", one, [masks[i] for i in one], MIN_STATICS_TABLE, MAX_STATICS_TABLE, 0))
    if not kinds and fixed + MIN_STATICS * table.static_s(min(dwells_s)) > budget_s:
        raise UserError(f"a budget of {budget_s:.0f} s holds fewer than {MIN_STATICS} static attitudes on this "
                        f"table and it reaches fewer than {MIN_STATICS_TABLE} in one mounting (the least for nine: "
                        f"{fixed + MIN_STATICS * table.static_s(min(dwells_s)):.0f} s with the shortest dwell, "
                        f"{min(dwells_s):g} s)")
    if not kinds:
        raise UserError(f"the table reaches fewer than {MIN_STATICS} static attitudes "
                        f"({'with' if config.run.operator else 'without'} an operator) and fewer than "
                        f"{MIN_STATICS_TABLE} in one mounting: no design (run.operator: true lets the IMU be remounted)")
    seconds["candidates"] = time.perf_counter() - t0
    seconds["information"] = seconds["search"] = 0.0
    found_all = []
    for attitudes, subset, sub_masks, least_statics, most_statics, level in kinds:
        t1 = time.perf_counter()
        sub = [cands[i] for i in subset]
        say(f"the information of {len(sub)} candidates, statics of {attitudes} attitude (one simulated capture "
            "of them, the estimator's Jacobian)")
        info = information(chunks, effects, noise, config, geometry_of(config), centred, attitudes=attitudes,
                           timeline=True)
        seconds["information"] += time.perf_counter() - t1
        crit, which = parse_criterion(criterion, info.parameters.names)
        scorer = Scorer(info, sub, crit, which)
        scorer.chamber = config.chamber
        t2 = time.perf_counter()
        found = _search(scorer, sub, sub_masks, budget_s, fixed, max_passes, remount_s, least_statics,
                        most_statics, name, centred, config, say, level)
        seconds["search"] += time.perf_counter() - t2
        if found is None:
            continue
        if attitudes == "table" and len(set(found[4].mounting_of.values())) > 1:
            continue            # (the compiler remounted: not one mounting rotation)
        value = true_value(scorer, found[0].chosen)
        say(f"  statics of {attitudes} attitude: {len(found[0].chosen)} candidates, criterion {value:.6g} (search)")
        found_all.append((attitudes, scorer, found))
    if not found_all:
        raise UserError(f"no design within {budget_s:.0f} s found whose compiled time fits")
    t3 = time.perf_counter()
    verification = None
    verified: dict = {}
    if len(found_all) > 1:
        # the better by the estimator's own fit of each (the search ranks time- and temperature-
        # dependent effects on the candidates' timeline, not the designed order's: docs/design.md)
        say("the estimator's fit of each kind's design, the better kept")
        preds = _map(executor, lambda f: predict(f[2][3], effects, noise, config, f[2][4].duration_s, f[2][4]),
                     found_all)
        values = [criterion_of(pr, criterion) for pr in preds]
        for f, v in zip(found_all, values):
            say(f"  statics of {f[0]} attitude: criterion {v:.6g} (the estimator's)")
        k = int(np.nanargmin(values))
        if verify_runs:
            # the better that the estimator delivers: a kind's design refused by the noisy dry
            # runs gives way to the other's (the thirteenth session: the unknown-attitude size-effect
            # design at 1500 s, every turn about a vertical axis, whose noisy fits end at a reduced
            # chi-square of 1e7 while its information is sound: docs/design.md)
            t4 = time.perf_counter()
            order = [int(i) for i in np.argsort(np.where(np.isfinite(values), values, np.inf))]
            for i in order:
                f = found_all[i]
                say(f"{verify_runs} noisy dry runs of the statics-of-{f[0]}-attitude design through the "
                    "estimator (does it deliver the prediction?)")
                v = verify(f[2][3], effects, noise, preds[i], f[1].which, verify_runs, executor=executor,
                           chamber=config.chamber, ramp_accel_dps2=ramp_accel_of(config), warmup=config.warmup)
                if v.ok or i == order[-1]:
                    k, verification = (i, v) if v.ok else (k, verified.get(k, v))
                    break
                verified[i] = v
                say(f"  refused ({len(v.problems)} problem(s), the first: {v.problems[0]}); the other kind's next")
            seconds["verification"] = time.perf_counter() - t4
        found_all = [found_all[k]]
    attitudes, scorer, (result, entries, specs, scheme, plan, evaluations, passes) = found_all[0]
    crit = scorer.criterion
    which = scorer.which
    search_sigma = scorer.sigma(result.chosen)
    say(f"the 1σ of the designed scheme and of {', '.join(compare) or 'no built-in scheme'} at the same duration "
        f"(the estimator's fit, {'one forked process' if executor is None else 'one Dask task'} per scheme)")

    def job(other):
        if other is None:
            return predict(scheme, effects, noise, config, plan.duration_s, plan, seeds=GEOMETRY_SEEDS)
        try:
            base = load_scheme(other)
            stretched, total, p = scaled(base, config, plan.duration_s)
            pr = predict(stretched, effects, noise, config, total, p)
            pr.note = f"x{stretched.duration_s / base.duration_s:.3g} of its recording time"
        except UserError as e:
            pr = Prediction(other, math.nan, [], [], np.zeros(0), np.zeros(0, bool), note=str(e))
        return pr

    # the design's own prediction over the bench's geometries (what station montecarlo's runs
    # draw and its bound averages: GEOMETRY_SEEDS); the kinds and the built-ins compared at one
    # (seed 0), as the search's candidates are: four fits for each would double a design's CPU
    prediction, *builtins = _map(executor, job, [None, *compare])
    seconds["predictions"] = time.perf_counter() - t3
    if verify_runs and verification is None:
        t4 = time.perf_counter()
        say(f"{verify_runs} noisy dry runs of the design through the estimator (does it deliver the prediction?)")
        verification = verify(scheme, effects, noise, prediction, which, verify_runs, executor=executor,
                              chamber=config.chamber, ramp_accel_dps2=ramp_accel_of(config), warmup=config.warmup)
        seconds["verification"] = time.perf_counter() - t4
    header = [f"{name}: designed by `station design` for the {config.table.axes}-axis table of {config.source}",
              f"criterion {crit.text}: {criterion_of(prediction, crit.text):.6g}; compiled time {plan.duration_s:.0f} s "
              f"(budget {budget_s:.0f} s); effects: {', '.join(e.id for e in effects) or 'none'}",
              f"noise: accel {noise.accel_noise_ug:g} ug/rtHz, gyro {noise.gyro_noise_dph:g} deg/h/rtHz, table "
              f"angle {noise.table_angle_arcsec:g} arcsec, disturbance {noise.accel_disturbance_ug:g} ug "
              f"({noise.source})",
              ("statics: nine or more, each attitude unknown (fitted)" if attitudes == "unknown" else
               f"statics: {sum(isinstance(s, StaticSpec) for s in specs)}, fewer than nine: the estimator takes the "
               "table's attitudes, known to its angle error, in one mounting"),
              "predicted 1-sigma (the estimator's fit of this scheme's noiseless capture):"]
    for n, u, s, r in zip(prediction.names, prediction.units, prediction.sigma, prediction.revealed):
        header.append(f"  {n}: {s:.4g} {u}" + ("" if r else " (not revealed)"))
    from station.simulate.dryrun import warmup_seconds

    warm_s = warmup_seconds(config.warmup, quiet_truth(noise, config).temperature)
    if warm_s > 0:
        # the timeline, the predictions (the built-ins' too), the verification, station run --sim and
        # station montecarlo with this configuration record after the warm-up (seventeenth session)
        notes.append(f"warm-up ({config.source}): every scheme predicted as recorded after it, the simulated IMU "
                     f"powered on {warm_s:.0f} s before the first segment (station run --sim and station montecarlo "
                     "wait for it too, given the same --config)")
    if config.chamber is not None:
        sets = [s.chamber_c for s in specs if s.chamber_c is not None]
        c = config.chamber
        notes.append(f"chamber ({c.describe()}): the design sets it to "
                     + (", ".join(f"{x:g} C" for x in sets) if sets else "nothing (the room's temperature serves best)")
                     + f", {sum(isinstance(st, Chamber) for st in plan.steps)} chamber step(s) of the compiled "
                       f"{plan.duration_s:.0f} s; the built-in schemes set none: they run at the room's temperature "
                       "and its warm-up")
    text = scheme_text(name, entries, header, centred)
    if verification is not None:
        header.append(f"verified: {verification.runs} noisy dry runs estimated as station montecarlo does: "
                      f"the largest error {verification.worst_z:.2f} x the predicted 1-sigma ({verification.worst})")
        text = scheme_text(name, entries, header, centred)
    return Design(scheme, text, crit.text, criterion_of(prediction, crit.text), plan.duration_s, budget_s, prediction, builtins,
                  search_sigma, len(cands), evaluations, passes, seconds, notes + list(plan.notes), verification,
                  attitudes)


def one_mounting(cands: list, masks: list) -> list | None:
    """The candidates a design of known attitudes may use: those of the one right-angle mounting
    (bits 0-23: not a fixture) that reaches the most of them, when it reaches at least
    MIN_STATICS_TABLE static attitudes and a rotation; else None."""
    counts = [sum(1 for m in masks if m >> b & 1) for b in range(cand_mod.FIXTURE_BIT)]
    b = int(np.argmax(counts))
    subset = [i for i, m in enumerate(masks) if m >> b & 1]
    ups = {cands[i].slot for i in subset if cands[i].kind == "static"}
    if len(ups) < MIN_STATICS_TABLE or not any(cands[i].kind == "rotation" for i in subset):
        return None
    return subset


def true_value(scorer: Scorer, chosen) -> float:
    """The criterion as reported (criterion_of's: the worst 1σ itself, not the search's power mean)."""
    cov = scorer.covariance(chosen)
    sub = cov[np.ix_(scorer.which, scorer.which)]
    if scorer.criterion.kind == "worst":
        return float(np.sqrt(np.max(np.diag(sub))))
    return scorer.value_of(scorer.information(chosen))


def _search(scorer, cands, masks, budget_s, fixed, max_passes, remount_s, min_statics, max_statics,
            name, centred, config, say, min_level_axes=0):
    """The exchange search within the budget as the compiler counts it: searched again with the
    budget less twice the compiled excess, from the last design, up to BUDGET_ROUNDS times.
    (result, entries, specs, scheme, plan, evaluations, passes), or None when no design fits."""
    budget = budget_s
    start = None
    evaluations = passes = 0
    for _ in range(BUDGET_ROUNDS):
        say(f"exchange search within {budget:.0f} s")
        try:
            result = timed_exchange(scorer, budget, fixed, max_passes, min_statics=min_statics, masks=masks,
                              remount_s=remount_s, start=start, max_statics=max_statics,
                              min_level_axes=min_level_axes, level_cost=chamber_cost(config))
        except UserError:
            return None
        evaluations += result.evaluations
        passes += result.passes
        entries, specs = _segments_of(result.chosen, cands, masks, config.chamber, result.order)
        scheme = Scheme(name, "designed by station design", "docs/design.md", {}, tuple(specs), centred=centred)
        plan = compile_scheme(scheme, config)
        if plan.duration_s <= budget_s * 1.0005:
            return result, entries, specs, scheme, plan, evaluations, passes
        budget -= max(2.0 * (plan.duration_s - budget_s), 10.0)
        start = result.chosen
    return None


def criterion_of(prediction: Prediction, criterion: str) -> float:
    """The criterion (search.Scorer.value_of's definition) of a prediction's covariance."""
    crit, which = parse_criterion(criterion, prediction.names)
    sub = prediction.covariance[np.ix_(which, which)]
    if crit.kind == "A":
        return float(np.trace(sub))
    if crit.kind == "worst":
        return float(np.sqrt(np.max(np.diag(sub))))
    sign, logdet = np.linalg.slogdet(sub)
    return float(logdet) if sign > 0 else math.inf


def efficiency(design_value: float, other_value: float, criterion: str, parameters: int) -> float:
    """How much better the design is than another scheme by the criterion, as a ratio > 1 when
    better: D: (det C_other / det C_design)^(1/p) (D-efficiency); A: trace ratio; worst: 1σ ratio."""
    if criterion == "D":
        return float(np.exp((other_value - design_value) / parameters))
    return float(other_value / design_value)
