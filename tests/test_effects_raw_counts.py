"""Effects on captures in raw counts: estimate --add and apply work as on a capture in m/s^2 and
deg/s (the terms scaled to counts by the nominal scale, station/model/raw_counts.py)."""
import numpy as np
import pytest
import yaml

from station.cli import main
from station.io.calfile import read_calfile
import simhelpers

COUNTS_PER_MPS2 = 1000.0        # the simulated ADC: 1 count = 1 mm/s^2 (about 100 µg)
COUNTS_PER_DPS = 50.0           # 1 count = 0.02 deg/s
GYRO_NOMINAL_ERROR = 0.01       # the manifest's nominal gyro scale is 1 % off (a datasheet value)
K2 = [3000.0, -2000.0, 4000.0]  # ug/g^2
ASYM = [3000.0, -2000.0, 2500.0]  # ppm
FAST = {"rate_dps": 100.0, "rotation_s": 10.8, "dwell_s": 6.0}


def to_counts(physical, raw):
    """The same recording as an IMU that outputs integer counts: samples times the ADC scale,
    rounded; units 'raw'; the gyro's nominal scale in the manifest, the accelerometer's left out
    (station then takes it from the statics)."""
    raw.mkdir()
    doc = yaml.safe_load((physical / "manifest.yaml").read_text())
    doc["imu"].update(accel_unit="raw", gyro_unit="raw",
                      gyro_nominal_dps_per_count=(1 + GYRO_NOMINAL_ERROR) / COUNTS_PER_DPS)
    for seg in doc["segments"]:
        seg.pop("sha256", None)
        text = (physical / seg["file"]).read_text().splitlines()
        header = text[0].split(",")
        d = np.loadtxt(text[1:], delimiter=",", ndmin=2)
        d[:, 1:4] = np.round(d[:, 1:4] * COUNTS_PER_MPS2)
        d[:, 4:7] = np.round(d[:, 4:7] * COUNTS_PER_DPS)
        fmt = ["%.6f"] + ["%d"] * 6 + ["%.4f"] * (d.shape[1] - 7)
        np.savetxt(raw / seg["file"], d, delimiter=",", header=",".join(header), comments="", fmt=fmt)
    (raw / "manifest.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
    return raw


@pytest.fixture(scope="module")
def captures(tmp_path_factory):
    d = tmp_path_factory.mktemp("raw")
    truth, physical = simhelpers.mems_capture(4, "optimal9", FAST, d / "si", accel__nonlinearity_ug_per_g2=K2,
                                              gyro__scale_asymmetry_ppm=ASYM)
    return truth, physical, to_counts(physical, d / "raw")


@pytest.fixture(scope="module")
def calibrations(captures, tmp_path_factory):
    """The same capture calibrated in m/s^2 and deg/s and in counts with both effects; and the
    counts calibration with its effects struck out of the compensation (the control: what apply
    gives when it does not compensate them)."""
    truth, physical, raw = captures
    d = tmp_path_factory.mktemp("cals")
    add = ["--add", "accel_nonlinearity", "--add", "gyro_scale_asymmetry"]
    cals = {"si": d / "si.yaml", "raw": d / "raw.yaml", "base": d / "base.yaml"}
    assert main(["estimate", str(physical), *add, "-o", str(cals["si"])]) == 0
    assert main(["estimate", str(raw), *add, "-o", str(cals["raw"])]) == 0
    doc = yaml.safe_load(cals["raw"].read_text())
    doc["compensation"]["effects"] = []
    doc["effects"] = ["base_triads", "inter_triad"]
    cals["base"].write_text(yaml.safe_dump(doc, sort_keys=False))
    return cals


def _effect_values(cal):
    doc = read_calfile(cal)
    return {name: value for e in doc["compensation"]["effects"] for name, value in e["parameters"].items()}


def test_estimate_add_on_raw_counts_matches_physical_units_and_the_truth(calibrations):
    si, rw = _effect_values(calibrations["si"]), _effect_values(calibrations["raw"])
    doc = yaml.safe_load(calibrations["raw"].read_text())
    state = {e["id"]: e["state"] for e in doc["compensation"]["effects"]}
    n_a, n_g = state["accel_nonlinearity"]["raw_counts_per_unit"]
    # accelerometer scale from the statics (|a| over g: the biases average out over the attitudes)
    assert abs(n_a / COUNTS_PER_MPS2 - 1) < 0.02, n_a
    assert n_g == pytest.approx(COUNTS_PER_DPS / (1 + GYRO_NOMINAL_ERROR))    # the manifest's nominal
    sig = {name: p["sigma"] for name, p in doc["parameters"].items() if "sigma" in p}
    for k, axis in enumerate("xyz"):
        name = f"accel_k2_{axis}"
        # the same data in counts: K2 scales with the counts-per-unit the term was sized with
        # (n_a from the data, within 2 %); the rounding to counts (0.29 count rms against a noise
        # of ~20 counts per sample) changes the estimate by ~1 % of its 1σ
        assert rw[name] == pytest.approx(si[name] * COUNTS_PER_MPS2 / n_a, rel=1e-3, abs=0.05 * sig[name])
        # an asymmetry scales with the gyro's own scale factor: the nominal's error cancels
        name = f"gyro_asym_{axis}"
        assert rw[name] == pytest.approx(si[name], rel=1e-3, abs=0.05 * sig[name])
        # and against the hidden truth, within 4σ of the fit
        assert abs(rw[f"accel_k2_{axis}"] - K2[k]) < 4 * sig[f"accel_k2_{axis}"]
        assert abs(rw[f"gyro_asym_{axis}"] - ASYM[k]) < 4 * sig[f"gyro_asym_{axis}"]


def test_apply_compensates_raw_counts_like_physical_units(captures, calibrations, tmp_path, capsys):
    """apply on the raw-count CSV gives the same m/s^2 and deg/s as on the physical CSV, and the
    effects are compensated (without them the ±1 g statics would be off by the K2 term)."""
    truth, physical, raw = captures
    doc = yaml.safe_load((raw / "manifest.yaml").read_text())
    g = doc["site"]["gravity_mps2"]
    statics = [seg for seg in doc["segments"] if seg["kind"] == "static"]
    rotations = [seg for seg in doc["segments"] if seg["kind"] == "rotation"][:2]
    errors = {"si": [], "raw": [], "base": []}
    rot_err = {"si": [], "raw": []}
    capsys.readouterr()
    for seg in statics + rotations:
        for label, cap in (("si", physical), ("raw", raw), ("base", raw)):
            if seg["kind"] != "static" and label == "base":
                continue
            out = tmp_path / f"{label}-{seg['name']}.csv"
            assert main(["apply", str(calibrations[label]), str(cap / seg["file"]), "-o", str(out)]) == 0
            d = np.loadtxt(out, delimiter=",", skiprows=1)
            if seg["kind"] == "static":
                errors[label].append(np.linalg.norm(d[:, 1:4].mean(axis=0)) - g)
            else:
                rot_err[label].append(np.trapezoid(d[:, 4:7], d[:, 0], axis=0))
    assert "compensated: accel_nonlinearity (library)" in capsys.readouterr().err
    rms = {k: float(np.sqrt(np.mean(np.square(v)))) for k, v in errors.items()}
    # K2 up to 4 mg/g^2 uncompensated leaves ~mg at ±1 g; compensated, the norm of a 6 s static mean
    # is good to a few tens of µg (200 µg/√Hz over 6 s: 80 µg per axis, with the fit's own error)
    assert rms["raw"] < 0.25 * rms["base"], rms
    assert rms["raw"] < 300e-6 * g, rms
    assert abs(rms["raw"] - rms["si"]) < 30e-6 * g, rms
    # the rotations' integrated rate: raw and physical calibrations agree to a fraction of the noise
    diff = np.abs(np.array(rot_err["raw"]) - np.array(rot_err["si"]))
    assert np.max(diff) < 0.02, np.max(diff)     # deg, against 1080 deg turned
