"""The noise model every data group is weighted with, stated term by term (issue 24, item 1).

The fit's residuals are divided by their noise.  White noise alone (the per-sample standard
deviation from the statics' first differences) is what a sensor on a quiet bench obeys; real
sensors and hand sessions need more, and each term here is measured from the capture or
estimated from the data group it concerns, and said in the file (``fit.noise_model``):

- **white** (per sample, per axis): the statics' first differences (summaries.py).
- **quantisation**: the output step q of each axis (the smallest gap between distinct values when
  every gap is a whole multiple of it).  A dithered output (sample spread above half a step: the
  estimator refuses coarser statics) carries q^2/12 per sample inside the white noise already;
  what is left is the bias of a quantised mean (Widrow): at most (q / pi) exp(-2 pi^2 sigma^2 /
  q^2), taken as a variance of half its square (a uniform phase against the grid).
- **bias instability over a pose**: the bias moves while a pose is held (flicker, random walk,
  a drift).  Each static's first-half mean less its second-half mean, D_j, is N(0, E_j) under
  white noise, E_j = sigma^2 (1/n1 + 1/n2); the Allan variance at half the pose length is D^2/2.
  The part of D that follows the temperature change between the halves or the pose's length (a
  bias that follows temperature or drifts steadily: an effect, not noise) is taken out by
  weighted least squares.  What is left is tested robustly (a pose or two that jump, a bias step
  or a knock, are effects or faults, not a noise every pose shares): per sensor, with its three
  axes pooled, the number of D_j^2 / E_j above chi2(1)'s 95th percentile against the binomial
  count of white noise (Bonferroni over the two sensors, P_TERM in all).  When it exceeds white
  noise beyond chance, the Allan variance left per axis, B^2 = (r - 1) mean_j E_j / 2, r the
  median of D_j^2 / E_j over chi2(1)'s median, is added to
  the variance of every pose mean (a flicker floor: the same for every pose length), and to each
  gyro integral over a rotation or a hand turn as (B T)^2.  Slower wander, over more than a
  pose, is not measured within a pose: when the halves show the bias moving, the sensor's
  static means' group is reweighted by its own scatter between the poses (lsq._reweight).
- **turn angle** (hand turns): the up after a turn against the up before carried through the
  integrated gyro misses by the operator's turn, the gyro's bandwidth and timing during a fast
  turn, its scale nonlinearity: nothing a static can measure.  An explicit 1-sigma per turn
  (degrees, each of the two directions across the up), stated by the user (``turn_sigma_deg``)
  or estimated: Helmert's variance component of the hand-turn group, iterated with the fit
  (station/estimate/lsq.py, ``fit``) until the turns scatter as stated.  An estimated group
  carries no test of the model: the chi-square verdict is then taken over the other groups.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from station.estimate import solver
from station.estimate.arrays import median
from station.estimate.distributions import binom_sf, norm_ppf

P_TERM = 1e-3               # a term is added when white noise alone is this improbable (6 axes in all)
MIN_POSE_SAMPLES = 8        # a pose's halves must have at least 4 samples each
MIN_POSES = 4               # poses needed to measure the bias instability
TURN_ITERATIONS = 8         # reweighting rounds at most
TURN_TOLERANCE = 0.05       # stop when the turns' scatter s^2 is within this of 1
CHI2_1_MEDIAN = 0.454936    # the median of chi2(1)
CHI2_1_EXCEED = 3.841459    # its 95th percentile: exceeded by 5 % of white-noise half-differences
EXCEED_P = 0.05


def stats_binom_sf(k: int, n: int) -> float:
    """P(K >= k) for K ~ Binomial(n, EXCEED_P) (station.estimate.distributions: scipy.special
    costs 0.17 s to import, scipy.stats half a second)."""
    return binom_sf(k, n, EXCEED_P)


@dataclass
class PoseInstability:
    """What the poses' half-differences say, per axis (accel x y z, gyro x y z)."""
    variance: np.ndarray                 # (6,) B^2 added to each pose mean (summary units^2); 0: none
    ratio: np.ndarray                    # (6,) chi2 / dof of the half-differences under white noise
    p_value: np.ndarray                  # (6,)
    poses: int
    regressors: list                     # the names of what was taken out (temperature, drift)
    follows: list = field(default_factory=list)     # (axis, regressor, z) found significant
    sensor_p: np.ndarray = field(default_factory=lambda: np.ones(2))   # (accel, gyro) pooled test


