"""A calibration by hand, simulated: the IMU held still in a sequence of poses and turned by
hand from each to the next, recorded continuously (imu_tk's and imucal's way, no table).

Physics (frames and conventions of :mod:`sim_devices.world`: ENU, C_bn takes ENU to body):

* Poses: random attitudes, uniform over the rotation group (``faces=True``: the IMU laid on
  one of its six faces at a random heading, as Ferraris' method asks), each held still for a
  random dwell in ``dwell_s``; the first one (the initial rest) for ``init_rest_s``.
* A hand turn from pose a to pose b over T seconds (random in ``turn_s``): with R = C_bn^T
  (body to ENU) and tau = (t - t0) / T,
      R(tau) = R_a exp(s(tau) phi) exp(sin^2(pi tau) epsilon),   R_b = R_a exp(phi),
  s the minimum-jerk profile 10 tau^3 - 15 tau^4 + 6 tau^5 and epsilon a random wobble
  (``wobble_deg``, 1-sigma per axis) that vanishes, with its rate, at both ends: the axis
  wanders during the turn as a hand's does, and the rate starts and ends smoothly.  The body rate relative to the Earth is R^T dR/dt, taken as the
  central difference rotvec(R(t - h)^T R(t + h)) / 2h (h = 1 us: error ~ h^2 |w|^3, far below
  any gyro's noise).  The hand also lifts the IMU: position d sin^2(pi tau) (``lift_m``, a
  random direction), acceleration d 2 pi^2 / T^2 cos(2 pi tau).
* Specific force f_b = C_bn ([0, 0, g] + a_n), inertial rate w_ib = w_eb + C_bn Omega_E (site
  of the truth's bench), then the sensor model of :class:`sim_devices.truth.Truth` (noise,
  biases, scale factors, misalignments, temperature) at the true sample times.
* ``turn_error_deg``: a turn the gyro does not follow exactly (1-sigma per axis, deg): the
  gyro's output during turn k carries an extra rate e_k (2/T) sin^2(pi tau) (rad/s, e_k a random
  rotation vector, N(0, turn_error^2) per axis), which integrates to e_k over the turn and
  vanishes at its ends: what a hand-held turn adds beyond the white noise (g-sensitivity and
  vibration rectification while shaken, bias instability over the turn, bandwidth), so that
  the turn integrated from the gyro misses the true one by e_k.  The statics are untouched.
* ``bias_instability``: (accelerometer ug, gyro deg/h) 1-sigma of a bias that wanders while the
  session runs (each a number for every axis or three, x y z), each axis a first-order Gauss-Markov process of correlation time
  ``bias_tau_s`` (exact discretisation b_k+1 = phi b_k + sqrt(1 - phi^2) sigma w_k, phi =
  exp(-dt / tau), started in its stationary distribution), added at the sensor's input (to the
  specific force and the rate it senses: an output bias to within the scale factor's error):
  what makes real pose means scatter beyond their white noise (flicker over seconds).
* ``counts``: the outputs in raw counts (m/s^2 and deg/s per count), rounded to integers.

Returns the samples and the truth: the sample ranges of the still poses (between turns) and
their true attitudes.  Nothing here uses the station's model or estimator.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy import signal
from scipy.spatial.transform import Rotation

from . import world
from .truth import Truth

STEP_S = 1e-6          # central-difference half step for the body rate


@dataclass
class HandSession:
    t: np.ndarray                   # (N,) s, true sample times from 0
    accel: np.ndarray               # (N,3) m/s^2 (or counts)
    gyro: np.ndarray                # (N,3) deg/s (or counts)
    temp: np.ndarray                # (N,) deg C
    statics: list                   # (first, stop) sample ranges where the IMU is still
    attitudes: list                 # C_bn (Rotation) of each static pose
    counts: tuple | None = None     # (m/s^2 per count, deg/s per count) when in counts
    truth: dict = field(default_factory=dict)


def _min_jerk(tau):
    return tau**3 * (10.0 - 15.0 * tau + 6.0 * tau**2)


def _pose(rng, faces: bool) -> Rotation:
    """R (body -> ENU) of a pose."""
    if not faces:
        return Rotation.random(random_state=rng)
    up = np.zeros(3)
    k = int(rng.integers(3))
    up[k] = 1.0 if rng.random() < 0.5 else -1.0
    C_bn = world.attitude_up(up, rng.uniform(0.0, 2.0 * np.pi))
    return C_bn.inv()


def hand_session(truth: Truth, seed: int, *, poses: int = 38, dwell_s=(2.5, 4.0), turn_s=(1.0, 2.0),
                 init_rest_s: float = 5.0, wobble_deg: float = 10.0, lift_m: float = 0.05,
                 faces: bool = False, counts: tuple | None = None, turn_error_deg: float = 0.0,
                 bias_instability: tuple = (0.0, 0.0), bias_tau_s: float = 10.0) -> HandSession:
    rng = np.random.default_rng(seed)
    noise_rng = np.random.default_rng(np.random.SeedSequence(seed).spawn(1)[0])
    site = world.Site(truth.bench.latitude_deg, truth.bench.height_m)
    fs = float(truth.sample_rate_hz)
    dt = 1.0 / fs
    g_up = np.array([0.0, 0.0, site.g])
    R = [_pose(rng, faces)]
    for _ in range(poses - 1):
        R.append(_pose(rng, faces))
    err_rng = np.random.default_rng(np.random.SeedSequence(seed).spawn(2)[1])   # (draws only when asked)
    pieces_R, pieces_w, pieces_a, pieces_e, statics = [], [], [], [], []
    turn_errors = []
    n = 0

    def hold(Rp: Rotation, seconds: float):
        nonlocal n
        m = max(1, int(round(seconds * fs)))
        statics.append((n, n + m))
        pieces_R.append(Rotation.concatenate([Rp] * m))
        pieces_w.append(np.zeros((m, 3)))
        pieces_a.append(np.zeros((m, 3)))
        pieces_e.append(np.zeros((m, 3)))
        n += m

    def turn(Ra: Rotation, Rb: Rotation, seconds: float):
        nonlocal n
        m = max(2, int(round(seconds * fs)))
        T = m * dt
        phi = (Ra.inv() * Rb).as_rotvec()
        eps = np.radians(wobble_deg) * rng.standard_normal(3)
        lift = rng.standard_normal(3)
        lift *= lift_m / np.linalg.norm(lift)
        tk = (np.arange(m) + 0.5) * dt       # sample times within the turn (strictly inside)

        def path(t):
            tau = np.clip(t / T, 0.0, 1.0)
            return (Ra * Rotation.from_rotvec(np.outer(_min_jerk(tau), phi))
                    * Rotation.from_rotvec(np.outer(np.sin(np.pi * tau) ** 2, eps)))

        Rk = path(tk)
        w = (path(tk - STEP_S).inv() * path(tk + STEP_S)).as_rotvec() / (2.0 * STEP_S)   # rad/s, body
        a_n = np.outer(np.cos(2.0 * np.pi * tk / T), lift) * (2.0 * np.pi**2 / T**2)
        pieces_R.append(Rk)
        pieces_w.append(w)
        pieces_a.append(a_n)
        e_k = (np.radians(turn_error_deg) * err_rng.standard_normal(3) if turn_error_deg > 0
               else np.zeros(3))
        turn_errors.append(np.degrees(e_k))
        # the midpoint rule of the rate below integrates to e_k over the m samples (to 1e-6 rel.)
        pieces_e.append(np.outer(2.0 / T * np.sin(np.pi * tk / T) ** 2, e_k))
        n += m

    hold(R[0], init_rest_s)
    for k in range(1, poses):
        turn(R[k - 1], R[k], rng.uniform(*turn_s))
        hold(R[k], rng.uniform(*dwell_s))
    R_all = Rotation.concatenate(pieces_R)
    C_bn = R_all.inv()
    w_eb = np.vstack(pieces_w)
    a_n = np.vstack(pieces_a)
    f_b = C_bn.apply(g_up + a_n)
    w_ib = w_eb + C_bn.apply(site.earth_rate_enu) + np.vstack(pieces_e)     # rad/s
    t = np.arange(n) * dt
    temp = truth.temperature.at(t)
    if any(np.any(np.asarray(v) != 0) for v in bias_instability):
        walk_rng = np.random.default_rng(np.random.SeedSequence(seed).spawn(3)[2])
        phi = math.exp(-dt / bias_tau_s)
        start = walk_rng.standard_normal(6)                        # stationary at the first sample
        drive = walk_rng.standard_normal((n, 6)) * math.sqrt(1.0 - phi * phi)
        b, _ = signal.lfilter([1.0], [1.0, -phi], drive, axis=0, zi=(phi * start)[None, :])
        size = np.concatenate([np.broadcast_to(np.asarray(v, float), (3,)) for v in bias_instability])
        f_b = f_b + b[:, :3] * size[:3] * world.MICRO_G
        w_ib = w_ib + b[:, 3:] * np.radians(size[3:] / 3600.0)
        still = np.concatenate([np.arange(i, j) for i, j in statics])
        walk_mean = b[still].mean(axis=0) * size     # ug, deg/h
    else:
        walk_mean = np.zeros(6)
    accel, gyro = truth.measure(f_b, np.degrees(w_ib), temp, noise_rng)
    if counts is not None:
        accel = np.round(accel / counts[0])
        gyro = np.round(gyro / counts[1])
    return HandSession(t=t, accel=accel, gyro=gyro, temp=temp, statics=statics,
                       attitudes=[r.inv() for r in R], counts=counts,
                       truth={"gravity_mps2": site.g, "latitude_deg": float(truth.bench.latitude_deg),
                              "turn_errors_deg": np.array(turn_errors).reshape(-1, 3),
                              # the wandering bias' mean over the still samples (accel ug, gyro
                              # deg/h): the session's own bias is the truth's plus this
                              "bias_walk_mean": walk_mean})
