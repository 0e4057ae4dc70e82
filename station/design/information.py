"""The Fisher information each candidate segment brings, from the estimator's own model.

All candidates are recorded once on the simulated bench without noise (the truth of the
Monte Carlo, station/simulate/montecarlo.py), summarised, and the least-squares model
(station/estimate/lsq.py) is built on them with the noise stated (the white noise densities
and the table's angle error): its whitened Jacobian J at the start point is the square root of
the information.  The rows of one candidate (a static, or a +/- rotation pair) touch the base
and effect parameters and the bench's mounting offset (the shared columns G), the candidate's
own nuisances (a static's attitude, a rotation's phases: eliminated here, per candidate) and
its rotation axis' nuisances (tangent, gravity along it, Earth rate: columns A of its axis
group, shared by every rotation about that axis, eliminated when a design is scored).  So the
information of a design is a sum over its candidates, each a small matrix:
    static s with dwell T:      T * m_s              (G x G; information per second)
    rotation pair c, group k:   M_c                  ((G+A_k) x (G+A_k))
and the information of G is  sum_s T_s m_s + sum_k Schur_A(sum_{c in k} M_c + W_k), W_k the
axis' own prior rows.  A static's information is linear in its dwell: white noise, its mean's
variance sigma^2 / n (the noise model's pose terms are zero for white noise); a rotation's is
not (its gyro integral carries the encoder's angle error, whatever its length), so each
rotation length is a candidate of its own.
"""
from __future__ import annotations

import copy
from dataclasses import dataclass, field

import numpy as np

from station.io.scheme import Scheme
# the effects whose terms carry the square of (T - T_ref): the library's bias curve and the scale
# factors' second order (station/model/unlisted.py); the others are linear in it
from station.model.temperature import SQUARED_IN_TEMPERATURE

# a static's rows that are priors on its attitude (the table's angles; the weak one), not data:
# their information does not grow with the dwell
PRIOR_QUANTITIES = ("attitude_prior", "weak_prior")
UNIT_DWELL_S = 10.0          # the dwell the statics are simulated with (information per second x this)


@dataclass
class Noise:
    """The noise the design is for (white densities and the table's angle error)."""
    accel_noise_ug: float = 100.0        # µg/√Hz
    gyro_noise_dph: float = 0.03         # °/h/√Hz
    table_angle_arcsec: float = 2.0      # 1σ, every encoder angle
    accel_disturbance_ug: float = 50.0   # 1σ white acceleration disturbance per sample
    source: str = "defaults (the Monte Carlo's)"

    def settings(self):
        from station.simulate.montecarlo import Settings

        return Settings(accel_noise_ug=self.accel_noise_ug, gyro_noise_dph=self.gyro_noise_dph,
                        table_angle_arcsec=self.table_angle_arcsec,
                        accel_disturbance_ug=self.accel_disturbance_ug)


@dataclass
class Parameters:
    """The reported parameters: names, units, their columns in the shared block G, the factor
    from the model's internal unit to the reported one (scale factors: ppm)."""
    names: list
    units: list
    columns: np.ndarray            # indices into G
    factors: np.ndarray
    typical: np.ndarray            # an effect parameter's typical size (reported unit), inf for base
    effects: list | None = None    # the effect id of each (None for the base model's)


@dataclass
class Information:
    """Per candidate key its information block (module doc)."""
    shared: int                                    # |G|
    parameters: Parameters
    static: dict = field(default_factory=dict)     # key -> (G x G) per second
    # attitudes="table": key -> (data per second, prior), each ((G+a) x (G+a)) over G and the
    # static's own attitude columns (a), eliminated when the dwell is known (static_information)
    static_parts: dict = field(default_factory=dict)
    attitudes: str = "unknown"
    rotation: dict = field(default_factory=dict)   # key -> (group key, ((G+4) x (G+4)))
    group_prior: dict = field(default_factory=dict)  # group key -> ((G+4) x (G+4))
    # temperature_powers (timeline=True): per column of G the power of the temperature difference
    # its Jacobian carries (0: none; 1: a linear coefficient; 2: a quadratic one).  The blocks
    # above are then at a temperature difference of 1 degC everywhere; a candidate at dT has
    # them scaled by dT^power on those rows and columns (at_temperature)
    temp_power: np.ndarray | None = None
    temperature: object = None                     # the temperature model T(t) (the simulated bench's)
    clock: tuple = (0.0, 0.0)                      # the dry run's (gap before a segment, sample rate[,
                                                   #   its recorded ramps' acceleration deg/s^2])
    # the bench's clock when the scheme starts: the configured warm-up's end on the simulated IMU
    # powered on at 0 (station.simulate.dryrun.warmup_seconds; 0 without a warm-up), s
    start_s: float = 0.0
    # per candidate key the temperature difference it had in the candidates' own capture (the
    # information before timeline=True: the search's first stage ranks on it, search.Scorer.natural)
    natural_dt: dict = field(default_factory=dict)
    # effects linear in the time (bias_drift, its time_shear): (drift column, bias column, per
    # second) over G: a candidate recorded s seconds later than in the candidates' capture has
    # its block moved by at_time; natural_time: per candidate key its time in that capture less
    # its reference there (the chunk's statics' mean time, as the effect's setup takes it), s
    time_shear: list = field(default_factory=list)
    natural_time: dict = field(default_factory=dict)
    # the reported parameters each chunk's model has (the first: the capture's own segments in
    # station design --from), and the union's shared columns by name (column_names)
    chunk_parameters: list = field(default_factory=list)
    column_names: list = field(default_factory=list)
    # the axis groups (keys of group_prior) that eliminate columns of their own beyond the axis'
    # (a vertical group's vibration across the axis: _vertical_own); their complement is taken by
    # group_schur, cleaned of rounding
    own_columns: dict = field(default_factory=dict)     # group key -> how many (the block's last)


