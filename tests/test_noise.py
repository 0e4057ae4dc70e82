"""station noise: the Allan deviation's noise terms against the simulated bench's known white
noise, and against a synthetic random walk (the simulated IMU has white noise only)."""
import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from station.cli import main
from station.estimate.noise import characterise
from station.io.capture import read_capture, read_segment_csv

UG = 9.80665e-6


@pytest.fixture(scope="module")
def noise_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("noise") / "cap"
    assert main(["run", "--scheme", "noise", "--sim", "--seed", "5", "--dwell-s", "300", "--out", str(out)]) == 0
    return out


def test_noise_run_recovers_the_simulated_white_noise_densities(noise_run):
    doc = yaml.safe_load((noise_run / "noise.yaml").read_text())
    truth = yaml.safe_load((noise_run / "sim_truth.yaml").read_text())
    assert doc["format"] == "station-noise/1" and doc["imu"]["serial"] == "SIM-5"
    block = doc["noise"]
    assert block["sample_rate_hz"] == 100.0 and block["duration_s"] == pytest.approx(300.0)
    # The reported 1 sigma is the half-width of the 68 % interval of sigma(tau) at the tau read
    # (chi-squared with the estimator's degrees of freedom: ~0.3 % with 30000 samples); six axes at
    # 4 sigma: a false alarm of 6 * 6e-5.
    for sensor, key, true in (("accel", "white_noise_ug_rthz", truth["accelerometer"]["noise_density_ug_rthz"]),
                              ("gyro", "white_noise_dph_rthz", truth["gyroscope"]["noise_density_dph_rthz"])):
        for axis in "xyz":
            r = block[sensor][axis]
            sigma = r[key.replace("white_noise", "white_noise_sigma")]
            assert 0 < sigma < 0.01 * true
            assert abs(r[key] - true) < 4 * sigma, (sensor, axis, r[key], true, sigma)
    # white noise only: no flicker floor, no random walk may be claimed; upper bounds instead
    for axis in "xyz":
        assert block["accel"][axis]["bias_instability_ug"] is None
        assert block["accel"][axis]["random_walk_ug_rth"] is None
        assert block["gyro"][axis]["bias_instability_dph"] is None
        assert block["gyro"][axis]["bias_instability_upper_dph"] > 0
    kal = block["kalibr"]
    assert kal["accelerometer_random_walk_is_upper_bound"] and kal["gyroscope_random_walk_is_upper_bound"]
    assert kal["gyroscope_noise_density"] == pytest.approx(
        math.radians(max(block["gyro"][a]["white_noise_dph_rthz"] for a in "xyz") / 3600.0))
    assert (noise_run / "allan.png").stat().st_size > 10_000


def test_random_walk_and_white_noise_of_a_synthetic_signal():
    """White noise N = 1 unit/sqrt(Hz) plus a bias random walk K = 0.1 unit/sqrt(s) (crossing at
    tau = sqrt(3) N / K = 17 s), 2e5 samples at 10 Hz: both terms within 4 sigma of the reported
    1 sigma (the confidence half-width at the tau read)."""
    rng = np.random.default_rng(21)
    fs, n, N, K = 10.0, 200_000, 1.0, 0.1
    y = N * math.sqrt(fs) * rng.standard_normal((n, 3)) + np.cumsum(K / math.sqrt(fs) * rng.standard_normal((n, 3)), axis=0)
    result = characterise(y, y, fs, "synthetic")
    for a in result.axes[:3]:
        assert abs(a.white - N) < 4 * a.white_sigma
        assert a.random_walk is not None and abs(a.random_walk - K) < 4 * a.random_walk_sigma
        assert a.bias_instability is None   # the dip between the two slopes is no flicker floor


def test_flicker_floor_is_found_as_bias_instability():
    """White noise plus a bias that wanders as flicker (1/f) noise, strong enough for a plateau
    from ~10 s on: a floor is reported, at the plateau's level / 0.664 (between the lowest and
    the median point of the flat part: B is read at its lowest significant point)."""
    rng = np.random.default_rng(4)
    fs, n = 10.0, 2**17
    white = 0.02 * math.sqrt(fs) * rng.standard_normal(n)
    spectrum = np.fft.rfft(rng.standard_normal(n))
    f = np.fft.rfftfreq(n, 1 / fs)
    f[0] = f[1]
    flicker = np.fft.irfft(spectrum / np.sqrt(f), n)
    flicker *= 0.05 / np.std(flicker)
    y = np.column_stack([white + flicker] * 3)
    a = characterise(y, y, fs, "flicker").axes[0]
    assert a.bias_instability is not None and a.random_walk is None
    plateau = a.adev[a.taus > 10.0]
    assert 0.9 * plateau.min() <= 0.664 * a.bias_instability <= np.median(plateau)


