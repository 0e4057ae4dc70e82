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
                               default_truth, mems_truth)
from sim_devices.world import ARCSEC, G_STANDARD, MICRO_G, OMEGA_EARTH
from station.core.errors import UserError

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
    ("accelerometer", "nonlinearity_ug_per_g2", [10.0, 20.0]),
    ("accelerometer", "nonlinearity_ug_per_g2", [10.0, 2e6, 0.0]),
    ("accelerometer", "cross_coupling_ug_per_g2", [[5.0, 1.0, 2.0], [0, 0, 0], [0, 0, 0]]),
    ("accelerometer", "cross_coupling_ug_per_g2", [[1.0, 2.0], [3.0, 4.0]]),
    ("accelerometer", "cross_coupling_ug_per_g2", [[1.0, 2.0], [3.0, 4.0], [5.0, "x"]]),
    ("gyroscope", "g_sensitivity_dph_per_g", [[0, 0, 0], [0, 0, 0]]),
    ("gyroscope", "g_sensitivity_dph_per_g", [[0, 0, 0], [0, float("inf"), 0], [0, 0, 0]]),
    ("gyroscope", "scale_asymmetry_ppm", [0.0, 0.0, 2e5]),
    ("gyroscope", "nonlinearity_ug_per_g2", [0.0, 0.0, 0.0]),      # accelerometer-only
    ("accelerometer", "scale_asymmetry_ppm", [0.0, 0.0, 2e5]),
    ("accelerometer", "rate_squared_ppm_per_dps", [0.0, 0.0, 0.0]),  # gyro-only
    ("accelerometer", "anisoelastic_dph_per_g2", [[0] * 6] * 3),     # gyro-only
    ("gyroscope", "bias_step_ug", [0.0, 0.0, 0.0]),                  # accelerometer's name
    ("accelerometer", "scale_tempco_ppm_per_c", [1.0, 2.0]),
    ("gyroscope", "scale_tempco_ppm_per_c", [0.0, 2e4, 0.0]),
    ("accelerometer", "bias_step_ug", [0.0, "big", 0.0]),
    ("gyroscope", "bias_step_time_s", -1.0),
    ("gyroscope", "rate_squared_ppm_per_dps", [0.0, float("nan"), 0.0]),
    ("gyroscope", "anisoelastic_dph_per_g2", [[0] * 6, [0] * 6, [0] * 5]),
    ("gyroscope", "anisoelastic_dph_per_g2", [[0] * 3] * 3),
    ("bench", "vibration_mg", 1.0),
    ("bench", "vibration_mg", [0.0, 2e4, 0.0]),
    ("bench", "vibration_phase_deg", 400.0),
    ("bench", "vibration_ref_rate_dps", 0.0),
    ("bench", "vibration_ref_rate_dps", "100 dps"),
    ("bench", "imbalance_g_mm", -1.0),
    ("bench", "base_mass_kg", 0.0),
    ("bench", "imbalance_phase_deg", float("inf")),
    ("bench", "remount_error_arcsec", -5.0),
    ("bench", "remount_rotations", 1),
    ("bench", "time_stamp_jitter_ms", 1.5),                          # > 10 % of 10 ms
    ("bench", "time_stamp_jitter_ms", -0.1),
    ("bench", "time_offset_s", 2.0),
    ("bench", "time_offset_s", "5 ms"),
    ("bench", "wobble_arcsec", -1.0),
    ("bench", "wobble_phase_deg", float("nan")),
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


def test_a_vibration_without_its_reference_rate_is_refused_in_one_message(tmp_path):
    """A truth file written before the twenty-first session gave vibration_mg without
    vibration_ref_rate_dps (it meant that amplitude at every rate, which no imbalance makes): with a
    non-zero vibration it is refused, naming the field and what it means now (exit 2 via UserError);
    with none it loads; with the rate it loads that rate."""
    data = default_truth(0).to_yaml_dict()
    del data["bench"]["vibration_ref_rate_dps"]
    path = tmp_path / "old.yaml"
    path.write_text(yaml.safe_dump(data))
    assert Truth.from_yaml(path).bench.vibration_ref_rate_dps == 100.0      # no vibration: loads
    data["bench"]["vibration_mg"] = [1.0, 0.0, 0.0]
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(UserError) as exc:
        Truth.from_yaml(path)
    msg = str(exc.value)
    assert "bench.vibration_mg" in msg and "vibration_ref_rate_dps" in msg and "at the steady rate" in msg, msg
    data["bench"]["vibration_ref_rate_dps"] = 30.0
    path.write_text(yaml.safe_dump(data))
    assert Truth.from_yaml(path).bench.vibration_ref_rate_dps == 30.0


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


