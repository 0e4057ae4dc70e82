"""The twins' physics and determinism: gimbal kinematics, axis motion profiles, the IMU twin
coupled to the table twin, speed independence, and the front-ends under fuzzing."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from drivers.base import ImuSettings
from drivers.protocols import vectornav as V
from drivers.registry import open_imu
from sim_devices import world
from sim_devices.truth import BenchSettings, TemperatureTruth, Truth, TriadTruth, default_truth
from sim_devices.twins.clock import ManualClock
from sim_devices.twins.faults import ImuFaults, StreamFaulter
from sim_devices.twins.geometry import TableGeometry
from sim_devices.twins.imu import ImuTwin
from sim_devices.twins.imu_vectornav import VectorNavFrontEnd
from sim_devices.twins.motion import AxisMotion
from sim_devices.twins.serve import BenchOptions, BenchServer
from sim_devices.twins.table import CommandRefused, TableConfig, TableTwin
from sim_devices.twins.table_acutrol import AcutrolFrontEnd
from sim_devices.twins.table_aerosmith import AerosmithFrontEnd

FUZZ = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def _ideal_truth(lever_arm=(0.0, 0.0, 0.0)) -> Truth:
    return Truth(accel=TriadTruth(noise_density=0.0), gyro=TriadTruth(noise_density=0.0),
                 temperature=TemperatureTruth(warmup_delta_c=0.0),
                 bench=BenchSettings(lever_arm_m=np.array(lever_arm)))


# ------------------------------------------------------------------------------ geometry

def test_one_axis_matches_the_world_functions():
    geo = TableGeometry(((0.0, 1.0, 0.0),))
    t = np.linspace(0, 3, 31)
    th, thd, thdd = world.rate_profile(t, 0.0, 0.7, 0.2, 1.3, 0.4)
    C, w, wd = geo.kinematics(th[:, None], thd[:, None], thdd[:, None])
    C_ref = world.table_attitude(Rotation.identity(), [0, 1, 0], th)
    w_ref, wd_ref = world.table_rates_body(Rotation.identity(), [0, 1, 0], thd, thdd)
    np.testing.assert_allclose(C.as_matrix(), C_ref.as_matrix(), atol=1e-15)
    np.testing.assert_allclose(w, w_ref, atol=1e-15)
    np.testing.assert_allclose(wd, wd_ref, atol=1e-15)


def test_three_axis_rates_are_the_derivatives_of_the_attitude():
    geo = TableGeometry.default(3)
    rng = np.random.default_rng(1)
    a0, a1, a2 = rng.uniform(-3, 3, 3), rng.uniform(-2, 2, 3), rng.uniform(-1, 1, 3)

    def angles(t):
        t = np.asarray(t)[:, None]
        return a0 + a1 * t + 0.5 * a2 * t * t, a1 + a2 * t, np.broadcast_to(a2, (t.shape[0], 3))

    t = np.array([0.3, 1.1, 2.0])
    h = 1e-5
    C, w, wd = geo.kinematics(*angles(t))
    Cm, wm, _ = geo.kinematics(*angles(t - h))
    Cp, wp, _ = geo.kinematics(*angles(t + h))
    # C_nb' = C_nb [w x]  =>  C_bn(t-h) C_bn(t+h)^-1 = exp([w x] 2h)
    w_num = (Cm * Cp.inv()).as_rotvec() / (2 * h)
    np.testing.assert_allclose(w, w_num, atol=1e-8)
    np.testing.assert_allclose(wd, (wp - wm) / (2 * h), atol=1e-6)


def test_default_geometry_at_zero_is_enu_and_axes_are_outer_to_inner():
    geo = TableGeometry.default(2)
    C, w, _ = geo.kinematics([[math.pi / 2, 0.0]], [[1.0, 0.0]], [[0.0, 0.0]])
    # outer vertical axis at +90 deg: the case x axis points north
    np.testing.assert_allclose(C.inv().apply([1, 0, 0]), [[0, 1, 0]], atol=1e-15)
    np.testing.assert_allclose(w, [[0, 0, 1]], atol=1e-15)
    with pytest.raises(ValueError):
        TableGeometry(((0, 0, 0),))


# ------------------------------------------------------------------------------ motion

@pytest.mark.parametrize("seed", range(12))
def test_moves_are_limited_continuous_and_arrive(seed):
    rng = np.random.default_rng(seed)
    m = AxisMotion(settle_s=0.5)
    vmax, amax = rng.uniform(5, 100), rng.uniform(5, 200)
    m.plan_rate(0.0, rng.uniform(-vmax, vmax), amax)           # start from any motion
    t_cmd = rng.uniform(0.0, 3.0)
    goal = rng.uniform(-400, 400)
    m.plan_position(t_cmd, goal, vmax, amax)
    t = np.linspace(t_cmd, t_cmd + 40.0, 400001)
    p, v, a = m.eval(t)
    assert np.all(np.abs(v) <= vmax * (1 + 1e-9) + 1e-9)
    assert np.all(np.abs(a) <= amax * (1 + 1e-9) + 1e-6 + 4 * 0.01 * (2 * math.pi * 2) ** 2)
    dt = t[1] - t[0]
    assert np.max(np.abs(np.diff(p))) <= (vmax + 1e-9) * dt * 1.0001      # no jump
    assert np.max(np.abs(np.diff(v))) <= amax * dt * 1.0001 + 2 * 0.01 * 30 * dt
    assert abs(p[-1] - goal) < 1e-9 and abs(v[-1]) < 1e-9


def test_rate_mode_reaches_the_rate_at_the_acceleration_limit():
    m = AxisMotion()
    m.plan_rate(1.0, 30.0, 10.0)
    p, v, a = m.eval(np.array([1.0, 2.0, 4.0, 5.0]))
    np.testing.assert_allclose(v, [0, 10, 30, 30])
    np.testing.assert_allclose(p, [0, 5, 45, 75])
    m.plan_stop(5.0, 15.0)
    assert m.state(7.0)[1] == 0.0 and m.state(100.0)[0] == pytest.approx(75 + 30)


# ------------------------------------------------------------------------------ IMU twin

def test_the_imu_twin_sees_centripetal_acceleration_and_the_table_rate():
    clock = ManualClock()
    truth = _ideal_truth(lever_arm=(0.1, 0.0, 0.05))
    table = TableTwin(TableGeometry.default(1, truth.bench.lever_arm_m), clock, interlocks_closed=True)
    imu = ImuTwin(table, truth)
    table.set_mode(1, "rate")
    table.demand_rate(1, 360.0)                           # 1 rev/s after 3.6 s at 100 deg/s^2
    clock.advance(10.0)
    t = np.array([5.0, 7.25, 9.5])
    accel, gyro, _ = imu.measure(t)
    w = 2 * math.pi
    site = world.Site(45.0)
    np.testing.assert_allclose(accel, [[-w * w * 0.1, 0.0, site.g]] * 3, atol=1e-12)
    # gyro: 360 deg/s about z plus the Earth rate seen by the turning case
    theta = np.radians(table.axis_states(t)[0][:, 0])
    earth = np.degrees(site.earth_rate_enu)
    ex = earth[1] * np.sin(theta)
    ey = earth[1] * np.cos(theta)
    np.testing.assert_allclose(gyro, np.column_stack([ex, ey, 360 + earth[2] + 0 * theta]), atol=1e-12)


def test_the_imu_twin_accelerometers_sense_at_their_own_positions():
    """The size effect in the twin: each accelerometer senses the centripetal acceleration at its
    own position (truth.accel.position_m, m, case axes), beyond the lever arm's (before, the twin
    ignored the positions: a capture over the ports had no size effect whatever the truth said).
    Reference: w x (w x p) at 1 rev/s about z, by hand."""
    clock = ManualClock()
    truth = _ideal_truth(lever_arm=(0.1, 0.0, 0.05))
    truth.accel.position_m = np.array([[0.004, 0.0, 0.0], [0.0, 0.006, 0.0], [0.0, 0.0, 0.008]])
    table = TableTwin(TableGeometry.default(1, truth.bench.lever_arm_m), clock, interlocks_closed=True)
    imu = ImuTwin(table, truth)
    table.set_mode(1, "rate")
    table.demand_rate(1, 360.0)
    clock.advance(10.0)
    accel, _, _ = imu.measure(np.array([5.0, 7.25, 9.5]))
    w2, g = (2 * math.pi) ** 2, world.Site(45.0).g
    # x: lever arm and its own 4 mm; y: its own 6 mm; z: along the axis, nothing more
    np.testing.assert_allclose(accel, [[-w2 * 0.104, -w2 * 0.006, g]] * 3, atol=1e-12)


def test_same_seed_same_bytes_whatever_the_batching():
    """Noise depends on the sample index, not on how samples are batched: a twin at
    --speed 1 and one at --speed 50 send the same frames for a table at rest."""
    def frames(steps):
        clock = ManualClock()
        truth = default_truth(3)
        table = TableTwin(TableGeometry.default(2, truth.bench.lever_arm_m), clock)
        fe = VectorNavFrontEnd(ImuTwin(table, truth, seed=9), StreamFaulter(ImuFaults(), None),
                               startup="binary")          # frames from power-up, no driver
        fe.imu.restart(0.0)
        out = b""
        for dt in steps:
            out += fe.produce(clock.advance(dt))
        return out
    a = frames([0.01] * 500 + [1e-6])              # one frame at a time
    b = frames([0.37, 1.9, 0.05, 2.68, 1e-6])      # batches of any size
    assert len(a) == len(b) == 500 * V.STATION_LAYOUT.frame_length and a == b


def test_speed_does_not_change_the_samples_over_the_ports():
    got = []
    for speed, n in ((10.0, 1000), (50.0, 150)):
        # the stream starts when the driver has connected: at 50 x that is a few device seconds
        # later than at 10 x (0.1 s of wall time under load is 5 s), so the slow one reads 10 s
        # (1 s of wall at 10 x; 2 s at the 5 x used before, for the same check of two speeds)
        with BenchServer(default_truth(4), BenchOptions(speed=speed, seed=4)) as server:
            with open_imu(server.imu_path, "vectornav", ImuSettings()) as imu:
                got.append(imu.read(n))
    a, b = got
    common, ia, ib = np.intersect1d(np.round(a.t_s * 100), np.round(b.t_s * 100), return_indices=True)
    assert len(common) > 0
    np.testing.assert_array_equal(a.accel_mps2[ia], b.accel_mps2[ib])
    np.testing.assert_array_equal(a.gyro_dps[ia], b.gyro_dps[ib])


def test_encoder_readback_is_quantised_and_wrapped():
    clock = ManualClock()
    table = TableTwin(TableGeometry.default(1), clock, interlocks_closed=True)
    table.set_mode(1, "position")
    table.demand_position(1, -0.123456789)
    clock.advance(100.0)
    assert table.read_position(1) == pytest.approx(359.87654, abs=1e-9)
    assert table.read_rate(1) == 0.0


# ------------------------------------------------------------------------------ fuzzing

@FUZZ
@given(st.binary(max_size=300))
def test_table_front_ends_never_raise(data):
    clock = ManualClock()
    for axes, fe_cls in ((3, AcutrolFrontEnd), (1, AerosmithFrontEnd)):
        fe = fe_cls(TableTwin(TableGeometry.default(axes), clock, interlocks_closed=True))
        out = fe.receive(data)
        assert isinstance(out, bytes)


@FUZZ
@given(st.lists(st.sampled_from([":Mode:Rate 1", ":Demand:Rate 1,5", ":Mode:Position 2",
                                 ":Demand:Position 2,-10", ":Interlock:Open 3", "*STB?",
                                 ":Read:Position? 4", ":Limit:Rate P,1,0", ":Read:Rate? 1", "bogus"]),
                max_size=8))
def test_acutrol_gpib_answers_the_queries_and_the_error_bit_follows_the_queue(parts):
    clock = ManualClock()
    fe = AcutrolFrontEnd(TableTwin(TableGeometry.default(3), clock, interlocks_closed=True), "gpib")
    reply = fe.receive((";".join(parts + ["*STB?"]) + "\n").encode())
    fields = reply.decode().strip().split(";")
    stb = int(fields[-1])
    n_errors = sum(p in ("bogus", ":Read:Position? 4", ":Limit:Rate P,1,0") for p in parts)
    # bit 7 (error queue) while the queue holds a message, whatever *STB? read before (TM-8004
    # §4.11.4); MSS only for a bit *SRE enables, at power-up SI (bit 0) alone (§3.9, §3.10)
    assert bool(stb & 0x80) == (n_errors > 0) == bool(fe.errors)
    assert bool(stb & 0x40) == bool(stb & 0x01)
    good_queries = [p for p in parts if "?" in p and p != ":Read:Position? 4"]
    assert len(fields) == len(good_queries) + 1
    assert len(fe.errors) >= min(n_errors, 32)


@FUZZ
@given(st.binary(max_size=300))
def test_vectornav_front_end_never_raises(data):
    clock = ManualClock()
    truth = default_truth(1)
    table = TableTwin(TableGeometry.default(1), clock)
    fe = VectorNavFrontEnd(ImuTwin(table, truth), StreamFaulter(ImuFaults(), None))
    out = fe.receive(data + b"\n", clock.now())
    assert isinstance(out, bytes)


def test_per_axis_hardware_limits():
    clock = ManualClock()
    cfg = TableConfig(max_rate_dps=(100.0, 400.0), max_accel_dps2=(50.0, 500.0))
    table = TableTwin(TableGeometry.default(2), clock, config=cfg, interlocks_closed=True)
    table.set_limit("R", 2, rate_dps=400.0)
    with pytest.raises(CommandRefused):
        table.set_limit("R", 1, rate_dps=400.0)
    table.set_mode(1, "rate")
    with pytest.raises(CommandRefused):
        table.demand_rate(1, 150.0)
    table.demand_rate(1, 100.0)                        # at 50 deg/s^2: 2 s
    clock.advance(1.0)
    assert table.read_rate(1) == pytest.approx(50.0)
