"""Physics checks of the simulated bench (sim_devices).

Tolerances are derived either from floating point (exact identities), from
the numerical integration rule, or from the noise statistics (chi-square /
normal quantiles at 99.9 %), never tuned to pass.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml
from scipy import stats
from scipy.spatial.transform import Rotation

from sim_devices import world
from sim_devices.bench import SimulatedBench
from sim_devices.truth import (BenchSettings, TemperatureTruth, Truth, TriadTruth,
                               default_truth)
from sim_devices.world import ARCSEC, MICRO_G, OMEGA_EARTH
from station.errors import UserError

EPS = np.finfo(float).eps
UPS = [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1],
       [1, 1, 0], [1, 0, 1], [0, 1, 1]]
AXES = [[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 0], [1, 0, 1], [0, 1, 1]]


def perfect_truth(**bench) -> Truth:
    """Ideal sensors, no noise, perfect table."""
    settings = dict(table_angle_error_arcsec=0.0)
    settings.update(bench)
    return Truth(accel=TriadTruth(noise_density=0.0), gyro=TriadTruth(noise_density=0.0),
                 temperature=TemperatureTruth(warmup_delta_c=0.0),
                 bench=BenchSettings(**settings))


def unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


# --------------------------------------------------------------------------
# Gravity
# --------------------------------------------------------------------------

def test_somigliana_reference_values():
    assert world.somigliana_gravity(0.0) == pytest.approx(9.7803253359, abs=1e-10)
    assert world.somigliana_gravity(90.0) == pytest.approx(9.8321849378, abs=1e-9)
    assert world.somigliana_gravity(-90.0) == pytest.approx(9.8321849378, abs=1e-9)
    assert world.somigliana_gravity(45.0) == pytest.approx(9.80620, abs=1e-5)
    # height 0 is the ellipsoid itself
    assert world.local_gravity(45.0, 0.0) == world.somigliana_gravity(45.0)


def test_free_air_gradient():
    # normal free-air gradient ~ -3.086e-6 s^-2 (varies ~0.1 % with latitude)
    dg = world.local_gravity(45.0, 1000.0) - world.local_gravity(45.0, 0.0)
    assert dg == pytest.approx(-3.086e-3, rel=3e-3)
    assert world.gravity_enu(45.0, 0.0)[2] == -world.local_gravity(45.0, 0.0)


def test_earth_rate_enu():
    w = world.earth_rate_enu(30.0)
    assert np.linalg.norm(w) == pytest.approx(OMEGA_EARTH, rel=1e-15)
    assert w[0] == 0.0
    assert w[2] / w[1] == pytest.approx(math.tan(math.radians(30.0)), rel=1e-14)


# --------------------------------------------------------------------------
# At rest
# --------------------------------------------------------------------------

@pytest.mark.parametrize("lat", [0.0, 45.0, -33.0, 89.0])
def test_rest_perfect_sensors(lat):
    bench = SimulatedBench(perfect_truth(latitude_deg=lat, height_m=250.0), seed=1)
    g = world.local_gravity(lat, 250.0)
    assert bench.gravity_mps2 == g
    for up in UPS:
        seg = bench.static(up, 1.0)
        assert seg.accel.shape == (100, 3) and seg.gyro.shape == (100, 3)
        f = seg.accel
        w = np.radians(seg.gyro)
        np.testing.assert_allclose(np.linalg.norm(f, axis=1), g, rtol=8 * EPS)
        np.testing.assert_allclose(np.linalg.norm(w, axis=1), OMEGA_EARTH, rtol=8 * EPS)
        np.testing.assert_allclose(f / g, np.tile(unit(up), (100, 1)), atol=8 * EPS)
        # f . w = g Omega sin(lat): the up component of Earth rate
        np.testing.assert_allclose(np.einsum("ij,ij->i", f, w),
                                   g * OMEGA_EARTH * math.sin(math.radians(lat)),
                                   atol=16 * EPS * g * OMEGA_EARTH)


def test_attitude_helpers():
    for up in UPS:
        C = world.attitude_up(up, 1.234)
        np.testing.assert_allclose(C.apply([0, 0, 1]), unit(up), atol=4 * EPS)
    a_n = world.horizontal_axis_enu(0.7)
    for a in AXES:
        C = world.attitude_axis(a, a_n, up_body=[1, -1, 0.3])
        np.testing.assert_allclose(C.apply(a_n), unit(a), atol=4 * EPS)
        h = np.array([1, -1, 0.3]) - np.dot([1, -1, 0.3], unit(a)) * unit(a)
        np.testing.assert_allclose(C.apply([0, 0, 1]), unit(h), atol=4 * EPS)


def test_static_attitude_error_statistics():
    """Static attitude errors have the configured sigma per axis."""
    sigma = 2.0
    bench = SimulatedBench(perfect_truth(table_angle_error_arcsec=sigma), seed=5)
    errs = np.array([bench.static([0, 0, 1], 0.01).truth["attitude_error_rad"]
                     for _ in range(400)]) / ARCSEC
    n = errs.size
    ss = np.sum(errs**2)  # zero-mean Gaussian: ss / sigma^2 ~ chi2(n)
    assert stats.chi2.ppf(0.0005, n) < ss / sigma**2 < stats.chi2.ppf(0.9995, n)


# --------------------------------------------------------------------------
# Rotation
# --------------------------------------------------------------------------

def _earth_rate_integral_body(C_bn0, a_n, w, theta1, theta2, lat):
    """Exact integral over the window of C_bn(t) Omega_E (rad), body axes.

    C_bn(t) = C_bn0 Rot(a_n, -theta), dt = dtheta / w.
    """
    Om = world.earth_rate_enu(lat)
    par = np.dot(Om, a_n) * a_n
    perp = Om - par
    integral = (par * (theta2 - theta1) + perp * (math.sin(theta2) - math.sin(theta1))
                + np.cross(a_n, Om) * (math.cos(theta2) - math.cos(theta1))) / w
    return C_bn0 @ integral


@pytest.mark.parametrize("axis", AXES)
def test_rotation_zero_errors(axis):
    lat = 45.0
    lever = np.array([0.03, -0.02, 0.04])
    bench = SimulatedBench(perfect_truth(latitude_deg=lat, lever_arm_m=lever), seed=3)
    fs = bench.sample_rate_hz
    dt = 1.0 / fs
    g = bench.gravity_mps2
    rate_dps = 10.0
    segs = [bench.rotation(axis, s * rate_dps, 180.0) for s in (+1, -1)]
    a_b = unit(axis)
    for seg in segs:
        r = seg.meta["rate_dps"]
        w = math.radians(r)
        n = len(seg.t)
        assert n == 18000
        assert seg.meta["axis_body"] == pytest.approx(list(a_b))
        # with no table error the encoder angle is the swept angle: rate * N dt
        assert seg.meta["angle_deg"] == pytest.approx(r * n * dt, rel=1e-13)
        assert seg.truth["axis_enu"][2] == 0.0   # horizontal table axis
        np.testing.assert_allclose(seg.truth["axis_body_true"], a_b, atol=4 * EPS)

        # gyro integral over the window = angle * axis + Earth-rate projection
        integral = seg.gyro.sum(axis=0) * dt        # deg
        theta1, theta2 = -0.5 * w * dt, w * (n - 0.5) * dt
        earth = np.degrees(_earth_rate_integral_body(
            seg.truth["C_bn0"], seg.truth["axis_enu"], w, theta1, theta2, lat))
        expected = seg.meta["angle_deg"] * a_b + earth
        # midpoint rule on the rotating Earth-rate term: |err| <= (w dt)^2/24 Omega T
        tol = math.degrees((w * dt) ** 2 / 24 * OMEGA_EARTH * n * dt) + 1e-12 * abs(r) * n * dt
        np.testing.assert_allclose(integral, expected, atol=tol)
        # along the axis the Earth rate adds exactly Omega . a_n per second
        along = np.degrees(np.dot(world.earth_rate_enu(lat), seg.truth["axis_enu"])) * n * dt
        assert integral @ a_b == pytest.approx(seg.meta["angle_deg"] + along,
                                               abs=1e-12 * abs(r) * n * dt)

        # specific force along the rotation axis is constant (= -g a.up = 0:
        # horizontal axis, centripetal and tangential terms are perpendicular)
        f_along = seg.accel @ a_b
        np.testing.assert_allclose(f_along, 0.0, atol=32 * EPS * g)
        # |f| is constant-free: gravity rotates, centripetal is fixed in body
        # = -w^2 r_perp; over 5 whole revolutions gravity averages to zero
        r_perp = lever - np.dot(lever, a_b) * a_b
        centripetal = seg.accel.mean(axis=0)
        np.testing.assert_allclose(centripetal, -w**2 * r_perp, atol=1e-12 * g)
        assert np.linalg.norm(centripetal) == pytest.approx(
            w**2 * np.linalg.norm(r_perp), rel=1e-9)
        # the remainder is gravity of magnitude g
        np.testing.assert_allclose(np.linalg.norm(seg.accel + w**2 * r_perp, axis=1), g,
                                   rtol=16 * EPS)

    # the +/- pair starts from the same attitude: identical first accel sample
    np.testing.assert_array_equal(segs[0].truth["C_bn0"], segs[1].truth["C_bn0"])
    np.testing.assert_allclose(segs[0].accel[0], segs[1].accel[0], atol=8 * EPS * g)
    assert segs[0].truth["heading_deg"] == segs[1].truth["heading_deg"]


def test_rotation_sense_right_handed():
    """Positive rate_dps = right-handed about axis_body; gyro sees +rate on the axis."""
    bench = SimulatedBench(perfect_truth(), seed=11)
    seg = bench.rotation([0, 0, 1], 10.0, 2.0)
    # attitude increments: C_bn(t-h) C_nb(t+h) = exp([w_b x] 2h)
    C_bn0 = Rotation.from_matrix(seg.truth["C_bn0"])
    a_n = seg.truth["axis_enu"]
    h = 0.01
    th = np.radians(10.0) * np.array([1.0 - h, 1.0 + h])
    C = world.table_attitude(C_bn0, a_n, th)
    w_fd = (C[0] * C[1].inv()).as_rotvec() / (2 * h)
    np.testing.assert_allclose(w_fd, [0, 0, math.radians(10.0)], atol=1e-12)
    # the gyro output is that plus the (tiny) Earth rate
    assert seg.gyro[:, 2].mean() == pytest.approx(10.0, abs=2 * math.degrees(OMEGA_EARTH))
    assert seg.meta["angle_deg"] > 0
    seg2 = bench.rotation([0, 0, 1], -10.0, 2.0)
    assert seg2.meta["angle_deg"] < 0
    assert seg2.gyro[:, 2].mean() == pytest.approx(-10.0, abs=2 * math.degrees(OMEGA_EARTH))


def test_lever_arm_kinematics_against_finite_differences():
    """f_b - C_bn g_up must be the body-frame acceleration of the sensing point,
    obtained here by differentiating its ENU position twice (ripple on)."""
    site = world.Site(45.0, 0.0)
    a_n = world.horizontal_axis_enu(0.3)
    C_bn0 = world.attitude_axis([1, 2, 0.5], a_n, roll_rad=0.4)
    r = np.array([0.04, -0.03, 0.02])
    prof = dict(t0=0.0, rate_rad_s=math.radians(-20.0), ripple_fraction=0.3,
                ripple_hz=0.7, ripple_phase_rad=0.9)
    t = np.linspace(0.0, 3.0, 31)
    h = 2e-3
    th, thd, thdd = world.rate_profile(t, **prof)
    C = world.table_attitude(C_bn0, a_n, th)
    w_b, wd_b = world.table_rates_body(C_bn0, a_n, thd, thdd)
    f_b, w_ib = world.body_kinematics(C, w_b, wd_b, r, site)
    lever_acc_b = f_b - C.apply([0.0, 0.0, site.g])

    def pos(tt):
        return world.table_attitude(C_bn0, a_n, world.rate_profile(tt, **prof)[0]).inv().apply(r)

    # 5-point second derivative: truncation h^4/90 |p^(6)|, with
    # |p^(6)| ~ r w rho (2 pi f)^5 ~ 9 m/s^6 -> ~2e-12; rounding ~ 64/12 eps r / h^2 ~ 2e-11
    acc_n = (-pos(t + 2 * h) + 16 * pos(t + h) - 30 * pos(t) + 16 * pos(t - h)
             - pos(t - 2 * h)) / (12 * h**2)
    np.testing.assert_allclose(lever_acc_b, C.apply(acc_n), rtol=0, atol=1e-9)
    assert np.abs(wd_b).max() > 0.01   # the tangential term was really exercised
    # rate: theta_dot is the derivative of theta
    thp = world.rate_profile(t + h, **prof)[0]
    thm = world.rate_profile(t - h, **prof)[0]
    # central difference truncation: h^2/6 |theta'''| <= h^2/6 |w| rho (2 pi f)^2
    tol = h**2 / 6 * abs(prof["rate_rad_s"]) * 0.3 * (2 * np.pi * 0.7) ** 2
    np.testing.assert_allclose((thp - thm) / (2 * h), thd, rtol=0, atol=1.01 * tol)
    np.testing.assert_allclose(w_ib - w_b, C.apply(site.earth_rate_enu), atol=1e-20)


def test_ripple_encoder_matches_gyro():
    """With ripple over whole ripple periods the gyro integral along the axis
    still equals the encoder angle plus the Earth-rate projection."""
    lat = 45.0
    bench = SimulatedBench(perfect_truth(rate_ripple_fraction=0.2, rate_ripple_hz=1.0,
                                         latitude_deg=lat), seed=2)
    seg = bench.rotation([0, 1, 0], 10.0, 180.0)
    dt = 1.0 / bench.sample_rate_hz
    a_b = np.array([0.0, 1.0, 0.0])
    along = np.degrees(np.dot(world.earth_rate_enu(lat), seg.truth["axis_enu"])) * 180.0
    assert seg.gyro.sum(axis=0) @ a_b * dt == pytest.approx(seg.meta["angle_deg"] + along,
                                                            abs=1e-9)
    # the rate really varies
    assert np.ptp(seg.gyro @ a_b) > 3.0


def test_encoder_error_statistics():
    sigma = 2.0
    bench = SimulatedBench(perfect_truth(table_angle_error_arcsec=sigma), seed=9)
    err = []
    for _ in range(300):
        seg = bench.rotation([1, 0, 0], -10.0, 0.5)
        err.append((seg.meta["angle_deg"] - seg.truth["swept_angle_deg"]) * 3600.0)
        assert seg.truth["swept_angle_deg"] == pytest.approx(-5.0, rel=1e-12)
    err = np.array(err)
    n = err.size
    assert stats.chi2.ppf(0.0005, n) < np.sum(err**2) / sigma**2 < stats.chi2.ppf(0.9995, n)
    # true rotation axis off the commanded one by the mounting error (same for all)
    off = np.degrees(np.arccos(np.clip(seg.truth["axis_body_true"] @ [1, 0, 0], -1, 1))) * 3600
    assert off < 6 * sigma


# --------------------------------------------------------------------------
# Paper parameterisation
# --------------------------------------------------------------------------

@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_paper_parameter_identity(seed):
    truth = default_truth(seed)
    if seed == 3:   # large errors too
        truth.accel.axis_tilt_arcsec *= 20.0
        truth.gyro.axis_tilt_arcsec *= 20.0
    p = truth.paper_parameters()
    rng = np.random.default_rng(seed)
    f_b = rng.normal(0.0, 10.0, (50, 3))
    w_b = rng.normal(0.0, 20.0, (50, 3))
    acc, gyr = truth.measure(f_b, w_b, truth.temperature.reference_c, None)
    f_p = f_b @ p["C_pb"].T
    w_p = w_b @ p["C_pb"].T
    acc_paper = f_p @ (np.diag(p["accel_scale"]) @ p["accel_T"]).T + p["accel_bias"]
    gyr_paper = w_p @ (np.diag(p["gyro_scale"]) @ p["gyro_T"] @ p["R_po"]).T + p["gyro_bias"]
    np.testing.assert_allclose(acc, acc_paper, rtol=0, atol=1e-12)
    np.testing.assert_allclose(gyr, gyr_paper, rtol=0, atol=1e-12)

    for T in (p["accel_T"], p["gyro_T"]):
        assert T[0, 1] == T[0, 2] == T[1, 2] == 0.0
        np.testing.assert_allclose(np.linalg.norm(T, axis=1), 1.0, atol=4 * EPS)
    # frames: x_p = u_ax, y_p in the (u_ax, u_ay) plane, right-handed
    for C, S in ((p["C_pb"], truth.accel.axes), (p["C_ob"], truth.gyro.axes)):
        np.testing.assert_allclose(C @ C.T, np.eye(3), atol=4 * EPS)
        assert np.linalg.det(C) == pytest.approx(1.0, abs=4 * EPS)
        np.testing.assert_allclose(C[0], S[0], atol=4 * EPS)
        assert abs(np.dot(np.cross(S[0], S[1]), C[1])) < 4 * EPS
    R = p["R_po"]
    np.testing.assert_allclose(R, p["C_ob"] @ p["C_pb"].T, atol=4 * EPS)
    np.testing.assert_allclose(Rotation.from_rotvec(p["inter_triad_rad"]).as_matrix(), R,
                               atol=8 * EPS)
    a = p["accel_misalignment_rad"]
    T = p["accel_T"]
    assert (math.sin(a[0]), -math.sin(a[1]), math.sin(a[2])) == pytest.approx(
        (T[1, 0], T[2, 0], T[2, 1]), abs=4 * EPS)


def test_paper_parameters_small_angle_meaning():
    """First-order meaning of the paper angles in terms of the physical tilts.

    T10 = u_y.u_x ~ t(x->y) + t(y->x); T20 = u_z.u_x ~ t(x->z) + t(z->x);
    T21 = u_z.y_p ~ t(y->z) + t(z->y); errors are second order
    (<~ 3 * (300 arcsec)^2 in rad).  Eq. (6): R_po ~ I + [theta x].
    """
    truth = default_truth(4)
    p = truth.paper_parameters()
    second = 3 * (300 * ARCSEC) ** 2
    for tilt, ang in ((truth.accel.axis_tilt_arcsec, p["accel_misalignment_rad"]),
                      (truth.gyro.axis_tilt_arcsec, p["gyro_misalignment_rad"])):
        t = tilt * ARCSEC   # rows x:[->y,->z], y:[->x,->z], z:[->x,->y]
        assert ang[0] == pytest.approx(t[0, 0] + t[1, 0], abs=second)
        assert ang[1] == pytest.approx(-(t[0, 1] + t[2, 0]), abs=second)
        assert ang[2] == pytest.approx(t[1, 1] + t[2, 1], abs=second)
    th = p["inter_triad_rad"]
    skew = np.array([[0, -th[2], th[1]], [th[2], 0, -th[0]], [-th[1], th[0], 0]])
    np.testing.assert_allclose(p["R_po"], np.eye(3) + skew, atol=np.dot(th, th))


# --------------------------------------------------------------------------
# Noise
# --------------------------------------------------------------------------

@pytest.mark.parametrize("fs", [100.0, 400.0])
def test_white_noise_density(fs):
    truth = default_truth(21)
    truth.sample_rate_hz = fs
    bench = SimulatedBench(truth, seed=8)
    seg = bench.static([0, 1, 1], 600.0)
    n = len(seg.t)
    assert n == round(600.0 * fs)
    sig_a = 100.0 * MICRO_G * math.sqrt(fs)            # 100 ug/rtHz
    sig_g = 0.03 / 3600.0 * math.sqrt(fs)              # 0.03 deg/h/rtHz
    assert truth.accel_noise_sigma == pytest.approx(sig_a, rel=1e-15)
    assert truth.gyro_noise_sigma == pytest.approx(sig_g, rel=1e-15)
    lo, hi = stats.chi2.ppf([0.0005, 0.9995], n - 1)
    for data, sig in ((seg.accel, sig_a), (seg.gyro, sig_g)):
        ratio = (n - 1) * data.var(axis=0, ddof=1) / sig**2
        assert np.all((lo < ratio) & (ratio < hi)), (ratio, lo, hi)
    # means: unbiased around the noise-free output, sigma / sqrt(N)
    acc0, gyr0 = truth.measure(seg.truth["f_b"][None], seg.truth["w_ib_dps"][None],
                               seg.temp[:1], None)
    zq = stats.norm.ppf(0.9995)
    assert np.all(np.abs(seg.accel.mean(0) - acc0[0]) < zq * sig_a / math.sqrt(n))
    assert np.all(np.abs(seg.gyro.mean(0) - gyr0[0]) < zq * sig_g / math.sqrt(n))
    # IEEE convention: means over tau = 1 s have sigma = density / sqrt(1 s)
    m = int(fs)
    blocks = seg.accel[: n // m * m].reshape(-1, m, 3).mean(axis=1) / MICRO_G  # ug
    k = blocks.shape[0]
    lo_b, hi_b = stats.chi2.ppf([0.0005, 0.9995], k - 1)
    ratio = (k - 1) * blocks.var(axis=0, ddof=1) / 100.0**2
    assert np.all((lo_b < ratio) & (ratio < hi_b)), ratio


def test_acceleration_disturbance_adds_in_quadrature():
    truth = perfect_truth(accel_disturbance_ug=50.0)
    bench = SimulatedBench(truth, seed=4)
    seg = bench.static([0, 0, 1], 200.0)
    n = len(seg.t)
    lo, hi = stats.chi2.ppf([0.0005, 0.9995], n - 1)
    ratio = (n - 1) * seg.accel.var(axis=0, ddof=1) / (50.0 * MICRO_G) ** 2
    assert np.all((lo < ratio) & (ratio < hi)), ratio


def test_quantisation_and_temperature():
    truth = perfect_truth()
    truth.accel.lsb = 1e-3
    truth.gyro.lsb = 1e-4
    truth.accel.bias_tempco = np.array([10.0, -20.0, 0.0])   # ug/degC
    truth.temperature = TemperatureTruth(start_c=20.0, reference_c=25.0, drift_c_per_h=36.0,
                                         warmup_delta_c=4.0, warmup_time_constant_s=100.0)
    bench = SimulatedBench(truth, seed=0)
    seg = bench.static([1, 0, 0], 50.0)
    np.testing.assert_allclose(seg.temp, truth.temperature.at(seg.t), rtol=0, atol=0)
    T = truth.temperature
    expect = T.start_c + 0.01 * seg.t + 4.0 * (1 - np.exp(-seg.t / 100.0))
    np.testing.assert_allclose(seg.temp, expect, atol=1e-12)
    for data, lsb in ((seg.accel, 1e-3), (seg.gyro, 1e-4)):
        np.testing.assert_allclose(data / lsb, np.round(data / lsb), atol=1e-6)
    # temperature coefficient without quantisation
    truth.accel.lsb = truth.gyro.lsb = 0.0
    f = np.tile([0.0, 0.0, 9.8], (2, 1))
    acc, _ = truth.measure(f, np.zeros((2, 3)), np.array([25.0, 35.0]), None)
    np.testing.assert_allclose(acc[1] - acc[0], 10.0 * np.array([10.0, -20.0, 0.0]) * MICRO_G,
                               atol=1e-15)


# --------------------------------------------------------------------------
# Timing, reproducibility, speed
# --------------------------------------------------------------------------

def _full_scheme(bench):
    segs = [bench.static(u, 100.0) for u in UPS]
    for a in AXES:
        for s in (1, -1):
            segs.append(bench.rotation(a, 10.0 * s, 180.0))
    return segs


def test_time_continues_with_gaps():
    truth = default_truth(0)
    bench = SimulatedBench(truth, seed=0)
    segs = [bench.static([0, 0, 1], 1.0), bench.rotation([1, 0, 0], 10, 1.0),
            bench.rotation([1, 0, 0], -10, 1.0)]
    gap = truth.bench.move_s + truth.bench.settle_s
    for s in segs:
        np.testing.assert_allclose(np.diff(s.t), 0.01, atol=1e-9)
    for a, b in zip(segs, segs[1:]):
        assert b.t[0] - a.t[-1] == pytest.approx(gap + 0.01, abs=1e-9)


def test_reproducible_with_seed():
    truth = default_truth(5)
    s1 = _full_scheme(SimulatedBench(truth, seed=42))[8:11]
    s2 = _full_scheme(SimulatedBench(truth, seed=42))[8:11]
    s3 = _full_scheme(SimulatedBench(truth, seed=43))[8:11]
    for a, b, c in zip(s1, s2, s3):
        for name in ("t", "accel", "gyro", "temp"):
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
        assert a.meta == b.meta
        assert not np.array_equal(a.accel, c.accel)
    t1, t2 = default_truth(5), default_truth(6)
    assert t1.to_yaml_dict() == default_truth(5).to_yaml_dict()
    assert t1.to_yaml_dict() != t2.to_yaml_dict()


def test_full_scheme_sample_count():
    segs = _full_scheme(SimulatedBench(default_truth(0), seed=0))
    assert sum(len(s.t) for s in segs) == 306000


# --------------------------------------------------------------------------
# Truth YAML
# --------------------------------------------------------------------------

def test_truth_yaml_round_trip(tmp_path):
    truth = default_truth(7)
    truth.gyro.lsb = 1e-5
    truth.bench.rate_ripple_fraction = 1e-4
    path = tmp_path / "truth.yaml"
    truth.to_yaml(path)
    back = Truth.from_yaml(path)
    assert back.to_yaml_dict() == truth.to_yaml_dict()
    p1, p2 = truth.paper_parameters(), back.paper_parameters()
    for k in p1:
        np.testing.assert_array_equal(p1[k], p2[k])
    # a minimal file gives the documented defaults
    path.write_text("accelerometer:\n  bias_ug: [1, 2, 3]\n")
    t = Truth.from_yaml(path)
    assert t.accel.noise_density == 100.0 and t.gyro.noise_density == 0.03
    assert t.sample_rate_hz == 100.0 and t.bench.latitude_deg == 45.0
    assert t.bench.table_angle_error_arcsec == 2.0


@pytest.mark.parametrize("section,field,value", [
    ("accelerometer", "scale", [1.0, -1.0, 1.0]),
    ("accelerometer", "scale", [1.0, 1.0]),
    ("accelerometer", "axis_tilt_arcsec", [[0, 0], [0, 0], [0]]),
    ("accelerometer", "noise_density_ug_rthz", "loud"),
    ("accelerometer", "bias_ug", [1.0, float("nan"), 0.0]),
    ("gyroscope", "noise_density_dph_rthz", -0.1),
    ("gyroscope", "lsb_dps", True),
    ("gyroscope", "bias_dph", None),
    ("bench", "latitude_deg", 91.0),
    ("bench", "rate_ripple_fraction", 1.0),
    ("bench", "lever_arm_m", [0.1, 0.0]),
    ("bench", "bogus_field", 1),
    ("temperature", "warmup_time_constant_s", 0.0),
    (None, "sample_rate_hz", 0),
    (None, "extra", {}),
])
def test_bad_truth_field_raises_user_error(tmp_path, section, field, value):
    data = default_truth(0).to_yaml_dict()
    if section is None:
        data[field] = value
        name = field
    else:
        data[section][field] = value
        name = f"{section}.{field}"
    path = tmp_path / "bad_truth.yaml"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(UserError) as exc:
        Truth.from_yaml(path)
    msg = str(exc.value)
    assert str(path) in msg and name in msg, msg


def test_truth_yaml_not_a_mapping(tmp_path):
    path = tmp_path / "t.yaml"
    path.write_text("- 1\n- 2\n")
    with pytest.raises(UserError, match="t.yaml"):
        Truth.from_yaml(path)
    path.write_text("accelerometer: [1, 2\n")
    with pytest.raises(UserError, match="t.yaml"):
        Truth.from_yaml(path)
    with pytest.raises(UserError, match="missing.yaml"):
        Truth.from_yaml(tmp_path / "missing.yaml")


def test_accelerometer_element_positions_size_effect():
    """Each accelerometer senses w x (w x p_i) at its own position (2017 paper, eq. 12)."""
    truth = perfect_truth(lever_arm_m=[0.0, 0.0, 0.0])
    truth.accel.position_m = np.array([[0.010, 0.002, -0.003], [0.004, -0.012, 0.001], [0.0, 0.003, 0.015]])
    rate = 200.0
    bench = SimulatedBench(truth, 1)
    seg = bench.rotation([0, 0, 1], rate, 2.0, axis_elevation_deg=90.0)
    w = math.radians(rate)
    # rotation about body z (vertical): element x reads -w^2 p_1x, element y -w^2 p_2y, z only gravity
    mean = seg.accel.mean(axis=0)
    g = bench.gravity_mps2
    np.testing.assert_allclose(mean, [-w * w * 0.010, -w * w * -0.012, g], atol=1e-9)
    # a vertical table axis: the specific force is constant in body
    assert np.ptp(seg.accel, axis=0).max() < 1e-9


def test_drift_fraction_changes_rate_and_encoder_angle():
    truth = perfect_truth()
    seg = SimulatedBench(truth, 2).rotation([1, 0, 0], 720.0, 10.0, drift_fraction=-0.2, encoder=False)
    assert "angle_deg" not in seg.meta
    gx = seg.gyro[:, 0]
    assert gx[0] == pytest.approx(720.0, rel=1e-3) and gx[-1] == pytest.approx(576.0, rel=1e-3)
