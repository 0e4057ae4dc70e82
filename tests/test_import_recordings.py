"""Continuous recordings in (station import csv / rosbag) and the gyro calibrated from hand turns
of unknown angle between statics (station/estimate/hand_rotation.py, inside the least-squares
model), against simulated hand sessions with known truth (sim_devices/hand.py) and the imucal
recording in tests/data/imucal.

Tolerances.  Every estimated parameter is compared with the truth at 4.5 times its reported 1-sigma:
for 21 Gaussian errors the chance that any exceeds 4.5 sigma is 21 x 6.8e-6 = 1.4e-4, so a
failure means the estimate or its 1-sigma is wrong, not bad luck.  The 1-sigma itself is checked
by the reduced chi2 (within 3 standard deviations sqrt(2/dof) of 1) and by an upper bound that
the session must reach to be worth anything (gyro scale better than 0.2 %).
"""
import json
from pathlib import Path

import re

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from sim_devices.hand import hand_session
from sim_devices.truth import mems_truth
from station import cli
from station.core.errors import UserError
from station.estimate import choose_method, estimate_capture
from station.estimate.hand_rotation import HandRotation, Integrator
from station.io.capture import read_capture
from station.io.importers.rosbag import read_rosbag, write_imu_bag
from station.model.calibration import Calibration, parameter_errors
from station.simulate.dryrun import truth_calibration

DATA = Path(__file__).resolve().parent / "data" / "imucal"
COUNTS = (8 * 9.80665 / 32768, 1000.0 / 32768)      # +-8 g and +-1000 deg/s in 16 bits
SEED = 7


def session(seed=SEED, poses=16, dwell_s=(2.5, 3.5), **kw):
    truth = mems_truth(seed)
    return truth, hand_session(truth, seed, poses=poses, dwell_s=dwell_s, turn_s=(1.0, 1.8), **kw)


def write_csv(path, hs, *, columns="t", rad=False, delimiter=","):
    gyro = np.radians(hs.gyro) if rad else hs.gyro
    data = np.column_stack([hs.t, hs.accel, gyro]) if columns == "t" else np.column_stack([hs.accel, gyro])
    header = "t,ax,ay,az,gx,gy,gz" if columns == "t" else ""
    np.savetxt(path, data, delimiter=delimiter, header=header, comments="", fmt="%.10g")
    return path


def counts_truth(truth, counts) -> Calibration:
    t = truth_calibration(truth)
    return Calibration(accel_unit="raw", gyro_unit="raw", accel_scale=t.accel_scale / counts[0],
                       accel_T=t.accel_T, accel_bias=t.accel_bias / counts[0],
                       gyro_scale=t.gyro_scale / counts[1], gyro_T=t.gyro_T, gyro_bias=t.gyro_bias / counts[1],
                       R_po=t.R_po)


def check_against_truth(cal, truth_cal, *, k=4.5):
    dof = cal.fit["dof"]
    assert abs(cal.fit["reduced_chi2"] - 1.0) < 3 * np.sqrt(2.0 / dof), cal.fit["reduced_chi2"]
    assert cal.fit["hand_rotations"] > 0
    for name, _, true, err, unit in parameter_errors(cal, truth_cal):
        sigma = cal.sigma[name] / true * 1e6 if "_scale_" in name else cal.sigma[name]
        assert abs(err) <= k * sigma, (name, err, sigma, unit)
    for a in "xyz":
        assert cal.sigma[f"gyro_scale_{a}"] / truth_cal.gyro_scale["xyz".index(a)] < 2e-3


def statics_inside_truth(capture, hs):
    """Every static found lies inside one of the true still intervals (the time base is 0 at
    the first sample in both)."""
    dt = hs.t[1] - hs.t[0]
    found = capture.complete("static")
    for seg in found:
        first, last = int(round(seg.data.t[0] / dt)), int(round(seg.data.t[-1] / dt))
        assert any(a <= first and last < b for a, b in hs.statics), seg.name
    return len(found)


