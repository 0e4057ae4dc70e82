"""Data faults found before the fit (station/estimate/data_faults.py): samples at a rail, stuck
samples and a temperature that changes, found in simulated captures with the fault hidden in the
simulated IMU (sim_devices.truth: full_scale, stuck_at_s), left out and said; and no false alarm
on clean captures (table and hand sessions, float and quantised outputs) nor on the real
recordings in tests/data/imucal.

Tolerances: every estimated parameter against the truth at 4.5 times its reported 1-sigma (for 21
Gaussian errors a chance of 1.4e-4 that any exceeds it: a failure means the estimate or its
1-sigma is wrong)."""
import contextlib
import io
import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from simhelpers import mems_capture
from station import cli
from station.estimate import data_faults, lsq, poses, summaries
from station.estimate.verdict import judge
from station.io.capture import read_capture
from station.model.calibration import parameter_errors
from station.simulate.dryrun import truth_calibration

DATA = Path(__file__).resolve().parent / "data" / "imucal"
RAIL = 10.0                                     # m/s^2: the z accelerometer's full scale
CLIPPING = dict(bench__lever_arm_m=[0.0, 0.0, -0.1], accel__full_scale=RAIL)
# with the IMU 10 cm off the axes, the turns about x and y at 100 deg/s add w^2 r = 0.30 m/s^2 to
# the z accelerometer's 1 g: its peaks pass 10 m/s^2, the statics (z up: 9.84 +- 0.016) do not


def fit(capture):
    cal = poses.estimate(capture, [])
    judge(cal)
    return cal


def within_sigma(cal, truth, k=4.5):
    for name, _, true, err, unit in parameter_errors(cal, truth_calibration(truth)):
        sigma = cal.sigma[name] / true * 1e6 if "_scale_" in name else cal.sigma[name]
        assert abs(err) <= k * sigma, (name, err, sigma, unit)


def at_rail(capture, axis=2, value=RAIL):
    return {seg.name: int((seg.data.accel[:, axis] == value).sum()) for seg in capture.segments
            if (seg.data.accel[:, axis] == value).any()}


# --- saturation ------------------------------------------------------------------------------------

def test_z_accelerometer_clipping_in_the_fast_turns_is_named_left_out_and_the_fit_passes(monkeypatch):
    truth, capture = mems_capture(seed=3, **CLIPPING)
    clipped = at_rail(capture)
    assert set(clipped) and all(name.startswith("rot") for name in clipped)     # the turns only
    cal = fit(capture)
    notes = cal.fit["notes"]
    said = [n for n in notes if n.startswith("z accelerometer saturates above 10 m/s^2")]
    assert len(said) == 1, notes
    assert f": {sum(clipped.values())} samples at the rail" in said[0]
    assert cal.fit["verdict"]["result"] == "passes", cal.fit["verdict"]
    within_sigma(cal, truth)
    # without the scan the same capture fails: the clipped peaks are what broke it
    monkeypatch.setattr(data_faults.Scanner, "scan", lambda self, seg, t, a, g, temp: data_faults.Verdict())
    unscanned = lsq.fit(lsq.summarise(capture), [])
    assert unscanned.chi2 / unscanned.dof > 10 * cal.fit["reduced_chi2"]


def test_a_static_at_the_rail_is_left_out_whole_and_a_gyro_at_its_rail_drops_the_turn():
    truth, capture = mems_capture(seed=5)
    pos05 = capture.segment("pos05").data.accel             # z up
    rail = float(np.quantile(pos05[:, 2], 0.9))              # a tenth of its samples beyond
    pos05[:, 2] = np.minimum(pos05[:, 2], rail)
    rot = capture.segment("rotz_p").data.gyro
    gyro_rail = float(np.quantile(rot[:, 2], 0.7))
    rot[:, 2] = np.minimum(rot[:, 2], gyro_rail)
    s = summaries.summarise(capture)
    assert "pos05" not in [st.name for st in s.statics] and "rotz_p" not in [r.name for r in s.rotations]
    words = " ".join(s.skipped)
    assert f"z accelerometer saturates above {rail:.4g} m/s^2: {int((pos05[:, 2] == rail).sum())} samples" in words
    assert "pos05: static left out: z accelerometer at its rail" in words and "mean is biased" in words
    assert f"z gyro saturates above {gyro_rail:.4g} deg/s" in words and "rotz_p: rotation left out" in words
    assert len(s.statics) == 8 and len(s.rotations) == 11