# --------------------------------------------------------------------------
# Hidden effects (issue 4): each checked alone, noise and all other errors off
# --------------------------------------------------------------------------

SIX_UPS = [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]]


def test_default_truth_hides_nothing_and_mems_truth_ranges():
    for truth in (default_truth(3), mems_truth(3), Truth()):
        for a in (truth.accel.nonlinearity_ug_per_g2, truth.accel.cross_coupling_ug_per_g2,
                  truth.gyro.g_sensitivity_dph_per_g, truth.gyro.scale_asymmetry_ppm,
                  truth.accel.bias_tempco, truth.gyro.bias_tempco):
            assert not np.any(a)
        b = truth.bench
        assert b.time_offset_s == 0.0 and b.wobble_arcsec == 0.0 and b.wobble_phase_deg == 0.0
    for seed in range(20):
        t = mems_truth(seed)
        assert 100.0 <= t.accel.noise_density <= 200.0 and 5.0 <= t.gyro.noise_density <= 20.0
        for tri in (t.accel, t.gyro):
            err = np.abs(tri.scale - 1.0)
            assert np.all((1e-3 <= err) & (err <= 1e-2))
            assert np.all((360.0 <= np.abs(tri.axis_tilt_arcsec)) & (np.abs(tri.axis_tilt_arcsec) <= 3600.0))
        assert np.all((1000.0 <= np.abs(t.accel.bias)) & (np.abs(t.accel.bias) <= 20000.0))
        assert np.all((360.0 <= np.abs(t.gyro.bias)) & (np.abs(t.gyro.bias) <= 3600.0))
        assert t.to_yaml_dict() == mems_truth(seed).to_yaml_dict()
    assert mems_truth(1).to_yaml_dict() != mems_truth(2).to_yaml_dict()


def test_hidden_effects_yaml_round_trip(tmp_path):
    truth = mems_truth(4)
    truth.accel.nonlinearity_ug_per_g2 = np.array([40.0, -25.0, 90.0])
    truth.accel.cross_coupling_ug_per_g2 = np.array([[0.0, 12.0, -7.0], [3.0, 0.0, 20.0],
                                                     [-15.0, 8.0, 0.0]])
    truth.gyro.g_sensitivity_dph_per_g = np.arange(9.0).reshape(3, 3) * 10.0 - 40.0
    truth.gyro.scale_asymmetry_ppm = np.array([300.0, -800.0, 150.0])
    truth.accel.bias_tempco = np.array([30.0, -50.0, 80.0])
    truth.gyro.bias_tempco = np.array([3.0, -5.0, 8.0])
    truth.bench.time_offset_s = -0.004
    truth.bench.wobble_arcsec = 12.0
    truth.bench.wobble_phase_deg = 33.0
    path = tmp_path / "t.yaml"
    truth.to_yaml(path)
    back = Truth.from_yaml(path)
    assert back.to_yaml_dict() == truth.to_yaml_dict()
    # a 3x2 cross-coupling (columns: the other two case axes in x<y<z order) is the same
    data = truth.to_yaml_dict()
    data["accelerometer"]["cross_coupling_ug_per_g2"] = [[12.0, -7.0], [3.0, 20.0], [-15.0, 8.0]]
    np.testing.assert_array_equal(Truth.from_dict(data).accel.cross_coupling_ug_per_g2,
                                  truth.accel.cross_coupling_ug_per_g2)


def _statics(truth, ups, seed=0):
    bench = SimulatedBench(truth, seed)
    return [bench.static(u, 0.1) for u in ups]


def test_accel_nonlinearity_plus_minus_one_g():
    """+-1 g statics: the difference shows 2 k g (2 K2 * 0 from the nonlinearity), the sum
    2 K2 (g/g0)^2 (not multiplied by the scale factor); the other axes see nothing."""
    truth = perfect_truth()
    K2 = np.array([60.0, -35.0, 90.0])
    k = np.array([1.0008, 0.9993, 1.0004])
    truth.accel.nonlinearity_ug_per_g2 = K2
    truth.accel.scale = k
    segs = _statics(truth, SIX_UPS)
    g = SimulatedBench(truth, 0).gravity_mps2
    a1 = g / G_STANDARD                         # the input in g: local gravity, not g0
    tol = 16 * EPS * g
    for i in range(3):
        plus, minus = segs[2 * i].accel, segs[2 * i + 1].accel
        np.testing.assert_allclose(plus[:, i] - minus[:, i], 2 * k[i] * g, rtol=0, atol=tol)
        np.testing.assert_allclose(plus[:, i] + minus[:, i], 2 * K2[i] * a1**2 * MICRO_G,
                                   rtol=0, atol=tol)
        others = [j for j in range(3) if j != i]
        np.testing.assert_allclose(plus[:, others], 0.0, atol=tol)
    # the direct formula, once, for an arbitrary specific force
    f = np.array([[3.0, -7.0, 5.5]])
    acc, _ = truth.measure(f, np.zeros((1, 3)), 25.0, None)
    np.testing.assert_allclose(acc[0], k * f[0] + K2 * (f[0] / G_STANDARD) ** 2 * MICRO_G,
                               rtol=0, atol=16 * EPS * 10)