def test_noise_of_a_csv_file_writes_noise_yaml_beside_it(noise_run, tmp_path):
    """Named after the CSV: two recordings in one folder keep their own noise file and plot."""
    seg = read_capture(noise_run).complete("static")[0]
    for name in ("still", "other"):
        (tmp_path / f"{name}.csv").write_text((noise_run / seg.file).read_text())
        assert main(["noise", str(tmp_path / f"{name}.csv")]) == 0
    for name in ("still", "other"):
        block = yaml.safe_load((tmp_path / f"{name}-noise.yaml").read_text())["noise"]
        assert block["sample_rate_hz"] == pytest.approx(100.0)
        assert (tmp_path / f"{name}-allan.png").exists()
    assert not (tmp_path / "allan.png").exists() and not (tmp_path / "noise.yaml").exists()


def test_noise_refuses_too_short_a_recording(tmp_path, capsys):
    csv = tmp_path / "short.csv"
    csv.write_text("t,ax,ay,az,gx,gy,gz\n" + "".join(f"{i / 100},0,0,9.8,0,0,{i % 3}\n" for i in range(50)))
    assert main(["noise", str(csv)]) == 2
    assert "short.csv" in capsys.readouterr().err


def test_kalibr_export_takes_the_noise_of_a_noise_run(noise_run, optimal9_run, tmp_path, capsys):
    """The noise run is of IMU SIM-5, the calibration of SIM-13: refused unless --force."""
    target = tmp_path / "imu.yaml"
    cmd = ["export", str(optimal9_run / "calibration.yaml"), "--to", "kalibr",
           "--noise", str(noise_run / "noise.yaml"), "-o", str(target)]
    assert main(cmd) == 2
    assert "'SIM-5'" in capsys.readouterr().err and not target.exists()
    assert main([*cmd, "--force"]) == 0
    doc = yaml.safe_load(target.read_text())
    kal = yaml.safe_load((noise_run / "noise.yaml").read_text())["noise"]["kalibr"]
    assert all(isinstance(doc[k], float) and doc[k] == kal[k] for k in
               ("accelerometer_noise_density", "accelerometer_random_walk", "gyroscope_noise_density",
                "gyroscope_random_walk", "update_rate"))
    assert "(upper bound)" in target.read_text()


def test_noise_is_not_written_into_another_imus_calibration(noise_run, optimal9_run, tmp_path, capsys):
    import shutil

    cal = tmp_path / "cal.yaml"
    shutil.copy(optimal9_run / "calibration.yaml", cal)
    before = cal.read_bytes()
    assert main(["noise", str(noise_run), "--cal", str(cal)]) == 2
    assert "SIM-13" in capsys.readouterr().err and cal.read_bytes() == before


def test_noise_of_a_named_segment_of_a_calibration_capture(optimal9_run, tmp_path, capsys):
    """--segment: that static segment only is read and characterised (the others are not read:
    nothing of theirs may be asked for)."""
    import shutil

    cap = tmp_path / "cap"
    shutil.copytree(optimal9_run, cap)
    (cap / "calibration.yaml").unlink()          # noise.yaml beside it, not into the calibration
    assert main(["noise", str(cap), "--segment", "pos02"]) == 0
    block = yaml.safe_load((cap / "noise.yaml").read_text())["noise"]
    assert "static segment pos02" in block["source"]
    assert main(["noise", str(cap), "--segment", "rotx_p"]) == 2
    assert "is not a static segment" in capsys.readouterr().err


def test_the_longest_static_is_found_holding_one_segment_at_a_time(optimal9_run, monkeypatch):
    """from_capture on a capture read without its samples reads the static segments one at a
    time and keeps only the longest (a capture of several long recordings is never held whole):
    no other segment's samples are alive when the next is read, and the result is that of the
    capture loaded whole."""
    import weakref

    from station.estimate import noise
    from station.io import capture as capture_io

    loaded = read_capture(optimal9_run)
    want = noise.from_capture(loaded)
    cap = read_capture(optimal9_run, load_data=False)
    alive, real = [], capture_io.Capture.read_samples

    def read(self, segment):
        held = [ref() for ref in alive if ref() is not None]
        assert len(held) <= 1, f"{len(held)} segments' samples held while reading {segment.name}"
        data = real(self, segment)
        alive.append(weakref.ref(data))
        return data
    monkeypatch.setattr(capture_io.Capture, "read_samples", read)
    got = noise.from_capture(cap)
    assert got.source == want.source and len(alive) == len(cap.complete("static"))
    for a, b in zip(got.axes, want.axes):
        np.testing.assert_array_equal(a.adev, b.adev)
    assert [s.name for s in cap.segments if s.data is not None] == [got.source.split("segment ")[1].split()[0]]


