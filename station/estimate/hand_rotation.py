"""Hand rotations of unknown angle between static poses: the gyro calibrated by carrying the
gravity direction of the pose before through the turn to the pose after (the imu_tk approach,
Tedaldi et al. 2014), as terms of the least-squares model (station/estimate/lsq.py).

A hand rotation is a complete ``rotation`` segment without ``angle_deg`` (no encoder) that is
a hand turn, not a steady Fourier rotation: its manifest says ``motion: hand``, or the
magnitude of its rate varies by more than summaries.STEADY_SPREAD of its mean.  It is used when
a static segment ends just before it and another begins just after it (within ``MAX_GAP_S``,
the IMU still in between).

Model, frame p (the accelerometers'), with M_g the gyro matrix and b_g the gyro bias of the
model (gyro_raw = M_g w_p + b_g):
  w_k   = M_g^-1 (gyro_k - b_g)                         each sample, deg/s
  dR    = exp(w_1 dt) exp(w_2 dt) ... exp(w_N dt)        the body's turn, sample k standing for dt
                                                         (the midpoint rule: for 150-degree turns
                                                         in 1.5 s at 100 Hz within 3 arcsec of the
                                                         path; curvature and coning terms from the
                                                         neighbouring samples did not do better
                                                         where a turn starts from rest)
  u_after = dR^T exp(Omega_p T) u_before                 u: unit "up" of the static poses, the
                                                         model's attitude parameters
where Omega_p is the Earth rate in p at the pose before (known when the site's latitude is:
the pose's full attitude is then a parameter); without the latitude it is not modelled and its
largest effect, |Omega_E| T per axis / sqrt(3), is added to the noise.  The residual is the
difference of the two unit vectors across the predicted one (two components, the tangent plane
of the pose after), divided by the angle noise of the integral: sigma_theta = sigma_gyro dt
sqrt(N) (rad; sigma_gyro the per-sample white noise of the statics, in deg/s through the
model's start scale).  Only the gravity direction is matched, so a turn says nothing about the
rotation about the vertical: every rotation gives two equations.

The integration is vectorised over all turns: per-sample rotation vectors -> quaternions, then
the ordered product by pairwise reduction (log2 N steps of quaternion products,
station.model.rotation.quat_product), each turn's quaternion normalised and made a matrix.  In
numpy only, as scipy's Rotation did it before: `import scipy.spatial` (~0.3 s of CPU: it imports
scipy.sparse, scipy.linalg and scipy.special) was most of what a hand session's estimate
imported beyond numpy (issue 27).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from station.model.geometry import cross
from station.model.rotation import matrix_from_quat, matrix_from_rotvec, quat_product

STEADY_SPREAD = 0.3         # as summaries.STEADY_SPREAD: a rotation whose rate varies more is a hand turn
MAX_GAP_S = 1.0             # static end -> turn start (and turn end -> static start), IMU still
MIN_SAMPLES = 2
EARTH_RATE_DPS = 360.0 / 86164.0905


@dataclass
class HandRotation:
    name: str
    before: int                 # index into Summaries.statics
    after: int
    gyro: np.ndarray            # (N,3) after the unit conversion (deg/s, or raw)
    dt: float                   # s per sample
    temp_c: float | None = None

    @property
    def duration_s(self) -> float:
        return len(self.gyro) * self.dt

    @property
    def samples(self) -> int:
        return len(self.gyro)


def is_hand(seg) -> bool:
    """A rotation segment without an encoder angle that a hand made (see the module doc)."""
    if seg.kind != "rotation" or seg.angle_deg is not None:
        return False
    if seg.extra.get("motion") == "hand":
        return True
    if seg.data is None or len(seg.data.t) < 4:
        return False
    magnitude = np.linalg.norm(seg.data.gyro, axis=1)
    return bool(np.std(magnitude) >= STEADY_SPREAD * np.mean(magnitude))


def collect(static_segments: list, hand_segments: list, gyro_factor: float) -> tuple[list, list]:
    """HandRotation per usable segment (statics in the order of Summaries.statics), and a note
    per segment left out."""
    ends = np.array([s.data.t[-1] for s in static_segments]) if static_segments else np.zeros(0)
    starts = np.array([s.data.t[0] for s in static_segments]) if static_segments else np.zeros(0)
    out, skipped = [], []
    for seg in hand_segments:
        t = seg.data.t
        if len(t) < MIN_SAMPLES:
            skipped.append(f"{seg.name}: hand rotation of {len(t)} samples: too short")
            continue
        dt = float(np.median(np.diff(t)))
        gap_before = t[0] - ends
        gap_after = starts - t[-1]
        before = [j for j in np.argsort(gap_before) if 0 < gap_before[j] <= MAX_GAP_S + dt]
        after = [j for j in np.argsort(gap_after) if 0 < gap_after[j] <= MAX_GAP_S + dt]
        if not before or not after:
            skipped.append(f"{seg.name}: hand rotation without a static segment just before and after it "
                           f"(within {MAX_GAP_S:g} s): not used")
            continue
        temp = None if seg.data.temp is None else float(np.mean(seg.data.temp))
        out.append(HandRotation(seg.name, int(before[0]), int(after[0]), seg.data.gyro * gyro_factor, dt, temp))
    return out, skipped


def _unit_matrix(q: np.ndarray) -> np.ndarray:
    """The rotation matrices (..., 3, 3) of quaternions (..., 4), scalar last, each normalised
    first (a product of many unit quaternions drifts from unit norm by rounding)."""
    return matrix_from_quat(q / np.linalg.norm(q, axis=-1, keepdims=True))


class Integrator:
    """The turns of all hand rotations at once, for a given gyro matrix and bias."""

    def __init__(self, hands: list[HandRotation]):
        self.hands = hands
        self.gyro = np.vstack([h.gyro for h in hands])
        self.step_rad = np.concatenate([np.full(h.samples, np.radians(h.dt)) for h in hands])[:, None]
        width = 1
        while width < max(h.samples for h in hands):
            width *= 2
        self.flat = np.concatenate([i * width + np.arange(h.samples) for i, h in enumerate(hands)])
        self.identity = np.zeros((len(hands) * width, 4))
        self.identity[:, 3] = 1.0
        self.shape = (len(hands), width, 4)
        self._key = None
        self._tangent = None

    def turns(self, gyro_inverse: np.ndarray, bias: np.ndarray) -> np.ndarray:
        """dR of every turn (rotation matrices, (H,3,3)), with w_p = gyro_inverse (gyro - bias), deg/s.
        The last result is kept: the Jacobian's columns that move neither give it again.  While
        linearised (see linearise()), any other gyro_inverse and bias give the first-order turn
        about the linearisation point instead of a new integration."""
        key = np.concatenate([np.ravel(gyro_inverse), np.ravel(bias)]).tobytes()
        if key == self._key:
            return self._last
        if self._tangent is not None:
            return self._linearised(gyro_inverse, bias)
        theta = ((self.gyro - bias) @ gyro_inverse.T) * self.step_rad       # rad, per sample
        angle = np.sqrt(np.einsum("ij,ij->i", theta, theta))
        half = 0.5 * angle
        with np.errstate(invalid="ignore", divide="ignore"):
            k = np.where(angle > 1e-8, np.sin(half) / angle, 0.5 - angle * angle / 48.0)   # sin(a/2)/a
        Q = self.identity.copy()
        Q[self.flat] = np.column_stack([theta * k[:, None], np.cos(half)])
        levels = [Q.reshape(self.shape)]
        while levels[-1].shape[1] > 1:
            levels.append(quat_product(levels[-1][:, 0::2], levels[-1][:, 1::2]))
        self._key, self._last = key, _unit_matrix(levels[-1][:, 0])
        self._levels, self._theta = levels, theta
        return self._last

    # --- first order about a point, for the Jacobian ---------------------------------------
    # dR = E_1 ... E_N with E_k = exp(theta_k); a change d theta_k turns it into
    # dR exp(d phi), d phi = sum_k S_k^T J_r(theta_k) d theta_k, with S_k = E_{k+1} ... E_N (the
    # rest of the turn after sample k) and J_r the right Jacobian of the exponential map; and
    # d theta_k = dt (d gyro_inverse (gyro_k - bias) - gyro_inverse d bias) to first order.  The
    # S_k come from the integration's own pairwise products (a down-sweep of its tree).

    def linearise(self, gyro_inverse: np.ndarray, bias: np.ndarray) -> None:
        """Integrate at (gyro_inverse, bias) and keep the first-order change of every turn with
        them: until exact() is called, turns() at other values costs no integration."""
        self._tangent = None
        self.turns(gyro_inverse, bias)
        levels = self._levels
        suffix = np.zeros_like(levels[-1])
        suffix[..., 3] = 1.0
        for level in reversed(levels[:-1]):          # the exclusive suffix product of every node
            below = np.empty_like(level)
            below[:, 1::2] = suffix
            below[:, 0::2] = quat_product(level[:, 1::2], suffix)
            suffix = below
        S = _unit_matrix(suffix.reshape(-1, 4)[self.flat])                      # (N,3,3)
        theta = self._theta
        angle = np.sqrt(np.einsum("ij,ij->i", theta, theta))
        with np.errstate(invalid="ignore", divide="ignore"):
            c1 = np.where(angle > 1e-4, (1.0 - np.cos(angle)) / angle**2, 0.5 - angle**2 / 24.0)
            c2 = np.where(angle > 1e-4, (angle - np.sin(angle)) / angle**3, 1.0 / 6.0 - angle**2 / 120.0)
        # row a of S_k^T J_r(theta_k) is J_r^T s_a = s_a + c1 theta x s_a + c2 theta x (theta x s_a)
        # = (1 - c2 |theta|^2) s_a + c1 theta x s_a + c2 (theta . s_a) theta, s_a the column a of S_k
        St = S.transpose(0, 2, 1)                                           # rows: s_a
        along = np.einsum("nc,nac->na", theta, St)
        A = ((1.0 - c2 * angle**2)[:, None, None] * St + c1[:, None, None] * cross(theta[:, None, :], St)
             + c2[:, None, None] * along[:, :, None] * theta[:, None, :]) * self.step_rad[:, :, None]
        starts = np.concatenate([[0], np.cumsum([h.samples for h in self.hands])[:-1]])
        outer = A[:, :, :, None] * (self.gyro - bias)[:, None, None, :]    # A_k (x) u_k
        T = np.add.reduceat(outer.reshape(len(A), 27), starts).reshape(-1, 3, 3, 3)
        B = np.add.reduceat(A.reshape(len(A), 9), starts).reshape(-1, 3, 3)
        self._tangent = (np.array(gyro_inverse, float), np.array(bias, float), self._last, T, B)

    def exact(self) -> None:
        """Back to integrating every new gyro_inverse and bias (after linearise())."""
        self._tangent = None

    def _linearised(self, gyro_inverse, bias) -> np.ndarray:
        M0, b0, dR0, T, B = self._tangent
        d_phi = np.einsum("haij,ij->ha", T, gyro_inverse - M0) - B @ (M0 @ (bias - b0))
        return dR0 @ matrix_from_rotvec(d_phi)

    def turns_batch(self, gyro_inverse: np.ndarray, bias: np.ndarray) -> np.ndarray:
        """The rotation matrices (B*H,3,3) of turns() for every row of gyro_inverse (B,3,3) and
        bias (B,3), the H turns of each row together.  While linearised: dR0 exp(d_phi), to
        first order about the linearisation point, complex-step safe (station/model/rotation.py):
        the Jacobian's imaginary steps give d_phi's derivative exactly."""
        if self._tangent is None:
            return np.concatenate([self.turns(m, b) for m, b in zip(gyro_inverse, bias)])
        M0, b0, dR0, T, B = self._tangent
        d_phi = (np.einsum("haij,nij->nha", T, gyro_inverse - M0)
                 - np.einsum("hij,nj->nhi", B, (bias - b0) @ M0.T))
        return (dR0[None] @ matrix_from_rotvec(d_phi)).reshape(-1, 3, 3)


def mismatch(integrator: Integrator, gyro_inverse, bias, ups: np.ndarray) -> float:
    """Sum of squared differences between the up after each turn and the up before carried
    through it (Earth rate neglected): the start's objective."""
    hands = integrator.hands
    dR = integrator.turns(gyro_inverse, bias)
    before = ups[[h.before for h in hands]]
    after = ups[[h.after for h in hands]]
    return float(np.sum((after - np.einsum("hji,hj->hi", dR, before)) ** 2))      # dR^T before


