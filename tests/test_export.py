"""station export: every format read back by its own tool (imucal) or by a faithful reader of
its documented format, giving the same compensated output as station's own compensation."""
import json
import math
import os
import shutil
import subprocess

import numpy as np
import pytest
import yaml

from station.cli import main
from station.io.calfile import read_calfile
from station.io.exporters import FORMATS, source_from_document
from station.model.compensate import compensate

TOL = 1e-9    # the bound; doubles written with repr round-trip exactly, so ~1e-14 remains


@pytest.fixture(scope="module")
def cal(optimal9_run):
    return optimal9_run / "calibration.yaml"


@pytest.fixture(scope="module")
def raw():
    """Raw samples around 1 g and up to 300 deg/s, in the capture's units (m/s^2, deg/s)."""
    rng = np.random.default_rng(5)
    return rng.normal(0.0, 6.0, (50, 3)), rng.normal(0.0, 150.0, (50, 3))


def station_output(cal_path, accel, gyro):
    comp = read_calfile(cal_path)["compensation"]
    return compensate(comp, np.arange(len(accel)) * 0.01, accel, gyro)


def no_gyro_source(cal_path):
    """The same calibration without its gyro block (an accelerometer-only calibration)."""
    doc = read_calfile(cal_path)
    for key in ("gyro_matrix", "gyro_bias"):
        del doc["compensation"][key]
    return source_from_document(doc, cal_path)


def test_imucal_reads_the_export_and_calibrates_the_same(cal, raw, tmp_path):
    from imucal.management import load_calibration_info

    target = tmp_path / "cal.json"
    assert main(["export", str(cal), "--to", "imucal", "-o", str(target)]) == 0
    info = load_calibration_info(target)
    assert type(info).__name__ == "TurntableCalibrationInfo"
    assert "convention" in info.comment
    acc, gyr = info.calibrate(raw[0], raw[1], acc_unit="m/s^2", gyr_unit="deg/s")
    f, w = station_output(cal, *raw)
    np.testing.assert_allclose(acc, f, rtol=0, atol=TOL)
    np.testing.assert_allclose(gyr, w, rtol=0, atol=TOL)


def test_imucal_export_of_an_accelerometer_only_calibration_passes_the_gyro_through(cal, raw, tmp_path):
    from imucal.management import load_calibration_info

    paths = FORMATS["imucal"].write(no_gyro_source(cal), tmp_path / "acc.json")
    info = load_calibration_info(paths[0])
    assert "gyro passed through" in info.comment
    acc, gyr = info.calibrate(raw[0], raw[1], acc_unit="m/s^2", gyr_unit="deg/s")
    np.testing.assert_allclose(acc, station_output(cal, *raw)[0], rtol=0, atol=TOL)
    np.testing.assert_array_equal(gyr, raw[1])


def read_imu_tk(path):
    """imu_tk's CalibratedTriad_::load: 21 whitespace-separated numbers (T, K row by row, B)."""
    numbers = [float(v) for v in path.read_text().split()[:21]]
    T = np.array(numbers[:9]).reshape(3, 3)
    K = np.array(numbers[9:18]).reshape(3, 3)
    return T, K, np.array(numbers[18:21])


def test_imu_tk_files_read_back_give_the_same_output(cal, raw, tmp_path):
    assert main(["export", str(cal), "--to", "imu_tk", "-o", str(tmp_path / "imu.calib")]) == 0
    f, w = station_output(cal, *raw)
    for name, x, expected in (("imu_acc.calib", raw[0], f), ("imu_gyro.calib", raw[1], w)):
        T, K, B = read_imu_tk(tmp_path / name)
        np.testing.assert_allclose(np.diag(T), 1.0, rtol=0, atol=1e-15)
        np.testing.assert_array_equal(K, np.diag(np.diag(K)))
        np.testing.assert_allclose((x - B) @ (T @ K).T, expected, rtol=0, atol=TOL)
        assert "convention" in (tmp_path / name).read_text()


