"""An independent Cramér–Rao bound for the simulated bench (issue 30 item 1).

The station's own bound (``station.simulate.montecarlo.cramer_rao``) is the least-squares fit's
covariance at noiseless summaries: the estimator's model and Jacobian compared with themselves.
This module shares nothing with them -- it imports neither ``station.model`` nor
``station.estimate`` -- and computes the bound from the simulator's own forward model
(``sim_devices.world`` for the kinematics, ``sim_devices.truth.Truth.measure`` for the sensors,
``Truth.paper_parameters`` for the parameterisation the calibration file reports), by its own
differentiation (central finite differences):

* the data are every raw sample of every segment (accelerometer and gyro, 6 channels) with white
  Gaussian noise of the simulator's stated density (per sample sigma = density x sqrt(rate); the
  accelerometers' white "disturbance" added in quadrature), and each rotation's encoder angle
  with the bench's stated angle error (arc-seconds, 1 sigma);
* the unknowns are the 24 physical sensor parameters of ``sim_devices.truth`` (3 scale factors,
  6 axis tilts and 3 biases per triad), the lever arm (m) and, as nuisances, what the station
  does not know of the bench: every static attitude (3 angles each), every rotation pair's start
  attitude (3) and table axis (heading and elevation), the start phase of the pair's second
  half and each rotation's true rate (the encoder measures its angle);
* the Fisher information is J^T J of the whitened samples (J by central differences: the model is
  smooth and nearly linear in every unknown, so the steps below give the derivatives to ~1e-8
  relative), the nuisances eliminated by inversion of the whole matrix;
* three directions are not identifiable (the case frame can turn with every attitude turning
  back): the gauge is fixed by holding the accelerometer x axis' two tilts and the y axis' tilt
  towards z, which defines the paper's frame p (x' = u_x, y' in the u_x u_y plane); the reported
  parameters do not depend on the gauge;
* the bound on the reported parameters is G F^-1 G^T with G the derivative of
  ``Truth.paper_parameters`` (central differences), in the units ``parameter_errors`` uses:
  scale factors in ppm of the true value, misalignments and inter-triad angles in arc-seconds,
  accelerometer biases in µg, gyro biases in °/h.

Only the effects the default bench simulates are supported (no ripple, wobble, vibration,
stamp jitter, rate drift, quantisation or higher-order sensor terms): anything else raises.
"""
from __future__ import annotations

import copy
import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from sim_devices import world
from sim_devices.bench import SimulatedBench
from sim_devices.world import MICRO_G

#: the reported parameters, in the order of ``station.model.calibration.parameter_errors``
NAMES = ([f"accel_scale_{a}" for a in "xyz"] + [f"accel_misalignment_{a}" for a in ("yz", "zy", "zx")]
         + [f"gyro_scale_{a}" for a in "xyz"] + [f"gyro_misalignment_{a}" for a in ("yz", "zy", "zx")]
         + [f"accel_bias_{a}" for a in "xyz"] + [f"gyro_bias_{a}" for a in "xyz"]
         + [f"inter_triad_{a}" for a in "xyz"])

# the unknowns of the sensors and the bench, with their central-difference steps
#   accel scale (1), accel tilts (arcsec), accel bias (ug), gyro scale, gyro tilts, gyro bias (deg/h),
#   lever arm (m)
GLOBAL_STEPS = np.array([1e-6] * 3 + [1.0] * 6 + [1.0] * 3 + [1e-6] * 3 + [1.0] * 6 + [0.01] * 3 + [1e-4] * 3)
N_SENSOR = 24
N_GLOBAL = len(GLOBAL_STEPS)
# the gauge: accel tilts x->y, x->z (row 0) and y->z (row 1, column 1) held at their true values
GAUGE = (3 + 0, 3 + 1, 3 + 3)
ANGLE_STEP_RAD = 1e-6        # attitude, axis heading/elevation and start phase nuisances
RATE_STEP_RAD_S = 1e-7       # each rotation's true rate


