"""The multi-position calibration of Zhang et al. 2010 (sections 3 and 4), algebraic.

No initial guess is needed anywhere:
  * accelerometers: the static means lie on an ellipsoid (eqs. 12-14); its coefficients are the
    null vector of a linear system, from which K_a T_a and b_a follow by a triangular
    factorisation;
  * gyro scale factors and misalignments: the difference of the integrated +/- rotations about
    one axis has the length of the encoder angle swept (eqs. 18-22), linear in M = L^T L;
  * gyro biases: every static mean has the length of the Earth rate (eqs. 23-25), linear in
    (L b, |L b|^2 - Omega^2), then refined with the exact norm;
  * inter-triad misalignment: the rotation axis seen by the gyros (eq. 41) and by the
    accelerometers (the null vector of [s^T, -1], eqs. 44-47), aligned over all axes at once
    (Wahba's problem, as in [18]).
Arrays are in m/s^2 and deg/s after the manifest's unit conversion ("raw" is taken as is).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from station.core import units
from station.estimate import solver
from station.model.calibration import Calibration
from station.core.errors import UserError
from station.model.rotation import align_vectors

EARTH_RATE_DPS = units.EARTH_RATE_DPS

# A rotation axis closer to vertical than this leaves the accelerometers blind to it.
MIN_AXIS_CONDITION = 100.0


@dataclass
class RotationPair:
    name: str
    axis_body: np.ndarray        # commanded, unit
    phi: np.ndarray              # integral(+) - integral(-) of the gyro, bias removed, SI-deg
    swept_deg: float             # angle(+) - angle(-) from the encoder, > 0
    duration_diff_s: float       # T(+) - T(-)
    integral_plus: np.ndarray    # raw integrals (before bias removal), for re-use
    integral_minus: np.ndarray
    duration_plus_s: float
    duration_minus_s: float
    accel: np.ndarray            # (N,3) accelerometer samples of both directions, m/s^2


@dataclass
class Summaries:
    """What the algebraic solution needs from a capture, in m/s^2 and deg/s."""
    gravity_mps2: float
    accel_factor: float
    gyro_factor: float
    static_names: list
    accel_means: np.ndarray      # (J,3)
    gyro_means: np.ndarray       # (J,3)
    pairs: list


def window_integral(t: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, float]:
    """Integral of samples y(t) over [t0 - dt/2, tN + dt/2] (sample k stands for its interval)."""
    if len(t) < 2:
        raise UserError("a rotation segment needs at least two samples")
    dt_first, dt_last = t[1] - t[0], t[-1] - t[-2]
    integral = np.trapezoid(y, t, axis=0) + 0.5 * (y[0] * dt_first + y[-1] * dt_last)
    return integral, float(t[-1] - t[0] + 0.5 * (dt_first + dt_last))


def summarise(capture) -> Summaries:
    ca = units.accel_to_mps2_factor(capture.imu.accel_unit) or 1.0
    cg = units.gyro_to_dps_factor(capture.imu.gyro_unit) or 1.0
    statics = capture.complete("static")
    names = [s.name for s in statics]
    accel_means = np.array([s.data.accel.mean(axis=0) * ca for s in statics]).reshape(-1, 3)
    gyro_means = np.array([s.data.gyro.mean(axis=0) * cg for s in statics]).reshape(-1, 3)
    pairs = []
    for plus, minus in capture.rotation_pairs():
        for seg in (plus, minus):
            if seg.angle_deg is None:
                raise UserError(f"{capture.path}: segment '{seg.name}': no angle_deg; the 2010 method "
                                "needs the encoder angle of every rotation")
        ip, tp = window_integral(plus.data.t, plus.data.gyro * cg)
        im, tm = window_integral(minus.data.t, minus.data.gyro * cg)
        axis = np.asarray(plus.axis_body, float)
        pairs.append(RotationPair(
            name=f"{plus.name}/{minus.name}", axis_body=axis / np.linalg.norm(axis),
            phi=ip - im, swept_deg=float(plus.angle_deg - minus.angle_deg),
            duration_diff_s=tp - tm, integral_plus=ip, integral_minus=im,
            duration_plus_s=tp, duration_minus_s=tm,
            accel=np.vstack([plus.data.accel, minus.data.accel]) * ca))
    return Summaries(capture.site.gravity_mps2, ca, cg, names, accel_means, gyro_means, pairs)


# --- linear algebra helpers ---------------------------------------------------------------------

def lower_factor(A: np.ndarray) -> np.ndarray:
    """Lower-triangular L with positive diagonal such that A = L^T L (A symmetric positive)."""
    P = np.eye(3)[::-1]
    try:
        C = np.linalg.cholesky(P @ A @ P)
    except np.linalg.LinAlgError:
        raise UserError("the data do not define a calibration (the fitted quadric is not an "
                        "ellipsoid): check the attitudes and rotation axes of the scheme") from None
    return P @ C.T @ P


def scale_and_T(L: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Split KT = inv(L) into scale factors (row norms) and unit-row sensing directions."""
    KT = np.linalg.inv(L)
    k = np.linalg.norm(KT, axis=1)
    return k, KT / k[:, None]