def temperature_powers(effects: list, parameters: "Parameters", shared: int) -> np.ndarray | None:
    """Per column of G the power of (T - T_ref) in its Jacobian: the parameters of the effects in
    the temperature's difference from a reference (station.model.temperature.TemperatureReferenced:
    temperature_bias, scale_temperature linear, temperature_bias_quadratic quadratic); None when
    the model has none, or has another effect that needs the temperature (its columns could not be
    scaled: such a model is informed on the candidates' own timeline, as before)."""
    from station.model.temperature import TemperatureReferenced

    if not any("temperature" in getattr(e, "needs", ()) for e in effects):
        return None
    if not all(isinstance(e, TemperatureReferenced) for e in effects if "temperature" in getattr(e, "needs", ())):
        return None
    power = np.zeros(shared, int)
    at = {n: c for n, c in zip(parameters.names, parameters.columns)}
    for e in effects:
        if isinstance(e, TemperatureReferenced):
            for p in e.params:
                power[at[p.name]] = temperature_power(e)
    return power


def temperature_power(effect) -> int:
    """The power of (T - T_ref) in a TemperatureReferenced effect's terms (1 or 2).  Before the
    fifteenth session every effect but temperature_bias_quadratic counted as linear, so the
    unlisted scale-in-T^2 effects were placed on the timeline as if linear (their information at
    dT scaled by dT, not dT^2)."""
    return 2 if getattr(effect, "id", "") in SQUARED_IN_TEMPERATURE else 1


def squared_in_temperature(effects) -> bool:
    """A model with a term in the square of the temperature difference (a chamber design then
    offers a middle setpoint too: designer.chamber_levels)."""
    from station.model.temperature import TemperatureReferenced

    return any(isinstance(e, TemperatureReferenced) and temperature_power(e) == 2 for e in effects)


def at_temperature(M: np.ndarray, power: np.ndarray, dt_c: float) -> np.ndarray:
    """A candidate's information block computed at dT = 1 degC (Information.temp_power) moved to
    dT = ``dt_c``: the temperature columns' Jacobian is dT^power times theirs at 1 (a segment's
    summaries carry one temperature, its mean: station/estimate/summaries.py), and nothing else
    depends on it (the simulated IMU's temperature coefficients are zero), so the block is
    Lambda M Lambda, Lambda = diag(dT^power) on G and 1 on the block's own nuisance columns."""
    lam = np.ones(M.shape[0])
    lam[:len(power)] = np.where(power > 0, float(dt_c) ** power, 1.0)
    return M * np.outer(lam, lam)


def at_time(M: np.ndarray, shear: list, delta_s: float) -> np.ndarray:
    """A candidate's information block moved ``delta_s`` seconds later relative to the reference of
    the effects in the time (Information.time_shear): each drift column's Jacobian gains delta_s x
    factor x its bias column's (a drift d over s seconds adds the bias d s), so the block is
    T^T M T, T = I + delta_s K (K: the bias column into the drift column, K^2 = 0) -- exact, as
    the drift is linear in the time and its columns are in G (they commute with the elimination of
    a candidate's own nuisances and its axis group's)."""
    if not shear or not delta_s:
        return M
    out = np.array(M, dtype=float, copy=True)
    for d, b, k in shear:                        # columns: M T
        out[:, d] += (delta_s * k) * out[:, b]
    for d, b, k in shear:                        # rows: T^T (M T)
        out[d, :] += (delta_s * k) * out[b, :]
    return out


def time_shear_of(effects, names: list) -> list:
    """Information.time_shear from the effects' time_shear() and the union's column names."""
    at = {n: k for k, n in enumerate(names)}
    out = []
    for e in effects:
        for param, block, axis, per_s in (e.time_shear() if hasattr(e, "time_shear") else ()):
            d, b = at.get(f"{e.id}:{param}"), at.get(f"{block}[{axis}]")
            if d is not None and b is not None:
                out.append((d, b, float(per_s)))
    return out