def perturbed(truth, d: np.ndarray):
    """A copy of ``truth`` with the 27 global unknowns moved by ``d`` (units of GLOBAL_STEPS)."""
    t = copy.deepcopy(truth)
    t.accel.scale = t.accel.scale + d[0:3]
    t.accel.axis_tilt_arcsec = t.accel.axis_tilt_arcsec + d[3:9].reshape(3, 2)
    t.accel.bias = t.accel.bias + d[9:12]
    t.gyro.scale = t.gyro.scale + d[12:15]
    t.gyro.axis_tilt_arcsec = t.gyro.axis_tilt_arcsec + d[15:21].reshape(3, 2)
    t.gyro.bias = t.gyro.bias + d[21:24]
    t.bench.lever_arm_m = t.bench.lever_arm_m + d[24:27]
    return t


def reported(truth, reference) -> np.ndarray:
    """The 21 reported parameters of ``truth`` (the simulator's paper parameterisation), scale
    factors in ppm of ``reference``'s."""
    p = truth.paper_parameters()
    r = reference.paper_parameters()
    return np.concatenate([(p["accel_scale"] / r["accel_scale"] - 1.0) * 1e6, p["accel_misalignment_arcsec"],
                           (p["gyro_scale"] / r["gyro_scale"] - 1.0) * 1e6, p["gyro_misalignment_arcsec"],
                           p["accel_bias_ug"], p["gyro_bias_dph"], p["inter_triad_arcsec"]])


def _check_supported(truth) -> None:
    b, a, g = truth.bench, truth.accel, truth.gyro
    unsupported = {
        "rate ripple": b.rate_ripple_fraction, "wobble": b.wobble_arcsec, "vibration": np.any(b.vibration_mg),
        "imbalance": b.imbalance_g_mm,
        "stamp jitter": b.time_stamp_jitter_ms, "remount": b.remount_error_arcsec, "encoder scale": b.encoder_scale_error_ppm,
        "accel LSB": a.lsb, "gyro LSB": g.lsb, "accel positions": np.any(a.position_m),
        "accel nonlinearity": np.any(a.nonlinearity_ug_per_g2) or np.any(a.cross_coupling_ug_per_g2) or np.any(a.cubic_ug_per_g3),
        "scale asymmetry": np.any(a.scale_asymmetry_ppm) or np.any(g.scale_asymmetry_ppm),
        "g-sensitivity": np.any(g.g_sensitivity_dph_per_g) or np.any(g.anisoelastic_dph_per_g2),
        "temperature coefficients": np.any(a.bias_tempco) or np.any(g.bias_tempco) or np.any(a.scale_tempco_ppm_per_c)
        or np.any(g.scale_tempco_ppm_per_c),
        "gyro rate terms": np.any(g.rate_squared_ppm_per_dps) or np.any(g.rate_odd_squared_ppm_per_dps),
    }
    present = [k for k, v in unsupported.items() if v]
    if present:
        raise ValueError(f"the independent bound does not model: {', '.join(present)}")


@dataclass
class _Static:
    C_bn: object          # the true attitude (scipy Rotation)
    tau: np.ndarray       # table times of the samples


@dataclass
class _Half:
    rate_rad_s: float
    t: np.ndarray         # nominal sample times (the stamps: no jitter)
    tau: np.ndarray
    axis_index: int       # the table axis (axis_offsets_m row) that turns it


@dataclass
class _Pair:
    C_bn0: object
    heading_rad: float
    elevation_rad: float
    halves: list


def record_geometry(scheme, truth, seed: int):
    """Run the simulated bench once for ``scheme`` and keep what it hides: the true attitudes,
    table axes, rates and sample times (the nuisances' true values)."""
    _check_supported(truth)
    if getattr(scheme, "centred", False):
        truth = copy.deepcopy(truth)
        truth.bench.lever_arm_m = np.zeros(3)
    bench = SimulatedBench(truth, seed)
    statics, pairs = [], {}
    for spec in scheme.segments:
        if spec.kind == "rotation":
            if not spec.encoder:
                raise ValueError("the independent bound needs an encoder angle on every rotation")
            seg = bench.rotation(spec.axis_body, spec.rate_dps, spec.duration_s,
                                 axis_elevation_deg=spec.axis_elevation_deg, encoder=True)
            key = (tuple(np.round(world._unit(spec.axis_body), 12)), float(spec.axis_elevation_deg))
            t = seg.truth["nominal_t"]
            half = _Half(math.radians(spec.rate_dps), t, t + truth.bench.time_offset_s,
                         int(np.argmax(np.abs(spec.axis_body))))
            if key not in pairs:
                pairs[key] = _Pair(Rotation.from_matrix(seg.truth["C_bn0"]), math.radians(seg.truth["heading_deg"]),
                                   math.radians(spec.axis_elevation_deg), [])
            pairs[key].halves.append(half)
        else:
            seg = bench.static(spec.up_body, spec.dwell_s)
            statics.append(_Static(Rotation.from_matrix(seg.truth["C_bn"]), seg.t + truth.bench.time_offset_s))
    return truth, statics, list(pairs.values())


