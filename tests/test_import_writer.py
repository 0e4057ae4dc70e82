"""An import's writer (ImportCaptureWriter, issue 27): the same bundle as a run's writer, byte for
byte, without an fsync of every segment file (the manifest still replaced atomically, fsynced);
a segment torn after the import is refused by its sha256 when read, never read as data."""
import os

import numpy as np
import pytest

import station.io.capture as capture
from station.core.errors import CaptureError
from station.io.capture import CaptureWriter, ImportCaptureWriter, ImuInfo, Site, read_capture


def record(writer_class, path, fsynced: list):
    rng = np.random.default_rng(1)
    t = np.arange(300) * 0.01
    a = rng.integers(30000, 36000, (300, 3)).astype(float)
    g = rng.normal(size=(300, 3))
    writer = writer_class(path, ImuInfo(100.0, "raw", "deg/s"), Site(9.81), scheme="hand-poses")
    for k, (start, stop) in enumerate([(0, 100), (100, 180), (180, 300)]):
        kind, meta = ("static", {}) if k % 2 == 0 else ("rotation", {"axis_body": [0, 0, 1], "motion": "hand"})
        with writer.begin_segment(f"s{k}", kind, **meta) as seg:
            seg.write(t[start:stop], a[start:stop], g[start:stop])
            seg.close()
    if hasattr(writer, "finish"):
        writer.finish()
    return {p.name: p.read_bytes() for p in sorted(path.iterdir())}


def test_the_import_writer_writes_the_same_bundle_and_syncs_only_the_manifest(tmp_path, monkeypatch):
    fsynced = []
    real_fsync = os.fsync

    def watched(fd):
        fsynced.append(os.readlink(f"/proc/self/fd/{fd}") if os.path.exists("/proc/self/fd") else str(fd))
        real_fsync(fd)

    monkeypatch.setattr(capture.os, "fsync", watched)
    theirs = record(CaptureWriter, tmp_path / "run", fsynced)
    run_syncs = list(fsynced)
    fsynced.clear()
    mine = record(ImportCaptureWriter, tmp_path / "import", fsynced)

    def without_start_times(files):
        import yaml
        manifest = yaml.safe_load(files["manifest.yaml"])
        for s in manifest["segments"]:
            s.pop("started_utc")
        return {**files, "manifest.yaml": manifest}

    assert without_start_times(mine) == without_start_times(theirs)
    assert any(p.endswith(".csv") for p in run_syncs)        # the run's writer syncs its samples
    if os.path.exists("/proc/self/fd"):
        assert not [p for p in fsynced if p.endswith(".csv")]
        # the manifest twice (at the start and at the end), each time its temporary file and the folder
        assert len([p for p in fsynced if ".manifest.yaml." in p]) == 2
        assert fsynced.count(str(tmp_path / "import")) == 2


def test_a_segment_torn_after_an_import_is_refused_by_its_hash(tmp_path):
    record(ImportCaptureWriter, tmp_path / "c", [])
    csv = tmp_path / "c" / "s1.csv"
    csv.write_bytes(csv.read_bytes()[:-40])            # what a crash before the data reached the disk leaves
    cap = read_capture(tmp_path / "c", load_data=False)
    with pytest.raises(CaptureError, match="sha256"):
        cap.read_samples(cap.segments[1])


def test_an_imports_manifest_is_read_by_libyaml(tmp_path):
    """What an import writes into the manifest keeps it within what station.core.yaml_text gives
    libyaml (no '|', '!', '>' or tab): a '|' in the detector's note sent the whole manifest of
    imu_tk's Xsens log to the pure-Python loader, 4 times slower, at every read."""
    from sim_devices.hand import hand_session
    from sim_devices.truth import mems_truth
    from station.core import yaml_text
    from station.io.importers.recording import Recording, write_capture

    counts = (8 * 9.80665 / 32768, 1000.0 / 32768)
    hs = hand_session(mems_truth(7), 7, poses=12, dwell_s=(2.5, 3.0), turn_s=(1.0, 1.5), counts=counts)
    rec = Recording(source="log.txt", t=hs.t, accel=hs.accel + 32768, gyro=hs.gyro + 32768,
                    accel_unit="raw", gyro_unit="raw", time_from="column 0 in s", time_option="--time-unit")
    report = write_capture(rec, tmp_path / "c", gravity_mps2=9.81744)
    text = (tmp_path / "c" / "manifest.yaml").read_text()
    assert "accel_scale_from" in text                 # the detector scaled raw counts from the rest
    assert yaml_text._c_safe(text, True) is not None
    assert len(read_capture(report.path, load_data=False).segments) == len(report.sections) + 1