@pytest.mark.parametrize("pair", [(0, 1), (0, 2), (1, 2)])
def test_accel_cross_coupling_at_45_degrees(pair):
    """up = (e_i +- e_j)/sqrt 2: accelerometer i adds +-C_ij (g/g0)^2 / 2, j adds +-C_ji (g/g0)^2 / 2,
    the third nothing (its own input is zero)."""
    truth = perfect_truth()
    C = np.array([[0.0, 40.0, -25.0], [15.0, 0.0, 60.0], [-30.0, 10.0, 0.0]])
    truth.accel.cross_coupling_ug_per_g2 = C
    i, j = pair
    m = 3 - i - j
    up_p = np.zeros(3)
    up_p[[i, j]] = 1.0
    up_m = np.zeros(3)
    up_m[[i, j]] = [1.0, -1.0]
    seg_p, seg_m = _statics(truth, [up_p, up_m])
    g = SimulatedBench(truth, 0).gravity_mps2
    half = 0.5 * (g / G_STANDARD) ** 2 * MICRO_G
    tol = 16 * EPS * g
    for seg, s in ((seg_p, 1.0), (seg_m, -1.0)):
        extra = seg.accel - seg.truth["f_b"]              # perfect linear part
        np.testing.assert_allclose(extra[:, i], s * C[i, j] * half, rtol=0, atol=tol)
        np.testing.assert_allclose(extra[:, j], s * C[j, i] * half, rtol=0, atol=tol)
        np.testing.assert_allclose(extra[:, m], 0.0, rtol=0, atol=tol)
    # a +-1 g static along a case axis shows no cross-coupling (a_i a_j = 0)
    for seg in _statics(truth, SIX_UPS):
        np.testing.assert_allclose(seg.accel - seg.truth["f_b"], 0.0, rtol=0, atol=tol)


def test_gyro_g_sensitivity_between_attitudes():
    """Static gyro output minus the Earth rate = G f / g0 (deg/h); between two attitudes the
    change is G (f2 - f1), not multiplied by the scale factor."""
    truth = perfect_truth()
    rng = np.random.default_rng(7)
    G = rng.uniform(-100.0, 100.0, (3, 3))
    truth.gyro.g_sensitivity_dph_per_g = G
    truth.gyro.scale = np.array([1.002, 0.997, 1.0005])
    segs = _statics(truth, SIX_UPS + [[1, 1, 1]])
    outs, forces = [], []
    for seg in segs:
        earth = truth.gyro.scale * seg.truth["w_ib_dps"]
        outs.append((seg.gyro - earth) * 3600.0)           # deg/h
        forces.append(seg.truth["f_b"] / G_STANDARD)       # g, case axes
        tol = 16 * EPS * 3600.0 * np.abs(seg.gyro).max()
        np.testing.assert_allclose(outs[-1], np.tile(G @ forces[-1], (len(seg.t), 1)),
                                   rtol=0, atol=tol)
    for a in range(len(segs)):
        for b in range(a):
            np.testing.assert_allclose(outs[a][0] - outs[b][0], G @ (forces[a] - forces[b]),
                                       rtol=0, atol=32 * EPS * 3600.0 * 0.1)