def start_scale(integrator: Integrator, bias: np.ndarray, ups: np.ndarray, nominal: float | None) -> float:
    """Gyro scale (output units per deg/s) to start the fit from: the nominal one (1 for deg/s,
    the manifest's nominal count for raw) refined, or for raw without a nominal scale the
    median ratio of the integrated turn to the gravity direction's change, refined; the
    refinement minimises the mismatch over the scale (a bounded 1-D search)."""
    from station.estimate.arrays import median
    from station.estimate.solver import minimise_bounded

    if nominal is None:
        ratios = []
        for h in integrator.hands:
            tilt = np.degrees(np.arccos(np.clip(ups[h.before] @ ups[h.after], -1.0, 1.0)))
            if tilt > 30.0:
                ratios.append(np.linalg.norm(((h.gyro - bias) * h.dt).sum(axis=0)) / tilt)
        nominal = float(median(ratios)) if ratios else 1.0
    if not nominal > 0:
        nominal = 1.0
    log_scale = minimise_bounded(lambda ls: mismatch(integrator, np.eye(3) / np.exp(ls), bias, ups),
                                 np.log(nominal) - np.log(1.6), np.log(nominal) + np.log(1.6), xatol=1e-3)
    return float(np.exp(log_scale))


def heading_visible(s, counts_per_dps: float = 1.0) -> bool:
    """Whether the gyros can see the Earth rate's horizontal component in a pose (and so the
    pose's heading): its size above three times the noise of a pose's mean gyro output (the
    median pose; ``counts_per_dps`` converts a raw gyro's noise to deg/s)."""
    if not s.statics:
        return False
    horizontal = EARTH_RATE_DPS * np.cos(np.radians(s.latitude_deg or 0.0))
    samples = float(np.median([st.samples for st in s.statics]))
    noise_dps = float(np.max(s.gyro_sigma)) / abs(counts_per_dps) / np.sqrt(samples)
    return bool(horizontal > 3.0 * noise_dps)


def static_colours(n_statics: int, hands: list[HandRotation]) -> list[int]:
    """A colour per static such that no two statics joined by a hand rotation share one (the
    Jacobian perturbs the statics of one colour together)."""
    neighbours = [set() for _ in range(n_statics)]
    for h in hands:
        if h.before != h.after:
            neighbours[h.before].add(h.after)
            neighbours[h.after].add(h.before)
    colour = [0] * n_statics
    for j in range(n_statics):
        used = {colour[k] for k in neighbours[j] if k < j}
        colour[j] = next(c for c in range(n_statics + 1) if c not in used)
    return colour