def test_the_gap_warning_is_about_the_segment_characterised(optimal9_run, tmp_path, capsys):
    """A gap in a static segment that is not the one characterised says nothing; in the one
    characterised (--segment), the warning that the Allan deviation assumes even sampling."""
    import hashlib
    import shutil

    cap = tmp_path / "cap"
    shutil.copytree(optimal9_run, cap)
    (cap / "calibration.yaml").unlink()
    lines = (cap / "pos01.csv").read_bytes().splitlines(keepends=True)
    half = len(lines) // 2
    gapped = lines[:half] + lines[half + 50:]          # 50 samples missing in pos01
    (cap / "pos01.csv").write_bytes(b"".join(gapped))
    manifest = yaml.safe_load((cap / "manifest.yaml").read_text())
    seg = next(s for s in manifest["segments"] if s["name"] == "pos01")
    seg["samples"], seg["sha256"] = len(gapped) - 1, hashlib.sha256(b"".join(gapped)).hexdigest()
    (cap / "manifest.yaml").write_text(yaml.safe_dump(manifest, sort_keys=False))
    assert main(["noise", str(cap)]) == 0              # the longest: another segment
    assert "gaps" not in capsys.readouterr().err
    assert main(["noise", str(cap), "--segment", "pos01"]) == 0
    assert "the recording has gaps" in capsys.readouterr().err


def test_a_stopped_noise_recording_is_characterised_from_the_rows_it_holds(noise_run, tmp_path, capsys):
    """A noise recording killed before its end (an incomplete segment, its last line cut):
    `station noise` characterises the rows recorded, says so on screen and in the source, and
    gives the same numbers as those rows as a complete recording would."""
    import shutil

    cap = tmp_path / "cap"
    shutil.copytree(noise_run, cap)
    for name in ("calibration.yaml", "noise.yaml"):
        (cap / name).unlink(missing_ok=True)
    manifest = yaml.safe_load((cap / "manifest.yaml").read_text())
    seg = manifest["segments"][0]
    content = (cap / seg["file"]).read_bytes()
    kept = content[:content.rfind(b"\n", 0, len(content) * 2 // 3) + 1]     # whole lines
    (cap / seg["file"]).write_bytes(kept + b"12.3,4")          # killed mid-line
    seg["status"] = "incomplete"
    for key in ("sha256", "samples"):
        seg.pop(key, None)
    (cap / "manifest.yaml").write_text(yaml.safe_dump(manifest, sort_keys=False))
    assert main(["noise", str(cap)]) == 0
    err = " ".join(capsys.readouterr().err.split())
    rows = kept.count(b"\n") - 1
    assert f"is incomplete (the recording stopped): its {rows} samples" in err
    block = yaml.safe_load((cap / "noise.yaml").read_text())["noise"]
    assert f"({rows} samples, incomplete" in block["source"]
    # the same rows as a complete segment
    (cap / seg["file"]).write_bytes(kept)
    seg["status"] = "complete"
    (cap / "manifest.yaml").write_text(yaml.safe_dump(manifest, sort_keys=False))
    assert main(["noise", str(cap)]) == 0
    again = yaml.safe_load((cap / "noise.yaml").read_text())["noise"]
    assert {k: v for k, v in again.items() if k != "source"} == {k: v for k, v in block.items() if k != "source"}


@pytest.mark.parametrize("fmt", ["rosbag1", "mcap"])
def test_noise_of_a_still_imu_in_a_ros_bag(noise_run, tmp_path, fmt):
    """allan_variance_ros's use: a still IMU recorded as a bag goes to `station noise` as it is;
    the figures are those of the same samples as a CSV (the bag's rad/s converted)."""
    from station.io.importers.rosbag import write_imu_bag

    seg = read_capture(noise_run).complete("static")[0]
    d = read_segment_csv(noise_run / seg.file)
    csv = tmp_path / "still.csv"
    csv.write_text((noise_run / seg.file).read_text())
    bag = write_imu_bag(tmp_path / ("still.bag" if fmt == "rosbag1" else "still"), d.t, d.accel, np.radians(d.gyro),
                        fmt=fmt)
    assert main(["noise", str(csv)]) == 0
    assert main(["noise", str(bag)]) == 0
    from_csv = yaml.safe_load((tmp_path / "still-noise.yaml").read_text())["noise"]
    name = f"{Path(bag).stem}-noise.yaml"
    from_bag = yaml.safe_load((tmp_path / name).read_text())["noise"]
    for key in ("accelerometer_noise_density", "gyroscope_noise_density"):
        assert from_bag["kalibr"][key] == pytest.approx(from_csv["kalibr"][key], rel=1e-5)