def test_a_declared_full_scale_is_a_rail_and_a_bad_one_is_ignored(tmp_path):
    truth, path = mems_capture(seed=3, out=tmp_path / "cap", **CLIPPING)
    manifest = path / "manifest.yaml"
    doc = yaml.safe_load(manifest.read_text())
    doc["imu"]["accel_full_scale"] = [16.0, 16.0, RAIL]
    manifest.write_text(yaml.safe_dump(doc, sort_keys=False))
    capture = read_capture(path)
    report = summaries.summarise(capture).data_faults
    rails = [f for f in report["faults"] if f["kind"] == "rail"]
    assert [(f["axis"], f["value"], f["side"]) for f in rails] == [("z", RAIL, "above")]
    assert rails[0]["samples"] == sum(at_rail(capture).values())
    for bad in ("sixteen", [1.0, 2.0], -3.0, None):
        doc["imu"]["accel_full_scale"] = bad
        manifest.write_text(yaml.safe_dump(doc, sort_keys=False))
        assert summaries.summarise(read_capture(path)).data_faults["faults"][0]["value"] == RAIL


# --- stuck samples ---------------------------------------------------------------------------------

def test_frozen_frames_and_a_stuck_axis_are_named_and_left_out():
    truth, clean = mems_capture(seed=3)
    start = {seg.name: float(seg.data.t[0]) for seg in clean.segments}
    windows = [start["pos03"] + 20.0, start["rotx_p"] + 10.0]       # 0.25 s = 25 samples each
    truth, capture = mems_capture(seed=3, accel__stuck_at_s=windows + [start["roty_p"] + 5.0],
                                  accel__stuck_duration_s=0.25,
                                  gyro__stuck_at_s=windows + [start["pos07"] + 30.0],
                                  gyro__stuck_duration_s=0.25, gyro__stuck_axes=[1])
    cal = fit(capture)
    notes = " ".join(cal.fit["notes"])
    assert ("accelerometer frozen (all three axes repeat the previous sample): 75 samples in 3 runs "
            "(longest 25 samples;") in notes, notes
    assert "y gyro stuck (repeats the previous sample): 75 samples in 3 runs" in notes, notes
    report = summaries.summarise(capture).data_faults
    # a static's and a gyro's stuck rows are removed as lost frames; an accelerometer's alone, in a
    # turn, only from its harmonics
    assert report["stuck_samples_left_out"] == {"pos03": 25, "rotx_p": 25, "pos07": 25}
    assert report["harmonics_left_out"] == [{"segment": "roty_p", "samples": 25, "of": 3600}]
    assert cal.fit["verdict"]["result"] == "passes", cal.fit["verdict"]
    within_sigma(cal, truth)


# --- no false alarm --------------------------------------------------------------------------------

@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("noise_over_lsb", [0.0, 0.6, 1.0, 3.0])
def test_clean_table_captures_raise_no_alarm(seed, noise_over_lsb):
    """Float outputs and outputs quantised to an LSB of 1/0.6 to 1/3 of the noise (a quantised
    sensor repeats values legitimately: at 0.6 the commonest level holds half the samples)."""
    from sim_devices.truth import mems_truth
    from station.io.scheme import load_scheme
    from station.simulate import dryrun

    truth = mems_truth(seed)
    if noise_over_lsb:
        truth.accel.lsb = truth.accel_noise_sigma / noise_over_lsb
        truth.gyro.lsb = truth.gyro_noise_sigma / noise_over_lsb
    scheme = load_scheme("optimal9", {"rate_dps": 100.0, "rotation_s": 36.0, "dwell_s": 30.0})
    report = summaries.summarise(dryrun.simulate_capture(scheme, truth, seed)).data_faults
    assert report["faults"] == [] and report["samples_scanned"] == 70200