class IndependentBound:
    """The bound for one scheme, truth and seed's geometry; ``sigma`` (21, units of NAMES) and
    ``covariance`` (21 x 21)."""

    def __init__(self, scheme, truth, seed: int = 1000):
        self.truth, self.statics, self.pairs = record_geometry(scheme, truth, seed)
        t = self.truth
        fs = float(t.sample_rate_hz)
        self.site = world.Site(t.bench.latitude_deg, t.bench.height_m)
        # per-sample white noise, raw units: the density times sqrt(rate); the accelerometers'
        # white disturbance (added to the specific force, through K S ~ identity to 1e-3) in quadrature
        self.sigma_accel = math.hypot(t.accel.noise_density * math.sqrt(fs), t.bench.accel_disturbance_ug) * MICRO_G
        self.sigma_gyro = t.gyro.noise_density * math.sqrt(fs) / 3600.0
        self.sigma_encoder_deg = t.bench.table_angle_error_arcsec / 3600.0
        self.dt = 1.0 / fs
        from threadpoolctl import threadpool_limits

        with threadpool_limits(limits=1, user_api="blas"):   # J^T J of ~20,000 rows: 5x slower on a
            self._fisher()                                    # thread pool that a loaded machine starves

    # ------------------------------------------------------------------ forward model
    def _whitened(self, truth, kin, tau):
        f_b, w_ib, w_b, wd_b = kin
        temp = truth.temperature.at(tau)
        acc, gyr = truth.measure(f_b, np.degrees(w_ib), temp, None, w_eb_b=w_b, wdot_eb_b=wd_b, t=tau)
        return np.concatenate([(acc / self.sigma_accel).ravel(), (gyr / self.sigma_gyro).ravel()])

    def _static_kin(self, s: _Static, delta):
        C = world.small_rotation(delta) * s.C_bn
        f_b, w_ib = world.static_kinematics(C, len(s.tau), self.site)
        return f_b, w_ib, None, None

    def _rotation_kin(self, p: _Pair, half: _Half, nuisance, lever_arm):
        """nuisance: start attitude (3, rad), axis heading and elevation (rad), start phase (rad),
        rate (rad/s) offsets."""
        a_n = world.table_axis_enu(p.heading_rad + nuisance[3], p.elevation_rad + nuisance[4])
        C0 = world.small_rotation(nuisance[0:3]) * p.C_bn0
        theta, thd, thdd = world.rate_profile(half.tau, t0=half.t[0], rate_rad_s=half.rate_rad_s + nuisance[6])
        C_bn = world.table_attitude(C0, a_n, theta + nuisance[5])
        w_b, wd_b = world.table_rates_body(C0, a_n, thd, thdd)
        lever = lever_arm + self.truth.bench.axis_offsets_m[half.axis_index]
        f_b, w_ib = world.body_kinematics(C_bn, w_b, wd_b, lever, self.site)
        return f_b, w_ib, w_b, wd_b

    def _encoder(self, half: _Half, rate_offset) -> float:
        """The swept angle over the station's window [t0 - dt/2, t_last + dt/2], whitened."""
        window = half.t[-1] - half.t[0] + self.dt
        return math.degrees((half.rate_rad_s + rate_offset) * window) / self.sigma_encoder_deg

    # ------------------------------------------------------------------ Fisher information
    def _global_columns(self, kin_of, tau):
        """Whitened-sample derivatives by the 27 global unknowns (kin_of(lever_arm) -> kinematics)."""
        base_kin = kin_of(self.truth.bench.lever_arm_m)
        cols = []
        for k, h in enumerate(GLOBAL_STEPS):
            d = np.zeros(N_GLOBAL)
            d[k] = h
            ys = []
            for sign in (1.0, -1.0):
                tp = perturbed(self.truth, sign * d)
                kin = base_kin if k < N_SENSOR else kin_of(tp.bench.lever_arm_m)
                ys.append(self._whitened(tp, kin, tau))
            cols.append((ys[0] - ys[1]) / (2.0 * h))
        return np.column_stack(cols)

    def _fisher(self):
        n_nuis = 3 * len(self.statics) + 7 * len(self.pairs) + sum(len(p.halves) for p in self.pairs) - len(self.pairs)
        size = N_GLOBAL + n_nuis
        F = np.zeros((size, size))
        at = N_GLOBAL
        for s in self.statics:
            Jg = self._global_columns(lambda lever, s=s: self._static_kin(s, np.zeros(3)), s.tau)
            Jn = []
            for k in range(3):
                d = np.zeros(3)
                d[k] = ANGLE_STEP_RAD
                plus = self._whitened(self.truth, self._static_kin(s, d), s.tau)
                minus = self._whitened(self.truth, self._static_kin(s, -d), s.tau)
                Jn.append((plus - minus) / (2 * ANGLE_STEP_RAD))
            idx = list(range(N_GLOBAL)) + list(range(at, at + 3))
            J = np.column_stack([Jg] + Jn)
            F[np.ix_(idx, idx)] += J.T @ J
            at += 3
        for p in self.pairs:
            shared = list(range(at, at + 5))             # start attitude, axis heading, elevation
            at += 5
            for i, half in enumerate(p.halves):
                own = []
                if i > 0:                                # the second half's start phase
                    own.append(("phase", at))
                    at += 1
                own.append(("rate", at))
                at += 1
                zero = np.zeros(7)
                Jg = self._global_columns(lambda lever, p=p, half=half: self._rotation_kin(p, half, zero, lever), half.tau)
                Jn = []
                which = [(k, ANGLE_STEP_RAD) for k in range(5)] + [(5 if kind == "phase" else 6,
                                                                    ANGLE_STEP_RAD if kind == "phase" else RATE_STEP_RAD_S)
                                                                   for kind, _ in own]
                for k, h in which:
                    d = np.zeros(7)
                    d[k] = h
                    plus = self._whitened(self.truth, self._rotation_kin(p, half, d, self.truth.bench.lever_arm_m), half.tau)
                    minus = self._whitened(self.truth, self._rotation_kin(p, half, -d, self.truth.bench.lever_arm_m), half.tau)
                    Jn.append((plus - minus) / (2 * h))
                idx = list(range(N_GLOBAL)) + shared + [j for _, j in own]
                J = np.column_stack([Jg] + Jn)
                F[np.ix_(idx, idx)] += J.T @ J
                # the encoder's reading of this half's angle: derivative by its rate only
                r = at - 1
                F[r, r] += ((self._encoder(half, RATE_STEP_RAD_S) - self._encoder(half, -RATE_STEP_RAD_S))
                            / (2 * RATE_STEP_RAD_S)) ** 2
        assert at == size
        keep = [k for k in range(size) if k not in GAUGE]
        Fk = F[np.ix_(keep, keep)]
        scale = 1.0 / np.sqrt(np.diag(Fk))
        cov = scale[:, None] * np.linalg.inv(scale[:, None] * Fk * scale[None, :]) * scale[None, :]
        self.condition = float(np.linalg.cond(scale[:, None] * Fk * scale[None, :]))
        n_kept_global = N_GLOBAL - len(GAUGE)
        cov_global = cov[:n_kept_global, :n_kept_global]
        G = self._reported_jacobian()
        Gk = G[:, [k for k in range(N_GLOBAL) if k not in GAUGE]]
        self.covariance = Gk @ cov_global @ Gk.T
        self.sigma = np.sqrt(np.diag(self.covariance))
        self.fisher = F

    def _reported_jacobian(self) -> np.ndarray:
        cols = []
        for k, h in enumerate(GLOBAL_STEPS):
            d = np.zeros(N_GLOBAL)
            d[k] = h
            cols.append((reported(perturbed(self.truth, d), self.truth)
                         - reported(perturbed(self.truth, -d), self.truth)) / (2.0 * h))
        return np.column_stack(cols)
