"""A calibration never lies (issue 11): the fit verdict and exit status 3, honest 1-sigma,
parameters the capture cannot determine left out, large inter-triad rotations named, the IMU's
serial checked by apply and diagnose --calib."""
import hashlib

import numpy as np
import pytest
import yaml

from station.cli import main
from station.io.calfile import read_calfile
from station.io.capture import read_capture, read_segment_csv
from station.io.scheme import scheme_from_text
from station.simulate import dryrun
from simhelpers import THREE_ROTATIONS, scheme_yaml

STATICS = scheme_yaml("statics9", 10.0, rotations=False, title="nine static attitudes, no rotation")
ROTATIONS = THREE_ROTATIONS


def record(text, directory, seed=3):
    scheme = scheme_from_text(text, "test scheme")
    return dryrun.record_scheme(scheme, dryrun.load_truth(None, seed), seed, directory)


@pytest.fixture(scope="module")
def statics_only(tmp_path_factory):
    return record(STATICS, tmp_path_factory.mktemp("statics") / "cap")


@pytest.fixture(scope="module")
def with_rotations(tmp_path_factory):
    return record(STATICS + ROTATIONS, tmp_path_factory.mktemp("rot") / "cap")


def edit_manifest(capture, change):
    path = capture / "manifest.yaml"
    doc = yaml.safe_load(path.read_text())
    change(doc)
    path.write_text(yaml.safe_dump(doc, sort_keys=False))