def _segment_times(model, chunk, owner) -> dict:
    """Per candidate key of a chunk its time less the time effects' reference in the chunk's
    capture (Information.natural_time): the mean of its segments' mean sample times, counted as
    the effect's setup counts them (from the earliest segment's, less the statics' mean)."""
    e = next((x for x in model.effects if hasattr(x, "time_shear")), None)
    if e is None:
        return {}
    s = model.s
    mids = {x.name: x.t_mid_s for x in (*s.statics, *s.rotations) if np.isfinite(x.t_mid_s)}
    t0 = min(mids.values()) if mids else 0.0
    by_key: dict = {}
    for name, key in owner.items():
        if name in mids:
            by_key.setdefault(key, []).append(mids[name])
    return {key: float(np.mean(t)) - t0 - float(e.reference_s) for key, t in by_key.items() if key[0] != "anchor"}


def _after_the_step(effect):
    """``effect`` for segments recorded after the capture's end (information's ``first_times``):
    a bias step (a located step time, bias_step) before all of them; any other as it is."""
    if getattr(effect, "id", "") != "bias_step":
        return effect
    e = copy.deepcopy(effect)
    e.locate(-1e12, "before every segment added after the capture")
    return e


def ramp_accel_of(config) -> float:
    """The recorded ramps' acceleration on the simulated bench (deg/s^2): the configured table's
    (station.simulate.dryrun.table_ramp_accel), the dry run's default without a configuration."""
    from station.simulate import dryrun

    return dryrun.table_ramp_accel(config.table) if config is not None else dryrun.RAMP_ACCEL_DPS2


def quiet_truth(noise: Noise, config=None):
    """The simulated IMU of the Monte Carlo without noise, placed as the configured table
    places it (table.imu_offset_m), for the Jacobian."""
    from station.simulate.montecarlo import make_truth

    truth = copy.deepcopy(make_truth(noise.settings()))
    truth.accel.noise_density = truth.gyro.noise_density = 0.0
    truth.bench.accel_disturbance_ug = truth.bench.table_angle_error_arcsec = 0.0
    if config is not None and config.table.imu_offset_m is not None:
        truth.bench.lever_arm_m = np.asarray(config.table.imu_offset_m, float)
    return truth


def model_of(scheme: Scheme, effects: list, noise: Noise, truth, geometry: dict | None = None,
             attitudes: str = "unknown", seed: int = 0, chamber=None, appended=(), ramp_accel_dps2=None,
             warmup=None, times=None, temperatures=None):
    """The least-squares model of the noiseless capture of ``scheme`` with the noise stated, as
    station.simulate.montecarlo.cramer_rao weights it: (model, capture).  ``seed``: the simulated
    bench's geometry (each static's heading, each rotation axis' heading and roll: drawn at
    random by the simulator, as a real table's azimuths are unknown to the estimator).
    ``appended``: the segments recorded by a later ``run --append``: their names (``appended: 1``
    in the manifest), or {name: N} (the N-th extension's, as the manifest numbers them: a capture
    already extended once, then extended again): their rotations are axis groups of their own per
    extension, as the estimator reads them (summaries: one group per body axis and session).
    ``times``: {segment name: its mean sample time, s} in place of the simulated bench's (station
    design --from: the capture's own segments at theirs, the extension's after the capture's end;
    the effects in the time read them: bias_drift), or {name: (that time, the span from its first
    sample to its last, s)} (a static simulated at another dwell than its own: where a bias step
    falls inside it).  ``temperatures``: {segment name: its mean temperature, degC} likewise (the
    effects in the temperature read them)."""
    from station.estimate import lsq
    from station.estimate.summaries import summarise
    from station.simulate import dryrun

    capture = dryrun.simulate_capture(scheme, truth, seed, geometry, chamber=chamber, ramp_accel_dps2=ramp_accel_dps2,
                                      warmup=warmup)
    sessions = appended if isinstance(appended, dict) else {name: 1 for name in appended}
    for seg in capture.segments:
        if sessions.get(seg.name):
            seg.extra["appended"] = int(sessions[seg.name])
    capture.extra["noise_free"] = True          # (no data-fault scan: station/estimate/data_faults.py)
    s = summarise(capture, table_angle_arcsec=noise.table_angle_arcsec)
    if times:
        for x in (*s.statics, *s.rotations):
            if x.name in times:
                v = times[x.name]
                if isinstance(v, tuple):        # (mean sample time, span from first to last sample)
                    x.t_mid_s, x.duration_s = float(v[0]), float(v[1])
                else:
                    x.t_mid_s = float(v)
    if temperatures:
        for x in (*s.statics, *s.rotations):
            if x.name in temperatures:
                x.temp_c = float(temperatures[x.name])
    fs = s.sample_rate_hz
    accel_sigma = np.hypot(noise.accel_noise_ug * np.sqrt(fs), noise.accel_disturbance_ug)
    s.accel_sigma = np.full(3, accel_sigma * 9.80665e-6)
    s.gyro_sigma = np.full(3, noise.gyro_noise_dph * np.sqrt(fs) / 3600.0)
    return lsq.Model(s, [copy.deepcopy(e) for e in effects], attitudes=attitudes), capture


def _shared_columns(model) -> np.ndarray:
    local = set(model.local_columns().tolist())
    return np.array([c for c in range(model.layout.size) if c not in local], dtype=int)


