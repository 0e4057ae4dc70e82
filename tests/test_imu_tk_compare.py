"""benchmarks/imu_tk_compare.py turns imu_tk's calibration (T K B per triad, its compensation in
its own accelerometer frame, m/s^2 and rad/s) into station's parameters: made from known station
parameters in a frame turned by a random rotation, it gives them back."""
import math
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import imu_tk_compare as cmp  # noqa: E402
from station.model.rotation import matrix_from_rotvec  # noqa: E402

ARCSEC = math.pi / 180 / 3600


def lower(angles):
    """station's unit-row lower-triangular sensing matrix from (yz, zy, zx) in rad."""
    yz, zy, zx = angles
    t = np.eye(3)
    t[1, :2] = math.sin(yz), math.cos(yz)
    t[2, 0], t[2, 1] = -math.sin(zy), math.sin(zx)
    t[2, 2] = math.sqrt(1 - t[2, 0] ** 2 - t[2, 1] ** 2)
    return t


def split(c):
    """imu_tk's T (unit diagonal) and K (diagonal) with T K = c."""
    return c / np.diag(c)[None, :], np.diag(np.diag(c))


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_imu_tk_in_any_frame_comes_back_as_station_parameters(seed):
    rng = np.random.default_rng(seed)
    truth = {f"accel_scale_{a}": v for a, v in zip("xyz", 414 + rng.normal(size=3))}
    truth |= {f"gyro_scale_{a}": v for a, v in zip("xyz", 83 + rng.normal(size=3))}
    for triad in ("accel", "gyro"):
        truth |= {f"{triad}_misalignment_{m}": v for m, v in zip(("yz", "zy", "zx"), rng.normal(0, 5000, 3))}
    truth |= {f"inter_triad_{a}": v for a, v in zip("xyz", rng.normal(0, 8000, 3))}
    truth |= {f"accel_bias_{a}": v for a, v in zip("xyz", 32768 + rng.normal(0, 500, 3))}
    truth |= {f"gyro_bias_{a}": v for a, v in zip("xyz", 32768 + rng.normal(0, 50, 3))}

    def vec(prefix, names="xyz"):
        return np.array([truth[f"{prefix}_{n}"] for n in names])

    A_p = np.diag(vec("accel_scale")) @ lower(vec("accel_misalignment", ("yz", "zy", "zx")) * ARCSEC)
    G_p = (np.diag(vec("gyro_scale")) @ lower(vec("gyro_misalignment", ("yz", "zy", "zx")) * ARCSEC)
           @ matrix_from_rotvec(vec("inter_triad") * ARCSEC))          # raw per deg/s, frame p
    R_bp = matrix_from_rotvec(rng.normal(size=3))                      # imu_tk's frame: any rotation of p
    C_a = np.linalg.inv(A_p @ R_bp.T)                                  # raw - B -> f_b, m/s^2
    C_g = np.linalg.inv(G_p * (180 / math.pi) @ R_bp.T)                # raw - B -> w_b, rad/s
    got = cmp.station_parameters((*split(C_a), vec("accel_bias")), (*split(C_g), vec("gyro_bias")))
    assert set(got) == set(truth)
    for name, value in truth.items():
        assert got[name] == pytest.approx(value, rel=1e-9, abs=1e-6), name


def test_read_triad_and_compare(tmp_path):
    path = tmp_path / "acc.calib"
    path.write_text("1 -0.0033593 -0.00890639\n0 1 -0.0213341\n-0 0 1\n\n"
                    "0.00241278 0 0\n0 0.00242712 0\n0 0 0.00241168\n\n33124.2\n33275.2\n32364.4\n")
    T, K, B = cmp.read_triad(path)
    assert T[0, 2] == -0.00890639 and K[1, 1] == 0.00242712 and B.tolist() == [33124.2, 33275.2, 32364.4]
    path.write_text("1 2 3\n")
    with pytest.raises(ValueError, match="21"):
        cmp.read_triad(path)
    rows = cmp.compare({"a": 1.5, "b": 2.0}, {"a": (1.0, 0.25), "c": (3.0, 1.0)})
    assert rows == [("a", 1.0, 0.25, 1.5, 2.0)]


def test_without_the_program_the_comparison_is_skipped_and_said(tmp_path, monkeypatch):
    monkeypatch.delenv("STATION_IMU_TK", raising=False)
    monkeypatch.delenv("STATION_IMU_TK_DATA", raising=False)
    assert cmp.find_imu_tk()[2].startswith("imu_tk's test_imu_calib not given")
    assert "not an executable file" in cmp.find_imu_tk(tmp_path / "nothing")[2]
    program = tmp_path / "bin" / "test_imu_calib"
    program.parent.mkdir()
    program.write_text("#!/bin/sh\n")
    program.chmod(0o755)
    assert "no xsens_acc.mat" in cmp.find_imu_tk(program)[2]
    (tmp_path / "bin" / "test_data").mkdir()
    for name in ("xsens_acc.mat", "xsens_gyro.mat"):
        (tmp_path / "bin" / "test_data" / name).write_text("0 1 2 3\n")
    assert cmp.find_imu_tk(program) == (program, tmp_path / "bin" / "test_data", "")
