"""station.yaml: the example station init writes, one clear error per bad field, and the order
file < environment < flags."""
import argparse

import pytest
import yaml

from sim_devices.world import local_gravity
from station.cli import main
from station.cli.run import _config
from station.bench.config import EXAMPLE, Config, from_dict, load_config, normal_gravity, parse_config
from station.core.errors import UserError


def test_the_example_parses_and_round_trips(tmp_path):
    config = parse_config(yaml.safe_load(EXAMPLE), "station.yaml")
    assert config.imu.port == "/dev/ttyUSB0" and config.table.protocol == "acutrol"
    assert config.table.axis_list() == [[0, 0, 1], [1, 0, 0], [0, 1, 0]]
    assert config.table.axis_limits()[2].rate_accel_dps2 == 50
    assert config.site.gravity == pytest.approx(normal_gravity(45.0))
    back = from_dict(config.to_dict(), "run.yaml")
    assert back.source == "run.yaml"
    assert {**back.to_dict(), "source": None} == {**config.to_dict(), "source": None}


def test_normal_gravity_is_the_simulated_benchs():
    for lat, h in ((0.0, 0.0), (45.0, 0.0), (52.5, 350.0), (-80.0, 2000.0)):
        assert normal_gravity(lat, h) == pytest.approx(local_gravity(lat, h), abs=1e-12)


def test_init_writes_the_example_and_never_overwrites(tmp_path, capsys):
    path = tmp_path / "station.yaml"
    assert main(["init", str(path)]) == 0
    assert path.read_text() == EXAMPLE
    assert main(["init", str(path)]) == 2
    assert "already exists" in capsys.readouterr().err


@pytest.mark.parametrize("text, field", [
    ("imu: {prot: x}\n", "imu.prot"),
    ("table: {axes: 4}\n", "table.axes"),
    ("table: {limits: [{max_rate_dps: -3}]}\n", "table.limits[0].max_rate_dps"),
    ("table: {axes: 3, limits: [{}, {}]}\n", "table.limits"),
    ("table: {limits: [{max_rate_dps: 10, move_rate_dps: 60}]}\n", "table.limits[0]"),
    ("table: {limits: [{angle_min_deg: -10}]}\n", "table.limits[0]"),
    ("table: {mounting: [+x, +y, -z]}\n", "table.mounting"),
    ("table: {axes_enu: [[0, 0, 1], [0, 0, 0]]}\n", "table.axes_enu[1]"),
    ("table: {load_position_deg: [0, 0]}\n", "table.load_position_deg"),
    ("site: {latitude_deg: 91}\n", "site.latitude_deg"),
    ("site: {gravity_mps2: 1.0}\n", "site.gravity_mps2"),
    ("warmup: {temp_slope_c_per_h: 0.5}\n", "warmup.max_s"),
    ("run: {operator: maybe}\n", "run.operator"),
    ("imu: {serial: {parity: X}}\n", "imu.serial"),
    ("version: 2\n", "version"),
    ("colour: blue\n", "colour"),
])
def test_a_bad_field_is_one_error_naming_file_and_field(tmp_path, text, field):
    path = tmp_path / "station.yaml"
    path.write_text(text)
    with pytest.raises(UserError) as e:
        load_config(str(path), env={})
    assert str(e.value).startswith(f"{path}: field '{field}': ")
    assert "\n" not in str(e.value)


def test_not_yaml_names_the_file_and_line(tmp_path):
    path = tmp_path / "station.yaml"
    path.write_text("imu:\n  port: [unclosed\n")
    with pytest.raises(UserError, match=rf"{path}: not valid YAML \(line \d+\)"):
        load_config(str(path), env={})


def test_file_then_environment_then_flags(tmp_path, monkeypatch):
    path = tmp_path / "station.yaml"
    path.write_text("imu: {port: /dev/file-imu, protocol: csv}\ntable: {port: /dev/file-table}\n")
    config = load_config(str(path), env={"STATION_TABLE_PORT": "/dev/env-table"})
    assert (config.imu.port, config.imu.protocol, config.table.port) == ("/dev/file-imu", "csv", "/dev/env-table")

    monkeypatch.setenv("STATION_CONFIG", str(path))
    monkeypatch.setenv("STATION_IMU_PORT", "/dev/env-imu")
    args = argparse.Namespace(config=None, port=None, imu_protocol="vectornav", table_port="/dev/flag-table",
                              table_protocol=None, unattended=True)
    config = _config(args)
    assert config.source == str(path)
    assert (config.imu.port, config.imu.protocol) == ("/dev/env-imu", "vectornav")
    assert config.table.port == "/dev/flag-table" and config.run.operator is False
    assert Config().run.operator is True


def test_the_tables_poll_interval_has_a_floor():
    """table.poll_interval_s below 1 ms is refused in one message naming the field (a driver
    polling faster starved station run's own IMU reader on the twins: CI of the twenty-first
    session); 1 ms and the 10 ms default are taken."""
    with pytest.raises(UserError, match=r"field 'table.poll_interval_s': must be at least 0.001 s"):
        parse_config({"table": {"poll_interval_s": 0.0001}}, "station.yaml")
    assert parse_config({"table": {"poll_interval_s": 0.001}}, "station.yaml").table.poll_interval_s == 0.001
    assert parse_config({}, "station.yaml").table.poll_interval_s == 0.01