@dataclass
class NoiseModel:
    instability: PoseInstability | None
    lsb: np.ndarray                      # (6,) output step per axis, summary units (0: none seen)
    widrow_variance: np.ndarray          # (6,) the quantised mean's bias, as a variance

    def pose_variance(self) -> np.ndarray:
        """(6,) variance added to every pose mean (summary units^2)."""
        extra = self.widrow_variance.copy()
        if self.instability is not None:
            extra += self.instability.variance
        return extra


AXES = ("accel x", "accel y", "accel z", "gyro x", "gyro y", "gyro z")


def of(s) -> NoiseModel:
    """The noise model of the summaries (computed once per Summaries, then kept on it)."""
    kept = getattr(s, "noise_model", None)
    cached = kept[1] if isinstance(kept, tuple) and kept[0] is s.statics else None
    if cached is None:
        sigma = np.concatenate([np.asarray(s.accel_sigma, float), np.asarray(s.gyro_sigma, float)])
        lsb = _lsb(s.statics)
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            widrow = np.where(lsb > 0, 0.5 * (lsb / np.pi) ** 2 * np.exp(-4.0 * np.pi**2 * sigma**2 / lsb**2), 0.0)
        widrow = np.nan_to_num(widrow)
        cached = NoiseModel(instability=pose_instability(s.statics, sigma), lsb=lsb, widrow_variance=widrow)
        s.noise_model = (s.statics, cached)     # kept with the statics it was computed from
    return cached


def _lsb(statics) -> np.ndarray:
    """Per axis, the output step the statics share (the smallest non-zero one; 0 if none)."""
    steps = np.array([st.lsb for st in statics if getattr(st, "lsb", None) is not None], float).reshape(-1, 6)
    out = np.zeros(6)
    for k in range(6):
        seen = steps[:, k][steps[:, k] > 0]
        out[k] = float(np.min(seen)) if seen.size else 0.0
    return out