def test_integrator_follows_a_turn_with_a_wandering_axis():
    """A minimum-jerk turn of 150 deg with a 15-degree wobble, sampled at 100 Hz (rates at the
    sample instants, from the path's central difference): the integrated turn is within 5
    arcsec of the path's (measured 0.4-2.3), far below the angle noise a MEMS gyro adds over such
    a turn (20-90 arcsec); with a gyro matrix and bias, the turn is that of the compensated
    rates."""
    def path(t, T, phi, eps):
        tau = np.clip(t / T, 0.0, 1.0)
        s = tau**3 * (10 - 15 * tau + 6 * tau**2)
        return Rotation.from_rotvec(np.outer(s, phi)) * Rotation.from_rotvec(np.outer(np.sin(np.pi * tau) ** 2, eps))

    rng = np.random.default_rng(0)
    T, dt = 1.5, 0.01
    tk = (np.arange(150) + 0.5) * dt
    M, b = np.eye(3) + 0.01 * rng.normal(size=(3, 3)), rng.normal(size=3)
    hands, truths = [], []
    for k in range(4):
        phi = rng.normal(size=3)
        phi *= np.radians(150) / np.linalg.norm(phi)
        eps = np.radians(15) * rng.normal(size=3)
        w = np.degrees((path(tk - 1e-6, T, phi, eps).inv() * path(tk + 1e-6, T, phi, eps)).as_rotvec() / 2e-6)
        w = np.vstack([np.zeros((3, 3)), w, np.zeros((3, 3))])
        raw = w @ np.linalg.inv(M).T + b                  # what a gyro with matrix M^-1, bias b reads
        hands.append(HandRotation(f"t{k}", k, k + 1, raw, dt))
        truths.append(path(np.array([T]), T, phi, eps)[0])
    got = Rotation.from_matrix(Integrator(hands).turns(M, b))
    for i, true in enumerate(truths):
        assert (got[i] * true.inv()).magnitude() < np.radians(5.0 / 3600)