def test_gyro_scale_asymmetry_plus_minus_rotations():
    """Rotations +-w about x: the x gyro's input is +-w + E (E: Earth rate along the
    horizontal axis, constant), its scale k (1 +- A) by the sign of the input, so
        I+ = k (1 + A)(theta + E T),   I- = k (1 - A)(-theta + E T)
        I+ + I- = 2 k (A theta + E T),  I+ - I- = 2 k (theta + A E T)."""
    truth = perfect_truth()
    A = 700e-6
    k = 1.0006
    truth.gyro.scale_asymmetry_ppm = np.array([A * 1e6, -400.0, 250.0])
    truth.gyro.scale = np.array([k, 1.0, 1.0])
    bench = SimulatedBench(truth, 5)
    dt = 1.0 / bench.sample_rate_hz
    seg_p = bench.rotation([1, 0, 0], 10.0, 36.0)
    seg_m = bench.rotation([1, 0, 0], -10.0, 36.0)
    n = len(seg_p.t)
    T = n * dt
    theta = seg_p.meta["angle_deg"]
    assert theta == pytest.approx(360.0, rel=1e-13)
    assert seg_m.meta["angle_deg"] == pytest.approx(-theta, rel=1e-13)
    E = math.degrees(np.dot(world.earth_rate_enu(45.0), seg_p.truth["axis_enu"]))
    Ip = seg_p.gyro[:, 0].sum() * dt
    Im = seg_m.gyro[:, 0].sum() * dt
    tol = 16 * EPS * n * 10.0 * dt         # rounding of N samples of ~10 deg/s
    assert Ip + Im == pytest.approx(2 * k * (A * theta + E * T), abs=tol)
    assert Ip - Im == pytest.approx(2 * k * (theta + A * E * T), abs=tol)
    # the direct formula: k r + k A |r|
    w = np.array([[5.0, -3.0, 0.0], [-5.0, 3.0, 0.0]])
    _, gyr = truth.measure(np.zeros((2, 3)), w, 25.0, None)
    np.testing.assert_allclose(gyr[:, 0], [k * (1 + A) * 5.0, -k * (1 - A) * 5.0], rtol=1e-15)
    np.testing.assert_allclose(gyr[:, 1], [-3.0 * (1 + 400e-6), 3.0 * (1 - 400e-6)], rtol=1e-15)


def test_paper_parameters_carry_the_higher_order_effects():
    """K2 and A act on the sensors' own inputs (rows of accel_T f_p and gyro_T R_po w_p),
    the g-sensitivity against f_p is G C_pb^T: identities to rounding."""
    truth = mems_truth(9)
    truth.accel.nonlinearity_ug_per_g2 = np.array([40.0, -25.0, 90.0])
    truth.gyro.g_sensitivity_dph_per_g = np.arange(9.0).reshape(3, 3) * 10.0 - 40.0
    truth.gyro.scale_asymmetry_ppm = np.array([300.0, -800.0, 150.0])
    p = truth.paper_parameters()
    rng = np.random.default_rng(1)
    f_b = rng.normal(0.0, 10.0, (50, 3))
    w_b = rng.normal(0.0, 20.0, (50, 3))
    acc, gyr = truth.measure(f_b, w_b, truth.temperature.reference_c, None)
    f_p = f_b @ p["C_pb"].T
    w_p = w_b @ p["C_pb"].T
    a_in = f_p @ p["accel_T"].T
    r_in = w_p @ (p["gyro_T"] @ p["R_po"]).T
    acc_paper = (a_in * p["accel_scale"] + p["accel_bias"]
                 + p["accel_nonlinearity_ug_per_g2"] * (a_in / G_STANDARD) ** 2 * MICRO_G)
    gyr_paper = (r_in * p["gyro_scale"] * (1 + np.sign(r_in) * p["gyro_scale_asymmetry_ppm"] * 1e-6)
                 + p["gyro_bias"] + (f_p / G_STANDARD) @ p["gyro_g_sensitivity_dph_per_g"].T / 3600)
    np.testing.assert_allclose(acc, acc_paper, rtol=0, atol=1e-12)
    np.testing.assert_allclose(gyr, gyr_paper, rtol=0, atol=1e-12)


