"""Contract of the Imu interface, for every protocol, against the IMU twin over real
pseudo-terminals; the twin's samples come from the table twin's state."""
from __future__ import annotations

import math

import numpy as np
import pytest

from drivers.base import ImuSettings
from drivers.errors import LimitError
from drivers.protocols.csvlines import CsvFormat
from drivers.registry import open_imu, open_table
from sim_devices import world
from sim_devices.truth import default_truth
from sim_devices.twins.serve import BenchOptions, BenchServer

PROTOCOLS = ["vectornav", "csv"]
SPEED = 50.0
SEED = 5


@pytest.fixture(params=PROTOCOLS)
def bench(request):
    truth = default_truth(SEED)
    server = BenchServer(truth, BenchOptions(speed=SPEED, seed=SEED, axes=2, imu_protocol=request.param))
    with server:
        yield server, request.param, truth


def _open(server, protocol, **kw):
    return open_imu(server.imu_path, protocol, ImuSettings(**kw))


def test_connect_configure_and_read_consecutive_samples(bench):
    server, protocol, truth = bench
    with _open(server, protocol) as imu:
        assert imu.identity
        assert imu.configure(100.0) == 100.0
        s = imu.read(500)
        assert len(s) == 500
        assert s.accel_mps2.shape == s.gyro_dps.shape == (500, 3)
        np.testing.assert_allclose(np.diff(s.t_s), 0.01, atol=2e-6)
        assert np.all(np.isfinite(s.temp_c))
        more = imu.read(10)              # the stream continues where it was
        assert abs(more.t_s[0] - s.t_s[-1] - 0.01) < 2e-6
        c = imu.counters
        assert (c.frames >= 510, c.checksum_errors, c.gaps, c.missing_frames) == (True, 0, 0, 0)


def test_read_seconds_counts_device_time(bench):
    server, protocol, truth = bench
    with _open(server, protocol) as imu:
        s = imu.read_seconds(20.0)           # 20 s of device time: 0.4 s wall at speed 50
        assert len(s) == 2000
        assert abs(s.t_s[-1] - s.t_s[0] - 19.99) < 1e-5


def test_static_samples_match_the_true_error_model(bench):
    """At rest at zero the case axes are ENU: f = [0, 0, g], w = Earth rate; the mean of the
    samples is the truth's measurement of that, within 5 sigma of the noise of the mean."""
    server, protocol, truth = bench
    with _open(server, protocol) as imu:
        s = imu.read(2000)
    site = world.Site(truth.bench.latitude_deg, truth.bench.height_m)
    f = np.array([[0.0, 0.0, site.g]])
    w = np.degrees(site.earth_rate_enu)[None, :]
    accel, gyro = truth.measure(f, w, s.temp_c.mean(), None)
    n = len(s)
    sa, sg = truth.accel_noise_sigma / math.sqrt(n), truth.gyro_noise_sigma / math.sqrt(n)
    # float32 (vectornav) or 9 significant digits (csv) add < 1e-6 relative
    np.testing.assert_allclose(s.accel_mps2.mean(axis=0), accel[0], rtol=0, atol=5 * sa + 1e-5)
    np.testing.assert_allclose(s.gyro_dps.mean(axis=0), gyro[0], rtol=0, atol=5 * sg + 1e-6)


def test_the_imu_sees_the_table_turn(bench):
    """The IMU twin reads the table twin's state: turning the outer (vertical) axis at
    20 deg/s shows on the gyro z, and gravity turns in the case frame when the inner
    (east) axis is at 90 deg."""
    server, protocol, truth = bench
    with open_table(server.table_path) as table, _open(server, protocol) as imu:
        table.close_interlocks()
        table.move_to([0.0, 90.0])
        s = _after(imu, server.clock.now(), 500)
        # inner axis east at 90 deg: the case z axis now points south-ish, y up
        g = world.local_gravity(truth.bench.latitude_deg)
        np.testing.assert_allclose(np.median(s.accel_mps2, axis=0), [0, g, 0], atol=0.05)
        table.set_rate(1, 20.0)
        s = _after(imu, server.clock.now(), 500)      # samples once the rate has settled
        np.testing.assert_allclose(np.median(s.gyro_dps, axis=0), [0, 20.0, 0], atol=0.05)
        table.stop()


def _after(imu, t_device_s, n):
    """``n`` samples taken after device time ``t_device_s`` (what the ports hold from before
    is read and dropped: the samples' own time says which are new)."""
    while True:
        s = imu.read(n)
        if s.t_s[0] > t_device_s:
            return s
        if s.t_s[-1] > t_device_s:
            return imu.read(n)


def test_output_rate(bench):
    server, protocol, truth = bench
    with _open(server, protocol) as imu:
        if protocol == "vectornav":
            assert imu.configure(200.0) == 200.0
            s = imu.read(400)
            np.testing.assert_allclose(np.diff(s.t_s), 0.005, atol=2e-6)
            with pytest.raises(LimitError, match="not 800 Hz / N"):
                imu.configure(300.0)
        with pytest.raises(LimitError, match="output rate"):
            imu.configure(-1.0)


def test_vectornav_without_temperature_gives_nan():
    truth = default_truth(SEED)
    with BenchServer(truth, BenchOptions(speed=SPEED)) as server:
        with open_imu(server.imu_path, "vectornav", ImuSettings(temperature=False)) as imu:
            s = imu.read(50)
            assert np.all(np.isnan(s.temp_c)) and np.all(np.isfinite(s.accel_mps2))
            assert server.imu_frontend.layout.frame_length == 40


def test_csv_units_are_converted():
    truth = default_truth(SEED)
    fmt = CsvFormat(time_unit="ms", accel_unit="g", gyro_unit="rad/s")
    with BenchServer(truth, BenchOptions(speed=SPEED, imu_protocol="csv", csv_format=fmt)) as server:
        with open_imu(server.imu_path, "csv", ImuSettings(csv_format=fmt)) as imu:
            s = imu.read(200)
    np.testing.assert_allclose(np.diff(s.t_s), 0.01, atol=1e-9)
    assert abs(np.linalg.norm(s.accel_mps2.mean(axis=0)) - 9.806) < 0.05
    assert np.linalg.norm(s.gyro_dps.mean(axis=0)) < 0.01          # Earth rate + bias, deg/s


def test_use_before_connect_and_after_close_is_a_device_error():
    from drivers.errors import DeviceError
    from drivers.registry import imu_driver, table_driver
    imu = imu_driver("vectornav")("/dev/null-imu")
    with pytest.raises(DeviceError, match=r"imu /dev/null-imu \(vectornav\): not connected"):
        imu.read(1)
    table = table_driver("acutrol")("/dev/null-table")
    with pytest.raises(DeviceError, match="not connected"):
        table.status()
    table.close()                                   # closing twice is harmless