def parameters_of(model, shared: np.ndarray) -> Parameters:
    """The reported parameters (lsq._reported_index's order and units; scale factors in ppm)."""
    from station.estimate import lsq

    class _R:               # _reported_index reads only .model
        pass

    r = _R()
    r.model = model
    names, index, factors, units_ = lsq._reported_index(r, "m/s^2", "deg/s")
    where = {int(c): k for k, c in enumerate(shared)}
    factors = np.array(factors, float)
    units_ = list(units_)
    typical = np.full(len(names), np.inf)
    for k, n in enumerate(names):
        if "_scale_" in n and units_[k] == "1":
            factors[k], units_[k] = 1e6, "ppm"          # relative (the scale is ~1)
    effect_of = [None] * len(names)
    at = 21
    for e in model.effects:
        for p in e.params:
            typical[at] = p.typical
            effect_of[at] = e.id
            at += 1
    keep = [k for k, c in enumerate(index) if int(c) in where]     # (a candidate group's own offsets: nuisances)
    return Parameters([names[k] for k in keep], [units_[k] for k in keep],
                      np.array([where[int(index[k])] for k in keep], dtype=int), factors[keep], typical[keep],
                      [effect_of[k] for k in keep])


def column_names(model, shared: np.ndarray) -> list:
    """A name for each shared column that means the same in every model of the same effects: a
    block's name and place (the base model's, the mounting offset's), an effect parameter's own
    name.  A bench effect's parameters are set from the segments recorded (table_wobble one pair
    per table axis, table_vibration_once_per_rev six per table axis and rate): each chunk of
    candidates has the columns of the table axes and rates it turns at, named alike where they
    are the same parameter (information() takes their union)."""
    out = {}
    for block, sl in model.layout.blocks.items():
        if block.startswith("effect:"):
            e = next(x for x in model.effects if x.id == block[len("effect:"):])
            for k, p in enumerate(e.params):
                out[sl.start + k] = f"{e.id}:{p.name}"
        else:
            for k in range(sl.stop - sl.start):
                out[sl.start + k] = f"{block}[{k}]"
    return [out[int(c)] for c in shared]


_NONE = np.zeros(0, dtype=int)


def _is_capture_key(key) -> bool:
    """A key of the capture's own segments (station design --from: ("capture", ...))."""
    return isinstance(key[0], tuple) and bool(key[0]) and key[0][0] == "capture" or key[0] == "capture"


def _anchored(segments: list, owner: dict, n: int) -> list:
    """With an offset per axis group (rotation_axis_offsets) the first group takes the model's
    common mounting offset and has none of its own: a chunk of candidates gets an anchor turn
    (about an axis no candidate has, its rows not used) before its first rotation, so that every
    candidate's group has its own, as an appended rotation has (information()).  A chunk whose
    first rotation is the capture's keeps it (the capture's first group is the first group)."""
    from station.io.scheme import RotationSpec

    first = next((k for k, p in enumerate(segments) if isinstance(p, RotationSpec)), None)
    if first is None or _is_capture_key(owner[segments[first].name]):
        return segments
    r = segments[first]
    axis = tuple(float(x) for x in np.array([1.0, 2.0, 4.0]) / np.sqrt(21.0))
    rate = abs(float(r.rate_dps))
    anchor = [RotationSpec(f"anchor{n}_{d}", axis, sign * rate, 360.0 / rate,
                           axis_elevation_deg=r.axis_elevation_deg) for d, sign in (("p", 1.0), ("m", -1.0))]
    for a in anchor:
        owner[a.name] = ("anchor", "rotation", n)
    return segments[:first] + anchor + segments[first:]


def _group_offsets(model, owner: dict) -> dict:
    """{axis group: its offset's columns} of the groups of candidates (not the capture's own) with
    an offset of their own (rotation_axis_offsets): nuisances of that group."""
    e = next((x for x in model.effects if x.id == "rotation_axis_offsets"), None)
    if e is None:
        return {}
    sl = model.layout["effect:rotation_axis_offsets"]
    keys: dict = {}
    for r in model.s.rotations:
        keys.setdefault(int(r.group), []).append(owner.get(r.name, ("anchor",)))
    out = {}
    for n, g in enumerate(e.groups):
        if not any(_is_capture_key(k) for k in keys.get(int(g), [])):
            out[int(g)] = np.arange(sl.start + 3 * n, sl.start + 3 * n + 3)
    return out