def pose_instability(statics, sigma: np.ndarray) -> PoseInstability | None:
    """The bias instability over a pose from the statics' half-differences (module doc)."""
    use = [st for st in statics if getattr(st, "half_diff", None) is not None and st.samples >= MIN_POSE_SAMPLES
           and np.all(np.isfinite(st.half_diff))]
    if len(use) < MIN_POSES or not np.all(np.isfinite(sigma)) or np.any(sigma <= 0):
        return None
    D = np.array([st.half_diff for st in use], float)                       # (S, 6)
    h = np.array([st.samples // 2 for st in use], float)
    E = sigma[None, :] ** 2 * (2.0 / h)[:, None]                            # (S, 6)
    columns, names = [], []
    temps = np.array([st.temp_rate_c_per_s * st.duration_s / 2.0 for st in use], float)
    if np.all(np.isfinite(temps)) and np.ptp(temps) > 0:
        columns.append(-temps)                  # first half less second: minus the change
        names.append("temperature")
    durations = np.array([st.duration_s / 2.0 for st in use], float)
    if np.ptp(durations) > 0.05 * np.mean(durations) or not columns:
        columns.append(-durations)              # a steady drift c: D = -c T / 2
        names.append("drift")
    if len(use) - len(columns) < MIN_POSES - 1:
        columns, names = [], []
    variance, ratio, p, follows, exceed = np.zeros(6), np.zeros(6), np.ones(6), [], np.zeros(6, int)
    for k in range(6):
        w = 1.0 / np.sqrt(E[:, k])
        resid = D[:, k].copy()
        dof = len(use)
        if columns:
            # robust (Huber, at 2 sigma of white noise): a pose that jumps must not tilt the
            # drift and spread its jump over the others
            A = np.column_stack(columns) * w[:, None]
            coef, *_ = np.linalg.lstsq(A, D[:, k] * w, rcond=None)
            coef = solver.huber_linear(A, D[:, k] * w, 2.0, coef)
            resid = D[:, k] - np.column_stack(columns) @ coef
            dof -= len(columns)
            cov = np.linalg.pinv(A.T @ A)
            chi = float(np.sum((resid * w) ** 2)) / max(dof, 1)
            for name, c, v in zip(names, coef, np.diag(cov)):
                z = abs(c) / math.sqrt(v * max(chi, 1.0)) if v > 0 else 0.0
                if z > norm_ppf(1.0 - P_TERM / 24.0):
                    follows.append((AXES[k], name, float(z), float(c)))
        # robust to a pose or two that jump (a bias step, a knock: effects or faults, not a
        # noise that every pose shares): the median of D^2 / E against chi2(1)'s, 0.4549
        u = resid**2 / (E[:, k] * dof / len(use))
        ratio[k] = median(u) / CHI2_1_MEDIAN
        exceed[k] = int(np.sum(u > CHI2_1_EXCEED))
        p[k] = float(stats_binom_sf(exceed[k], len(use)))
        variance[k] = max(0.0, ratio[k] - 1.0) * float(np.mean(E[:, k])) / 2.0
    # the test, per sensor (its three axes pooled): how many half-differences exceed chi2(1)'s
    # 95th percentile, against the binomial count of white noise (Bonferroni over the two
    # sensors); a sensor that passes it adds no term
    sensor_p = np.ones(2)
    for i, k in enumerate((slice(0, 3), slice(3, 6))):
        sensor_p[i] = float(stats_binom_sf(int(np.sum(exceed[k])), 3 * len(use)))
        if sensor_p[i] >= P_TERM / 2.0:
            variance[k] = 0.0
    return PoseInstability(variance=variance, ratio=ratio, p_value=p, poses=len(use), regressors=names,
                           follows=follows, sensor_p=sensor_p)


# ----------------------------------------------------------------------------- reporting

def describe(noise: NoiseModel, accel_to_ug: np.ndarray, gyro_to_dph: np.ndarray | None,
             pose_seconds: float, turn: dict | None, tested: dict | None, between: dict | None = None) -> dict:
    """The file's ``fit.noise_model``: every term in reported units (accel µg, gyro °/h, turns
    degrees).  ``accel_to_ug``/``gyro_to_dph``: (3,) factors from summary units (gyro None: its
    scale unknown, raw counts reported).  ``turn``: {sigma, source, scatter_before} of the hand
    turns' term (lsq.fit), None without one."""
    g_factor = gyro_to_dph if gyro_to_dph is not None else np.ones(3)
    g_unit = "deg/h" if gyro_to_dph is not None else "raw"
    out = {"terms": ["white"]}
    if np.any(noise.lsb > 0):
        out["quantisation"] = {
            "accel_lsb_ug": (noise.lsb[:3] * accel_to_ug).tolist(),
            f"gyro_lsb_{g_unit.replace('/', 'p')}": (noise.lsb[3:] * g_factor).tolist(),
            "mean_bias_ug": (np.sqrt(noise.widrow_variance[:3]) * accel_to_ug).tolist(),
            f"mean_bias_{g_unit.replace('/', 'p')}": (np.sqrt(noise.widrow_variance[3:]) * g_factor).tolist(),
            "note": "q^2/12 per sample is inside the white noise (dithered output); the quantised "
                    "mean's bias is added to each pose mean"}
        out["terms"].append("quantisation")
    inst = noise.instability
    if inst is not None:
        entry = {"poses": inst.poses, "taken_out": inst.regressors,
                 "ratio_to_white": inst.ratio.tolist(), "p_value": inst.p_value.tolist(),
                 "accel_ug": (np.sqrt(inst.variance[:3]) * accel_to_ug).tolist(),
                 f"gyro_{g_unit.replace('/', 'p')}": (np.sqrt(inst.variance[3:]) * g_factor).tolist(),
                 "over_s": pose_seconds}
        if inst.follows:
            entry["follows"] = [{"axis": a, "with": n, "z": z} for a, n, z, _ in inst.follows]
        out["bias_instability"] = entry
        if np.any(inst.variance > 0):
            out["terms"].append("bias instability")
    for group, entry in (between or {}).items():
        unit = "ug" if group == "static accel" else g_unit
        out.setdefault("between_poses", {})[group] = {f"sigma_{unit.replace('/', 'p')}": entry["sigma"],
                                                      "scatter_before": entry["scatter_before"],
                                                      "source": "estimated from the group's scatter"}
        out["terms"].append(f"bias between poses ({group})")
    if turn is not None:
        out["turn_angle_deg"] = {k: v for k, v in turn.items() if v is not None}
        if turn["sigma"] > 0:
            out["terms"].append("turn angle")
    if tested is not None:
        out["tested"] = tested
    return out


def words(noise: NoiseModel, described: dict) -> list[str]:
    """The notes that state the noise model beyond white noise."""
    notes = []
    inst, entry = noise.instability, described.get("bias_instability")
    if inst is not None and np.any(inst.variance > 0):
        g_key = next(k for k in entry if k.startswith("gyro_"))
        parts = []
        for k in range(6):
            if inst.variance[k] > 0:
                value = entry["accel_ug"][k] if k < 3 else entry[g_key][k - 3]
                unit = "ug" if k < 3 else g_key[5:].replace("p", "/")
                parts.append(f"{AXES[k]} {value:.3g} {unit} ({inst.ratio[k]:.3g}x white)")
        notes.append(f"noise model: bias instability over a pose (the poses' half-means differ beyond "
                     f"their white noise, p < {P_TERM:g}; {', '.join(parts)}; measured over "
                     f"{entry['over_s']:.3g} s poses, slower wander not measured), added to every pose "
                     "mean and to the gyro integrals")
    for axis, name, z, _ in (inst.follows if inst is not None else []):
        notes.append(f"the {axis} bias moves within the poses with the {'temperature' if name == 'temperature' else 'time (a steady drift)'} "
                     f"({z:.3g} sigma): an effect, not noise ("
                     + ("--add temperature_bias" if name == "temperature" else "a bias drift") + ")")
    for group, entry in described.get("between_poses", {}).items():
        key = next(k for k in entry if k.startswith("sigma_"))
        unit = key[6:].replace("p", "/")
        notes.append(f"noise model: the {group.replace('static ', '')} bias moves between the poses by "
                     f"{', '.join(f'{v:.3g}' for v in entry[key])} {unit} (1-sigma per axis, estimated from the "
                     f"{group} means' scatter, {entry['scatter_before']:.3g} times their white noise before; "
                     "their halves show it moving within a pose): these means carry no test of the model")
    turn = described.get("turn_angle_deg")
    if turn and turn["source"] == "estimated" and turn["sigma"] > 0:
        notes.append(f"noise model: the hand turns miss by {turn['sigma']:.3g} deg per turn (1-sigma, "
                     f"estimated from their scatter: {turn.get('scatter_before', float('nan')):.3g} times "
                     "their white-noise sigma before; the operator's turn, the gyro's bandwidth and "
                     "timing, its scale at high rate); the turns carry no test of the model, the "
                     "verdict is over the other data")
    elif turn and turn["source"] == "stated":
        notes.append(f"noise model: the hand turns' stated 1-sigma {turn['sigma']:.3g} deg per turn")
    return notes