def test_default_temperature_profile_makes_tempcos_visible():
    """The default profile warms the IMU by 2 (1 - e^-t/900 s) degC: ~1.9 degC over the
    one-hour scheme; a bias temperature coefficient c then moves the outputs by c dT."""
    truth = default_truth(0)
    assert truth.temperature == TemperatureTruth()
    segs = _full_scheme(SimulatedBench(truth, 0))
    t0, t1 = segs[0].t[0], segs[-1].t[-1]
    assert 3300.0 < t1 < 3600.0
    dT = segs[-1].temp[-1] - segs[0].temp[0]
    assert dT == pytest.approx(2.0 * (math.exp(-t0 / 900.0) - math.exp(-t1 / 900.0)), abs=1e-12)
    assert dT > 1.9
    # the coefficients, noise off: the output minus the perfect output is c (T - T_ref)
    truth = perfect_truth()
    truth.temperature = TemperatureTruth()
    ca, cg = np.array([50.0, -30.0, 80.0]), np.array([5.0, -2.0, 8.0])
    truth.accel.bias_tempco, truth.gyro.bias_tempco = ca, cg
    bench = SimulatedBench(truth, 0)
    early = bench.static([0, 0, 1], 10.0)
    bench.static([1, 0, 0], 3000.0)                 # an hour passes
    late = bench.static([0, 0, 1], 10.0)
    for seg in (early, late):
        dT = (seg.temp - 25.0)[:, None]
        np.testing.assert_allclose(seg.accel - seg.truth["f_b"], ca * dT * MICRO_G, rtol=0,
                                   atol=16 * EPS * 10.0)
        np.testing.assert_allclose(seg.gyro - seg.truth["w_ib_dps"], cg * dT / 3600.0, rtol=0,
                                   atol=16 * EPS * 0.01)
    # what a calibration sees: the static outputs move by c (T_late - T_early), ~1.9 degC here
    dT_seg = late.temp.mean() - early.temp.mean()
    assert dT_seg == pytest.approx(2.0 * np.mean(np.exp(-early.t / 900.0) - np.exp(-late.t / 900.0)),
                                   abs=1e-12)
    shift_a = (late.accel.mean(0) - late.truth["f_b"]) - (early.accel.mean(0) - early.truth["f_b"])
    shift_g = ((late.gyro.mean(0) - late.truth["w_ib_dps"])
               - (early.gyro.mean(0) - early.truth["w_ib_dps"]))      # Earth rate: random headings
    np.testing.assert_allclose(shift_a, ca * dT_seg * MICRO_G, rtol=0, atol=16 * EPS * 10.0)
    np.testing.assert_allclose(shift_g, cg * dT_seg / 3600.0, rtol=0, atol=16 * EPS * 0.01)
    # and a linear drift alone: drift_c_per_h * t / 3600
    truth.temperature = TemperatureTruth(warmup_delta_c=0.0, drift_c_per_h=1.5)
    seg = SimulatedBench(truth, 0).static([0, 0, 1], 1.0)
    np.testing.assert_allclose(seg.temp, 25.0 + 1.5 * seg.t / 3600.0, rtol=0, atol=1e-12)


def test_time_offset_with_ripple_shifts_data_against_encoder():
    """Stamps lag the table by delta: the IMU samples cover the table-time window shifted by
    +delta, the encoder the unshifted one.  With ripple (non-whole periods) the gyro integral
    then differs from the encoder angle by theta(window + delta) - theta(window)
    ~ delta (rate(end) - rate(start)); with delta = 0 only by the midpoint rule.

    Exact: sum_k sin(a + k b) = sin(N b/2) sin(a + (N-1) b/2) / sin(b/2) for the samples; the
    integral over the window is the same times sin(b/2) / (b/2)."""
    rho, fr, rate, dur = 0.2, 0.37, 10.0, 20.0
    results = {}
    for delta in (0.0, 0.005):
        bench = SimulatedBench(perfect_truth(rate_ripple_fraction=rho, rate_ripple_hz=fr,
                                             time_offset_s=delta), seed=6)
        seg = bench.rotation([1, 0, 0], rate, dur)
        dt = 1.0 / bench.sample_rate_hz
        n = len(seg.t)
        psi = seg.truth["ripple_phase_rad"]
        Om = 2 * np.pi * fr
        b = Om * dt
        E = math.degrees(np.dot(world.earth_rate_enu(45.0), seg.truth["axis_enu"]))
        gyro_int = seg.gyro[:, 0].sum() * dt - E * n * dt
        # the encoder: the unshifted window, whatever delta
        j0 = 2.0 / Om * math.sin(psi + (n - 1) * b / 2) * math.sin(n * b / 2)
        encoder = rate * n * dt + rate * rho * j0
        assert seg.meta["angle_deg"] == pytest.approx(encoder, abs=64 * EPS * encoder)
        # the samples: the shifted window, by the midpoint rule
        s = math.sin(n * b / 2) * math.sin(Om * delta + psi + (n - 1) * b / 2) / math.sin(b / 2)
        predicted = rate * n * dt + rate * rho * dt * s
        # rounding: each sample's argument Om (t + delta - t0) carries ~eps * t_max, its value a few ulp
        tol = n * dt * (rate * rho * Om * 4 * EPS * seg.t[-1] + 16 * EPS * rate * (1 + rho))
        assert gyro_int == pytest.approx(predicted, abs=tol)
        results[delta] = (seg, gyro_int - seg.meta["angle_deg"], psi)
    # physics: first order in delta, bounds from the neglected terms
    seg, diff, psi = results[0.005]
    t_lo, t_hi = seg.truth["window_s"]
    wr = rate * rho
    rate_at = lambda t: wr * math.sin(Om * (t - seg.t[0]) + psi)        # noqa: E731
    first_order = 0.005 * (rate_at(t_hi) - rate_at(t_lo))
    midpoint = wr * 2 / Om * (1 / math.sin(b / 2) * (b / 2) - 1)        # |sum - integral| bound
    second = 0.005**2 * wr * Om                                         # delta^2/2 * 2 max|theta''|
    assert abs(first_order) > 50 * (midpoint + second)                  # the effect is clear here
    assert diff == pytest.approx(first_order, abs=midpoint + second)
    assert abs(results[0.0][1]) <= midpoint
    # same geometry: the offset does not change the start attitude or the ripple phase
    assert results[0.0][2] == psi
    np.testing.assert_array_equal(results[0.0][0].truth["C_bn0"], seg.truth["C_bn0"])