def _vertical_own(model, owner: dict) -> dict:
    """{axis group: its own columns of table_vibration_once_per_rev} for the candidates' groups
    about a vertical axis: the vibration's part across such an axis is one (P, Q) per table axis,
    rate, axis group and mounting (station/model/table_vibration.py), four columns that only the
    turns of that group see -- a group's own nuisances, as its offset is (_group_offsets), not
    shared columns: eliminated with the group's nuisances (search: the Schur complement of each
    axis group), so that G stays the shared parameters' (the sixteenth session's vertical model
    made every vertical candidate bring four columns of its own into G: the search's matrices
    grew with the candidates, docs/design.md).  The capture's own groups (station design --from)
    keep theirs as parameters; an anchor's (no rows used) are dropped with them."""
    e = next((x for x in model.effects if x.id == "table_vibration_once_per_rev"), None)
    if e is None or not getattr(e, "vertical_across", None):
        return {}
    sl = model.layout["effect:table_vibration_once_per_rev"]
    across0 = sl.start + 6 * len(e.groups) + 2 * len(e.vertical_axial)
    rotations = {int(r.index): r for r in model.s.rotations}
    by_group: dict = {}           # position in vertical_across -> the axis groups and keys of its turns
    for index, n in e.vacross_of.items():
        r = rotations[int(index)]
        by_group.setdefault(n, set()).add((int(r.group), _is_capture_key(owner.get(r.name, ("anchor",)))))
    out: dict = {}
    for n, members in sorted(by_group.items()):
        groups = {g for g, _ in members}
        if len(groups) != 1 or any(capture for _, capture in members):
            continue              # (shared by two axis groups, or the capture's: a parameter)
        out.setdefault(groups.pop(), []).extend(range(across0 + 4 * n, across0 + 4 * n + 4))
    return {g: np.array(cols, dtype=int) for g, cols in out.items()}


def _offset_lines(model) -> list:
    """[(unit axis, table axis, its offset's three column names or None)] of the capture's own
    chunk (the first, station design --from): each axis line the capture turned about and the
    columns of its offset (rotation_axis_offsets), None for the first line, whose offset is the
    common one (the model's mounting offset)."""
    e = next((x for x in model.effects if x.id == "rotation_axis_offsets"), None)
    if e is None:
        return []
    out, seen = [], set()
    for r in model.s.rotations:
        g = e.group_of.get(int(r.index))
        if g is None or g in seen:
            continue
        seen.add(g)
        a = np.asarray(r.axis_body, float)
        cols = ([f"{e.id}:axis{g}_offset_{c}" for c in "xyz"] if g in e.groups else None)
        out.append((a / np.linalg.norm(a), getattr(r, "table_axis", None), cols))
    return out


def _capture_lines(model, group_own: dict, lines: list) -> tuple:
    """({column: the capture's column name}, [groups whose offset is the common one]) for the
    candidates' groups about an axis line the capture turned about (the same body axis and table
    axis): their offset is the capture's group's, as the estimator shares it with turns appended
    later (station.model.axis_offsets.offset_groups; docs/design.md, fifteenth session), not a
    nuisance of their own; about the capture's first line it is the common offset (none of its
    own: the columns are fixed at zero)."""
    rename, fixed = {}, []
    for g, cols in group_own.items():
        r = next((r for r in model.s.rotations if int(r.group) == g), None)
        if r is None:
            continue
        a = np.asarray(r.axis_body, float)
        a = a / np.linalg.norm(a)
        k = getattr(r, "table_axis", None)
        hit = next((names for b, kk, names in lines if kk == k and np.allclose(a, b, atol=1e-6)), False)
        if hit is None:
            fixed.append(g)
        elif hit:
            rename.update({int(c): n for c, n in zip(cols, hit)})
            fixed.append(g)              # (no longer the group's own nuisance)
    return rename, fixed


def _group_key(gkey: tuple, taken: set) -> tuple:
    """The search's key of an estimator axis group (Information.rotation's, group_prior's): the
    (axis, elevation) of its first turn, unless another group has that key already (the capture's
    turns about one axis and elevation recorded in two sessions, run --append: two groups, each
    with its axis nuisances and prior; one key overlaid the second group's nuisances on the
    first's and kept one prior), then that key with a count.  Every turn of one estimator group
    takes the group's key (search.Scorer.group), so its nuisances and prior are counted once."""
    if gkey not in taken:
        return gkey
    n = 1
    while gkey + (n,) in taken:
        n += 1
    return gkey + (n,)


def _embed(M: np.ndarray, idx: np.ndarray, G: int) -> np.ndarray:
    """A block over (a chunk's shared columns + its own nuisances) placed over (the union's shared
    columns + the same nuisances): the chunk's column j at idx[j]; a column the chunk has not (a
    rate it does not turn at) gets no information from it."""
    g = len(idx)
    if g == G and np.array_equal(idx, np.arange(G)):
        return M
    n = M.shape[0] - g
    where = np.concatenate([idx, G + np.arange(n)])
    out = np.zeros((G + n, G + n))
    out[np.ix_(where, where)] = M
    return out


def _reduce(J_rows, keep_cols, drop_cols) -> np.ndarray:
    """The rows' information about keep_cols with drop_cols eliminated (Schur complement)."""
    A = J_rows[:, keep_cols]
    if len(drop_cols):
        B = J_rows[:, drop_cols]
        q, rr = np.linalg.qr(B)
        keep = np.abs(np.diag(rr)) > 1e-12 * max(1e-300, np.max(np.abs(np.diag(rr)), initial=0.0))
        q = q[:, keep]
        A = A - q @ (q.T @ A)
    return A.T @ A


