"""The Fourier method: calibration on a low-grade turntable or an electric screwdriver.

After "IMU calibration on a low-grade turntable or a screwdriver, by the Fourier transform"
(shared/papers/fourier-turntable-screwdriver-calibration.txt; docs/method-fourier.md).  The IMU
is clamped to a shaft that turns about a roughly horizontal, Earth-fixed axis, in P >= 3
mountings that differ by turns about axes perpendicular to the shaft; nothing but the IMU
measures the rotation (no encoder angle, the rate unknown and somewhat irregular).

Per rotation experiment (one segment):
  1. FFT of the accelerometer signal (numpy.fft), the peak of the summed power spectrum, its
     frequency to a fraction of a bin (three-bin interpolation of Candan, a bias-corrected
     Jacobsen estimator), and the complex amplitude A at that frequency (a 3-vector: amplitudes
     and phases of the three axes).  For a rotation about a fixed axis the raw accelerometer
     reads  a(t) = c + P1 cos th(t) + P2 sin th(t);  Re A and -Im A are conjugate semi-diameters
     of that ellipse even when the rate drifts (a drift only shrinks |A| and turns its phase).
  2. Irregular rate (our addition, needed for a screwdriver whose rate falls 20 %): the angle
     th(t) is read from the accelerometers themselves, by projecting a(t) - c on the plane of
     (Re A, -Im A) and unwrapping atan2, smoothed with a least-squares cubic spline (knots every
     two revolutions), and the harmonic amplitudes P1, P2 and the constant c are re-fitted by
     linear least squares on [1, dth^2, d2th, cos th, sin th] (the last two absorbing the
     centrifugal and tangential terms of a proof mass off the axis when the rate changes).
     Two passes.  With a perfectly steady rate this is the paper's amplitude at the FFT peak.
     The mean rate is the mean of dth/dt over the samples: the rotation counted by the
     accelerometers, with no encoder.
Accelerometers (paper 3.1-3.2), with M = L_a^T L_a, f_p = L_a (a - b_a):
  3. ellipsoid in spectral space: L_a P1 and L_a P2 are orthogonal and of equal length, so
     P1^T M P1 - P2^T M P2 = 0 and P1^T M P2 = 0: two linear homogeneous equations in the six
     coefficients of M per rotation; M up to scale is the null vector (SVD); P >= 3 shaft
     directions are needed (two planes share a line and leave M undetermined).
  4. L~ from M~ by the triangular factorisation of the 2010 method (frame p); in L~ space each
     rotation gives the axis w^_p = unit(L~P2 x L~P1) (the sense of rotation included) and the
     radius rho_p.  The specific force along the shaft is the same in every mounting, g1 =
     g sin(elevation), while the centrifugal force is perpendicular to it, so
     a_p . (L~ c_p - beta) = gamma  (beta = L~ b_a, gamma = g1 / s) is linear in (beta, gamma);
     a_p = +-w^_p is the axis turned to point along the segment's axis_body (the sign check:
     the direction of rotation comes from the data; a manifest rate_dps of the other sign is
     reported).  gamma is estimated with >= 4 mountings, else the shaft is taken as horizontal.
     The scale s (L_a = s L~) from s^2 (rho_p^2 + gamma^2) = g^2.  Static segments, if any,
     add |L~ s_q - beta|^2 = g^2 / s^2, linear in (beta, |beta|^2 - g^2/s^2).
Gyros (paper 3.3), forward model  gyro_raw = S_g w_p + b_g,  S_g = K_g T_g R_po:
  5. low grade (Earth rate neglected): mean gyro of rotation p = S_g W_p w^_p + b_g, and of a
     static segment = b_g: linear least squares in the 12 unknowns.  The Earth rate along each
     shaft (up to 15 deg/h) goes into b_g.
     high grade (only |Omega_E| known): a per-mounting rate c_m along the shaft is added,
     mean = S_g (W_p w^_p + c_m a_m) + b_g, and each static mean satisfies
     |S_g^-1 (w_q - b_g)| = |Omega_E|; solved linearly in (L_g b_g, c_m, |L_g b_g|^2 - Omega^2)
     with S_g fixed, then S_g again (three passes), the static norms refined exactly.
  6. S_g = K_g T_g R_po by an RQ factorisation (lower triangular times a rotation).
Arrays are in m/s^2 and deg/s after the manifest's unit conversion ("raw" is taken as is).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.interpolate import BSpline, make_lsq_spline
from scipy.optimize import least_squares

from station.core import units
from station.model.calibration import Calibration
from station.core.errors import UserError
from station.estimate.zhang2010 import lower_factor, scale_and_T

EARTH_RATE_DPS = units.EARTH_RATE_DPS
VARIANTS = ("low", "high")
DEFAULT_VARIANT = "low"

MIN_REVOLUTIONS = 10.0       # fewer: hand turns, not a steady rotation (refused)
PAPER_REVOLUTIONS = 80.0     # the paper: > 40 s at 2 rev/s is accurate, < 20 revolutions is not
MIN_ROTATING_FRACTION = 0.2  # rotating part of gravity below 0.2 g: the shaft is near vertical
MIN_RATE_FRACTION = 0.25     # the smoothed rate must stay above this fraction of its median
KNOT_REVOLUTIONS = 2.0       # spline knot spacing of the tracked angle, in revolutions
MAX_PASSES = 12              # phase-tracking / re-fitting passes after the FFT (each gains ~4x)
PHASE_TOLERANCE_RAD = 1e-7   # ... until the tracked angle changes by less than this
SAME_AXIS_COS = math.cos(math.radians(5.0))   # rotation axes closer than 5 deg: one mounting


# --- step 1: the spectral peak ---------------------------------------------------------------

@dataclass
class SpectralPeak:
    frequency_hz: float      # interpolated peak frequency, > 0
    bin: int                 # FFT bin of the maximum
    offset_bins: float       # sub-bin offset, in [-0.5, 0.5] for a clean tone
    amplitude: np.ndarray    # complex amplitude per channel at frequency_hz: x ~ Re(A e^{i 2 pi f t})


def spectral_peak(x, sample_rate_hz: float, *, min_hz: float = 0.0, max_hz: float | None = None) -> SpectralPeak:
    """Peak of the power spectrum of x (N,) or (N, channels), with sub-bin interpolation.

    The peak bin k of the summed power |X_k|^2 is refined with Candan's three-bin estimator
    (bias-corrected Jacobsen): with y_j = v^H X_{k+j}, v = X_k / |X_k| (all channels share the
    spectral kernel of one tone),  delta = tan(pi/N)/(pi/N) Re[(y_-1 - y_1) / (2 y_0 - y_-1 - y_1)].
    The complex amplitude is the DTFT at the interpolated frequency, 2/N sum x_n e^{-i 2 pi f n / fs}.
    """
    x = np.asarray(x, dtype=float)
    squeeze = x.ndim == 1
    x2 = x[:, None] if squeeze else x
    n = len(x2)
    if n < 8:
        raise UserError("a spectral peak needs at least 8 samples")
    x2 = x2 - x2.mean(axis=0)
    X = np.fft.rfft(x2, axis=0)
    power = np.sum(np.abs(X) ** 2, axis=1)
    freqs = np.arange(len(X)) * sample_rate_hz / n
    lo = max(1, int(math.ceil(min_hz * n / sample_rate_hz)))
    hi = len(X) - 2 if max_hz is None else min(len(X) - 2, int(max_hz * n / sample_rate_hz))
    if hi < lo:
        raise UserError("no spectral bin in the search range")
    k = lo + int(np.argmax(power[lo:hi + 1]))
    k = min(max(k, 1), len(X) - 2)
    v = X[k] / np.linalg.norm(X[k])
    y = [np.vdot(v, X[k + j]) for j in (-1, 0, 1)]
    denom = 2 * y[1] - y[0] - y[2]
    delta = 0.0
    if abs(denom) > 0:
        c = math.tan(math.pi / n) / (math.pi / n)
        delta = float(np.clip(c * np.real((y[0] - y[2]) / denom), -1.0, 1.0))
    f = (k + delta) * sample_rate_hz / n
    phase = np.exp(-2j * np.pi * f * np.arange(n) / sample_rate_hz)
    A = 2.0 / n * (phase @ x2)
    return SpectralPeak(float(f), k, delta, A[0] if squeeze else A)


# --- step 2: one rotation experiment -------------------------------------------------------------

@dataclass
class RotationSummary:
    name: str
    axis_body: np.ndarray         # commanded shaft direction in IMU case axes, unit
    rate_sign: float | None       # sign of the manifest's rate_dps (None: not given)
    samples: int
    duration_s: float
    peak_hz: float                # FFT peak of the accelerometers, interpolated
    mean_rate_dps: float          # mean of d(theta)/dt over the samples, > 0, from the accelerometers
    min_rate_dps: float           # smoothed rate, lowest and highest
    max_rate_dps: float
    revolutions: float
    accel_cos: np.ndarray         # P1 (3,): accel = c + P1 cos th + P2 sin th, m/s^2
    accel_sin: np.ndarray         # P2 (3,)
    accel_const: np.ndarray       # c (3,), at the mean rate
    gyro_mean: np.ndarray         # (3,) deg/s
    accel_residual_rms: float     # m/s^2, per axis, after the harmonic fit
    rate_noise_factor: float = 0.0  # var(mean rate, rad/s) per var(phase noise, rad^2), 1/s^2


def _smooth_angle(t, theta, rate_hz):
    """Least-squares cubic spline through the unwrapped angle, knots every KNOT_REVOLUTIONS."""
    span = t[-1] - t[0]
    spacing = KNOT_REVOLUTIONS / max(rate_hz, 1e-9)
    intervals = max(1, int(span / spacing))
    interior = np.linspace(t[0], t[-1], intervals + 1)[1:-1]
    knots = np.concatenate([[t[0]] * 4, interior, [t[-1]] * 4])
    trend = np.polyfit(t - t[0], theta, 1)
    spline = make_lsq_spline(t, theta - np.polyval(trend, t - t[0]), knots, k=3)
    th = spline(t) + np.polyval(trend, t - t[0])
    dth = spline.derivative(1)(t) + trend[0]
    d2th = spline.derivative(2)(t)
    return th, dth, d2th, knots


def rate_noise_factor(t, knots) -> float:
    """Variance of the mean rate per unit variance of white phase noise, 1/s^2.

    The smoothed angle is the least-squares spline fit (it contains the straight line), so the
    mean rate is (th_s(t_end) - th_s(t_0)) / span = d^T coef, with var = sigma_phase^2 d^T (B^T B)^-1 d.
    """
    B = BSpline.design_matrix(t, knots, 3).tocsr()
    d = (B[[-1]].toarray()[0] - B[[0]].toarray()[0]) / (t[-1] - t[0])
    return float(d @ np.linalg.solve((B.T @ B).toarray(), d))


def _harmonic_fit(t, accel, th, dth, d2th):
    """accel = c + k1 (dth^2 - mean) + k2 (d2th - mean) + P1 cos th + P2 sin th, per axis."""
    r1 = dth ** 2 - np.mean(dth ** 2)
    r2 = d2th - np.mean(d2th)
    X = np.column_stack([np.ones_like(t), r1, r2, np.cos(th), np.sin(th)])
    norms = np.linalg.norm(X, axis=0)
    norms[norms == 0] = 1.0
    coef, *_ = np.linalg.lstsq(X / norms, accel, rcond=1e-10)
    coef = coef / norms[:, None]
    offset = X[:, :3] @ coef[:3]
    residual = accel - X @ coef
    return coef[0], coef[3], coef[4], offset, residual


def analyse_rotation(name, t, accel, gyro, axis_body, rate_dps=None) -> RotationSummary:
    """Spectral summary of one rotation segment (accel in m/s^2 or raw, gyro in deg/s or raw)."""
    t = np.asarray(t, float)
    n = len(t)
    span = float(t[-1] - t[0]) if n > 1 else 0.0
    if n < 16 or span <= 0:
        raise UserError(f"segment '{name}': too short for the Fourier method ({n} samples)")
    fs = (n - 1) / span
    peak = spectral_peak(accel, fs, min_hz=MIN_REVOLUTIONS / 2 / span)
    B = np.column_stack([peak.amplitude.real, -peak.amplitude.imag])
    if np.linalg.matrix_rank(B, tol=1e-12 * max(np.abs(B).max(), 1e-300)) < 2:
        raise UserError(f"segment '{name}': the accelerometers show no rotating gravity "
                        "(is the shaft vertical?)")
    # First angle from the time derivative (central differences: no phase shift), which a slowly
    # changing offset (the centrifugal force of a drifting rate) does not disturb:
    # da/dt = th' (P2 cos th - P1 sin th).  Then from a(t) - offset(t) itself.
    da = np.gradient(accel, t, axis=0)
    coords = da @ np.linalg.pinv(B).T
    theta = np.unwrap(np.arctan2(-coords[:, 0], coords[:, 1]))
    if theta[-1] < theta[0]:              # (Re A, -Im A) turns with increasing phase; be sure
        B = B[:, ::-1]
        coords = coords[:, ::-1]
        theta = np.unwrap(np.arctan2(-coords[:, 0], coords[:, 1]))
    th = None
    for k in range(MAX_PASSES):
        if k:
            coords = (accel - offset) @ np.linalg.pinv(B).T
            theta = np.unwrap(np.arctan2(coords[:, 1], coords[:, 0]))
        rate_hz = (theta[-1] - theta[0]) / (2 * np.pi * span)
        previous = th
        th, dth, d2th, knots = _smooth_angle(t, theta, rate_hz)
        c, p1, p2, offset, residual = _harmonic_fit(t, accel, th, dth, d2th)
        B = np.column_stack([p1, p2])
        if previous is not None:
            change = th - previous
            if np.max(np.abs(change - change.mean())) < PHASE_TOLERANCE_RAD:
                break
    radius = math.sqrt((p1 @ p1 + p2 @ p2) / 2)
    if radius < MIN_ROTATING_FRACTION * math.hypot(radius, np.linalg.norm(c)):
        raise UserError(f"segment '{name}': the accelerometers see gravity barely turn (a turning part of "
                        f"{radius / math.hypot(radius, np.linalg.norm(c)):.2f} of the total): is the shaft "
                        "near vertical? The Fourier method needs a roughly horizontal shaft")
    revolutions = float((th[-1] - th[0]) / (2 * np.pi) + np.mean(dth) / fs / (2 * np.pi))
    if revolutions < MIN_REVOLUTIONS:
        raise UserError(f"segment '{name}': {revolutions:.1f} revolutions; the Fourier method needs a "
                        f"steady rotation of at least {MIN_REVOLUTIONS:.0f} revolutions (the paper uses "
                        f"{PAPER_REVOLUTIONS:.0f}): hand turns are not enough")
    median_rate = float(np.median(dth))
    if np.min(dth) < MIN_RATE_FRACTION * median_rate:
        raise UserError(f"segment '{name}': the rotation stops or reverses (rate down to "
                        f"{np.degrees(np.min(dth)):.1f} deg/s against a median of "
                        f"{np.degrees(median_rate):.1f} deg/s); the Fourier method needs a monotonic rotation")
    axis = np.asarray(axis_body, float)
    return RotationSummary(
        name=name, axis_body=axis / np.linalg.norm(axis),
        rate_sign=None if rate_dps is None else float(np.sign(rate_dps)),
        samples=n, duration_s=span + 1.0 / fs, peak_hz=peak.frequency_hz,
        mean_rate_dps=float(np.degrees(np.mean(dth))),
        min_rate_dps=float(np.degrees(np.min(dth))), max_rate_dps=float(np.degrees(np.max(dth))),
        revolutions=revolutions, accel_cos=p1, accel_sin=p2, accel_const=c,
        gyro_mean=np.asarray(gyro, float).mean(axis=0),
        accel_residual_rms=float(np.sqrt(np.mean(residual ** 2))),
        rate_noise_factor=rate_noise_factor(t, knots))


@dataclass
class Summaries:
    """What the algebra needs from a capture, in m/s^2 and deg/s (raw kept as is)."""
    gravity_mps2: float
    accel_factor: float
    gyro_factor: float
    rotations: list                       # RotationSummary
    static_names: list = field(default_factory=list)
    static_accel: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    static_gyro: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))


def summarise(capture) -> Summaries:
    ca = units.accel_to_mps2_factor(capture.imu.accel_unit) or 1.0
    cg = units.gyro_to_dps_factor(capture.imu.gyro_unit) or 1.0
    rotations = [analyse_rotation(s.name, s.data.t, s.data.accel * ca, s.data.gyro * cg,
                                  s.axis_body, s.rate_dps)
                 for s in capture.complete("rotation")]
    statics = capture.complete("static")
    return Summaries(
        gravity_mps2=capture.site.gravity_mps2, accel_factor=ca, gyro_factor=cg, rotations=rotations,
        static_names=[s.name for s in statics],
        static_accel=np.array([s.data.accel.mean(axis=0) * ca for s in statics]).reshape(-1, 3),
        static_gyro=np.array([s.data.gyro.mean(axis=0) * cg for s in statics]).reshape(-1, 3))


# --- steps 3 and 4: accelerometers ----------------------------------------------------------------

def _quad_row(x, y):
    """Coefficients of x^T M y in the 6 unknowns (Mxx, Myy, Mzz, Mxy, Mxz, Myz) of symmetric M."""
    return np.array([x[0] * y[0], x[1] * y[1], x[2] * y[2], x[0] * y[1] + x[1] * y[0],
                     x[0] * y[2] + x[2] * y[0], x[1] * y[2] + x[2] * y[1]])


def _sym(m):
    return np.array([[m[0], m[3], m[4]], [m[3], m[1], m[5]], [m[4], m[5], m[2]]])


def mountings(rotations) -> list[list[int]]:
    """Indices of the rotations grouped by their commanded shaft direction (axis_body)."""
    groups: list[list[int]] = []
    for i, r in enumerate(rotations):
        for g in groups:
            if abs(float(rotations[g[0]].axis_body @ r.axis_body)) > SAME_AXIS_COS:
                g.append(i)
                break
        else:
            groups.append([i])
    return groups


def _distinct_planes(axes) -> int:
    reps: list[np.ndarray] = []
    for a in axes:
        if all(abs(float(a @ r)) < SAME_AXIS_COS for r in reps):
            reps.append(a)
    return len(reps)


@dataclass
class AccelSolution:
    L: np.ndarray             # f_p = L (a - b)
    bias: np.ndarray          # m/s^2 (or raw)
    axes: np.ndarray          # (P,3) unit rotation vectors in p (sense of rotation included)
    along: np.ndarray         # (P,3) the axes turned to point along axis_body
    g_along_mps2: float       # specific force along the shaft (g sin elevation)
    tilt_estimated: bool
    notes: list


def fit_accelerometers(s: Summaries) -> AccelSolution:
    rot = s.rotations
    g = s.gravity_mps2
    notes: list[str] = []
    raw_axes = []
    for r in rot:
        n = np.cross(r.accel_sin, r.accel_cos)
        raw_axes.append(n / np.linalg.norm(n))
    planes = _distinct_planes(raw_axes)
    if planes < 3:
        raise UserError(f"the Fourier method needs rotations in at least 3 mountings with different shaft "
                        f"directions in the IMU (the paper's P >= 3); the capture has {planes}")
    for r in rot:
        if math.hypot(*np.linalg.norm([r.accel_cos, r.accel_sin], axis=1)) / math.sqrt(2) < MIN_ROTATING_FRACTION * g:
            raise UserError(f"segment '{r.name}': gravity barely turns in the IMU (shaft within "
                            f"{math.degrees(math.acos(MIN_ROTATING_FRACTION)):.0f} deg of vertical?); the "
                            "Fourier method needs a roughly horizontal shaft")
    # step 3: M up to scale, homogeneous (data scaled by g)
    rows = []
    for r in rot:
        p1, p2 = r.accel_cos / g, r.accel_sin / g
        rows.append(_quad_row(p1, p1) - _quad_row(p2, p2))
        rows.append(_quad_row(p1, p2))
    sv, V = np.linalg.svd(np.array(rows))[1:]
    if len(sv) < 6 or sv[-2] < 1e-9 * sv[0]:
        raise UserError("the rotation planes do not determine the accelerometer ellipsoid: use mountings "
                        "whose shaft directions are not all in one plane")
    Mt = _sym(V[-1])
    if np.trace(Mt) < 0:
        Mt = -Mt
    Lt = lower_factor(Mt)
    # step 4: axes, radii, bias, tilt, scale in L~ space
    axes, along, rho2, y_rot = [], [], [], []
    for r in rot:
        u, v = Lt @ r.accel_cos, Lt @ r.accel_sin
        w = np.cross(v, u)
        w /= np.linalg.norm(w)
        axes.append(w)
        sign = 1.0 if w @ r.axis_body >= 0 else -1.0
        along.append(sign * w)
        if r.rate_sign is not None and r.rate_sign != sign:
            notes.append(f"{r.name}: the accelerometers show a {'positive' if sign > 0 else 'negative'} "
                         f"rotation about axis_body, the manifest's rate_dps says otherwise; the data are used")
        rho2.append((u @ u + v @ v) / 2)
        y_rot.append(Lt @ r.accel_const)
    axes, along, rho2, y_rot = map(np.array, (axes, along, rho2, y_rot))
    groups = mountings(rot)
    reps = np.array([np.append(along[g[0]], 1.0) for g in groups])
    tilt = len(groups) >= 4 and np.linalg.svd(reps, compute_uv=False)[-1] > 0.05 * math.sqrt(len(groups))
    if not tilt:
        notes.append(f"{len(groups)} mountings: the shaft is taken as horizontal (its elevation needs "
                     "at least 4 mountings)")
    y_st = s.static_accel @ Lt.T
    nq = len(y_st)
    ncol = 3 + int(tilt) + int(nq > 0)
    A, rhs = [], []
    for a, y in zip(along, y_rot):
        row = np.zeros(ncol)
        row[:3] = a
        if tilt:
            row[3] = 1.0
        A.append(row)
        rhs.append(a @ y)
    for y in y_st:
        row = np.zeros(ncol)
        row[:3] = 2 * y
        row[-1] = -1.0
        scale = 2 * np.linalg.norm(y)
        A.append(row / scale)
        rhs.append((y @ y) / scale)
    sol, *_ = np.linalg.lstsq(np.array(A), np.array(rhs), rcond=None)
    beta = sol[:3]
    gamma = float(sol[3]) if tilt else 0.0
    radii2 = list(rho2 + gamma ** 2)
    if nq:
        radii2 += [float(beta @ beta - sol[-1])] * nq
    scale = g / math.sqrt(np.mean(radii2))
    L = scale * Lt
    bias = np.linalg.solve(Lt, beta)
    return AccelSolution(L=L, bias=bias, axes=axes, along=along, g_along_mps2=scale * gamma,
                         tilt_estimated=bool(tilt), notes=notes)


# --- step 5: gyros ----------------------------------------------------------------------------------

def _lstsq_gyro(rates, means):
    """S, b from means = S rates + b (rates (J,3) with zero rows for statics)."""
    Phi = np.column_stack([rates, np.ones(len(rates))])
    if np.linalg.matrix_rank(Phi) < 4:
        raise UserError("the rotations do not determine the gyro matrix: need rotation axes in three "
                        "independent directions")
    X, *_ = np.linalg.lstsq(Phi, means, rcond=None)
    return X[:3].T, X[3]


def shared_axes(rotations, acc: AccelSolution):
    """Unit rotation vectors in p, the rotations of one mounting sharing one shaft direction.

    Both directions of a mounting turn about the same shaft: averaging their axes (turned to
    point along axis_body) cancels, in the sum of the two gyro means, the perpendicular error of
    each accelerometer-derived axis, which would otherwise go into the gyro bias (at 720 deg/s a
    1e-5 rad axis error is 26 deg/h).  Returns (rotation axes (P,3), mounting axes, membership).
    """
    groups = mountings(rotations)
    member = np.zeros(len(rotations), int)
    shafts = []
    for m, g in enumerate(groups):
        member[g] = m
        a = acc.along[g].sum(axis=0)
        shafts.append(a / np.linalg.norm(a))
    shafts = np.array(shafts)
    signs = np.sign(np.einsum("ij,ij->i", acc.axes, shafts[member]))
    return signs[:, None] * shafts[member], shafts, member


def fit_gyros(s: Summaries, acc: AccelSolution, variant: str):
    rot = s.rotations
    axes, shafts, member = shared_axes(rot, acc)
    rates = np.array([r.mean_rate_dps for r in rot])[:, None] * axes
    means = np.array([r.gyro_mean for r in rot])
    nq = len(s.static_gyro)
    info: dict = {}
    if variant == "low":
        S, b = _lstsq_gyro(np.vstack([rates, np.zeros((nq, 3))]), np.vstack([means, s.static_gyro]))
        return S, b, info
    groups = mountings(rot)
    along = shafts[member]
    S, b = _lstsq_gyro(rates, means)
    c = np.zeros(len(groups))
    for _ in range(3):
        Lg = np.linalg.inv(S)
        z = means @ Lg.T - rates                          # = beta + c_m a_m
        v = s.static_gyro @ Lg.T
        ncol = 3 + len(groups) + int(nq > 0)
        A, rhs = [], []
        for p in range(len(rot)):
            for k in range(3):
                row = np.zeros(ncol)
                row[k] = 1.0
                row[3 + member[p]] = along[p][k]
                A.append(row)
                rhs.append(z[p, k])
        for vq in v:
            row = np.zeros(ncol)
            row[:3] = 2 * vq
            row[-1] = -1.0
            sc = 2 * max(np.linalg.norm(vq), EARTH_RATE_DPS)
            A.append(row / sc)
            rhs.append(vq @ vq / sc)
        sol, *_ = np.linalg.lstsq(np.array(A), np.array(rhs), rcond=None)
        beta, c = sol[:3], sol[3:3 + len(groups)]
        if nq:
            def resid(x):
                bb, cc = x[:3], x[3:]
                r1 = (z - bb - cc[member][:, None] * along).ravel()
                r2 = np.linalg.norm(v - bb, axis=1) - EARTH_RATE_DPS
                return np.concatenate([r1, r2])
            x = least_squares(resid, np.concatenate([beta, c]), x_scale=EARTH_RATE_DPS,
                              xtol=1e-15, ftol=1e-15, gtol=1e-15).x
            beta, c = x[:3], x[3:]
        b = S @ beta
        S, _ = _lstsq_gyro_fixed_bias(rates + c[member][:, None] * along, means - b)
    info["earth_rate_along_shaft_dph"] = {
        "/".join(rot[i].name for i in g): float(c[m] * 3600) for m, g in enumerate(groups)}
    return S, b, info


def _lstsq_gyro_fixed_bias(rates, centred):
    if np.linalg.matrix_rank(rates) < 3:
        raise UserError("the rotations do not determine the gyro matrix: need rotation axes in three "
                        "independent directions")
    X, *_ = np.linalg.lstsq(rates, centred, rcond=None)
    return X.T, None


def rq_lower(S: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """S = L Q with L lower triangular (positive diagonal) and Q a rotation (det S > 0)."""
    Q1, R1 = np.linalg.qr(S.T)
    L, Q = R1.T, Q1.T
    d = np.sign(np.diag(L))
    d[d == 0] = 1.0
    L, Q = L * d[None, :], d[:, None] * Q
    if np.linalg.det(Q) < 0:
        raise UserError("the gyro triad comes out left-handed against the accelerometers (det < 0): "
                        "check the axis signs of the capture")
    return L, Q


# --- the whole method ------------------------------------------------------------------------------

@dataclass
class Solution:
    L_a: np.ndarray
    b_a: np.ndarray
    S_g: np.ndarray
    b_g: np.ndarray
    accel: AccelSolution
    gyro_info: dict


def solve(s: Summaries, variant: str = DEFAULT_VARIANT) -> Solution:
    if variant not in VARIANTS:
        raise UserError(f"unknown Fourier variant {variant!r}: use one of {', '.join(VARIANTS)}")
    if not s.rotations:
        raise UserError("the Fourier method needs rotation segments; the capture has none complete")
    acc = fit_accelerometers(s)
    S_g, b_g, info = fit_gyros(s, acc, variant)
    return Solution(acc.L, acc.bias, S_g, b_g, acc, info)


def estimate(capture, variant: str = DEFAULT_VARIANT) -> Calibration:
    """Run the Fourier calibration on a capture (rotations without encoder angles)."""
    if variant not in VARIANTS:
        raise UserError(f"unknown Fourier variant {variant!r}: use one of {', '.join(VARIANTS)}")
    s = summarise(capture)
    sol = solve(s, variant)
    ka, Ta = scale_and_T(sol.L_a)
    Lg, R_po = rq_lower(sol.S_g)
    kg = np.linalg.norm(Lg, axis=1)
    Tg = Lg / kg[:, None]
    g = s.gravity_mps2
    rot = s.rotations
    notes = list(sol.accel.notes)
    for r in rot:
        if r.revolutions < PAPER_REVOLUTIONS:
            notes.append(f"{r.name}: {r.revolutions:.0f} revolutions, fewer than the paper's "
                         f"{PAPER_REVOLUTIONS:.0f}")
    if variant == "low":
        notes.append("low-grade variant: the Earth rate is neglected, so the gyro biases include up to "
                     f"{EARTH_RATE_DPS * 3600:.1f} deg/h of it")
    ug = units.UG_MPS2
    shape_res, radius_res, axial_res, gyro_res, segs = {}, {}, {}, {}, {}
    Linv_g = np.linalg.inv(sol.S_g)
    for r, w, a in zip(rot, sol.accel.axes, sol.accel.along):
        u, v = sol.L_a @ r.accel_cos, sol.L_a @ r.accel_sin
        shape_res[r.name] = [float((np.linalg.norm(u) - np.linalg.norm(v)) / g * 1e6),
                             float(u @ v / g ** 2 * 1e6)]
        g_perp = math.sqrt(max(g ** 2 - sol.accel.g_along_mps2 ** 2, 0.0))
        radius_res[r.name] = float((math.sqrt((u @ u + v @ v) / 2) - g_perp) / ug)
        axial_res[r.name] = float((a @ (sol.L_a @ (r.accel_const - sol.b_a)) - sol.accel.g_along_mps2) / ug)
        gyro_res[r.name] = float(np.linalg.norm(Linv_g @ (r.gyro_mean - sol.b_g) - r.mean_rate_dps * w) * 3600)
        segs[r.name] = {
            "peak_hz": float(r.peak_hz), "mean_rate_dps": float(r.mean_rate_dps),
            "rate_range_dps": [float(r.min_rate_dps), float(r.max_rate_dps)],
            "revolutions": float(r.revolutions), "duration_s": float(r.duration_s),
            "accel_residual_rms_ug": float(r.accel_residual_rms / ug),
            "axis_p": [float(x) for x in w],
        }
    static_res = {n: float((np.linalg.norm(sol.L_a @ (f - sol.b_a)) - g) / ug)
                  for n, f in zip(s.static_names, s.static_accel)}
    fit = {
        "method": "fourier",
        "variant": variant,
        "rotation_segments": len(rot),
        "static_segments": len(s.static_names),
        "mountings": len(mountings(rot)),
        "shaft_elevation_deg": float(math.degrees(math.asin(max(-1.0, min(1.0, sol.accel.g_along_mps2 / g))))),
        "shaft_elevation_estimated": sol.accel.tilt_estimated,
        "segments": segs,
        "ellipse_shape_residual_ppm": shape_res,
        "rotation_radius_residual_ug": radius_res,
        "shaft_force_residual_ug": axial_res,
        "gyro_rate_residual_dph": gyro_res,
        "accel_norm_residual_ug": static_res,
        **sol.gyro_info,
        "notes": notes,
    }
    return Calibration(
        accel_unit=capture.imu.accel_unit, gyro_unit=capture.imu.gyro_unit,
        accel_scale=ka, accel_T=Ta, accel_bias=sol.b_a / s.accel_factor,
        gyro_scale=kg, gyro_T=Tg, gyro_bias=sol.b_g / s.gyro_factor,
        R_po=R_po, effects=["base_triads", "inter_triad"], fit=fit)


# --- first-order error propagation --------------------------------------------------------------

def _perturbed(s: Summaries, index: int, h: float) -> Summaries:
    """A copy of s with summary component ``index`` (see summary_vector) moved by h."""
    rots = [replace(r, accel_cos=r.accel_cos.copy(), accel_sin=r.accel_sin.copy(),
                    accel_const=r.accel_const.copy(), gyro_mean=r.gyro_mean.copy()) for r in s.rotations]
    out = replace(s, rotations=rots, static_accel=s.static_accel.copy(), static_gyro=s.static_gyro.copy())
    if index < 13 * len(rots):
        r, k = rots[index // 13], index % 13
        if k == 12:
            r.mean_rate_dps += h
        else:
            getattr(r, ("accel_cos", "accel_sin", "accel_const", "gyro_mean")[k // 3])[k % 3] += h
    else:
        j = index - 13 * len(rots)
        (out.static_accel if j % 6 < 3 else out.static_gyro)[j // 6, j % 3] += h
    return out


def summary_variances(s: Summaries, accel_density: float, gyro_density: float,
                      sample_rate_hz: float) -> np.ndarray:
    """Variance of every summary component from white noise densities (m/s^2/sqrt(Hz) and
    deg/s/sqrt(Hz)), in the order of _perturbed: per rotation P1 (3), P2 (3), c (3), gyro
    mean (3), mean rate (1); per static segment accel mean (3), gyro mean (3).

    Over T seconds: harmonic amplitudes 2 N^2 / T per axis, means N^2 / T; the mean rate
    sigma_phase^2 * rate_noise_factor with sigma_phase = N sqrt(fs) / radius (the per-sample
    noise across the radius of the turning gravity).
    """
    var = []
    for r in s.rotations:
        T = r.duration_s
        radius = math.sqrt((r.accel_cos @ r.accel_cos + r.accel_sin @ r.accel_sin) / 2)
        phase_var = accel_density ** 2 * sample_rate_hz / radius ** 2
        var += [2 * accel_density ** 2 / T] * 6 + [accel_density ** 2 / T] * 3
        var += [gyro_density ** 2 / T] * 3 + [phase_var * r.rate_noise_factor * (180 / math.pi) ** 2]
    for _ in s.static_names:
        raise UserError("error propagation with static segments needs their durations; not supported")
    return np.array(var)


def parameter_vector(sol: Solution, accel_unit="m/s^2", gyro_unit="deg/s") -> tuple[list, np.ndarray]:
    ka, Ta = scale_and_T(sol.L_a)
    Lg, R_po = rq_lower(sol.S_g)
    kg = np.linalg.norm(Lg, axis=1)
    cal = Calibration(accel_unit, gyro_unit, ka, Ta, sol.b_a, kg, Lg / kg[:, None], sol.b_g, R_po)
    rows = cal.parameters()
    return [name for name, _, _ in rows], np.array([v for _, v, _ in rows])


def propagate(s: Summaries, variant: str, accel_density_mps2: float, gyro_density_dps: float,
              sample_rate_hz: float) -> dict:
    """First-order 1-sigma of every parameter from white sensor noise, by finite differences of
    the algebraic solution over the spectral summaries: {name: sigma} in the units of
    Calibration.parameters(), scale factors in ppm (relative)."""
    names, p0 = parameter_vector(solve(s, variant))
    var = summary_variances(s, accel_density_mps2, gyro_density_dps, sample_rate_hz)
    J = np.zeros((len(p0), len(var)))
    for i, v in enumerate(var):
        h = max(math.sqrt(v), 1e-12) * 1e-2
        J[:, i] = (parameter_vector(solve(_perturbed(s, i, h), variant))[1]
                   - parameter_vector(solve(_perturbed(s, i, -h), variant))[1]) / (2 * h)
    sigma = np.sqrt((J ** 2) @ var)
    return {n: float(sg / p * 1e6) if "_scale_" in n else float(sg) for n, sg, p in zip(names, sigma, p0)}