def rewrite_csv(capture, name, change):
    """Change the columns of one segment's CSV and keep the manifest's sha256 true."""
    doc = yaml.safe_load((capture / "manifest.yaml").read_text())
    entry = next(e for e in doc["segments"] if e["name"] == name)
    path = capture / entry["file"]
    header = path.read_text().splitlines()[0].split(",")
    table = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    change(table, header)
    text = ",".join(header) + "\n" + "".join(",".join(f"{v:.15g}" for v in row) + "\n" for row in table)
    path.write_text(text)
    entry["sha256"] = hashlib.sha256(text.encode()).hexdigest()
    (capture / "manifest.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))


def copy_capture(src, dst):
    import shutil

    shutil.copytree(src, dst)
    (dst / "calibration.yaml").unlink(missing_ok=True)
    return dst


# ------------------------------------------------------------------ identifiability

@pytest.mark.parametrize("latitude", [True, False])
def test_statics_only_gives_an_accelerometer_only_calibration(statics_only, tmp_path, capsys, latitude):
    cap = copy_capture(statics_only, tmp_path / "cap")
    if not latitude:       # hand-placed poses at an unknown place: only |Earth rate| is known
        edit_manifest(cap, lambda d: d["site"].pop("latitude_deg"))
    assert main(["estimate", str(cap)]) == 0
    doc = read_calfile(cap / "calibration.yaml")
    assert doc["gyro_pass_through"] is True
    assert not [n for n in doc["parameters"] if n.startswith(("gyro", "inter_triad"))]
    assert {f"accel_scale_{a}" for a in "xyz"} <= set(doc["parameters"])
    assert doc["effects"] == ["base_triads"]
    assert "accelerometer-only calibration" in capsys.readouterr().err
    # and every estimated accelerometer parameter is written with a finite 1-sigma
    assert all(np.isfinite(p["sigma"]) for p in doc["parameters"].values())


@pytest.mark.parametrize("effect", ["accel_nonlinearity", "temperature_bias", "accel_lever_arm"])
def test_statics_only_with_an_added_effect_is_not_a_traceback(statics_only, tmp_path, effect):
    cap = copy_capture(statics_only, tmp_path / "cap")
    edit_manifest(cap, lambda d: d["site"].pop("latitude_deg"))
    assert main(["estimate", str(cap), "--add", effect]) in (0, 2)


def test_apply_passes_the_gyro_through_untouched(statics_only, tmp_path, capsys):
    cap = copy_capture(statics_only, tmp_path / "cap")
    assert main(["estimate", str(cap)]) == 0
    out = tmp_path / "out.csv"
    assert main(["apply", str(cap / "calibration.yaml"), str(cap / "pos05.csv"), "-o", str(out)]) == 0
    assert "passed through untouched" in capsys.readouterr().err
    raw, done = read_segment_csv(cap / "pos05.csv"), read_segment_csv(out)
    np.testing.assert_array_equal(done.gyro, raw.gyro)
    # the accelerometers are compensated: |f| is local gravity within the noise of one sample
    g = read_capture(cap, load_data=False).site.gravity_mps2
    assert abs(np.linalg.norm(done.accel.mean(axis=0)) - g) < 1e-3


def test_a_rotation_axis_left_out_leaves_the_inter_triad_rotation_undetermined(tmp_path, capsys):
    cap = record(STATICS + "  - {rotation: rotz, axis_body: [0, 0, 1]}\n", tmp_path / "cap")
    # without the latitude the statics give only |Earth rate|: nothing fixes the rotation of the
    # gyro triad about the one turning axis (a zero singular value of the fit, whose
    # pseudo-inverse would report a 1-sigma of zero)
    edit_manifest(cap, lambda d: d["site"].pop("latitude_deg"))
    assert main(["estimate", str(cap)]) == 0
    doc = read_calfile(cap / "calibration.yaml")
    err = capsys.readouterr().err
    assert "inter_triad_z" not in doc["parameters"] and "inter_triad" not in doc["effects"]
    assert "gyro_scale_z" in doc["parameters"]
    assert "inter-triad rotation is not determined" in err


# ------------------------------------------------------------------ verdict and exit status

def test_a_good_fit_passes_and_says_so(with_rotations, capsys):
    assert main(["estimate", str(with_rotations)]) == 0
    doc = read_calfile(with_rotations / "calibration.yaml")
    v = doc["verdict"]
    assert v["result"] == "passes" and 0 < v["p_value"] <= 1 and v["dof"] > 0
    assert "sigma_scale" not in doc["fit"]
    assert "fit passes" in capsys.readouterr().out


def test_a_failing_fit_exits_3_widens_sigma_and_says_why(with_rotations, tmp_path, capsys):
    cap = copy_capture(with_rotations, tmp_path / "cap")
    good = tmp_path / "good.yaml"
    assert main(["estimate", str(with_rotations), "-o", str(good)]) == 0

    def stretch(d):    # the encoder angle of one turn 0.5 % off: a table that slipped
        seg = next(s for s in d["segments"] if s["name"] == "rotz_p")
        seg["angle_deg"] *= 1.005
    edit_manifest(cap, stretch)
    capsys.readouterr()
    assert main(["estimate", str(cap)]) == 3
    captured = capsys.readouterr()
    assert "fit fails" in captured.out and "exit status 3" in captured.err
    doc = read_calfile(cap / "calibration.yaml")
    fit = doc["fit"]
    assert doc["verdict"]["result"] == "fails" and doc["verdict"]["p_value"] < 1e-3
    assert fit["sigma_scale"] == pytest.approx(np.sqrt(doc["verdict"]["reduced_chi2"]))   # on the data's redundancy
    assert any("sqrt(reduced chi2)" in n for n in fit["notes"])
    # the 1-sigma written is the fit's own times sqrt(reduced chi2): compare with the good fit's
    # covariance, which does not depend on the data's residuals at the same Jacobian to 1 %
    # (the gyro's: the slipped turn bends the joint fit's accelerometers, so those written are
    # the poses' own, with their own 1-sigma, and the rotations are named: station/estimate/poses.py)
    g = read_calfile(good)["parameters"]["gyro_bias_x"]["sigma"]
    assert doc["parameters"]["gyro_bias_x"]["sigma"] == pytest.approx(g * fit["sigma_scale"], rel=0.05)
    assert fit["pose_check"]["result"] == "disagree" and fit["pose_check"]["pulling"] == "rotations"
    assert "rotz_p" in [s["segment"] for s in fit["pose_check"]["pulling_segments"]]
    assert main(["estimate", str(cap), "--accept-poor-fit"]) == 0


def test_run_prints_the_verdict(tmp_path, capsys):
    scheme = tmp_path / "s.yaml"
    scheme.write_text(STATICS + ROTATIONS)
    assert main(["run", "--scheme", str(scheme), "--sim", "--out", str(tmp_path / "cap")]) == 0
    out = capsys.readouterr().out
    assert "fit passes" in out and "chi2" in out


def test_inverted_gyro_axes_are_named_in_words(with_rotations, tmp_path, capsys):
    cap = copy_capture(with_rotations, tmp_path / "cap")
    doc = yaml.safe_load((cap / "manifest.yaml").read_text())

    def invert(table, header):     # gyro x and y wired with the opposite sign: 180 deg about z
        for col in ("gx", "gy"):
            table[:, header.index(col)] *= -1
    for seg in doc["segments"]:
        rewrite_csv(cap, seg["name"], invert)
    main(["estimate", str(cap)])
    err = capsys.readouterr().err
    assert "inverted" in err and ("180" in err or "179" in err), err


# ------------------------------------------------------------------ IMU identity

def test_apply_and_diagnose_refuse_a_calibration_of_another_serial(with_rotations, tmp_path, capsys):
    cal = tmp_path / "cal.yaml"
    assert main(["estimate", str(with_rotations), "-o", str(cal)]) == 0
    assert read_calfile(cal)["imu"]["serial"] == "SIM-3"
    other = copy_capture(with_rotations, tmp_path / "other")
    edit_manifest(other, lambda d: d["imu"].update(serial="SIM-99"))
    out = tmp_path / "o.csv"
    capsys.readouterr()
    assert main(["apply", str(cal), str(other / "pos01.csv"), "-o", str(out)]) == 2
    assert "SIM-3" in capsys.readouterr().err
    assert main(["apply", str(cal), str(other / "pos01.csv"), "-o", str(out), "--force"]) == 0
    assert main(["apply", str(cal), str(tmp_path / "o.csv"), "-o", str(out), "--serial", "X1"]) == 2
    assert main(["apply", str(cal), str(with_rotations / "pos01.csv"), "-o", str(out)]) == 0
    assert main(["diagnose", str(other), "--calib", str(cal)]) == 2
    assert main(["diagnose", str(other), "--calib", str(cal), "--force"]) == 0


# ------------------------------------------------------------------ data loss

def test_a_segment_over_the_data_loss_limits_is_excluded_with_a_note(with_rotations, tmp_path, capsys):
    cap = copy_capture(with_rotations, tmp_path / "cap")
    # 1.5 s of frames missing in the middle of pos03 (an IMU stall): longest gap above 1 s
    rewrite_csv(cap, "pos03", lambda table, header: None)
    doc = yaml.safe_load((cap / "manifest.yaml").read_text())
    entry = next(e for e in doc["segments"] if e["name"] == "pos03")
    lines = (cap / entry["file"]).read_text().splitlines(keepends=True)
    text = "".join(lines[:300] + lines[450:])
    (cap / entry["file"]).write_text(text)
    entry["sha256"], entry["samples"] = hashlib.sha256(text.encode()).hexdigest(), len(lines) - 1 - 150
    (cap / "manifest.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
    assert main(["estimate", str(cap)]) == 0
    fit = read_calfile(cap / "calibration.yaml")["fit"]
    assert fit["excluded_segments"] == ["pos03"] and fit["static_segments"] == 8
    assert "segment pos03 excluded: 150 frames missing" in capsys.readouterr().err
    # with a looser limit it is used
    assert main(["estimate", str(cap), "--max-gap-s", "2", "--max-missing-fraction", "0.2"]) == 0
    assert read_calfile(cap / "calibration.yaml")["fit"]["static_segments"] == 9


def test_an_accelerometer_only_calibration_writes_no_gyro_calibration_anywhere(statics_only, tmp_path, capsys):
    """Its exports carry no gyro block (the unit factor read_calfile passes the gyro through with
    is no calibration: a raw gyro's was 1, counts taken for deg/s), and apply refuses a raw gyro
    it has no scale for instead of writing counts under deg/s."""
    import yaml

    from station.io.exporters import source_from_document

    cap = copy_capture(statics_only, tmp_path / "cap")
    assert main(["estimate", str(cap)]) == 0
    cal = cap / "calibration.yaml"
    assert source_from_document(read_calfile(cal), cal).has_gyro is False
    capsys.readouterr()
    assert main(["export", str(cal), "--to", "ros", "-o", str(tmp_path / "ros.yaml")]) == 0
    assert "gyro block is absent" in capsys.readouterr().err
    doc = yaml.safe_load(cal.read_text())
    doc["imu"]["gyro_unit"] = "raw"
    raw_cal = tmp_path / "raw.yaml"
    raw_cal.write_text(yaml.safe_dump(doc, sort_keys=False))
    assert main(["apply", str(raw_cal), str(cap / "pos05.csv"), "-o", str(tmp_path / "out.csv")]) == 2
    assert "no scale to write the gyros in deg/s" in capsys.readouterr().err
    assert not (tmp_path / "out.csv").exists()


def test_frames_missing_are_counted_from_the_span_not_from_jittering_steps():
    """Stamps that jitter by up to ±0.3 period (host time stamps) lose no frame, though some
    steps reach 1.6 periods; frames really dropped are counted through the jitter; a device 1-4 %
    off its stated rate loses nothing, its stamps jittering or not; every other frame dropped is
    half lost."""
    from types import SimpleNamespace

    from station.estimate import data_loss

    rate, n = 100.0, 20_000
    rng = np.random.default_rng(5)
    jitter = rng.uniform(-0.3, 0.3, n) / rate

    def loss(t):
        return data_loss(SimpleNamespace(data=SimpleNamespace(t=t)), rate)

    exact = np.arange(n) / rate
    assert np.diff(exact + jitter).max() > 1.5 / rate          # the old step-by-step count saw losses
    assert loss(exact + jitter)[0] == 0
    kept = np.delete(np.arange(n), [3, 100, 101, 102, 5000, 9000])   # six frames dropped
    missing, share, gap = loss(kept / rate + jitter[kept])
    assert missing == 6 and share == pytest.approx(6 / n)
    assert gap == pytest.approx(3 / rate, abs=0.61 / rate)
    for off in (1.04, 0.99, 0.981):                                  # a device off its stated rate
        assert loss(np.arange(n) / (off * rate))[0] == 0, off
        assert loss(np.arange(n) / (off * rate) + jitter / off)[0] == 0, off
        assert loss(kept / (off * rate) + jitter[kept] / off)[0] == 6, off
    missing, share, _ = loss(np.arange(0, n, 2) / rate)
    assert missing == n // 2 - 1 and share == pytest.approx(0.5, abs=1e-3)