def test_csv_hand_session_gives_accel_and_gyro_within_their_sigma(tmp_path, capsys):
    truth, hs = session()
    log = write_csv(tmp_path / "log.csv", hs)
    out = tmp_path / "cap"
    assert cli.main(["import", "csv", str(log), "--preset", "station", "-o", str(out),
                     "--gravity-mps2", str(hs.truth["gravity_mps2"])]) == 0
    text = capsys.readouterr().out
    assert "found 16 static poses" in text and "15 turns" in text
    capture = read_capture(out)
    assert statics_inside_truth(capture, hs) == 16
    assert choose_method(capture) == "lsq"
    cal, _, prov = estimate_capture(out)
    assert prov["method"] == "lsq"
    check_against_truth(cal, truth_calibration(truth))
    # diagnose works on it: residuals of the hand turns are labelled
    assert cli.main(["diagnose", str(out), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert any(seg["name"] == "turn01" for seg in report["segments"])


def test_raw_counts_without_timestamps_and_with_earth_rate(tmp_path, capsys):
    """Raw 16-bit counts, no time column (rate given), no nominal scale: the thresholds come from
    the initial rest; the latitude is known, so the Earth rate is modelled."""
    truth, hs = session(seed=SEED + 1, counts=COUNTS)
    log = write_csv(tmp_path / "raw.txt", hs, columns="none", delimiter=";")
    out = tmp_path / "cap"
    assert cli.main(["import", "csv", str(log), "--columns", "ax=0,ay=1,az=2,gx=3,gy=4,gz=5",
                     "--accel-unit", "raw", "--gyro-unit", "raw", "--rate-hz", "100", "-o", str(out),
                     "--gravity-mps2", str(hs.truth["gravity_mps2"]), "--latitude-deg", "45"]) == 0
    text = capsys.readouterr().out
    assert "initial rest" in text and "found 16 static poses" in text
    capture = read_capture(out)
    assert statics_inside_truth(capture, hs) == 16
    cal, _, _ = estimate_capture(out)
    check_against_truth(cal, counts_truth(truth, COUNTS))
    # diagnose: the candidates whose gyro term cannot be sized without a nominal scale say so;
    # they do not stop the diagnosis (it exited 2 on them)
    capsys.readouterr()
    assert cli.main(["diagnose", str(out), "--json"]) == 0
    untestable = {c["effect"]: c for c in json.loads(capsys.readouterr().out)["candidates"]
                  if c["advice"].startswith("cannot be tested on this capture")}
    assert "gyro_g_sensitivity" in untestable and "nominal scale" in untestable["gyro_g_sensitivity"]["advice"]
    assert all(not c["significant"] and c["dof"] == 0 for c in untestable.values())
    # with the nominal scales declared: thresholds in physical units, the same fit
    out2 = tmp_path / "cap2"
    assert cli.main(["import", "csv", str(log), "--columns", "ax=0,ay=1,az=2,gx=3,gy=4,gz=5",
                     "--accel-unit", "raw", "--gyro-unit", "raw", "--accel-nominal", str(COUNTS[0]),
                     "--gyro-nominal", str(COUNTS[1]), "--rate-hz", "100", "-o", str(out2),
                     "--gravity-mps2", str(hs.truth["gravity_mps2"]), "--latitude-deg", "45"]) == 0
    text = capsys.readouterr().out
    assert "|rate - bias| <= 1 deg/s" in text and "static |f| = " in text, text
    assert read_capture(out2).imu.extra["gyro_nominal_dps_per_count"] == COUNTS[1]


def test_ros_bags_ros1_db3_mcap(tmp_path, capsys):
    truth, hs = session(seed=SEED + 2)
    recs = {}
    for fmt, name in (("rosbag1", "s.bag"), ("sqlite3", "s_db3"), ("mcap", "s_mcap")):
        write_imu_bag(tmp_path / name, hs.t, hs.accel, np.radians(hs.gyro), fmt=fmt)
        recs[fmt] = read_rosbag(tmp_path / name)
    for rec in recs.values():
        np.testing.assert_allclose(rec.t, hs.t, atol=1e-9)
        np.testing.assert_allclose(rec.gyro, np.radians(hs.gyro), rtol=1e-15)
        assert rec.gyro_unit == "rad/s" and rec.accel_unit == "m/s^2"
    out = tmp_path / "cap"
    assert cli.main(["import", "rosbag", str(tmp_path / "s_mcap"), "-o", str(out),
                     "--gravity-mps2", str(hs.truth["gravity_mps2"])]) == 0
    assert "found 16 static poses" in capsys.readouterr().out
    cal, _, _ = estimate_capture(out)
    check_against_truth(cal, truth_calibration(truth))
    # two Imu topics: the user must choose
    write_imu_bag(tmp_path / "two.bag", hs.t[:50], hs.accel[:50], hs.gyro[:50], fmt="rosbag1")
    with pytest.raises(UserError, match=r"no sensor_msgs/msg/Imu topic /other \(Imu topics: /imu/data\)"):
        read_rosbag(tmp_path / "two.bag", topic="/other")


def test_imu_tk_pair_and_segments_file(tmp_path, capsys):
    truth, hs = session(seed=SEED + 3, poses=10)
    acc, gyr = tmp_path / "acc.txt", tmp_path / "gyr.txt"
    np.savetxt(acc, np.column_stack([hs.t, hs.accel]), fmt="%.10g")
    np.savetxt(gyr, np.column_stack([hs.t, np.radians(hs.gyro)]), fmt="%.10g")
    out = tmp_path / "cap"
    assert cli.main(["import", "csv", str(acc), "--preset", "imu_tk", "--gyro-file", str(gyr),
                     "-o", str(out)]) == 0
    assert "found 10 static poses" in capsys.readouterr().out
    # the same sections given by hand: the true still intervals
    sections = [{"name": f"p{k}", "kind": "static", "start": int(a), "end": int(b)} for k, (a, b) in enumerate(hs.statics)]
    sections += [{"name": f"r{k}", "kind": "rotation", "start": int(hs.statics[k][1]), "end": int(hs.statics[k + 1][0])}
                 for k in range(len(hs.statics) - 1)]
    seg_file = tmp_path / "sections.yaml"
    seg_file.write_text(json.dumps(sections))
    out2 = tmp_path / "cap2"
    assert cli.main(["import", "csv", str(acc), "--preset", "imu_tk", "--gyro-file", str(gyr),
                     "--segments", str(seg_file), "-o", str(out2)]) == 0
    capture = read_capture(out2)
    assert [s.name for s in capture.complete("static")] == [f"p{k}" for k in range(10)]
    assert len(capture.complete("rotation")) == 9
    cal, _, _ = estimate_capture(out2)
    assert cal.fit["hand_rotations"] == 9


@pytest.mark.skipif(not DATA.exists(), reason="tests/data/imucal not present")
def test_imucal_session_by_the_csv_importer_agrees_with_imucal(tmp_path, capsys):
    out = tmp_path / "cap"
    assert cli.main(["import", "csv", str(DATA / "example_ferraris_session.csv"), "--preset", "imucal",
                     "--rate-hz", "102.4", "--gravity-mps2", "9.81", "-o", str(out)]) == 0
    assert "found 13 static poses" in capsys.readouterr().out
    # its estimate against imucal's published result: tests/test_solver.py::
    # test_a_creeping_estimate_imports_no_scipy[csv-preset-imucal] (the same import and estimate,
    # in a fresh process that also shows it imports no scipy: the suite estimates it once)


# --- bad input: one line, exit 2 ------------------------------------------------------------------

def run_bad(argv, capsys, *patterns):
    assert cli.main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "Traceback" not in err, err
    for p in patterns:
        assert p in err, err
    return err


def test_bad_recordings_say_what_is_wrong(tmp_path, capsys):
    truth, hs = session(seed=SEED + 4, poses=12)
    good = write_csv(tmp_path / "good.csv", hs)
    base = ["import", "csv"]
    # no statics: a recording that never rests for long (turn after turn, 0.3-0.6 s pauses)
    _, tumble = session(seed=SEED + 6, poses=30, dwell_s=(0.3, 0.6), init_rest_s=0.5)
    write_csv(tmp_path / "moving.csv", tumble)
    run_bad(base + [str(tmp_path / "moving.csv"), "-o", str(tmp_path / "o1")], capsys, "no static pose found",
            "--segments")
    # too few poses
    _, few = session(seed=SEED + 5, poses=5)
    write_csv(tmp_path / "few.csv", few)
    run_bad(base + [str(tmp_path / "few.csv"), "-o", str(tmp_path / "o2")], capsys, "5 static pose(s) found",
            "at least 9")
    # wrong units: accelerometer in g declared m/s^2; gyro in rad/s declared deg/s
    g = hs.accel / 9.80665
    np.savetxt(tmp_path / "g.csv", np.column_stack([hs.t, g, hs.gyro]), delimiter=",",
               header="t,ax,ay,az,gx,gy,gz", comments="")
    run_bad(base + [str(tmp_path / "g.csv"), "-o", str(tmp_path / "o3")], capsys, "far from gravity",
            "declare --accel-unit g")
    write_csv(tmp_path / "rad.csv", hs, rad=True)
    run_bad(base + [str(tmp_path / "rad.csv"), "-o", str(tmp_path / "o4")], capsys, "gyro unit", "rad/s?")
    run_bad(base + [str(good), "--gyro-unit", "rad/s", "-o", str(tmp_path / "o12")], capsys,
            "the gyro reads", "no gyro reads that at rest", "are the rates in deg/s?")
    # NaN, a gap in time, time going back
    lines = good.read_text().splitlines()
    nan = lines[:]
    nan[100] = ",".join(nan[100].split(",")[:4] + ["nan"] + nan[100].split(",")[5:])
    (tmp_path / "nan.csv").write_text("\n".join(nan) + "\n")
    run_bad(base + [str(tmp_path / "nan.csv"), "-o", str(tmp_path / "o5")], capsys, "line 101", "column 'gx'",
            "not finite")
    gap = lines[:200] + lines[260:]
    (tmp_path / "gap.csv").write_text("\n".join(gap) + "\n")
    run_bad(base + [str(tmp_path / "gap.csv"), "-o", str(tmp_path / "o6")], capsys, "line 201", "gap in time",
            "60 samples lost")
    back = lines[:]
    back[300], back[301] = back[301], back[300]
    (tmp_path / "back.csv").write_text("\n".join(back) + "\n")
    run_bad(base + [str(tmp_path / "back.csv"), "-o", str(tmp_path / "o7")], capsys, "line 302",
            "time does not increase")
    # a missing column, a field count that changes, a bad sections file, a file that is no bag
    run_bad(base + [str(good), "--columns", "t=t,ax=ax,ay=ay,az=nope,gx=gx,gy=gy,gz=gz", "-o", str(tmp_path / "o8")],
            capsys, "no column 'nope'")
    short = lines[:]
    short[50] = ",".join(short[50].split(",")[:5])
    (tmp_path / "short.csv").write_text("\n".join(short) + "\n")
    run_bad(base + [str(tmp_path / "short.csv"), "-o", str(tmp_path / "o9")], capsys, "line 51", "5 fields")
    (tmp_path / "s.yaml").write_text("- {name: a, kind: static, start: 0, end: 999999}\n")
    run_bad(base + [str(good), "--segments", str(tmp_path / "s.yaml"), "-o", str(tmp_path / "o10")], capsys,
            "section 1 (a)", "outside the recording")
    (tmp_path / "nobag.bag").write_bytes(b"not a bag at all")
    run_bad(["import", "rosbag", str(tmp_path / "nobag.bag"), "-o", str(tmp_path / "o11")], capsys,
            "not a readable ROS bag")
    assert not any((tmp_path / f"o{k}").exists() for k in range(1, 13))


def test_offset_binary_counts_with_and_without_nominal_scales(tmp_path, capsys):
    """Unsigned 16-bit counts centred on 32768 (imu_tk's own sample, many ADC logs): with the
    nominal scales the unit checks measure |f| about the offset the statics are centred on (a
    sphere through the pose means), not about zero (it said "the unit is wrong" with raw
    declared); without them nothing is assumed.  The fit takes the offset as the bias; every
    stored noise figure is in the unit it is labelled with (micro-g, deg/h), not counts."""
    truth, hs = session(seed=SEED + 3, counts=COUNTS)
    hs.accel = hs.accel + 32768.0
    hs.gyro = hs.gyro + 32768.0
    assert hs.accel.min() >= 0 and hs.accel.max() < 65536
    log = write_csv(tmp_path / "u16.txt", hs, columns="none", delimiter=" ")
    expected = counts_truth(truth, COUNTS)
    expected.accel_bias = expected.accel_bias + 32768.0
    expected.gyro_bias = expected.gyro_bias + 32768.0
    for nominal in ([], ["--accel-nominal", str(COUNTS[0]), "--gyro-nominal", str(COUNTS[1])]):
        out = tmp_path / ("nominal" if nominal else "plain")
        code = cli.main(["import", "csv", str(log), "--columns", "ax=0,ay=1,az=2,gx=3,gy=4,gz=5",
                         "--accel-unit", "raw", "--gyro-unit", "raw", *nominal, "--rate-hz", "100", "-o",
                         str(out), "--gravity-mps2", str(hs.truth["gravity_mps2"]), "--latitude-deg", "45"])
        text = capsys.readouterr()
        assert code == 0, text.err
        if nominal:
            assert "static |f| = " in text.out and "about the statics' centre" in text.out, text.out
        cal, _, _ = estimate_capture(out)
        check_against_truth(cal, expected)
        noise = cal.fit["noise_per_sample"]
        # the simulated MEMS noise per sample with the quantisation's LSB^2/12, in micro-g and
        # deg/h (not counts: one count is 244 micro-g and 110 deg/h), within a factor 2
        accel_ug = np.array(noise["accel_ug"])
        gyro_dph = np.array(noise["gyro_dph"])
        lsb_ug, lsb_dph = COUNTS[0] / 9.80665e-6, COUNTS[1] * 3600
        true_accel_ug = np.hypot(truth.accel_noise_sigma / 9.80665e-6, lsb_ug / np.sqrt(12))
        true_gyro_dph = np.hypot(truth.gyro_noise_sigma * 3600, lsb_dph / np.sqrt(12))
        assert np.all(np.abs(np.log(accel_ug / true_accel_ug)) < np.log(2)), (accel_ug, true_accel_ug)
        assert np.all(np.abs(np.log(gyro_dph / true_gyro_dph)) < np.log(2)), (gyro_dph, true_gyro_dph)


def test_offset_binary_counts_with_too_few_poses_say_so_in_one_line(tmp_path, capsys):
    """Three poses of offset-binary counts with nominal scales: the offset cannot be placed,
    |f| is not checked (it raised UnboundLocalError), and the importer's own refusal of too few
    poses is the one line, exit 2."""
    truth, hs = session(seed=9, counts=COUNTS, poses=3)
    hs.accel = hs.accel + 32768.0
    hs.gyro = hs.gyro + 32768.0
    log = write_csv(tmp_path / "u16.txt", hs, columns="none", delimiter=" ")
    assert cli.main(["import", "csv", str(log), "--columns", "ax=0,ay=1,az=2,gx=3,gy=4,gz=5",
                     "--accel-unit", "raw", "--gyro-unit", "raw", "--accel-nominal", str(COUNTS[0]),
                     "--gyro-nominal", str(COUNTS[1]), "--rate-hz", "100", "-o", str(tmp_path / "c")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "3 static pose(s) found" in err


def test_a_bag_stamped_at_receive_time_is_re_timed_with_rate_hz(tmp_path, capsys):
    """A driver that stamps at receive time: the stamps jitter by the transport (here uniform
    ±4 ms at 100 Hz) and the import calls the wider steps lost samples; `--rate-hz 100` re-times
    the messages evenly after checking that their stamps span the count at 100 Hz (to 1 %), and
    refuses when a message was lost (it would shift every later sample), naming both spans."""
    truth, hs = session()
    rng = np.random.default_rng(4)
    stamped = hs.t + rng.uniform(-0.004, 0.004, len(hs.t))
    stamped[1:-1] = np.maximum.accumulate(stamped[1:-1])
    order = np.argsort(stamped)
    bag = write_imu_bag(tmp_path / "rx", stamped[order], hs.accel, np.radians(hs.gyro), fmt="mcap")
    common = ["--gravity-mps2", str(hs.truth["gravity_mps2"])]
    code = cli.main(["import", "rosbag", str(bag), "-o", str(tmp_path / "even"), "--rate-hz", "100", *common])
    assert code == 0, capsys.readouterr().err
    cal, _, _ = estimate_capture(tmp_path / "even")
    check_against_truth(cal, truth_calibration(truth))
    lost = write_imu_bag(tmp_path / "lost", np.delete(stamped, 3000), np.delete(hs.accel, 3000, axis=0),
                         np.radians(np.delete(hs.gyro, 3000, axis=0)), fmt="mcap")
    capsys.readouterr()
    assert cli.main(["import", "rosbag", str(lost), "-o", str(tmp_path / "x"), "--rate-hz", "100", *common]) == 2
    assert "a message was lost" in capsys.readouterr().err
    with pytest.raises(UserError) as e:
        read_rosbag(lost, rate_hz=100.0)
    m = re.search(r"--rate-hz 100: the stamps step by \+(\S+) ms .* near message (\d+)", str(e.value))
    # one period, 10 ms, measured by two medians of 51 jittered stamps (uniform +-4 ms: the
    # difference's 1-sigma about 1 ms): within 3 sigma; the block next to the loss at message 3001
    assert m and abs(float(m.group(1)) - 10.0) < 3.0 and abs(int(m.group(2)) - 3001) <= 2 * 51, str(e.value)
    # a rate that is not the bag's: its stamps' span disagrees with the count
    assert cli.main(["import", "rosbag", str(bag), "-o", str(tmp_path / "y"), "--rate-hz", "98", *common]) == 2
    err = capsys.readouterr().err
    assert "messages were lost or the rate is not 98 Hz" in err and "Traceback" not in err