def quiet(argv):
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        assert cli.main(argv) == 0


@pytest.mark.parametrize("counts", [False, True])
def test_clean_hand_sessions_raise_no_alarm(tmp_path, counts):
    from sim_devices.hand import hand_session
    from sim_devices.truth import mems_truth
    from test_import_recordings import COUNTS, write_csv

    for seed in (1, 2):
        truth = mems_truth(seed)
        hs = hand_session(truth, seed, poses=16, dwell_s=(2.5, 3.5), turn_s=(1.0, 1.8),
                          counts=COUNTS if counts else None)
        log = write_csv(tmp_path / f"log{seed}.csv", hs)
        out = tmp_path / f"cap{seed}"
        units = ["--accel-unit", "raw", "--gyro-unit", "raw", "--latitude-deg", "45"] if counts else []
        quiet(["import", "csv", str(log), "--preset", "station", "-o", str(out),
               "--gravity-mps2", str(hs.truth["gravity_mps2"]), *units])
        report = summaries.summarise(read_capture(out, load_data=False)).data_faults
        assert report["faults"] == [] and report["segments_scanned"] == 31


@pytest.mark.skipif(not DATA.exists(), reason="tests/data/imucal not present")
def test_the_real_recordings_raise_no_alarm(tmp_path):
    from station.io.importers import imucal

    session = DATA / "example_ferraris_session.csv"
    quiet(["import", "csv", str(session), "--preset", "imucal", "--rate-hz", "102.4", "--gravity-mps2", "9.81",
           "-o", str(tmp_path / "csv")])
    paths = [tmp_path / "csv",
             imucal.import_imucal(session, tmp_path / "sections", rate_hz=102.4,
                                  sections_path=DATA / "example_ferraris_session_list.json"),
             imucal.import_imucal(DATA / "annotated_session.csv", tmp_path / "counts", rate_hz=204.8)]
    scanned = 0
    for path in paths:
        report = summaries.summarise(read_capture(path, load_data=False)).data_faults
        assert report["faults"] == [], (path, report["faults"])
        scanned += report["samples_scanned"]
    assert scanned == 10326 + 4382 + 9414


# --- temperature -----------------------------------------------------------------------------------

def test_a_warm_up_is_said_with_its_range_and_the_effects_that_follow_temperature():
    truth, capture = mems_capture(seed=3, temperature__warmup_delta_c=12.0,
                                  temperature__warmup_time_constant_s=600.0, temperature__start_c=21.3)
    temps = np.concatenate([seg.data.temp for seg in capture.segments])
    s = summaries.summarise(capture)
    said = [n for n in s.skipped if n.startswith("temperature ")]
    assert said == [f"temperature {temps.min():.1f}–{temps.max():.1f} °C over the capture "
                    f"({temps.max() - temps.min():.1f} °C, at most {s.data_faults['temperature']['max_rate_c_per_min']:.2g} "
                    "°C/min within a segment): effects that follow temperature can be tested: "
                    "--add scale_temperature, --add temperature_bias, --add temperature_bias_quadratic"]
    assert s.data_faults["temperature"]["testable"] and s.data_faults["faults"] == []
    # a steady temperature is not offered
    truth, capture = mems_capture(seed=3, temperature__warmup_delta_c=0.0)
    report = summaries.summarise(capture).data_faults
    assert report["temperature"]["range_c"] == 0.0 and not report["temperature"]["testable"]
    assert not [n for n in summaries.summarise(capture).skipped if n.startswith("temperature ")]