def test_time_offset_at_constant_rate_changes_nothing_on_the_axis():
    """Without ripple the shift moves the data along a uniform rotation: the gyro integral on
    the axis still equals the encoder angle (plus Earth rate); a static segment is unchanged
    apart from its temperature, read at table time."""
    out = {}
    for delta in (0.0, 0.008):
        truth = perfect_truth(time_offset_s=delta)
        truth.temperature = TemperatureTruth(drift_c_per_h=36.0, warmup_delta_c=0.0)
        bench = SimulatedBench(truth, seed=2)
        st = bench.static([0, 1, 0], 1.0)
        seg = bench.rotation([0, 0, 1], 20.0, 18.0)
        dt = 0.01
        E = math.degrees(np.dot(world.earth_rate_enu(45.0), seg.truth["axis_enu"]))
        gyro_int = seg.gyro[:, 2].sum() * dt - E * 18.0
        assert gyro_int == pytest.approx(seg.meta["angle_deg"], abs=16 * EPS * 20.0 * len(seg.t) * dt)
        np.testing.assert_allclose(seg.temp, 25.0 + 0.01 * (seg.t + delta), rtol=0, atol=1e-12)
        out[delta] = st
    np.testing.assert_array_equal(out[0.0].accel, out[0.008].accel)
    np.testing.assert_array_equal(out[0.0].t, out[0.008].t)


# -- wobble ----------------------------------------------------------------

def _quat_mul(p, r):
    """Hamilton product of (N,4) scalar-last quaternions."""
    pv, pw = p[:, :3], p[:, 3:]
    rv, rw = r[:, :3], r[:, 3:]
    return np.hstack([pw * rv + rw * pv + np.cross(pv, rv),
                      pw * rw - np.einsum("ij,ij->i", pv, rv)[:, None]])


def _wobble_attitude_reference(C_bn0, a_n, d, b, theta, m=1):
    """C_nb = Rot(a_n, theta) Rot(b e) C_nb0, e = Rot(a_n, m theta) d, built by scipy
    compositions (independently of world.wobbling_table)."""
    theta = np.atleast_1d(theta)
    e = Rotation.from_rotvec(m * theta[:, None] * a_n[None, :]).apply(d)
    return Rotation.from_rotvec(theta[:, None] * a_n[None, :]) * Rotation.from_rotvec(b * e) * C_bn0.inv()


def _body_rate_fd(C_nb_of_t, t, h):
    """Body rate from the attitude quaternion q of C_nb: q' = q (x) (0, w_b) / 2, q' by a
    5-point central difference (truncation h^4/30 |q^(5)|, rounding ~1.5 ulp / h)."""
    qs = [C_nb_of_t(t + k * h).as_quat() for k in (-2, -1, 0, 1, 2)]
    for q in qs:
        q *= np.sign(np.einsum("ij,ij->i", q, qs[2]))[:, None]
    qd = (qs[0] - 8 * qs[1] + 8 * qs[3] - qs[4]) / (12 * h)
    conj = qs[2] * np.array([-1.0, -1.0, -1.0, 1.0])
    return 2.0 * _quat_mul(conj, qd)[:, :3]