def test_an_output_directory_gets_the_default_names_inside_it(cal, tmp_path, capsys):
    """-o DIR wrote imu_tk's pair next to DIR with DIR as the prefix (DIR_acc.calib) and the
    other formats failed on a directory: the default names now go inside it."""
    out = tmp_path / "exports"
    out.mkdir()
    for fmt in ("imu_tk", "json"):
        assert main(["export", str(cal), "--to", fmt, "-o", str(out)]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["calibration-imu_tk_acc.calib", "calibration-imu_tk_gyro.calib",
                                                     "calibration-json.json"]
    assert not list(tmp_path.glob("exports_*"))


def test_imu_tk_accelerometer_only_writes_one_file(cal, tmp_path):
    paths = FORMATS["imu_tk"].write(no_gyro_source(cal), tmp_path / "imu")
    assert [p.name for p in paths] == ["imu_acc.calib"]


def test_ros_imu_calib_yaml_read_back_gives_the_same_output(cal, raw, tmp_path):
    target = tmp_path / "imu_calib.yaml"
    assert main(["export", str(cal), "--to", "ros", "-o", str(target)]) == 0
    doc = yaml.safe_load(target.read_text())
    # imu_calib's loadCalib: SM row-major 3x3, bias 3; applyCalib: SM raw - bias (REP 103 units)
    SM, bias = np.array(doc["SM"]).reshape(3, 3), np.array(doc["bias"])
    gSM, gbias = np.array(doc["gyro_SM"]).reshape(3, 3), np.array(doc["gyro_bias"])
    f, w = station_output(cal, *raw)
    np.testing.assert_allclose(raw[0] @ SM.T - bias, f, rtol=0, atol=TOL)
    np.testing.assert_allclose(np.radians(raw[1]) @ gSM.T - gbias, np.radians(w), rtol=0, atol=TOL)
    assert "convention" in target.read_text()


def test_plain_json_read_back_gives_the_same_output(cal, raw, tmp_path):
    target = tmp_path / "cal.json"
    assert main(["export", str(cal), "--to", "json", "-o", str(target)]) == 0
    doc = json.loads(target.read_text())
    comp = {k: np.array(v) for k, v in doc["compensation"].items() if k.endswith(("matrix", "bias"))}
    f, w = station_output(cal, *raw)
    np.testing.assert_allclose((raw[0] - comp["accel_bias"]) @ comp["accel_matrix"].T, f, rtol=0, atol=TOL)
    np.testing.assert_allclose((raw[1] - comp["gyro_bias"]) @ comp["gyro_matrix"].T, w, rtol=0, atol=TOL)
    assert doc["parameters"]["accel_scale_x"]["unit"] == "1"
    assert "m/s^2" in doc["convention"]


C_PROGRAM = r"""
#include <stdio.h>
#include <math.h>
#include "station.h"
int main(void) {
    double a[3], g[3], o[3]; float af[3], of[3]; int32_t aq[3], oq[3];
    while (scanf("%lf %lf %lf %lf %lf %lf", &a[0], &a[1], &a[2], &g[0], &g[1], &g[2]) == 6) {
        station_accel_compensate(a, o);
        printf("%.17g %.17g %.17g ", o[0], o[1], o[2]);
        for (int i = 0; i < 3; ++i) af[i] = (float)a[i];
        station_accel_compensate_f(af, of);
        printf("%.9g %.9g %.9g ", of[0], of[1], of[2]);
        for (int i = 0; i < 3; ++i) aq[i] = (int32_t)llround(a[i] * (double)(1LL << STATION_ACCEL_INPUT_FRAC_BITS));
        station_accel_compensate_q(aq, oq);
        printf("%.17g %.17g %.17g ", oq[0] / (double)(1LL << STATION_ACCEL_INPUT_FRAC_BITS),
               oq[1] / (double)(1LL << STATION_ACCEL_INPUT_FRAC_BITS), oq[2] / (double)(1LL << STATION_ACCEL_INPUT_FRAC_BITS));
        station_gyro_compensate(g, o);
        printf("%.17g %.17g %.17g\n", o[0], o[1], o[2]);
    }
    return 0;
}
"""


@pytest.mark.skipif(shutil.which("cc") is None and os.environ.get("STATION_REQUIRE_CC") != "1",
                    reason="no C compiler (cc; Debian's gcc, README): .ci/run installs it and sets STATION_REQUIRE_CC=1")
def test_c_header_compiles_and_compensates_in_double_float_and_fixed_point(cal, raw, tmp_path):
    header = tmp_path / "station.h"
    assert main(["export", str(cal), "--to", "c", "-o", str(header)]) == 0
    (tmp_path / "main.c").write_text(C_PROGRAM)
    exe = tmp_path / "comp"
    subprocess.run(["cc", "-std=c99", "-Wall", "-Werror", "-O1", "-o", str(exe), str(tmp_path / "main.c"), "-lm"],
                   check=True, cwd=tmp_path)
    stdin = "\n".join(" ".join(repr(float(v)) for v in row) for row in np.hstack(raw))
    res = np.loadtxt(subprocess.run([str(exe)], input=stdin, capture_output=True, text=True, check=True)
                     .stdout.splitlines())
    f, w = station_output(cal, *raw)
    np.testing.assert_allclose(res[:, 0:3], f, rtol=0, atol=TOL)
    np.testing.assert_allclose(res[:, 9:12], w, rtol=0, atol=TOL)
    comp = read_calfile(cal)["compensation"]
    M, b = comp["accel_matrix"], comp["accel_bias"]
    # float: each input, bias and element rounded to float32 (relative 2^-24) and the products
    # and sums carried in float32: |error| <= 8 * 2^-24 * sum_j |M_ij| (|raw_j| + |b_j|)
    eps32 = 2.0**-24
    bound_f = 8 * eps32 * (np.abs(raw[0]) + np.abs(b)) @ np.abs(M).T
    assert np.all(np.abs(res[:, 3:6] - f) <= bound_f)
    # fixed point: M to 2^-(MF+1), raw and b to 2^-(IF+1) each, output rounded to 2^-(IF+1)
    mf = FORMATS["c"].matrix_frac_bits(M)
    inf = FORMATS["c"].input_frac_bits("m/s^2", b)
    bound_q = (2.0**-(mf + 1) * np.abs(raw[0] - b).sum(axis=1)[:, None]
               + 2 * 2.0**-(inf + 1) * np.abs(M).sum(axis=1)[None, :] + 2.0**-(inf + 1)) * 1.01
    assert np.all(np.abs(res[:, 6:9] - f) <= bound_q)
    text = header.read_text()
    assert "convention" in text and "STATION_HAS_GYRO 1" in text


def test_kalibr_needs_noise_figures_and_writes_them(cal, optimal9_run, tmp_path, capsys):
    target = tmp_path / "imu.yaml"
    assert main(["export", str(cal), "--to", "kalibr", "-o", str(target)]) == 2
    assert "station noise" in capsys.readouterr().err
    noise_cal = tmp_path / "cal.yaml"
    shutil.copy(cal, noise_cal)
    assert main(["noise", str(optimal9_run), "--cal", str(noise_cal), "--plot", str(tmp_path / "a.png")]) == 0
    assert main(["export", str(noise_cal), "--to", "kalibr", "-o", str(target)]) == 0
    doc = yaml.safe_load(target.read_text())
    kal = read_calfile(noise_cal)["noise"]["kalibr"]
    for key in ("accelerometer_noise_density", "accelerometer_random_walk", "gyroscope_noise_density",
                "gyroscope_random_walk", "update_rate"):
        assert doc[key] == kal[key]
    assert doc["rostopic"] == "/imu0" and doc["update_rate"] == 100.0
    # white-noise densities in SI from the simulated 100 ug/sqrt(Hz), 0.03 deg/h/sqrt(Hz): a 20 s
    # static (2000 samples) reads N to ~2 % (1 sigma), so 15 % is > 7 sigma of the largest axis
    assert doc["accelerometer_noise_density"] == pytest.approx(100e-6 * 9.80665, rel=0.15)
    assert doc["gyroscope_noise_density"] == pytest.approx(math.radians(0.03 / 3600), rel=0.15)


def test_every_format_states_its_convention(cal, tmp_path):
    source = source_from_document(read_calfile(cal), cal)
    source.noise = {"kalibr": {"accelerometer_noise_density": 1e-3, "accelerometer_random_walk": 1e-5,
                               "gyroscope_noise_density": 1e-6, "gyroscope_random_walk": 1e-8,
                               "update_rate": 100.0}}
    for name, mod in FORMATS.items():
        for path in mod.write(source, tmp_path / f"x{mod.SUFFIX}"):
            assert "convention" in path.read_text(), name


def test_export_refuses_a_file_that_is_not_a_calibration(tmp_path, capsys):
    bad = tmp_path / "bad.yaml"
    bad.write_text("format: something-else\n")
    assert main(["export", str(bad), "--to", "json"]) == 2
    assert "bad.yaml" in capsys.readouterr().err


from hypothesis import given, settings, strategies as st  # noqa: E402
from hypothesis.extra.numpy import arrays  # noqa: E402

from station.io.exporters.source import ExportSource  # noqa: E402

near_identity = arrays(float, (3, 3), elements=st.floats(-0.05, 0.05)).map(lambda d: np.eye(3) * 1.01 + d)
biases = arrays(float, (3,), elements=st.floats(-5.0, 5.0))


@settings(max_examples=40, deadline=None)
@given(M=near_identity, b=biases, G=near_identity, c=biases,
       units=st.sampled_from([("m/s^2", "deg/s"), ("g", "rad/s"), ("raw", "raw")]))
def test_any_calibration_round_trips_through_the_python_readable_formats(tmp_path_factory, M, b, G, c, units):
    """Random compensations (every raw unit): imucal, imu_tk and ROS read back give the same
    output as station's compensation within 1e-9 (relative to the output's size)."""
    from imucal.management import load_calibration_info

    tmp = tmp_path_factory.mktemp("h")
    src = ExportSource(M, b, G, c, units[0], units[1], "random")
    rng = np.random.default_rng(0)
    acc, gyr = rng.normal(0, 10, (5, 3)), rng.normal(0, 100, (5, 3))
    f, w = (acc - b) @ M.T, (gyr - c) @ G.T
    info = load_calibration_info(FORMATS["imucal"].write(src, tmp / "c.json")[0])
    a2, g2 = info.calibrate(acc, gyr, acc_unit=units[0], gyr_unit=units[1])
    np.testing.assert_allclose(a2, f, rtol=0, atol=TOL * 100)
    np.testing.assert_allclose(g2, w, rtol=0, atol=TOL * 1000)
    acc_file, gyro_file = FORMATS["imu_tk"].write(src, tmp / "t")
    T, K, B = read_imu_tk(acc_file)
    np.testing.assert_allclose((acc - B) @ (T @ K).T, f, rtol=0, atol=TOL * 100)
    doc = yaml.safe_load(FORMATS["ros"].write(src, tmp / "r.yaml")[0].read_text())
    u = {"m/s^2": 1.0, "g": 9.80665, "raw": 1.0}[units[0]]
    SM, bias = np.array(doc["SM"]).reshape(3, 3), np.array(doc["bias"])
    np.testing.assert_allclose((acc * u) @ SM.T - bias, f, rtol=0, atol=TOL * 100)


def test_a_singular_compensation_is_refused_in_one_line(cal, tmp_path, capsys):
    doc = yaml.safe_load(cal.read_text())
    doc["compensation"]["accel_matrix"] = [[1, 0, 0], [0, 0, 0], [0, 0, 1]]
    bad = tmp_path / "singular.yaml"
    bad.write_text(yaml.safe_dump(doc))
    assert main(["export", str(bad), "--to", "imucal"]) == 2
    err = capsys.readouterr().err
    assert "singular.yaml" in err and "accel_matrix" in err and len(err.strip().splitlines()) == 1