# --- through the commands --------------------------------------------------------------------------

def test_estimate_writes_the_faults_and_diagnose_says_them(tmp_path, capsys):
    truth, path = mems_capture(seed=3, out=tmp_path / "cap", **CLIPPING)
    assert cli.main(["estimate", str(path), "-o", str(tmp_path / "cal.yaml")]) == 0
    printed = capsys.readouterr().err
    assert "note: z accelerometer saturates above 10 m/s^2" in printed
    doc = yaml.safe_load((tmp_path / "cal.yaml").read_text())
    faults = doc["fit"]["data_faults"]
    assert [(f["kind"], f["sensor"], f["axis"], f["value"]) for f in faults["faults"]] == \
        [("rail", "accelerometer", "z", RAIL)]
    assert sum(h["samples"] for h in faults["harmonics_left_out"]) > faults["faults"][0]["samples"]
    assert cli.main(["diagnose", str(path), "--json"]) == 0
    diagnosis = json.loads(capsys.readouterr().out)
    assert any(n.startswith("z accelerometer saturates above 10 m/s^2") for n in diagnosis["notes"])
    assert diagnosis["data_faults"]["faults"] == faults["faults"]


def test_the_truth_file_keeps_the_converter_faults(tmp_path):
    from sim_devices.truth import Truth, mems_truth
    from station.core.errors import UserError

    truth = mems_truth(1)
    truth.accel.full_scale = 78.4532
    truth.gyro.stuck_at_s, truth.gyro.stuck_duration_s, truth.gyro.stuck_axes = [3.0, 9.5], 0.2, [2]
    truth.to_yaml(tmp_path / "t.yaml")
    back = Truth.from_yaml(tmp_path / "t.yaml")
    assert back.to_yaml_dict() == truth.to_yaml_dict()
    assert "full_scale_mps2" not in mems_truth(1).to_yaml_dict()["accelerometer"]     # older files as they were
    for key, value in (("full_scale_dps", -1.0), ("stuck_axes", [3]), ("stuck_at_s", ["x"])):
        with pytest.raises(UserError, match=f"gyroscope.{key}"):
            Truth.from_dict({"gyroscope": {key: value}})
    # the converter: a rail, then the register held
    f = np.array([[0.0, 0.0, 50.0], [0.0, 0.0, 90.0], [0.0, 0.0, -100.0]])
    w = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 2.0], [0.0, 0.0, 3.0]])
    accel, gyro = back.measure(f, w, 25.0, None, t=np.array([3.0, 3.1, 3.3]))
    assert accel[1, 2] == pytest.approx(78.4532) and accel[2, 2] == pytest.approx(-78.4532)
    assert gyro[1, 2] == gyro[0, 2] and gyro[2, 2] != gyro[0, 2]


def test_a_turn_mostly_at_the_rail_is_left_out_and_said():
    truth, capture = mems_capture(seed=4)
    x = capture.segment("roty_p").data.accel[:, 0]          # a sinusoid of 1 g about y
    x[:] = np.minimum(x, -8.0)                              # at a rail 290 deg of each turn
    s = summaries.summarise(capture)
    assert "roty_p" not in [r.name for r in s.rotations] and len(s.rotations) == 11
    words = " ".join(s.skipped)
    assert "x accelerometer saturates above -8 m/s^2" in words
    assert "roty_p: rotation left out: its accelerometer harmonics would keep" in words and "less than 25 %" in words


