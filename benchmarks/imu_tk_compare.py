"""station against imu_tk on imu_tk's own Xsens log (bin/test_data/xsens_acc.mat, xsens_gyro.mat):
the same parameters side by side, imu_tk's converted into station's convention (issue 27).

imu_tk is NOT a station dependency and is not built by this repository.  Build it yourself
(https://github.com/iralabdisco/imu_tk: Eigen3, Ceres, Qt, OpenGL, GLUT; BSD licence) and give
its `test_imu_calib` program and its test data:

    python benchmarks/imu_tk_compare.py --imu-tk BIN [--data DIR]      # or $STATION_IMU_TK(_DATA)

DIR defaults to BIN's folder's test_data/ (imu_tk's own layout: bin/test_imu_calib,
bin/test_data/).  Without the program the script says so and exits with status 0 (nothing run).

The two conventions (imu_tk/calibration.h; station/model/calibration.py):
  imu_tk   compensation X' = T K (X - B): T unit diagonal, K diagonal, B the raw bias; the
           accelerometers' T upper triangular (its "body" frame b: z along the z accelerometer's
           sensing axis, y in the y-z sensing plane), the gyros' T general (6 misalignments: the
           gyro triad's own and its rotation to b).  test_imu_calib's output is m/s^2 with
           g = 9.81744 and rad/s (its start, 1/6258 rad/s a count).  The gyro bias is the mean of
           the first 50 s at rest, not fitted (optimizeGyroBias false).
  station  forward model raw = K_a T_a f_p + b_a, raw = K_g T_g R_po w_p + b_g: K the scale
           (raw per m/s^2, raw per deg/s), T lower triangular with unit rows (frame p: x along the
           x accelerometer, y in the x-y sensing plane), R_po the inter-triad rotation.
The conversion: imu_tk's forward matrix A_b = (T K)^-1 maps f_b to raw - B.  Its LQ
factorisation A_b = L Q (L lower triangular with a positive diagonal, Q orthogonal) is station's
A_p = K_a T_a with Q = R_bp^T, R_bp the rotation from p to b (f_b = R_bp f_p): the scale
factors are the row norms (frame-free), the misalignments T's below-diagonal angles.  The gyro's
forward matrix in p is G_b R_bp = G_b Q^T (pi/180 per deg/s), whose LQ factorisation is
K_g T_g R_po.  The biases are raw counts in
both.  So every station parameter has an imu_tk counterpart, none is dropped or invented.
"""
from __future__ import annotations

import argparse
import math
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
GRAVITY = 9.81744           # test_imu_calib's setGravityMagnitude
ARCSEC = 180 / math.pi * 3600
AXES = "xyz"
MIS = ("yz", "zy", "zx")


def find_imu_tk(binary=None, data=None) -> tuple[Path | None, Path | None, str]:
    """(test_imu_calib, its test_data folder, why not) from the arguments or the environment."""
    binary = binary or os.environ.get("STATION_IMU_TK")
    if not binary:
        return None, None, "imu_tk's test_imu_calib not given (--imu-tk BIN or $STATION_IMU_TK)"
    binary = Path(binary)
    if not (binary.is_file() and os.access(binary, os.X_OK)):
        return None, None, f"{binary}: not an executable file (imu_tk's test_imu_calib)"
    data = Path(data or os.environ.get("STATION_IMU_TK_DATA") or binary.parent / "test_data")
    if not all((data / f).is_file() for f in ("xsens_acc.mat", "xsens_gyro.mat")):
        return None, None, f"{data}: no xsens_acc.mat and xsens_gyro.mat (imu_tk's bin/test_data: --data DIR)"
    return binary, data, ""


def run_imu_tk(binary: Path, data: Path, cwd: Path, **kw) -> subprocess.CompletedProcess:
    """test_imu_calib ACC GYRO in ``cwd`` (it writes test_imu_acc.calib, test_imu_gyro.calib
    there).  Its verbose output waits for Enter twice (waitForKey: getchar until a newline, an
    endless loop at end of input), so its standard input holds the newlines."""
    return subprocess.run([str(binary), str(data / "xsens_acc.mat"), str(data / "xsens_gyro.mat")], cwd=cwd,
                          input=b"\n" * 4, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, **kw)