def schur(S: np.ndarray, G: int) -> np.ndarray:
    """The information about the first G columns of S with the rest eliminated (a nuisance held
    only by its prior is kept: the pseudo-inverse on the unit-diagonal scaling)."""
    A = S[G:, G:]
    B = S[:G, G:]
    d = np.sqrt(np.diag(A))
    d[d == 0] = 1.0         # (scaled to unit diagonal: a nuisance held only by its prior is kept)
    Bs = B / d
    return S[:G, :G] - Bs @ np.linalg.pinv(A / np.outer(d, d), rcond=1e-13, hermitian=True) @ Bs.T


# an eigenvalue of a group's complement scaled by its information before the elimination (unit
# diagonal) below this is rounding, not information (group_schur)
ROUNDING = 1e-12


def group_schur(S: np.ndarray, G: int, own: int = 0, ridge: float = 0.0) -> np.ndarray:
    """schur(S, G) of an axis group whose last ``own`` columns are a vertical turn's vibration across
    the axis (_vertical_own), taken as the search took it while they were columns of G: the axis'
    columns eliminated first, then ``ridge`` (search.RIDGE) of their own diagonal added to them, as
    search.covariance_of adds it to every column of its unit-diagonal information, then they are
    eliminated -- and cleaned of rounding.  Those columns take nearly all a vertical turn tells of
    some shared columns (the size effect's constant across the axis is the vibration's: the
    positions keep ~1e-13 of their information before the elimination), so the complement's
    entries there are differences of numbers 1e13 times their size, and rounding leaves noise of
    ~1e-16 x the information before the elimination, of either sign: an indefinite complement whose
    noise, scaled by the design's own small diagonal there, gave negative variances (the known-
    attitude design's search stopped at 7 statics with a criterion of nan).  In the information
    before the elimination scaled to a unit diagonal the noise is ~1e-14 (n eps); an eigenvalue of
    the scaled complement below ROUNDING (1e-12, 100x that) is set to zero: what stays is the
    complement to 1e-12 of the information that entered it."""
    n = S.shape[0]
    if own:
        order = np.concatenate([np.arange(G), np.arange(n - own, n), np.arange(G, n - own)])
        S1 = schur(S[np.ix_(order, order)], G + own)
        if ridge:
            S1[G:, G:] += ridge * np.diag(np.diag(S1)[G:])
        R = schur(S1, G)
    else:
        S1, R = S, schur(S, G)
    d = np.sqrt(np.clip(np.diag(S)[:G], 0.0, None))
    d[d == 0] = 1.0
    Rs = R / np.outer(d, d)
    w, V = np.linalg.eigh(0.5 * (Rs + Rs.T))
    w = np.where(w > ROUNDING, w, 0.0)
    out = (V * w) @ V.T * np.outer(d, d)
    if ridge:
        # the shared columns' ridge as it was: covariance_of adds ridge x the design's diagonal, which
        # held this group's information before its own columns were eliminated (diag S1); the part
        # the elimination took is added here, so the ridge is the same
        out[np.diag_indices(G)] += ridge * np.clip(np.diag(S1)[:G] - np.diag(R), 0.0, None)
    return out


def static_information(info: Information, key, dwell_s: float) -> np.ndarray:
    """A static's information about G with a dwell of ``dwell_s``: its data rows scale with the
    dwell and its attitude's prior rows do not (the table's angles, attitudes="table"; the weak
    prior on an unknown attitude's rotation), so the attitude is eliminated (Schur complement)
    at that dwell: (dwell D + P) reduced to G (the table's prior scaled with the dwell, as an
    earlier attempt did, was 10 % off the estimator's 1σ for sizeeffect's segments)."""
    D, P = info.static_parts[key]
    return schur(D * dwell_s + P, info.shared)