@pytest.mark.parametrize("m", [1, -2, 0, -1])
def test_wobble_rate_is_the_derivative_of_the_attitude(m):
    """world.wobbling_table: w_b equals the angular velocity of the attitude (numerically
    differentiated), wdot_b the derivative of w_b, and the lever-arm acceleration the second
    derivative of the position, with ripple on and a large wobble."""
    a_n = world.table_axis_enu(0.4, 0.2)
    C_bn0 = world.attitude_axis([1, 2, 0.5], a_n, roll_rad=0.3)
    b, phase = math.radians(2.0), 0.7
    d = world.wobble_direction_enu(a_n, phase)
    assert abs(d @ a_n) < 4 * EPS and np.linalg.norm(d) == pytest.approx(1.0, abs=4 * EPS)
    prof = dict(t0=0.0, rate_rad_s=math.radians(30.0), ripple_fraction=0.3, ripple_hz=0.7,
                ripple_phase_rad=0.9)
    t = np.linspace(0.0, 12.0, 41)
    h = 1e-3

    def state(tt):
        th, thd, thdd = world.rate_profile(tt, **prof)
        return world.wobbling_table(C_bn0, a_n, th, thd, thdd, b, phase, harmonic=m)

    def C_nb(tt):
        return _wobble_attitude_reference(C_bn0, a_n, d, b, world.rate_profile(tt, **prof)[0], m)

    C_bn, w_b, wd_b = state(t)
    np.testing.assert_allclose(C_bn.as_matrix(), C_nb(t).inv().as_matrix(), rtol=0, atol=64 * EPS)
    # rounding: 1.5 * (a few ulp of q) / h; truncation h^4/30 * (|w|max ~ 1.1 rad/s)^5 ~ 5e-14
    tol_w = 1.5 * 2 * 32 * EPS / h + h**4 / 30 * 1.1**5
    np.testing.assert_allclose(w_b, _body_rate_fd(C_nb, t, h), rtol=0, atol=tol_w)
    ws = [state(t + k * h)[1] for k in (-2, -1, 0, 1, 2)]
    wd_fd = (ws[0] - 8 * ws[1] + 8 * ws[3] - ws[4]) / (12 * h)
    # truncation h^4/30 |w^(5)| with |w^(5)| <~ (2 pi 0.7 + 2 |w|)^5 |w|; rounding 1.5 * 16 ulp / h
    tol_wd = h**4 / 30 * (2 * np.pi * 0.7 + 2.2) ** 5 * 1.1 + 1.5 * 16 * EPS * 1.1 / h
    np.testing.assert_allclose(wd_b, wd_fd, rtol=0, atol=tol_wd)
    # the lever-arm terms of world.body_kinematics against the position's 2nd derivative
    r = np.array([0.04, -0.03, 0.02])
    site = world.Site(45.0, 0.0)
    f_b, _ = world.body_kinematics(C_bn, w_b, wd_b, r, site)
    pos = lambda tt: C_nb(tt).apply(r)                               # noqa: E731
    acc_n = (-pos(t + 2 * h) + 16 * pos(t + h) - 30 * pos(t) + 16 * pos(t - h)
             - pos(t - 2 * h)) / (12 * h**2)
    # rounding ~ 64/12 eps |r| / h^2 * few; truncation h^4/90 |p^(6)| ~ 1e-13
    np.testing.assert_allclose(f_b - C_bn.apply([0.0, 0.0, site.g]), C_bn.apply(acc_n),
                               rtol=0, atol=1e-8)
    if m in (0, -1):
        # no wobble at all: m = 0 is a constant mounting tilt, m = -1 a constant axis tilt
        Rd = Rotation.from_rotvec(b * d)
        C0p = C_bn0 * Rd.inv()
        axis = a_n if m == 0 else Rd.apply(a_n)
        th, thd, thdd = world.rate_profile(t, **prof)
        np.testing.assert_allclose(C_bn.as_matrix(), world.table_attitude(C0p, axis, th).as_matrix(),
                                   rtol=0, atol=64 * EPS)
        w_ref, wd_ref = world.table_rates_body(C0p, axis, thd, thdd)
        np.testing.assert_allclose(w_b, w_ref, rtol=0, atol=16 * EPS)
        np.testing.assert_allclose(wd_b, wd_ref, rtol=0, atol=16 * EPS)