@pytest.mark.parametrize("n", [0, 1, 2, 7, 8, 9, 40])
def test_odd_samples_never_crash_the_scan(n):
    from types import SimpleNamespace

    rng = np.random.default_rng(n)
    capture = SimpleNamespace(imu=SimpleNamespace(accel_unit="raw", gyro_unit="raw",
                                                  extra={"accel_full_scale": "bad", "gyro_full_scale": [0, 1]}))
    t = np.arange(n) / 100.0
    cases = [np.zeros((n, 3)), np.ones((n, 3)) * 1e11, rng.integers(-2, 2, (n, 3)).astype(float),
             rng.normal(size=(n, 3)), np.repeat(rng.normal(size=(1, 3)), n, axis=0)]
    for kind, angle in (("static", None), ("rotation", 360.0), ("rotation", None)):
        scanner = data_faults.Scanner(capture, 1.0, 1.0)
        seg = SimpleNamespace(kind=kind, name="s", angle_deg=angle, extra={})
        for a in cases:
            for g in cases:
                verdict = scanner.scan(seg, t, a, g, t * 0.0 + 20.0 if n else None)
                if verdict.masks:
                    verdict.accel_keep(np.linspace(0, 2 * np.pi, n), a)
        assert isinstance(data_faults.notes_of(scanner.report()), list)


def test_a_declared_rail_reached_twice_still_guards_the_turn():
    """Two samples at a declared full scale are no shape, but they are at the rail: found, and
    the turn's harmonics fitted without the phases near it."""
    truth, capture = mems_capture(seed=3, bench__lever_arm_m=[0.0, 0.0, -0.1])    # the turns peak highest
    rail = float(np.sort(np.concatenate([seg.data.accel[:, 2] for seg in capture.segments]))[-2])
    for seg in capture.segments:
        np.minimum(seg.data.accel[:, 2], rail, out=seg.data.accel[:, 2])
    reached = {seg.name for seg in capture.segments if (seg.data.accel[:, 2] == rail).any()}
    assert sum(int((seg.data.accel[:, 2] == rail).sum()) for seg in capture.segments) == 2
    report = summaries.summarise(capture).data_faults
    assert report["faults"] == []                                   # by its shape: nothing
    capture.imu.extra["accel_full_scale"] = [100.0, 100.0, rail]
    report = summaries.summarise(capture).data_faults
    assert [(f["axis"], f["value"], f["samples"]) for f in report["faults"]] == [("z", rail, 2)]
    left = {h["segment"]: h["samples"] for h in report["harmonics_left_out"]}
    assert set(left) == reached and all(0 < n < 0.25 * 3600 for n in left.values())


@pytest.mark.parametrize("rho", [0.0, 0.95, 0.99])
@pytest.mark.parametrize("lsb", [0.005, 0.02, 0.2])
def test_filtered_and_coarse_outputs_raise_no_alarm(rho, lsb):
    """Noise low-pass filtered (AR(1), rho: successive samples alike, as an IMU's digital filter
    makes them) and quantised from sigma/3 to 12 sigma: repeats and flat peaks come from the
    filter and the step, not from a fault.  A static, then ten revolutions of 1 g."""
    from types import SimpleNamespace

    rng = np.random.default_rng(int(1000 * rho + 1000 * lsb))
    capture = SimpleNamespace(imu=SimpleNamespace(accel_unit="m/s^2", gyro_unit="deg/s", extra={}))
    n = 3600
    t = np.arange(n) / 100.0
    phase = np.linspace(0.0, 20.0 * np.pi, n)
    for _ in range(4):
        scanner = data_faults.Scanner(capture, 1.0, 1.0)
        for kind, angle, signal in (("static", None, np.zeros((n, 6))),
                                    ("rotation", 3600.0, np.column_stack([9.8 * np.cos(phase), 9.8 * np.sin(phase),
                                                                          np.full(n, 0.3), np.full(n, 100.0),
                                                                          np.zeros(n), np.zeros(n)]))):
            w = np.empty((n, 6))
            w[0] = rng.normal(size=6)
            e = rng.normal(size=(n, 6)) * np.sqrt(1.0 - rho * rho)
            for i in range(1, n):
                w[i] = rho * w[i - 1] + e[i]
            x = np.round((signal + 0.016 * w) / lsb) * lsb
            scanner.scan(SimpleNamespace(kind=kind, name=kind, angle_deg=angle, extra={}), t, x[:, :3], x[:, 3:], None)
        assert scanner.findings == {}