# --- the four steps ----------------------------------------------------------------------------

def fit_accelerometers(means: np.ndarray, gravity: float) -> tuple[np.ndarray, np.ndarray]:
    """Ellipsoid through the static means: returns (L_a, b_a) with |L_a (f - b_a)| = g."""
    if len(means) < 9:
        raise UserError(f"the accelerometer fit needs at least 9 static attitudes; the capture has "
                        f"{len(means)} complete static segments")
    u = means / gravity                        # conditioned: |u| ~ 1
    x, y, z = u.T
    D = np.column_stack([x * x, y * y, z * z, 2 * x * y, 2 * x * z, 2 * y * z,
                         2 * x, 2 * y, 2 * z, np.ones_like(x)])
    # thin: a full U is N x N (80 GB at 100,000 statics); full only below 10 statics, for the null row
    q = np.linalg.svd(D, full_matrices=len(D) < D.shape[1])[2][-1]
    Q = np.array([[q[0], q[3], q[4], q[6]],
                  [q[3], q[1], q[5], q[7]],
                  [q[4], q[5], q[2], q[8]],
                  [q[6], q[7], q[8], q[9]]])
    try:
        centre = -np.linalg.solve(Q[:3, :3], Q[:3, 3])
    except np.linalg.LinAlgError:
        raise UserError("the static attitudes do not determine the accelerometer ellipsoid "
                        "(singular fit): use attitudes that spread gravity over all axes") from None
    xc = np.append(centre, 1.0)
    lam = -(xc @ Q @ xc)
    L = lower_factor(Q[:3, :3] / lam)
    return L, centre * gravity


def fit_gyro_matrix(pairs: list) -> np.ndarray:
    """L_g = (K_g T_g)^-1 from |L_g phi_j| = swept angle of pair j."""
    if len(pairs) < 6:
        raise UserError(f"the gyro fit needs at least 6 +/- rotation pairs about different axes; "
                        f"the capture has {len(pairs)}")
    u = np.array([p.phi / p.swept_deg for p in pairs])
    x, y, z = u.T
    D = np.column_stack([x * x, y * y, z * z, 2 * x * y, 2 * x * z, 2 * y * z])
    m, *_ = np.linalg.lstsq(D, np.ones(len(u)), rcond=None)
    M = np.array([[m[0], m[3], m[4]], [m[3], m[1], m[5]], [m[4], m[5], m[2]]])
    return lower_factor(M)


def fit_gyro_bias(L: np.ndarray, means: np.ndarray, earth_rate: float = EARTH_RATE_DPS) -> np.ndarray:
    """Bias b_g with |L (w_j - b_g)| = Earth rate at every static attitude (eqs. 23-25)."""
    if len(means) < 4:
        raise UserError("the gyro bias fit needs at least 4 static attitudes")
    v = means @ L.T
    A = np.column_stack([2 * v, -np.ones(len(v))])
    sol, *_ = np.linalg.lstsq(A, np.sum(v * v, axis=1), rcond=None)
    c = sol[:3]
    def jac(c):             # d(|v - c| - earth rate)/dc
        d = v - c
        return -d / np.linalg.norm(d, axis=1)[:, None]

    # (to the machine's precision; station/estimate/solver.py: no scipy import)
    res = solver.least_squares(lambda c: np.linalg.norm(v - c, axis=1) - earth_rate, c, jac,
                               xtol=1e-15, ftol=1e-15, gtol=1e-15)
    return np.linalg.solve(L, res.x)