def read_triad(path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(T, K, B) from an imu_tk .calib file: 21 numbers, T and K row by row, then B."""
    numbers = np.array(Path(path).read_text().split()[:21], dtype=float)
    if len(numbers) != 21:
        raise ValueError(f"{path}: {len(numbers)} numbers, an imu_tk calibration has 21")
    return numbers[:9].reshape(3, 3), numbers[9:18].reshape(3, 3), numbers[18:]


def lq(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """a = L Q: L lower triangular with a positive diagonal, Q orthogonal (QR of a's transpose)."""
    q, r = np.linalg.qr(a.T)
    d = np.sign(np.diag(r))
    return (r.T * d[None, :]), d[:, None] * q.T


def rotvec(r: np.ndarray) -> np.ndarray:
    """The rotation vector (rad) of a rotation matrix (angles below pi)."""
    angle = math.acos(max(-1.0, min(1.0, (np.trace(r) - 1) / 2)))
    axis = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
    return axis * (0.5 if angle < 1e-12 else angle / (2 * math.sin(angle)))


def station_parameters(acc, gyro, *, gyro_unit_rad: bool = True) -> dict:
    """imu_tk's two triads ((T, K, B) each, its compensation in m/s^2 and rad/s, or deg/s with
    gyro_unit_rad False) as station's parameters: name -> value in station's unit."""
    T, K, B = acc
    A_b = np.linalg.inv(T @ K)                   # raw - B = A_b f_b, raw per m/s^2
    A_p, Q = lq(A_b)                             # A_p = K_a T_a; Q = R_bp^T (f_b = R_bp f_p)
    scale = np.linalg.norm(A_p, axis=1)
    Ta = A_p / scale[:, None]
    out = {f"accel_scale_{a}": scale[i] for i, a in enumerate(AXES)}
    angles = (math.asin(Ta[1, 0]), -math.asin(Ta[2, 0]), math.asin(Ta[2, 1]))
    out |= {f"accel_misalignment_{m}": angles[i] * ARCSEC for i, m in enumerate(MIS)}
    Tg, Kg, Bg = gyro
    per_unit = math.pi / 180 if gyro_unit_rad else 1.0          # rad/s (or deg/s) per deg/s
    G_p = np.linalg.inv(Tg @ Kg) @ Q.T * per_unit    # raw - B_g = G_p w_p, raw per deg/s
    L, R_po = lq(G_p)
    gscale = np.linalg.norm(L, axis=1)
    Tgs = L / gscale[:, None]
    out |= {f"gyro_scale_{a}": gscale[i] for i, a in enumerate(AXES)}
    gangles = (math.asin(Tgs[1, 0]), -math.asin(Tgs[2, 0]), math.asin(Tgs[2, 1]))
    out |= {f"gyro_misalignment_{m}": gangles[i] * ARCSEC for i, m in enumerate(MIS)}
    out |= {f"accel_bias_{a}": B[i] for i, a in enumerate(AXES)}
    out |= {f"gyro_bias_{a}": Bg[i] for i, a in enumerate(AXES)}
    theta = rotvec(R_po)
    out |= {f"inter_triad_{a}": theta[i] * ARCSEC for i, a in enumerate(AXES)}
    return out


def station_calibration(cal_path) -> dict:
    """name -> (value, 1 sigma) of a station calibration file (the written parameters)."""
    import yaml

    doc = yaml.safe_load(Path(cal_path).read_text())
    return {name: (p["value"], p.get("sigma")) for name, p in doc["parameters"].items()}


def compare(theirs: dict, ours: dict) -> list[tuple]:
    """(name, station value, 1 sigma, imu_tk value, difference in station's sigma)."""
    rows = []
    for name, (value, sigma) in ours.items():
        if name in theirs:
            diff = (theirs[name] - value) / sigma if sigma else float("nan")
            rows.append((name, value, sigma, theirs[name], diff))
    return rows


def station_commands(data: Path, out: Path) -> list[list[str]]:
    """The import and the estimate of the same log (the gravity test_imu_calib uses)."""
    station = [sys.executable, "-P", "-c", "import sys; from station.cli import console_main; "
               "sys.argv[0] = 'station'; sys.exit(console_main())"]
    return [station + ["import", "csv", str(data / "xsens_acc.mat"), "--preset", "imu_tk", "--gyro-file",
                       str(data / "xsens_gyro.mat"), "--gravity-mps2", str(GRAVITY), "-o", str(out / "cap")],
            station + ["estimate", str(out / "cap"), "-o", str(out / "cal.yaml"), "--no-table"]]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--imu-tk", help="imu_tk's compiled test_imu_calib (or $STATION_IMU_TK)")
    ap.add_argument("--data", help="imu_tk's bin/test_data (or $STATION_IMU_TK_DATA)")
    args = ap.parse_args()
    binary, data, why = find_imu_tk(args.imu_tk, args.data)
    if binary is None:
        print(f"skipped: {why}")
        return 0
    with tempfile.TemporaryDirectory(prefix="imu-tk-compare-") as tmp:
        tmp = Path(tmp)
        r = run_imu_tk(binary, data, tmp, timeout=600)
        if r.returncode != 0:
            print(f"imu_tk's test_imu_calib exited with {r.returncode}: {r.stderr.decode(errors='replace')[-500:]}")
            return 1
        theirs = station_parameters(read_triad(tmp / "test_imu_acc.calib"), read_triad(tmp / "test_imu_gyro.calib"))
        env = dict(os.environ, PYTHONPATH=str(ROOT))
        for cmd in station_commands(data, tmp):
            r = subprocess.run(cmd, env=env, capture_output=True, text=True)
            if r.returncode not in (0, 3):
                print(f"{' '.join(cmd)}: exit {r.returncode}: {r.stderr[-500:]}")
                return 1
        ours = station_calibration(tmp / "cal.yaml")
        verdict = __import__("yaml").safe_load((tmp / "cal.yaml").read_text())["verdict"]
    print(f"station's fit: {verdict['result']}, reduced chi2 {verdict['reduced_chi2']:.3g} "
          "(its 1 sigma already scaled by sqrt(reduced chi2) when the fit fails)")
    print(f"\n{'parameter':24s} {'station':>16s} {'± 1σ':>10s} {'imu_tk':>16s} {'Δ/σ':>7s}")
    for name, value, sigma, other, diff in compare(theirs, ours):
        print(f"{name:24s} {value:16.6f} {sigma:10.4g} {other:16.6f} {diff:+7.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