def test_every_static_at_a_rail_is_one_line_that_says_so():
    from station.core.errors import UserError

    truth, capture = mems_capture(seed=3)
    for seg in capture.complete("static"):              # the axis nearest 1 g clips a tenth of the time
        k = int(np.argmax(np.abs(seg.data.accel.mean(axis=0))))
        column = seg.data.accel[:, k]
        top = np.quantile(column, 0.9)
        bottom = np.quantile(column, 0.1)
        column[:] = np.minimum(column, top) if column.mean() > 0 else np.maximum(column, bottom)
    with pytest.raises(UserError, match="every static segment was left out for a data fault, and the least-squares "
                                        "fit needs them: pos01: static left out: x accelerometer at its rail .* "
                                        "\\(and 8 more\\)"):
        summaries.summarise(capture)


def test_an_axis_at_a_declared_rail_throughout_is_a_rail_not_a_dead_axis():
    from station.estimate import check_static_resolution
    from station.core.errors import UserError

    truth, capture = mems_capture(seed=3)
    seg = capture.segment("pos05")
    seg.data.accel[:, 2] = 9.5                          # z up, at a rail below 1 g the whole dwell
    with pytest.raises(UserError, match="the same value in every sample: a dead axis, or one at its rail throughout"):
        check_static_resolution(capture, seg)
    capture.imu.extra["accel_full_scale"] = [16.0, 16.0, 9.5]
    check_static_resolution(capture, seg)               # a declared rail: not refused, left out below
    s = summaries.summarise(capture)
    assert "pos05" not in [st.name for st in s.statics]
    assert any(n.startswith("pos05: static left out: z accelerometer at its rail 9.5 m/s^2 in 10000 of 10000")
               for n in s.skipped), s.skipped


def test_the_fourier_method_says_the_faults_it_does_not_leave_out(tmp_path):
    from station.estimate import estimate_capture

    truth, path = mems_capture(seed=3, out=tmp_path / "cap", overrides={"rate_dps": 100.0, "rotation_s": 40.0},
                               **CLIPPING)                                  # 11 revolutions: enough for it
    cal, _, _ = estimate_capture(path, "fourier")
    said = [n for n in cal.fit["notes"] if n.startswith("z accelerometer saturates above 10 m/s^2")]
    assert len(said) == 1 and "NOT left out" in said[0] and "--method lsq" in said[0], cal.fit["notes"]
    assert cal.fit["data_faults"]["left_out"] is False and cal.fit["data_faults"]["faults"][0]["axis"] == "z"


def test_a_gyro_at_its_rail_throughout_a_turn_is_one_value_the_statics_say_is_stuck():
    """100 deg/s turns through a 90 deg/s gyro: the turn's axis reads 90 deg/s in every sample, no
    flat top to see; the statics show that axis moving, so one value throughout is stuck (said
    with its value), and the turn is left out."""
    truth, capture = mems_capture(seed=3, gyro__full_scale=90.0)
    s = summaries.summarise(capture)
    words = " ".join(s.skipped)
    assert "x gyro stuck (repeats the previous sample)" in words and "at 90 deg/s" in words, words
    assert "rotx_p: rotation left out: gyro stuck in 3600 of 3600 samples" in words
    assert {"rotx_p", "rotx_m", "roty_p", "roty_m", "rotz_p", "rotz_m"}.isdisjoint(r.name for r in s.rotations)
    assert len(s.rotations) == 6                                    # the diagonal turns (71 deg/s per axis)


