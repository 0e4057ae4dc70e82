"""The physical world of the simulated bench.

Frames and conventions (see docs/simulation.md):

* n  -- local level frame, ENU: x east, y north, z up.  Fixed to the Earth.
* b  -- the IMU case frame (the axes printed on the case).
* ``C_bn`` -- attitude, the rotation taking ENU coordinates to body
  coordinates: ``v_b = C_bn.apply(v_n)``.  Held as a
  :class:`scipy.spatial.transform.Rotation` (single or stacked over samples).
* Specific force  f = a - g_vec, with g_vec = [0, 0, -g] in ENU.  A body at
  rest therefore senses f_n = [0, 0, +g] (pointing up).
* Angular rates are in rad/s inside this module.

Everything here is independent of any sensor error: it turns a table state
(attitude, table rate relative to the Earth and its derivative, lever arm)
into the true specific force and inertial angular rate in body axes.  The
sensor model lives in :mod:`sim_devices.truth`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

# --------------------------------------------------------------------------
# Constants
# --------------------------------------------------------------------------

#: Earth rotation rate, rad/s (WGS-84).
OMEGA_EARTH = 7.292115e-5
#: Standard gravity, m/s^2 (definition of 1 g).
G_STANDARD = 9.80665
#: One micro-g in m/s^2.
MICRO_G = 9.80665e-6
#: Arc-second in rad.
ARCSEC = np.pi / (180.0 * 3600.0)
#: Degree per hour in deg/s.
DEG_PER_HOUR = 1.0 / 3600.0

# WGS-84 ellipsoid and normal gravity (NIMA TR8350.2, 3rd ed., ch. 3 and 4).
WGS84_A = 6378137.0                     # semi-major axis, m
WGS84_F = 1.0 / 298.257223563           # flattening
WGS84_B = 6356752.3142                  # semi-minor axis, m
WGS84_GM = 3.986004418e14               # m^3/s^2
WGS84_GAMMA_E = 9.7803253359            # normal gravity at the equator, m/s^2
WGS84_GAMMA_P = 9.8321849378            # normal gravity at the poles, m/s^2
WGS84_K = 0.00193185265241              # Somigliana constant (b*gp)/(a*ge) - 1
WGS84_E2 = 0.00669437999013             # first eccentricity squared
WGS84_M = OMEGA_EARTH**2 * WGS84_A**2 * WGS84_B / WGS84_GM  # ~0.00344978650684

UP_ENU = np.array([0.0, 0.0, 1.0])


# --------------------------------------------------------------------------
# Site: gravity and Earth rate
# --------------------------------------------------------------------------

def somigliana_gravity(latitude_deg: float) -> float:
    """Normal gravity on the WGS-84 ellipsoid surface (Somigliana), m/s^2.

    gamma(phi) = gamma_e (1 + k sin^2 phi) / sqrt(1 - e^2 sin^2 phi),
    phi = geodetic latitude.
    """
    s2 = np.sin(np.radians(latitude_deg)) ** 2
    return float(WGS84_GAMMA_E * (1.0 + WGS84_K * s2) / np.sqrt(1.0 - WGS84_E2 * s2))


def local_gravity(latitude_deg: float, height_m: float = 0.0) -> float:
    """Magnitude of normal gravity at geodetic latitude and ellipsoidal height.

    Somigliana on the ellipsoid plus the WGS-84 second-order free-air
    correction (TR8350.2 eq. 4-3):
        g(h) = gamma [1 - 2/a (1 + f + m - 2 f sin^2 phi) h + 3 h^2 / a^2]
    (about -3.086e-6 m/s^2 per metre near the surface).
    """
    s2 = np.sin(np.radians(latitude_deg)) ** 2
    gamma = somigliana_gravity(latitude_deg)
    h = float(height_m)
    corr = (1.0
            - 2.0 / WGS84_A * (1.0 + WGS84_F + WGS84_M - 2.0 * WGS84_F * s2) * h
            + 3.0 * h * h / WGS84_A**2)
    return float(gamma * corr)


def earth_rate_enu(latitude_deg: float) -> np.ndarray:
    """Earth rotation vector in ENU, rad/s: Omega [0, cos phi, sin phi]."""
    phi = np.radians(latitude_deg)
    return OMEGA_EARTH * np.array([0.0, np.cos(phi), np.sin(phi)])


def gravity_enu(latitude_deg: float, height_m: float = 0.0) -> np.ndarray:
    """Gravity vector in ENU, m/s^2: [0, 0, -g]."""
    return np.array([0.0, 0.0, -local_gravity(latitude_deg, height_m)])


@dataclass(frozen=True)
class Site:
    """Where the bench stands."""

    latitude_deg: float = 45.0
    height_m: float = 0.0

    @property
    def g(self) -> float:
        return local_gravity(self.latitude_deg, self.height_m)

    @property
    def earth_rate_enu(self) -> np.ndarray:
        return earth_rate_enu(self.latitude_deg)

    @property
    def gravity_enu(self) -> np.ndarray:
        return gravity_enu(self.latitude_deg, self.height_m)


# --------------------------------------------------------------------------
# Attitudes
# --------------------------------------------------------------------------

def cross3(a, b) -> np.ndarray:
    """a x b over the last axis (length 3), broadcast against each other: numpy.cross's own
    arithmetic (a1 b2 - a2 b1, a2 b0 - a0 b2, a0 b1 - a1 b0: the same floats) without its
    handling of axes and dtypes at every call (np.cross ~40 us a call on the twins' small batches
    against ~6 us; eighteenth session, the suite's time)."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    out[..., 0] = a1 * b2 - a2 * b1
    out[..., 1] = a2 * b0 - a0 * b2
    out[..., 2] = a0 * b1 - a1 * b0
    return out


def _unit(v, name: str = "vector") -> np.ndarray:
    v = np.asarray(v, dtype=float).reshape(-1)
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise ValueError(f"{name} must be 3 finite numbers, got {v!r}")
    n = np.linalg.norm(v)
    if n < 1e-12:
        raise ValueError(f"{name} must not be zero")
    return v / n


def _any_perpendicular(u: np.ndarray) -> np.ndarray:
    """A deterministic unit vector perpendicular to unit vector u."""
    e = np.zeros(3)
    e[int(np.argmin(np.abs(u)))] = 1.0
    p = cross3(u, e)
    return p / np.linalg.norm(p)


def _frame_map(src: tuple[np.ndarray, np.ndarray], dst: tuple[np.ndarray, np.ndarray]) -> Rotation:
    """Rotation R with R(src[0]) = dst[0] and R(src[1]) = dst[1].

    Both pairs must be orthonormal.
    """
    s1, s2 = src
    d1, d2 = dst
    S = np.column_stack([s1, s2, cross3(s1, s2)])
    D = np.column_stack([d1, d2, cross3(d1, d2)])
    return Rotation.from_matrix(D @ S.T)


def attitude_up(up_body, heading_rad: float = 0.0) -> Rotation:
    """Attitude C_bn (ENU -> body) that puts body direction ``up_body`` up.

    ``heading_rad`` turns the IMU about the local vertical (an arbitrary
    azimuth of the table).  C_bn.apply([0,0,1]) == unit(up_body).
    """
    u = _unit(up_body, "up_body")
    p = _any_perpendicular(u)
    c0 = _frame_map((UP_ENU, np.array([1.0, 0.0, 0.0])), (u, p))
    return c0 * Rotation.from_rotvec(heading_rad * UP_ENU)


def horizontal_axis_enu(heading_rad: float) -> np.ndarray:
    """Unit horizontal vector in ENU at ``heading_rad`` from north towards east."""
    return np.array([np.sin(heading_rad), np.cos(heading_rad), 0.0])


def table_axis_enu(heading_rad: float, elevation_rad: float = 0.0) -> np.ndarray:
    """Unit table axis in ENU: ``heading_rad`` from north towards east, raised by
    ``elevation_rad`` above the horizontal (pi/2: pointing up)."""
    c = np.cos(elevation_rad)
    return np.array([c * np.sin(heading_rad), c * np.cos(heading_rad), np.sin(elevation_rad)])


def axis_reference_enu(axis_enu) -> np.ndarray:
    """Unit reference direction perpendicular to ``axis_enu`` (ENU): the part of local up
    perpendicular to the axis, or the part of north when the axis is vertical."""
    a_n = _unit(axis_enu, "axis_enu")
    ref = UP_ENU - np.dot(UP_ENU, a_n) * a_n
    if np.linalg.norm(ref) < 1e-9:
        ref = np.array([0.0, 1.0, 0.0]) - a_n[1] * a_n
    return ref / np.linalg.norm(ref)


def attitude_axis(axis_body, axis_enu, *, up_body=None, roll_rad: float = 0.0) -> Rotation:
    """Attitude C_bn with C_bn.apply(axis_enu) == unit(axis_body).

    The remaining freedom (a turn about the axis) is fixed by a reference direction: the part
    of local up perpendicular to ``axis_enu`` (north when the axis is vertical).  If
    ``up_body`` is given, its component perpendicular to ``axis_body`` is put along that
    reference; otherwise a deterministic perpendicular direction turned by ``roll_rad``
    about ``axis_body`` is.
    """
    a_b = _unit(axis_body, "axis_body")
    a_n = _unit(axis_enu, "axis_enu")
    ref = axis_reference_enu(a_n)
    if up_body is not None:
        h = _unit(up_body, "start_up_body")
        h = h - np.dot(h, a_b) * a_b
        if np.linalg.norm(h) < 1e-6:
            raise ValueError("start_up_body must not be parallel to axis_body")
        h /= np.linalg.norm(h)
    else:
        h = Rotation.from_rotvec(roll_rad * a_b).apply(_any_perpendicular(a_b))
    return _frame_map((a_n, ref), (a_b, h))


def small_rotation(rotvec_rad) -> Rotation:
    """A small perturbation rotation (applied in body axes: C_bn' = dR * C_bn)."""
    return Rotation.from_rotvec(np.asarray(rotvec_rad, dtype=float))


# --------------------------------------------------------------------------
# Table motion
# --------------------------------------------------------------------------

def rate_profile(t, t0: float, rate_rad_s: float, ripple_fraction: float = 0.0,
                 ripple_hz: float = 1.0, ripple_phase_rad: float = 0.0,
                 drift_per_s: float = 0.0):
    """Table angle, rate and angular acceleration about its axis.

    theta_dot(t) = w (1 + d (t - t0) + rho sin(2 pi f (t - t0) + phase)),  theta(t0) = 0,
    with d the fractional rate drift per second (a screwdriver slowing down: d < 0).

    Returns (theta, theta_dot, theta_ddot), arrays shaped like ``t``
    (rad, rad/s, rad/s^2).
    """
    t = np.asarray(t, dtype=float)
    tau = t - t0
    w = float(rate_rad_s)
    d = float(drift_per_s)
    theta = w * (tau + 0.5 * d * tau * tau)
    theta_dot = w * (1.0 + d * tau)
    theta_ddot = np.full_like(tau, w * d)
    if ripple_fraction != 0.0:
        om = 2.0 * np.pi * ripple_hz
        arg = om * tau + ripple_phase_rad
        rho = float(ripple_fraction)
        theta = theta + w * rho / om * (np.cos(ripple_phase_rad) - np.cos(arg))
        theta_dot = theta_dot + w * rho * np.sin(arg)
        theta_ddot = theta_ddot + w * rho * om * np.cos(arg)
    return theta, theta_dot, theta_ddot


def ramp_profile(t, t0: float, rate_rad_s: float, accel_rad_s2: float, ramp: str, ramp_at: float):
    """Table angle, rate and angular acceleration about its axis for a turn whose ramp is part of
    the motion looked at: ``ramp`` "start": at rest until table time ``ramp_at``, then the rate
    grows at ``accel_rad_s2`` (magnitude) to ``rate_rad_s`` and holds; "end": ``rate_rad_s`` until
    ``ramp_at``, then it falls at ``accel_rad_s2`` to rest and stays there.  theta(t0) = 0.

    The rate is piecewise linear in time: with T = |w| / a the ramp's length and s(t) the time
    since ``ramp_at`` clipped to [0, T], the rate is w s/T (start) or w (1 - s/T) (end), and the
    angle its exact integral.  Returns (theta, theta_dot, theta_ddot) shaped like ``t``."""
    t = np.asarray(t, dtype=float)
    w = float(rate_rad_s)
    a = abs(float(accel_rad_s2))
    if not a > 0.0 or ramp not in ("start", "end"):
        raise ValueError(f"ramp_profile: accel must be > 0 and ramp start or end, got {accel_rad_s2!r}, {ramp!r}")
    T = abs(w) / a
    sign = math.copysign(1.0, w)

    def angle(x):
        """The angle turned from table time -inf (start: at rest) or from ramp_at (end) to x."""
        s = np.clip(x - ramp_at, 0.0, T)
        after = np.maximum(x - ramp_at - T, 0.0)
        if ramp == "start":
            return sign * 0.5 * a * s * s + w * after
        before = np.minimum(x - ramp_at, 0.0)       # (negative) time at the rate before the brake
        return w * before + w * s - sign * 0.5 * a * s * s

    theta = angle(t) - angle(np.asarray(float(t0)))
    s = np.clip(t - ramp_at, 0.0, T)
    inside = (t > ramp_at) & (t < ramp_at + T)
    if ramp == "start":
        theta_dot = sign * a * s
        theta_ddot = np.where(inside, sign * a, 0.0)
    else:
        theta_dot = w - sign * a * s
        theta_ddot = np.where(inside, -sign * a, 0.0)
    return theta, theta_dot, theta_ddot


def quat_product(p, q) -> np.ndarray:
    """Hamilton product p (x) q of unit quaternions stored scalar last, (x, y, z, w), as arrays
    (..., 4) broadcast against each other: the rotation q followed by p, i.e. scipy's
    ``Rotation.from_quat(p) * Rotation.from_quat(q)``.

        p (x) q = (p_w q_v + q_w p_v + p_v x q_v,  p_w q_w - p_v . q_v)

    One product of arrays: composing a rotation with a stack of 10,000 through scipy 1.17's
    ``Rotation.__mul__`` took 44 ms, this 1.5 ms (issue 27 item 5)."""
    p = np.asarray(p, dtype=float)
    q = np.asarray(q, dtype=float)
    pv, pw, qv, qw = p[..., :3], p[..., 3:], q[..., :3], q[..., 3:]
    out = np.empty(np.broadcast_shapes(p.shape, q.shape))
    out[..., :3] = pw * qv + qw * pv + cross3(pv, qv)
    out[..., 3] = (pw * qw)[..., 0] - np.einsum("...i,...i->...", pv, qv)
    return out


def axis_angle_quats(axis, angle) -> np.ndarray:
    """Quaternions (N, 4), scalar last, of the rotations by ``angle`` (rad, N) about the unit
    ``axis``: (sin(angle/2) axis, cos(angle/2))."""
    half = 0.5 * np.asarray(angle, dtype=float).reshape(-1)
    q = np.empty((len(half), 4))
    q[:, :3] = np.sin(half)[:, None] * np.asarray(axis, dtype=float)[None, :]
    q[:, 3] = np.cos(half)
    return q


def table_attitude(C_bn0: Rotation, axis_enu, theta) -> Rotation:
    """Attitude of a body turned by ``theta`` (rad, array) about the Earth-fixed
    ``axis_enu`` from the start attitude ``C_bn0``.

    C_nb(t) = Rot(axis_enu, theta) C_nb0   <=>   C_bn(t) = C_bn0 Rot(axis_enu, -theta).

    The stacked product as quaternion arrays (quat_product), not scipy's composition.
    """
    a_n = _unit(axis_enu, "axis_enu")
    q = quat_product(C_bn0.as_quat(), axis_angle_quats(a_n, -np.asarray(theta, dtype=float)))
    return Rotation.from_quat(q)


def table_rates_body(C_bn0: Rotation, axis_enu, theta_dot, theta_ddot):
    """Table angular velocity relative to the Earth, and its derivative, in body.

    The body sees the Earth-fixed axis at the constant body direction
    a_b = C_bn0 a_n, so  w = theta_dot a_b,  w_dot = theta_ddot a_b.
    """
    a_b = C_bn0.apply(_unit(axis_enu, "axis_enu"))
    theta_dot = np.asarray(theta_dot, dtype=float).reshape(-1, 1)
    theta_ddot = np.asarray(theta_ddot, dtype=float).reshape(-1, 1)
    return theta_dot * a_b[None, :], theta_ddot * a_b[None, :]


def wobble_direction_enu(axis_enu, phase_rad: float = 0.0) -> np.ndarray:
    """d: the direction of the wobble tilt's rotation vector at table angle 0, ENU.

    d = Rot(a_n, phase) ref, with ref = :func:`axis_reference_enu` (the part of local up
    perpendicular to the axis).  d is perpendicular to a_n.
    """
    a_n = _unit(axis_enu, "axis_enu")
    return Rotation.from_rotvec(float(phase_rad) * a_n).apply(axis_reference_enu(a_n))


def wobbling_table(C_bn0: Rotation, axis_enu, theta, theta_dot, theta_ddot,
                   wobble_rad: float, phase_rad: float = 0.0, harmonic: int = 1):
    """Attitude, rate and angular acceleration of a table whose axis wobbles.

    The platter is spun by theta about the Earth-fixed axis a_n and tilted by the constant
    angle b = ``wobble_rad`` about a direction e(theta) perpendicular to a_n that turns
    ``harmonic`` (m) times per revolution *relative to the platter*:

        C_nb(t) = Rot(a_n, theta) Rot(b e(theta)) C_nb0,     e(theta) = Rot(a_n, m theta) d
        <=>  C_bn(t) = C_bn0 Rot(-b e(theta)) Rot(a_n, -theta)

    with d = :func:`wobble_direction_enu` (coordinates of the platter frame, which is ENU at
    theta = 0).  The platter axis a_b = C_bn0 a_n (fixed in the body) then points, in ENU,
    along Rot(a_n, theta) Rot(b e) a_n: exactly b away from a_n, turning m + 1 times per
    revolution about it.  The exact angular velocity relative to the Earth, body axes
    (derivation in docs/simulation.md):

        w_b    = theta_dot C_bn0 [ (cos b - m (1 - cos b)) a_n + (1 + m) sin b (a_n x e) ]
        wdot_b = theta_ddot w_b / theta_dot - m (1 + m) sin b theta_dot^2 C_bn0 e

    m = 0 (a tilt fixed to the platter) is a constant mounting error and m = -1 (a tilt
    fixed to the Earth) a constant tilt of the rotation axis: neither makes a wobble.  The
    bench uses m = 1: the rate axis seen from the body cones once per revolution.

    Returns (C_bn stacked (N), w_eb_b (N,3) rad/s, wdot_eb_b (N,3) rad/s^2).
    """
    a_n = _unit(axis_enu, "axis_enu")
    theta = np.asarray(theta, dtype=float).reshape(-1)
    thd = np.asarray(theta_dot, dtype=float).reshape(-1, 1)
    thdd = np.asarray(theta_ddot, dtype=float).reshape(-1, 1)
    b = float(wobble_rad)
    m = int(harmonic)
    d = wobble_direction_enu(a_n, phase_rad)
    axd = cross3(a_n, d)
    phi = (m * theta)[:, None]
    e = np.cos(phi) * d[None, :] + np.sin(phi) * axd[None, :]          # Rot(a_n, m theta) d
    a_x_e = np.cos(phi) * axd[None, :] - np.sin(phi) * d[None, :]      # a_n x e
    # C_bn = C_bn0 Rot(-b e) Rot(a_n, -theta); the stacked product as quaternions (scalar
    # last), q_e (x) q_theta, which is much faster than composing two stacked Rotations
    ve = -math.sin(0.5 * b) * e                                         # Rot(-b e), e unit
    we = math.cos(0.5 * b)
    vt = -np.sin(0.5 * theta)[:, None] * a_n[None, :]                   # Rot(a_n, -theta)
    wt = np.cos(0.5 * theta)[:, None]
    q = np.empty((len(theta), 4))
    q[:, :3] = we * vt + wt * ve + cross3(ve, vt)
    q[:, 3] = we * wt[:, 0] - np.einsum("ij,ij->i", ve, vt)
    C_bn = Rotation.from_quat(quat_product(C_bn0.as_quat(), q))         # C_bn0 (x) q
    along = math.cos(b) - m * (1.0 - math.cos(b))
    perp = (1.0 + m) * math.sin(b)
    c_n = along * a_n[None, :] + perp * a_x_e                           # w / theta_dot, platter frame
    w_b = C_bn0.apply(thd * c_n)
    wd_b = C_bn0.apply(thdd * c_n - (m * perp) * thd * thd * e)
    return C_bn, np.atleast_2d(w_b), np.atleast_2d(wd_b)


def table_vibration_enu(axis_enu, theta, theta_dot, theta_ddot, amplitude_mps2, ref_rate_rad_s: float,
                        phase_rad: float = 0.0) -> np.ndarray:
    """Acceleration of a table base vibrating once per revolution, ENU, m/s^2 (N,3).

    The physics (issue 28, twenty-first session): a once-per-revolution vibration is driven by
    the platter's angle -- an eccentric bearing or belt pulley moves the base by a displacement
    that is a function of the table angle theta, as does an imbalance's force on a base that
    responds as a mass (below: :func:`imbalance_acceleration_enu`).  Here the displacement is
    along one direction D fixed in the table's (Earth-fixed) frame,

        x(theta) = -cos(theta + phase) D / w_ref^2,     D = A_axis a_n + A_ref r + A_perp (a_n x r)

    so that the base's acceleration, the second time derivative of x(theta(t)), is

        a_vib = [theta_dot^2 cos(theta + phase) + theta_ddot sin(theta + phase)] D / w_ref^2

    zero at rest, A cos(theta + phase) at the steady rate w_ref (the amplitudes A, m/s^2, are
    the acceleration at that reference rate), (w / w_ref)^2 of it at a steady rate w, and during
    a ramp a part theta_ddot sin(theta + phase) D / w_ref^2 from the angular acceleration.  a_n
    the table axis, r = :func:`axis_reference_enu` (the part of local up perpendicular to the axis;
    north for a vertical axis).  It adds to the specific force (f = a - g), like any acceleration of
    the sensing point.  ``theta``, ``theta_dot``, ``theta_ddot``: rad, rad/s, rad/s^2 (N,).
    """
    a_n = _unit(axis_enu, "axis_enu")
    w_ref = float(ref_rate_rad_s)
    if not (math.isfinite(w_ref) and w_ref > 0.0):
        raise ValueError(f"ref_rate_rad_s must be positive and finite, got {ref_rate_rad_s!r}")
    ref = axis_reference_enu(a_n)
    A = np.asarray(amplitude_mps2, dtype=float).reshape(3)
    direction = A[0] * a_n + A[1] * ref + A[2] * cross3(a_n, ref)
    psi = np.asarray(theta, dtype=float).reshape(-1) + float(phase_rad)
    thd = np.asarray(theta_dot, dtype=float).reshape(-1)
    thdd = np.asarray(theta_ddot, dtype=float).reshape(-1)
    size = (thd * thd * np.cos(psi) + thdd * np.sin(psi)) / (w_ref * w_ref)
    return size[:, None] * direction[None, :]


def imbalance_acceleration_enu(axis_enu, theta, theta_dot, theta_ddot, imbalance_kg_m: float,
                               base_mass_kg: float, phase_rad: float = 0.0) -> np.ndarray:
    """Acceleration of a table base shaken by an imbalance of the platter, ENU, m/s^2 (N,3).

    A mass m at radius rho on the platter (the imbalance U = m rho, kg m), at the platter angle
    psi = theta + phase from r = :func:`axis_reference_enu` about the table axis a_n (positive
    sense), has e(psi) = cos psi r + sin psi (a_n x r) and accelerates by
    rho [theta_ddot (a_n x e) - theta_dot^2 e].  The platter pushes it so; it pushes the platter
    and the base back with F = U [theta_dot^2 e - theta_ddot (a_n x e)], across the axis, turning
    with the platter: centripetal (along e) ~ w^2, tangential (across e) ~ dw/dt.  The base, of
    effective mass M (the base, the platter and all on them; its mount's resonance well below the
    rotation frequency, so that the mount's spring force is small beside the inertial one and the
    base moves as a free mass: the total momentum stays put), accelerates by

        a_vib = F / M = (U / M) [theta_dot^2 e(theta + phase) - theta_ddot a_n x e(theta + phase)]

    which is the second time derivative of the displacement -(U / M) e(theta + phase): a circle
    turning with the platter.  Zero at rest.  A mount stiff against the rotation frequency moves
    the base by F / k instead (acceleration ~ w^4): not this model."""
    a_n = _unit(axis_enu, "axis_enu")
    M = float(base_mass_kg)
    if not (math.isfinite(M) and M > 0.0):
        raise ValueError(f"base_mass_kg must be positive and finite, got {base_mass_kg!r}")
    ref = axis_reference_enu(a_n)
    psi = np.asarray(theta, dtype=float).reshape(-1, 1) + float(phase_rad)
    e = np.cos(psi) * ref[None, :] + np.sin(psi) * cross3(a_n, ref)[None, :]
    a_x_e = np.cos(psi) * cross3(a_n, ref)[None, :] - np.sin(psi) * ref[None, :]
    thd = np.asarray(theta_dot, dtype=float).reshape(-1, 1)
    thdd = np.asarray(theta_ddot, dtype=float).reshape(-1, 1)
    return (float(imbalance_kg_m) / M) * (thd * thd * e - thdd * a_x_e)


# --------------------------------------------------------------------------
# Kinematics: table state -> specific force and inertial rate in body
# --------------------------------------------------------------------------

def body_kinematics(C_bn: Rotation, w_eb_b, wdot_eb_b, lever_arm_b, site: Site):
    """True specific force and inertial angular rate in body axes.

    Parameters
    ----------
    C_bn : Rotation, single or stacked (N)
        ENU -> body attitude at each sample.
    w_eb_b, wdot_eb_b : (N,3) or (3,)
        Body angular velocity relative to the Earth (the table rate), rad/s,
        in body axes, and its time derivative (rad/s^2).
    lever_arm_b : (3,)
        Position of the sensing point (accelerometer centre) relative to a
        point on the rotation axis, body axes, m.
    site : Site

    Returns
    -------
    f_b : (N,3)  m/s^2,  C_bn [0,0,g] + wdot x r + w x (w x r)
    w_ib_b : (N,3) rad/s,  w + C_bn Omega_E
    """
    w = np.atleast_2d(np.asarray(w_eb_b, dtype=float))
    wd = np.atleast_2d(np.asarray(wdot_eb_b, dtype=float))
    r = np.asarray(lever_arm_b, dtype=float).reshape(3)
    g_up = np.array([0.0, 0.0, site.g])
    grav_b = np.atleast_2d(C_bn.apply(g_up))
    earth_b = np.atleast_2d(C_bn.apply(site.earth_rate_enu))
    n = max(len(w), len(wd), len(grav_b))
    r_row = r[None, :]
    f_b = grav_b + cross3(wd, r_row) + cross3(w, cross3(w, r_row))
    w_ib = w + earth_b
    return np.broadcast_to(f_b, (n, 3)).copy(), np.broadcast_to(w_ib, (n, 3)).copy()


def static_kinematics(C_bn: Rotation, n_samples: int, site: Site):
    """Specific force and inertial rate of a body at rest (N copies)."""
    zero = np.zeros((1, 3))
    f_b, w_ib = body_kinematics(C_bn, zero, zero, np.zeros(3), site)
    return np.repeat(f_b, n_samples, axis=0), np.repeat(w_ib, n_samples, axis=0)


def perturb_specific_force(f_b: np.ndarray, sigma_mps2: float, rng) -> np.ndarray:
    """Add a white acceleration disturbance (per axis sigma, m/s^2) to f_b."""
    if sigma_mps2 <= 0.0 or rng is None:
        return f_b
    return f_b + sigma_mps2 * rng.standard_normal(f_b.shape)