def information(chunks: list, effects: list, noise: Noise, config=None,
                geometry: dict | None = None, centred: bool = False,
                attitudes: str = "unknown", timeline: bool = False, appended=None, times: bool = False,
                first_times: dict | None = None) -> Information:
    """The information of every candidate.  ``chunks``: lists of (key, spec) where spec is a
    StaticSpec (dwell UNIT_DWELL_S) or a RotationSpec pair (``pair`` of two specs), each chunk
    a capture of its own (rotations about one body axis at two elevations go in different
    chunks: the estimator gives one axis group one gravity angle).

    ``timeline``: with effects in the temperature's difference from a reference
    (temperature_powers), every candidate's information is computed at dT = 1 degC (the
    candidates' capture recorded at one constant temperature, the effects' reference 1 degC
    below it), so that the search can place it at the temperature it will have in the designed
    scheme's own timeline (at_temperature; station/design/timeline.py) -- not at the one it had
    in the candidates' capture, whose order is not the design's (the twelfth session's temperature
    design: the search's worst 1σ 3.24 µg/°C, the estimator's fit of the written scheme 7.00).
    With effects in the time (bias_drift's time_shear), each candidate's time in that capture
    (natural_time) and the columns' shear (time_shear), so that the search moves it to the time it
    will have in the designed scheme (at_time; nineteenth session: a 900 s design ranked on the
    candidates' times at a worst drift 1σ of 1.24 µg/h, the estimator's fit of it 84.8).

    ``appended``: {segment name: N} of the capture's own segments recorded by its N-th ``run
    --append`` (station design --from on a capture already extended: sequential.capture_sessions),
    so that the capture's chunk has the estimator's axis groups (model_of).

    ``times``: the effects in the time only (natural_time, time_shear; the temperature's as
    without ``timeline``): station design --from places every candidate at its time after the
    capture's end, and the capture's own segments at theirs (sequential.py; twentieth session).

    ``first_times``: {segment name: mean sample time} of the first chunk's segments (station
    design --from: the capture's own, at their times on its clock), and with it a bias step
    (bias_step, its time located in the capture: sequential.locate_step) is where it was located
    for the first chunk and before every segment of the others (recorded after the capture's end:
    all after the step; twentieth session)."""
    from station.simulate import dryrun

    truth = quiet_truth(noise, config)
    ramp_accel = ramp_accel_of(config)
    # the configured warm-up (station.yaml warmup:): the candidates' capture and the design's
    # timeline start at its end on the simulated IMU, as the dry run and station montecarlo record
    warmup = config.warmup if config is not None else None
    warm = copy.deepcopy(truth.temperature)
    power = None
    if timeline:
        from station.model.temperature import TemperatureReferenced

        if any(isinstance(e, TemperatureReferenced) for e in effects):
            truth.temperature.warmup_delta_c = truth.temperature.drift_c_per_h = 0.0
    info = None
    union: dict = {}                 # column name (column_names) -> its place in the union's G
    merged = None                    # the union's reported parameters
    placed: list = []                # (dict, key, the chunk's idx): the blocks to embed at the end
    # an offset per axis group (rotation_axis_offsets): a candidate's axis group has an offset of its
    # own, eliminated with the group's nuisances -- except about an axis line the capture turned
    # about (station design --from), where it is the capture's group's (_capture_lines: the
    # estimator shares it with turns appended later, station.model.axis_offsets.offset_groups);
    # the capture's own groups' offsets stay parameters
    offsets_of_groups = any(e.id == "rotation_axis_offsets" for e in effects)
    lines = None                     # the capture's axis lines and their offsets (_offset_lines)
    later = [_after_the_step(e) for e in effects] if first_times is not None else effects
    taken: set = set()               # the axis groups' keys given so far (_group_key)
    for k_chunk, chunk in enumerate(chunks):
        segments, owner = [], {}
        for key, spec in chunk:
            parts = spec if isinstance(spec, tuple) else (spec,)
            for p in parts:
                segments.append(p)
                owner[p.name] = key
        if offsets_of_groups:
            segments = _anchored(segments, owner, len(placed))
        scheme = Scheme("candidates", "", "", {}, tuple(segments), centred=centred, table=True)
        model, _ = model_of(scheme, effects if k_chunk == 0 else later, noise, truth, geometry, attitudes,
                            ramp_accel_dps2=ramp_accel, appended=appended or (), warmup=warmup,
                            times=first_times if k_chunk == 0 else None)
        shared = _shared_columns(model)
        group_own = _group_offsets(model, owner)
        rename: dict = {}
        if offsets_of_groups and not group_own and lines is None:
            lines = _offset_lines(model)            # the capture's own chunk (station design --from)
        if group_own:
            mine = set(c for cols in group_own.values() for c in cols.tolist())
            rename, fixed = _capture_lines(model, group_own, lines or [])
            shared = np.array([c for c in shared if int(c) not in mine], dtype=int)
            shared = np.concatenate([shared, np.array(sorted(rename), dtype=int)]).astype(int)
            for g in fixed:
                group_own.pop(g)
        vertical_own = _vertical_own(model, owner)
        if vertical_own:
            mine = set(c for cols in vertical_own.values() for c in cols.tolist())
            shared = np.array([c for c in shared if int(c) not in mine], dtype=int)
            for g, cols in vertical_own.items():
                group_own[g] = np.concatenate([group_own.get(g, _NONE), cols]).astype(int)
        names_c = [rename.get(int(c), n) for c, n in zip(shared, column_names(model, shared))]
        for n in names_c:
            union.setdefault(n, len(union))
        idx = np.array([union[n] for n in names_c], dtype=int)
        p_c = parameters_of(model, shared)
        for k, c in enumerate(p_c.columns):          # a candidate's offset that is the capture's
            if int(shared[c]) in rename:
                p_c.names[k] = rename[int(shared[c])].split(":", 1)[1]
        if merged is None:
            merged = Parameters(list(p_c.names), list(p_c.units), idx[p_c.columns], np.array(p_c.factors, float),
                                np.array(p_c.typical, float), list(p_c.effects))
            power = temperature_powers(model.effects, p_c, len(shared)) if timeline else None
        else:
            known = set(merged.names)
            new = [k for k, n in enumerate(p_c.names) if n not in known]
            merged.names += [p_c.names[k] for k in new]
            merged.units += [p_c.units[k] for k in new]
            merged.columns = np.concatenate([merged.columns, idx[p_c.columns[new]]]).astype(int)
            merged.factors = np.concatenate([merged.factors, np.asarray(p_c.factors, float)[new]])
            merged.typical = np.concatenate([merged.typical, np.asarray(p_c.typical, float)[new]])
            merged.effects += [p_c.effects[k] for k in new]
        if power is not None:
            for e in model.effects:            # dT = 1 degC at every segment
                if hasattr(e, "reference_c"):
                    e.reference_c = float(truth.temperature.start_c) - 1.0
        x = model.x0
        if attitudes == "table":
            # the Jacobian at the noiseless fit's solution: the start leaves the Earth-rate phases of
            # part turns off by enough to move the gyro biases' 1σ by 9 % (sizeeffect's own turns)
            from station.estimate import lsq

            x = lsq._solve(model, x)[0]
        J = model.sparse_jacobian(x).tocsr()
        labels = model.row_labels(x)
        if info is None:
            info = Information(len(shared), merged, attitudes=attitudes)
            if power is not None or ((timeline or times) and any(hasattr(e, "time_shear") for e in model.effects)):
                info.temp_power, info.temperature = power, warm
                info.clock = (float(truth.bench.move_s + truth.bench.settle_s), float(truth.sample_rate_hz),
                              ramp_accel)
                info.start_s = dryrun.warmup_seconds(warmup, warm)
        info.chunk_parameters.append(list(p_c.names))
        if timeline or times:
            info.natural_time.update(_segment_times(model, chunk, owner))
        if power is not None:
            from station.design.timeline import seconds_temperatures

            temps = seconds_temperatures([[p.duration_s for p in (spec if isinstance(spec, tuple) else (spec,))]
                                          for _, spec in chunk], info.temperature, info.clock,
                                         start_s=info.start_s)
            ref = np.mean([t for (_, spec), t in zip(chunk, temps) if not isinstance(spec, tuple)])
            for (key, spec), t in zip(chunk, temps):
                if key[0] != "anchor":
                    info.natural_dt[key] = float(t - ref)
        L = model.layout
        rows_of: dict = {}
        for r, lab in enumerate(labels):
            rows_of.setdefault(lab[0], []).append(r)
        s = model.s
        static_index = {st.name: j for j, st in enumerate(s.statics)}
        rot_index = {r.name: i for i, r in enumerate(s.rotations)}
        by_key: dict = {}
        for name, key in owner.items():
            by_key.setdefault(key, []).append(name)
        groups_used = {}
        for key, names in by_key.items():
            rows = sorted(r for n in names for r in rows_of.get(n, []))
            if not rows or key[0] == "anchor":
                continue
            Jr = J[rows].toarray()
            if names[0] in static_index:
                sl = L[f"static{static_index[names[0]]}"]
                own = np.arange(sl.start, sl.stop)
                keep = np.concatenate([shared, own])
                prior = np.array([labels[r][2] in PRIOR_QUANTITIES for r in rows])
                Jd, Jp = Jr[~prior][:, keep], Jr[prior][:, keep]
                info.static_parts[key] = (Jd.T @ Jd / UNIT_DWELL_S, Jp.T @ Jp)
                placed.append(("static", info.static_parts, key, idx))
            else:
                group = s.rotations[rot_index[names[0]]].group
                axis = L[f"axis{group}"]
                drop = [c for n in names for c in range(L[f"phase{rot_index[n]}"].start,
                                                         L[f"phase{rot_index[n]}"].stop)]
                keep = np.concatenate([shared, np.arange(axis.start, axis.stop), group_own.get(group, _NONE)])
                if group not in groups_used:
                    groups_used[group] = _group_key((key[0], key[1]), taken)
                    taken.add(groups_used[group])
                gkey = groups_used[group]         # (axis, elevation): one per estimator axis group
                info.rotation[key] = (gkey, _reduce(Jr, keep, np.array(drop, int)))
                placed.append(("rotation", info.rotation, key, idx))
        for group, gkey in groups_used.items():
            rows = rows_of.get(f"axis{group}", [])
            axis = L[f"axis{group}"]
            keep = np.concatenate([shared, np.arange(axis.start, axis.stop), group_own.get(group, _NONE)])
            info.group_prior[gkey] = (_reduce(J[rows].toarray(), keep, np.zeros(0, int)) if rows
                                      else np.zeros((len(keep), len(keep))))
            placed.append(("prior", info.group_prior, gkey, idx))
            if group in vertical_own:
                info.own_columns[gkey] = len(vertical_own[group])
    # every block over the union's shared columns (column_names: a bench effect's table axes and
    # rates are those of the chunk's own turns; the base model's columns are the same in all)
    G = len(union)
    for kind, where, key, idx in placed:
        v = where[key]
        if kind == "rotation":
            where[key] = (v[0], _embed(v[1], idx, G))             # (group key, block)
        elif kind == "static":
            where[key] = tuple(_embed(m, idx, G) for m in v)      # (data, prior)
        else:
            where[key] = _embed(v, idx, G)
    info.shared = G
    info.column_names = list(union)
    if power is not None and len(power) != G:
        info.temp_power = temperature_powers(model.effects, merged, G)
    if timeline or times:
        info.time_shear = time_shear_of(model.effects, info.column_names)
    return info