def accel_rotation_axis(f_p: np.ndarray) -> tuple[np.ndarray, float]:
    """Rotation axis in p from calibrated specific force: null vector of [f^T, -1] (eqs. 44-47).

    Returns the unit axis and the condition (2nd smallest / smallest eigenvalue); a small
    condition means gravity barely moved, i.e. the axis was close to vertical.
    """
    mean = f_p.mean(axis=0)
    d = f_p - mean                            # centring removes kappa: (f - mean) . l = 0
    w, V = np.linalg.eigh(d.T @ d)
    return V[:, 0], float(w[1] / max(w[0], w[1] * 1e-16))


def fit_inter_triad(pairs, L_a, b_a, L_g) -> tuple[np.ndarray | None, list]:
    """R_po aligning the accelerometer-derived axes to the gyro-derived axes of every pair."""
    axes_o, axes_p, notes = [], [], []
    for pair in pairs:
        l_o = L_g @ pair.phi
        l_o /= np.linalg.norm(l_o)
        l_p, condition = accel_rotation_axis((pair.accel - b_a) @ L_a.T)
        if condition < MIN_AXIS_CONDITION:
            notes.append(f"{pair.name}: rotation axis too close to vertical for the accelerometers "
                         "to see it; not used for the inter-triad misalignment")
            continue
        axes_o.append(l_o)
        axes_p.append(l_p if l_p @ l_o > 0 else -l_p)
    if len(axes_o) < 2:
        return None, notes + ["inter-triad misalignment not estimated: fewer than two usable "
                              "rotation axes"]
    return align_vectors(np.array(axes_o), np.array(axes_p)), notes


def estimate(capture) -> Calibration:
    """Run the 2010 algebraic calibration on a capture."""
    s = summarise(capture)
    L_a, b_a = fit_accelerometers(s.accel_means, s.gravity_mps2)

    # Gyro: the +/- difference cancels the bias only if both directions last equally long;
    # remove the bias found from the statics and fit again (converges in one pass).
    bias = np.zeros(3)
    for _ in range(2):
        for p in s.pairs:
            p.phi = (p.integral_plus - bias * p.duration_plus_s) - (p.integral_minus - bias * p.duration_minus_s)
        L_g = fit_gyro_matrix(s.pairs)
        bias = fit_gyro_bias(L_g, s.gyro_means)

    R_po, notes = fit_inter_triad(s.pairs, L_a, b_a, L_g)
    ka, Ta = scale_and_T(L_a)
    kg, Tg = scale_and_T(L_g)
    effects = ["base_triads", "inter_triad"] if R_po is not None else ["base_triads"]

    accel_norm_res = np.linalg.norm((s.accel_means - b_a) @ L_a.T, axis=1) - s.gravity_mps2
    gyro_norm_res = np.linalg.norm((s.gyro_means - bias) @ L_g.T, axis=1) - EARTH_RATE_DPS
    pair_res = [np.linalg.norm(L_g @ p.phi) / p.swept_deg - 1.0 for p in s.pairs]
    fit = {
        "method": "zhang2010",
        "static_segments": len(s.static_names),
        "rotation_pairs": len(s.pairs),
        "accel_norm_residual_ug": {n: float(r / units.UG_MPS2) for n, r in zip(s.static_names, accel_norm_res)},
        "gyro_norm_residual_dph": {n: float(r * 3600) for n, r in zip(s.static_names, gyro_norm_res)},
        "rotation_angle_residual_ppm": {p.name: float(r * 1e6) for p, r in zip(s.pairs, pair_res)},
        "notes": notes,
    }
    return Calibration(
        accel_unit=capture.imu.accel_unit, gyro_unit=capture.imu.gyro_unit,
        accel_scale=ka, accel_T=Ta, accel_bias=b_a / s.accel_factor,
        gyro_scale=kg, gyro_T=Tg, gyro_bias=bias / s.gyro_factor,
        R_po=R_po if R_po is not None else np.eye(3), effects=effects, fit=fit)