def test_wobble_on_the_bench():
    """A 20 arcsec wobble, perfect sensors, no lever arm, horizontal axis, two revolutions:

    * gyro - Earth rate = the numerical derivative of the attitude
      C_nb = Rot(a_n, theta) Rot(b e(theta)) C_nb0, e = Rot(a_n, theta) d;
    * the rate seen in the body: |w| = w sqrt(5 - 4 cos b) exactly constant, along the platter
      axis w (2 cos b - 1), perpendicular to it 2 w sin b turning once per revolution;
    * gravity follows the attitude: along the platter axis g sin b at twice per revolution;
    * zero wobble: exactly the unwobbled bench, whatever the phase."""
    rate, wob = 10.0, 20.0
    b = wob * ARCSEC
    bench = SimulatedBench(perfect_truth(wobble_arcsec=wob, wobble_phase_deg=40.0,
                                         lever_arm_m=[0.0, 0.0, 0.0]), seed=4)
    seg = bench.rotation([0, 1, 0], rate, 72.0)
    n = len(seg.t)
    dt = 1.0 / bench.sample_rate_hz
    C_bn0 = Rotation.from_matrix(seg.truth["C_bn0"])
    a_n = seg.truth["axis_enu"]
    d = seg.truth["wobble_direction_enu"]
    np.testing.assert_allclose(d, world.wobble_direction_enu(a_n, math.radians(40.0)), atol=0)
    assert seg.truth["wobble_rad"] == b
    w = math.radians(rate)
    theta_of = lambda tt: w * (tt - seg.t[0])                          # noqa: E731
    C_nb = lambda tt: _wobble_attitude_reference(C_bn0, a_n, d, b, theta_of(tt))  # noqa: E731
    C_bn = C_nb(seg.t).inv()
    earth = np.degrees(C_bn.apply(world.earth_rate_enu(45.0)))
    w_body = np.radians(seg.gyro - earth)                            # w_eb_b, rad/s
    h = 1e-3
    tol_w = 1.5 * 2 * 32 * EPS / h + 16 * EPS * w
    np.testing.assert_allclose(w_body, _body_rate_fd(C_nb, seg.t, h), rtol=0, atol=tol_w)
    np.testing.assert_allclose(seg.accel, C_bn.apply([0.0, 0.0, bench.gravity_mps2]),
                               rtol=0, atol=64 * EPS * 10.0)
    # |w| constant; components along and across the platter axis a_b (body-fixed)
    a_b = seg.truth["axis_body_true"]
    norm = np.linalg.norm(w_body, axis=1)
    np.testing.assert_allclose(norm, w * math.sqrt(5 - 4 * math.cos(b)), rtol=16 * EPS)
    np.testing.assert_allclose(w_body @ a_b, w * (2 * math.cos(b) - 1), rtol=16 * EPS)
    u1 = np.cross(a_b, [1.0, 0.0, 0.0])
    u1 /= np.linalg.norm(u1)
    u2 = np.cross(a_b, u1)
    # Fourier amplitudes over the two whole turns (bin k = k/2 per revolution); a bin is a
    # mean of samples, so its rounding error is at most twice the per-sample one (~16 ulp of w)
    spec = np.fft.rfft(np.column_stack([w_body @ u1, w_body @ u2]), axis=0) * 2 / n
    amp = np.abs(spec)
    assert n * dt * rate == pytest.approx(720.0)
    tol_bin = 2 * 16 * EPS * w
    np.testing.assert_allclose(amp[2], 2 * w * math.sin(b), rtol=0, atol=tol_bin)  # both axes: a circle
    amp[2] = 0.0
    assert amp.max() < tol_bin                                       # nothing else
    # gravity along the platter axis: g sin b at twice per revolution (bin 4), nothing else
    g = bench.gravity_mps2
    fa = np.fft.rfft(seg.accel @ a_b) * 2 / n
    assert abs(fa[4]) == pytest.approx(g * math.sin(b), abs=2 * 16 * EPS * g)
    fa[4] = 0.0
    assert np.abs(fa).max() < 2 * 16 * EPS * g
    # the gyro integral along the platter axis after whole turns: (2 cos b - 1) theta, a coning
    # term of -b^2 theta (0.024 arcsec here) -- the encoder still reads theta
    assert seg.meta["angle_deg"] == pytest.approx(720.0, rel=1e-13)

    # zero wobble: bit-identical to the unwobbled bench
    ref = SimulatedBench(perfect_truth(lever_arm_m=[0.0, 0.0, 0.0]), seed=4).rotation([0, 1, 0], rate, 72.0)
    zero = SimulatedBench(perfect_truth(wobble_arcsec=0.0, wobble_phase_deg=40.0,
                                        lever_arm_m=[0.0, 0.0, 0.0]), seed=4).rotation([0, 1, 0], rate, 72.0)
    for name in ("t", "accel", "gyro", "temp"):
        np.testing.assert_array_equal(getattr(zero, name), getattr(ref, name))
    assert zero.meta == ref.meta
    np.testing.assert_array_equal(zero.truth["C_bn0"], seg.truth["C_bn0"])   # same geometry draws


def test_all_hidden_effects_off_is_the_old_bench():
    """Effects at zero change nothing: a truth with every new field explicitly 0 gives the same
    bytes as default_truth (whose effects are all 0)."""
    truth = default_truth(2)
    data = truth.to_yaml_dict()
    zeroed = Truth.from_dict(data)
    a = _full_scheme(SimulatedBench(truth, 3))[7:11]
    b = _full_scheme(SimulatedBench(zeroed, 3))[7:11]
    for x, y in zip(a, b):
        for name in ("t", "accel", "gyro", "temp"):
            np.testing.assert_array_equal(getattr(x, name), getattr(y, name))