def test_an_axis_constant_to_rounding_is_not_a_rail():
    """A noise-free axis along the turn's axis is constant to its 15th digit; its extreme value
    repeats because the rounding takes few values, not because a converter clipped (it made a
    noise-free fit of part turns about vertical axes leave out a whole rotation)."""
    from station.estimate.data_faults import rail_mask

    rng = np.random.default_rng(0)
    top = -0.008123008784178168
    column = top - rng.integers(1, 300, 2000) * 1.3e-17        # 4e-15 wide, as the simulation's
    column[rng.choice(2000, 115, replace=False)] = top
    mask, rails = rail_mask(column)
    assert not mask.any() and rails == []


def _columns_to_check():
    """Columns of every shape the scan meets: noise on a grid and in floating point, flat tops,
    stuck runs, a constant column, one that never repeats, NaN, short ones."""
    rng = np.random.default_rng(27)
    noise = rng.normal(9.8, 0.01, 5000)
    grid = np.round(noise / 0.001) * 0.001
    flat = np.minimum(grid, np.quantile(grid, 0.9))
    floor = np.maximum(grid, np.quantile(grid, 0.1))
    stuck = grid.copy()
    stuck[100:160] = stuck[100]
    nan = noise.copy()
    nan[77] = np.nan
    return [noise, grid, flat, floor, stuck, np.full(3000, 4.5), np.arange(2000.0), nan, grid[:9], grid[:2],
            -flat, np.round(rng.normal(0, 0.3, 4000)) * 0.25]


def test_the_columns_statistics_are_their_definitions_to_the_last_bit():
    """What the scan computes once per column and shares (issue 27: extremes, runs, repeats, the
    step as a minimum over the changes, np.mean's arithmetic without np.mean) is exactly what its
    definitions give: the same step, noise, rails and runs, bit for bit."""
    from station.estimate.data_faults import _Column, _mode_share, _runs, _share_outside_longest, rail_mask

    for column in _columns_to_check():
        c = _Column(column)
        d = np.diff(column)
        change = np.abs(d[d != 0])
        assert c.repeats == int((d == 0).sum())
        assert repr(c.step) == repr(float(change.min()) if len(change) else 0.0)
        assert repr(c.sigma) == repr(float(np.sqrt(np.mean(d * d) - np.mean(d) ** 2) / np.sqrt(2.0)) if len(d) else 0.0)
        assert repr(c.bounds()) == repr((float(np.min(column)), float(np.max(column))))
        for got, expected in zip(c.runs(), _runs(d == 0)):
            np.testing.assert_array_equal(got, expected)
        assert _share_outside_longest(c.equal, c.runs(), c.repeats) == _share_outside_longest(d == 0)
        assert _mode_share(column, c.step, c.bounds()) == _mode_share(column, c.step)
        for full_scale in (None, float(np.nanmax(np.abs(column))) if len(column) else None):
            mask, rails = rail_mask(column, full_scale, c)
            # the definition: each extreme, its count, the count at the next value inside
            expected_mask, expected_rails = np.zeros(len(column), bool), []
            if len(column) >= 8:
                lo, hi = float(column.min()), float(column.max())
                constant = hi - lo <= 1e-12 * max(1.0, abs(hi), abs(lo))
                for side, value in (("above", hi), ("below", lo)):
                    at = column == value
                    inside = column[~at]
                    nxt = (inside.max() if side == "above" else inside.min()) if len(inside) else None
                    inner = int((inside == nxt).sum()) if len(inside) else 0
                    declared = (full_scale is not None and abs(value) >= full_scale - max(c.step, 1e-9 * full_scale)
                                and (value > 0) == (side == "above"))
                    shaped = (not constant and at.sum() >= 3
                              and data_faults._poisson_tail_bound(int(at.sum()), 2.5 * (inner + 1)) < 1e-6)
                    if declared or shaped:
                        expected_mask |= at
                        expected_rails.append((side, value, int(at.sum())))
            np.testing.assert_array_equal(mask, expected_mask)
            assert [(s, repr(v), n) for s, v, n in rails] == [(s, repr(v), n) for s, v, n in expected_rails]
