"""Capture bundles: writer/reader round trip, every refusal, every tolerated variation."""

import hashlib
import math

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from station.io import capture as capture_module
from station.io.capture import CaptureWriter, ImuInfo, Site, read_capture, read_segment_csv
from station.core.errors import CaptureError, UserError
from station.core.units import (ACCEL_UNITS, GYRO_UNITS, STANDARD_GRAVITY, accel_to_mps2_factor,
                           gyro_to_dps_factor)

RATE = 100.0


def rows(n=5, *, t0=0.0, temp=False):
    """Deterministic sample rows: t, accel (3), gyro (3)[, temp]."""
    k = np.arange(n)
    columns = [t0 + k / RATE, 0.01 * k, -0.02 * k, 9.8 + 0 * k, 0.5 * k, 1.5 + 0 * k, -k]
    if temp:
        columns.append(25.0 + 0.1 * k)
    return np.column_stack(columns)


def write_rows(segment_writer, data):
    segment_writer.write(data[:, 0], data[:, 1:4], data[:, 4:7],
                         data[:, 7] if data.shape[1] == 8 else None)


def csv_text(n=5, *, t0=0.0, temp=False, newline="\n"):
    header = "t,ax,ay,az,gx,gy,gz" + (",temp" if temp else "")
    lines = [header] + [",".join(f"{v:.10g}" for v in row) for row in rows(n, t0=t0, temp=temp)]
    return newline.join(lines) + newline


def base_manifest():
    return {
        "format": "station-capture/1",
        "imu": {"sample_rate_hz": RATE, "accel_unit": "m/s^2", "gyro_unit": "deg/s"},
        "site": {"gravity_mps2": 9.80665},
        "segments": [
            {"name": "pos01", "kind": "static", "file": "pos01.csv", "status": "complete",
             "up_body": [0, 0, 1]},
            {"name": "rot1p", "kind": "rotation", "file": "rot1p.csv", "status": "complete",
             "axis_body": [1, 0, 0], "rate_dps": 50.0, "angle_deg": 2.5},
        ],
    }


def make_bundle(tmp_path, manifest=None, files=None):
    """A hand-written bundle: manifest (dict, or YAML text) and files (name -> str or bytes)."""
    directory = tmp_path / "cap"
    directory.mkdir()
    manifest = base_manifest() if manifest is None else manifest
    text = manifest if isinstance(manifest, str) else yaml.safe_dump(manifest, sort_keys=False)
    (directory / "manifest.yaml").write_text(text)
    for name, content in {"pos01.csv": csv_text(), "rot1p.csv": csv_text(), **(files or {})}.items():
        path = directory / name
        path.parent.mkdir(parents=True, exist_ok=True)
        if isinstance(content, bytes):
            path.write_bytes(content)
        else:
            path.write_text(content, newline="")
    return directory


def refusal(directory, **kwargs):
    with pytest.raises(CaptureError) as info:
        read_capture(directory, **kwargs)
    message = str(info.value)
    assert "\n" not in message
    return message


# ---------------------------------------------------------------------------------------------
# Writer -> reader


def test_round_trip_keeps_values_metadata_and_extra_keys(tmp_path):
    imu = ImuInfo(sample_rate_hz=RATE, accel_unit="g", gyro_unit="rad/s", model="VN-100",
                  serial="0100-1234", extra={"firmware": "2.1"})
    site = Site(gravity_mps2=9.80512, latitude_deg=45.5, extra={"lab": "B12"})
    writer = CaptureWriter(tmp_path / "cap", imu, site, scheme="optimal9",
                           extra={"operator": "ada", "table": {"model": "T-1"}})
    static = rows(300, t0=1e6, temp=True)
    with writer.begin_segment("pos01", "static", up_body=np.array([0, 0, 1]),
                              temperature_c=np.float64(24.5), custom="kept") as seg:
        write_rows(seg, static[:100])
        write_rows(seg, static[100:])
    rotation = rows(50) * 1.2345678901
    rotation[:, 0] = np.arange(50) / RATE
    with writer.begin_segment("rot1p", "rotation", file="rot/plus.csv",
                              axis_body=np.array([0.0, 1.0, 0.0]), rate_dps=np.float32(50.0),
                              note="hand") as seg:
        write_rows(seg, rotation)
        seg.close(angle_deg=25.0)
    writer.write_file("sim_truth.yaml", "bias: [1, 2, 3]\n")

    capture = read_capture(tmp_path / "cap")
    assert capture.imu == imu
    assert capture.site == site
    assert capture.scheme == "optimal9"
    assert capture.extra == {"operator": "ada", "table": {"model": "T-1"}}
    assert capture.warnings == []
    pos, rot = capture.segments
    assert (pos.name, pos.kind, pos.file, pos.status) == ("pos01", "static", "pos01.csv", "complete")
    np.testing.assert_array_equal(pos.up_body, [0, 0, 1])
    assert pos.extra["temperature_c"] == 24.5 and pos.extra["custom"] == "kept"
    assert pos.extra["samples"] == 300
    assert pos.extra["sha256"] == hashlib.sha256((capture.path / "pos01.csv").read_bytes()).hexdigest()
    assert isinstance(pos.extra["started_utc"], str)
    np.testing.assert_allclose(pos.data.t, static[:, 0], rtol=0, atol=1e-8)
    np.testing.assert_allclose(pos.data.accel, static[:, 1:4], rtol=1e-11)
    np.testing.assert_allclose(pos.data.gyro, static[:, 4:7], rtol=1e-11)
    np.testing.assert_allclose(pos.data.temp, static[:, 7], rtol=1e-11)
    assert pos.data.gaps == 0
    assert (rot.file, rot.rate_dps, rot.angle_deg, rot.note) == ("rot/plus.csv", 50.0, 25.0, "hand")
    np.testing.assert_array_equal(rot.axis_body, [0, 1, 0])
    assert rot.data.temp is None
    np.testing.assert_allclose(rot.data.accel, rotation[:, 1:4], rtol=1e-11)
    assert (capture.path / "sim_truth.yaml").read_text() == "bias: [1, 2, 3]\n"


def test_manifest_is_written_in_the_spec_key_order(tmp_path):
    writer = CaptureWriter(tmp_path / "cap", ImuInfo(RATE, "m/s^2", "deg/s", model="X"),
                           Site(9.8, latitude_deg=10), scheme="s")
    with writer.begin_segment("r", "rotation", note="n", rate_dps=1.0, axis_body=[0, 0, 1]) as seg:
        write_rows(seg, rows(3))
    manifest = yaml.safe_load((tmp_path / "cap" / "manifest.yaml").read_text())
    assert list(manifest) == ["format", "imu", "site", "scheme", "segments"]
    assert list(manifest["imu"]) == ["sample_rate_hz", "accel_unit", "gyro_unit", "model"]
    assert list(manifest["segments"][0]) == ["name", "kind", "file", "status", "axis_body",
                                             "rate_dps", "samples", "sha256", "started_utc",
                                             "note"]
    assert not list((tmp_path / "cap").glob("*.tmp"))


def test_writer_csv_header_and_number_format(tmp_path):
    writer = CaptureWriter(tmp_path / "cap", ImuInfo(RATE, "raw", "raw"), Site(9.8))
    with writer.begin_segment("s", "static") as seg:
        seg.write([1e6 + 1e-6, 1e6 + 2e-6], [[1, 2, 3], [4, 5, 6]], [[7, 8, 9], [10, 11, 12]],
                  [20.0, 21.0])
    lines = (tmp_path / "cap" / "s.csv").read_text().splitlines()
    assert lines == ["t,ax,ay,az,gx,gy,gz,temp", "1000000.000001,1,2,3,7,8,9,20",
                     "1000000.000002,4,5,6,10,11,12,21"]


def test_writer_refuses_an_existing_capture(tmp_path):
    CaptureWriter(tmp_path / "cap", ImuInfo(RATE, "g", "deg/s"), Site(9.8))
    with pytest.raises(UserError, match="already holds a capture"):
        CaptureWriter(tmp_path / "cap", ImuInfo(RATE, "g", "deg/s"), Site(9.8))


def test_writer_refuses_what_a_reader_would_refuse(tmp_path):
    with pytest.raises(CaptureError, match="imu.sample_rate_hz"):
        CaptureWriter(tmp_path / "a", ImuInfo(0.0, "g", "deg/s"), Site(9.8))
    with pytest.raises(CaptureError, match="imu.accel_unit"):
        CaptureWriter(tmp_path / "b", ImuInfo(RATE, "G", "deg/s"), Site(9.8))
    writer = CaptureWriter(tmp_path / "cap", ImuInfo(RATE, "g", "deg/s"), Site(9.8))
    with pytest.raises(CaptureError, match=r"segments\[0\] \(r\): field 'axis_body'"):
        writer.begin_segment("r", "rotation", rate_dps=5.0)
    with pytest.raises(CaptureError, match="field 'file'"):
        writer.begin_segment("s", "static", file="../s.csv")
    with pytest.raises(TypeError, match="sha256"):
        writer.begin_segment("s", "static", sha256="0" * 64)
    seg = writer.begin_segment("s", "static")
    with pytest.raises(CaptureError, match="duplicate segment name"):
        writer.begin_segment("s", "static", file="other.csv")
    with pytest.raises(UserError, match="already exists"):
        writer.begin_segment("t", "static", file="s.csv")
    with pytest.raises(ValueError, match="strictly increase"):
        seg.write([0.0, 0.0], np.zeros((2, 3)), np.zeros((2, 3)))
    with pytest.raises(ValueError, match="non-finite"):
        seg.write([0.0], [[np.nan, 0, 0]], np.zeros((1, 3)))
    with pytest.raises(ValueError, match="needs t"):
        seg.write([0.0, 1.0], np.zeros((2, 2)), np.zeros((2, 3)))
    seg.write([0.0], np.zeros((1, 3)), np.zeros((1, 3)))
    with pytest.raises(ValueError, match="strictly increase"):
        seg.write([0.0], np.zeros((1, 3)), np.zeros((1, 3)))
    with pytest.raises(ValueError, match="temp"):
        seg.write([1.0], np.zeros((1, 3)), np.zeros((1, 3)), [20.0])
    with pytest.raises(CaptureError, match="field 'angle_deg'"):
        seg.close(angle_deg="a lot")
    with pytest.raises(ValueError, match="'manifest.yaml'"):
        writer.write_file("manifest.yaml", "")
    with pytest.raises(ValueError, match=r"\.\."):
        writer.write_file("../x.txt", "")


def test_the_writer_writes_the_manifest_a_whole_dump_would(tmp_path, monkeypatch):
    """The writer keeps each segment's text and checks only the segment that begins or ends (a
    run was quadratic in its segments); the manifest is the text a dump of the whole would be,
    extra keys (after the segments), unicode and folded long strings included, and a segment
    that fails its checks or its write leaves the manifest and the writer as they were."""
    writer = CaptureWriter(tmp_path / "cap", ImuInfo(RATE, "g", "deg/s", serial="ü-1"), Site(9.8, 45.0),
                           scheme="x", extra={"operator": "a long note " * 12, "tags": [1, 2]})
    for k in range(4):
        with writer.begin_segment(f"s{k}", "static", up_body=np.array([0.0, 0.0, 1.0]), note="é" * 90) as seg:
            write_rows(seg, rows(5))
    path = tmp_path / "cap" / "manifest.yaml"
    text = path.read_text(encoding="utf-8")
    whole = yaml.safe_load(text)
    assert list(whole) == ["format", "imu", "site", "scheme", "segments", "operator", "tags"]
    assert text == yaml.safe_dump(whole, sort_keys=False, default_flow_style=None, allow_unicode=True)
    with pytest.raises(CaptureError, match=r"segments\[4\] \(s1\): field 'name': duplicate segment name \(also segments\[1\]\)"):
        writer.begin_segment("s1", "static", file="again.csv")
    with pytest.raises(CaptureError, match="field 'file'"):
        writer.begin_segment("t", "static", file="../t.csv")
    assert path.read_text(encoding="utf-8") == text
    with writer.begin_segment("t", "static") as seg:          # the writer goes on where it was
        write_rows(seg, rows(5))
    capture = read_capture(tmp_path / "cap")
    assert [s.name for s in capture.segments] == ["s0", "s1", "s2", "s3", "t"] and capture.warnings == []
    # a manifest that cannot be written: the segment is not begun, the writer unchanged
    text = path.read_text(encoding="utf-8")
    real = capture_module._atomic_write

    def full_disk(*args):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(capture_module, "_atomic_write", full_disk)
    with pytest.raises(OSError):
        writer.begin_segment("u", "static")
    monkeypatch.setattr(capture_module, "_atomic_write", real)
    assert path.read_text(encoding="utf-8") == text and not (tmp_path / "cap" / "u.csv").exists()
    # reopened: the names it holds are known to it
    writer = CaptureWriter.reopen(tmp_path / "cap")
    with pytest.raises(CaptureError, match=r"duplicate segment name \(also segments\[4\]\)"):
        writer.begin_segment("t", "static", file="t2.csv")
    with writer.begin_segment("u", "static") as seg:
        write_rows(seg, rows(5))
    assert [s.name for s in read_capture(tmp_path / "cap").segments] == ["s0", "s1", "s2", "s3", "t", "u"]


def test_a_reopened_manifest_with_aliases_in_its_entries_stays_readable(tmp_path):
    """Each segment's text is dumped on its own: two entries that each use one object twice (an
    alias in another tool's manifest) would each define the anchor &id001, which PyYAML refuses
    in one document; objects are written out instead of aliased."""
    writer = CaptureWriter(tmp_path / "cap", ImuInfo(RATE, "g", "deg/s"), Site(9.8))
    for name in ("a", "b"):
        with writer.begin_segment(name, "static", up_body=[0, 0, 1]) as seg:
            write_rows(seg, rows(5))
    path = tmp_path / "cap" / "manifest.yaml"
    text = path.read_text()
    for anchor in ("u", "v"):
        text = text.replace("  up_body: [0, 0, 1]\n", f"  up_body: &{anchor} [0, 0, 1]\n  also_up: *{anchor}\n", 1)
    assert text.count("also_up") == 2
    path.write_text(text)
    writer = CaptureWriter.reopen(tmp_path / "cap")
    with writer.begin_segment("c", "static", up_body=[0, 0, 1]) as seg:
        write_rows(seg, rows(5))
    capture = read_capture(tmp_path / "cap")
    assert [s.name for s in capture.segments] == ["a", "b", "c"]
    assert capture.segment("b").extra["also_up"] == [0, 0, 1] and "&" not in path.read_text()


def test_closing_a_segment_without_samples_as_complete_records_it_incomplete(tmp_path):
    writer = CaptureWriter(tmp_path / "cap", ImuInfo(RATE, "g", "deg/s"), Site(9.8))
    with pytest.raises(ValueError, match="no samples"):
        writer.begin_segment("s", "static").close()
    capture = read_capture(tmp_path / "cap")
    assert capture.segments[0].status == "incomplete"
    assert capture.segments[0].problem is not None and "empty" in capture.segments[0].problem


def test_a_segment_interrupted_by_an_exception_is_recorded_incomplete(tmp_path):
    writer = CaptureWriter(tmp_path / "cap", ImuInfo(RATE, "g", "deg/s"), Site(9.8))
    data = rows(20)
    with pytest.raises(KeyboardInterrupt):
        with writer.begin_segment("s", "static") as seg:
            write_rows(seg, data)
            raise KeyboardInterrupt
    capture = read_capture(tmp_path / "cap")
    (segment,) = capture.segments
    assert segment.status == "incomplete" and segment.problem is None
    assert len(segment.data.t) == 20 and segment.extra["samples"] == 20
    assert capture.complete() == []
    assert any("segments[0] (s): incomplete, 20 readable rows" in w for w in capture.warnings)


def test_reopen_keeps_complete_segments_and_appends(tmp_path):
    writer = CaptureWriter(tmp_path / "cap", ImuInfo(RATE, "g", "deg/s"), Site(9.8), scheme="x")
    for name in ("a", "b"):
        with writer.begin_segment(name, "static", up_body=[1, 0, 0], mine=name) as seg:
            write_rows(seg, rows(30))
    with pytest.raises(RuntimeError):
        with writer.begin_segment("c", "static") as seg:
            write_rows(seg, rows(5))
            raise RuntimeError("the run stopped")
    before = {n: (tmp_path / "cap" / f"{n}.csv").read_bytes() for n in ("a", "b", "c")}
    entries = yaml.safe_load((tmp_path / "cap" / "manifest.yaml").read_text())["segments"][:2]

    writer = CaptureWriter.reopen(tmp_path / "cap")
    with writer.begin_segment("c", "static") as seg:
        write_rows(seg, rows(7))

    capture = read_capture(tmp_path / "cap")
    assert [s.name for s in capture.segments] == ["a", "b", "c"]
    assert [s.status for s in capture.segments] == ["complete"] * 3
    assert capture.scheme == "x" and capture.warnings == []
    assert yaml.safe_load((tmp_path / "cap" / "manifest.yaml").read_text())["segments"][:2] == entries
    for name in ("a", "b"):
        data = (tmp_path / "cap" / f"{name}.csv").read_bytes()
        assert data == before[name]
        assert capture.segment(name).extra["sha256"] == hashlib.sha256(data).hexdigest()
    assert (tmp_path / "cap" / "c.csv.incomplete").read_bytes() == before["c"]
    assert len(capture.segment("c").data.t) == 7


# ---------------------------------------------------------------------------------------------
# Capture helpers


def test_complete_rotation_pairs_and_segment_lookup(tmp_path):
    manifest = base_manifest()
    rotation = {"kind": "rotation", "status": "complete", "axis_body": [0, 0, 1]}
    manifest["segments"] = [
        {"name": "p50", "file": "a.csv", "rate_dps": 50.0, **rotation},
        {"name": "p100", "file": "a.csv", "rate_dps": 100.0, **rotation},
        {"name": "m100", "file": "a.csv", "rate_dps": -100.0, **rotation},
        {"name": "m50", "file": "a.csv", "rate_dps": -50.0, **rotation},
        {"name": "xm", "file": "a.csv", "rate_dps": -50.0, **rotation, "axis_body": [2, 0, 0]},
        {"name": "xp", "file": "a.csv", "rate_dps": 10.0, **rotation, "axis_body": [1, 0, 0]},
        {"name": "norate", "file": "a.csv", **rotation},
        {"name": "broken", "file": "gone.csv", "rate_dps": -5.0, **rotation,
         "status": "incomplete"},
        {"name": "pos01", "kind": "static", "file": "a.csv", "status": "complete"},
    ]
    capture = read_capture(make_bundle(tmp_path, manifest, {"a.csv": csv_text()}))
    pairs = [(p.name, m.name) for p, m in capture.rotation_pairs()]
    assert pairs == [("p50", "m50"), ("p100", "m100"), ("xp", "xm")]
    assert [s.name for s in capture.complete("static")] == ["pos01"]
    assert len(capture.complete()) == 8
    assert capture.segment("m50").rate_dps == -50.0
    with pytest.raises(UserError, match="no segment named 'nope'"):
        capture.segment("nope")


# ---------------------------------------------------------------------------------------------
# Manifest refusals


def _set(path, value):
    def change(manifest):
        *parents, last = path
        target = manifest
        for key in parents:
            target = target[key]
        if value is DELETE:
            del target[last]
        else:
            target[last] = value
    return change


DELETE = object()

MANIFEST_REFUSALS = [
    # (id, change, what str(e) must contain besides the manifest's name)
    ("format missing", _set(["format"], DELETE), "field 'format'"),
    ("format wrong", _set(["format"], "station-capture/2"), "field 'format'"),
    ("imu missing", _set(["imu"], DELETE), "field 'imu'"),
    ("imu not a mapping", _set(["imu"], [100]), "field 'imu'"),
    ("rate missing", _set(["imu", "sample_rate_hz"], DELETE), "field 'imu.sample_rate_hz'"),
    ("rate zero", _set(["imu", "sample_rate_hz"], 0), "field 'imu.sample_rate_hz'"),
    ("rate negative", _set(["imu", "sample_rate_hz"], -100.0), "field 'imu.sample_rate_hz'"),
    ("rate nan", _set(["imu", "sample_rate_hz"], math.nan), "field 'imu.sample_rate_hz'"),
    ("rate inf", _set(["imu", "sample_rate_hz"], math.inf), "field 'imu.sample_rate_hz'"),
    ("rate text", _set(["imu", "sample_rate_hz"], "fast"), "field 'imu.sample_rate_hz'"),
    ("rate bool", _set(["imu", "sample_rate_hz"], True), "field 'imu.sample_rate_hz'"),
    ("accel unit", _set(["imu", "accel_unit"], "m/s2"), "field 'imu.accel_unit'"),
    ("accel unit missing", _set(["imu", "accel_unit"], DELETE), "field 'imu.accel_unit'"),
    ("gyro unit", _set(["imu", "gyro_unit"], "dps"), "field 'imu.gyro_unit'"),
    ("model not text", _set(["imu", "model"], {"a": 1}), "field 'imu.model'"),
    ("site missing", _set(["site"], DELETE), "field 'site'"),
    ("gravity missing", _set(["site", "gravity_mps2"], DELETE), "field 'site.gravity_mps2'"),
    ("gravity zero", _set(["site", "gravity_mps2"], 0.0), "field 'site.gravity_mps2'"),
    ("gravity inf", _set(["site", "gravity_mps2"], math.inf), "field 'site.gravity_mps2'"),
    ("latitude 91", _set(["site", "latitude_deg"], 91.0), "field 'site.latitude_deg'"),
    ("latitude -90.5", _set(["site", "latitude_deg"], -90.5), "field 'site.latitude_deg'"),
    ("latitude nan", _set(["site", "latitude_deg"], math.nan), "field 'site.latitude_deg'"),
    ("scheme not text", _set(["scheme"], ["a"]), "field 'scheme'"),
    ("segments missing", _set(["segments"], DELETE), "field 'segments'"),
    ("segments mapping", _set(["segments"], {"pos01": {}}), "field 'segments'"),
    ("segment not mapping", _set(["segments", 1], "rot1p"), "segments[1]: must be a mapping"),
    ("duplicate name", _set(["segments", 1, "name"], "pos01"),
     "segments[1] (pos01): field 'name': duplicate segment name (also segments[0])"),
    ("name missing", _set(["segments", 0, "name"], DELETE), "segments[0]: field 'name'"),
    ("name empty", _set(["segments", 0, "name"], ""), "field 'name'"),
    ("kind missing", _set(["segments", 0, "kind"], DELETE), "segments[0] (pos01): field 'kind'"),
    ("file missing", _set(["segments", 0, "file"], DELETE), "segments[0] (pos01): field 'file'"),
    ("status missing", _set(["segments", 0, "status"], DELETE), "(pos01): field 'status'"),
    ("status bad", _set(["segments", 0, "status"], "done"), "(pos01): field 'status'"),
    ("file absolute", _set(["segments", 0, "file"], "/etc/passwd"), "(pos01): field 'file'"),
    ("file windows absolute", _set(["segments", 0, "file"], "C:\\data\\pos01.csv"),
     "(pos01): field 'file'"),
    ("file dotdot", _set(["segments", 0, "file"], "../cap/pos01.csv"), "(pos01): field 'file'"),
    ("file inner dotdot", _set(["segments", 0, "file"], "sub/../pos01.csv"),
     "(pos01): field 'file'"),
    ("file empty", _set(["segments", 0, "file"], ""), "(pos01): field 'file'"),
    ("file of complete segment missing", _set(["segments", 0, "file"], "nope.csv"),
     "(pos01): field 'file': no such file"),
    ("file is a directory", _set(["segments", 0, "file"], "."), "(pos01): field 'file'"),
    ("table_file outside", _set(["segments", 0, "table_file"], "../table.log"),
     "(pos01): field 'table_file'"),
    ("rotation without axis", _set(["segments", 1, "axis_body"], DELETE),
     "segments[1] (rot1p): field 'axis_body'"),
    ("axis two numbers", _set(["segments", 1, "axis_body"], [1, 0]), "(rot1p): field 'axis_body'"),
    ("axis text", _set(["segments", 1, "axis_body"], "x"), "(rot1p): field 'axis_body'"),
    ("axis nan", _set(["segments", 1, "axis_body"], [1, math.nan, 0]), "field 'axis_body'"),
    ("axis non-number", _set(["segments", 1, "axis_body"], [1, "y", 0]), "field 'axis_body'"),
    ("axis zero", _set(["segments", 1, "axis_body"], [0, 0, 0]), "(rot1p): field 'axis_body'"),
    ("up zero", _set(["segments", 0, "up_body"], [0.0, 0.0, 0.0]), "(pos01): field 'up_body'"),
    ("up four numbers", _set(["segments", 0, "up_body"], [0, 0, 1, 0]), "field 'up_body'"),
    ("rate text", _set(["segments", 1, "rate_dps"], "fast"), "(rot1p): field 'rate_dps'"),
    ("rate inf", _set(["segments", 1, "rate_dps"], math.inf), "(rot1p): field 'rate_dps'"),
    ("angle nan", _set(["segments", 1, "angle_deg"], math.nan), "(rot1p): field 'angle_deg'"),
    ("angle list", _set(["segments", 1, "angle_deg"], [1.0]), "(rot1p): field 'angle_deg'"),
    ("sha256 not hex", _set(["segments", 0, "sha256"], "abc"), "(pos01): field 'sha256'"),
    ("samples negative", _set(["segments", 0, "samples"], -1), "(pos01): field 'samples'"),
    ("samples text", _set(["segments", 0, "samples"], "ten"), "(pos01): field 'samples'"),
]


@pytest.mark.parametrize("change, expected", [c[1:] for c in MANIFEST_REFUSALS],
                         ids=[c[0] for c in MANIFEST_REFUSALS])
def test_manifest_refusals_name_the_file_and_field(tmp_path, change, expected):
    manifest = base_manifest()
    change(manifest)
    directory = make_bundle(tmp_path, manifest)
    message = refusal(directory)
    assert message.startswith(f"{directory / 'manifest.yaml'}: ")
    assert expected in message
    assert message == str(refusal(directory, load_data=False))


@pytest.mark.parametrize("text, expected", [
    ("format: station-capture/1\nimu: [unclosed\n", "line 3: not valid YAML"),
    ("format: station-capture/1\n  bad: indent\n", "line 2: not valid YAML"),
    ("- a list\n- not a mapping\n", "must be a YAML mapping"),
    ("", "must be a YAML mapping, got NoneType"),
    ("started: 2024-13-45\n", "not valid YAML"),
    ("[" * 5000, "not valid YAML"),
], ids=["unclosed", "indent", "list", "empty", "bad timestamp", "deep nesting"])
def test_manifest_that_is_not_a_yaml_mapping(tmp_path, text, expected):
    directory = make_bundle(tmp_path, text)
    message = refusal(directory)
    assert message.startswith(f"{directory / 'manifest.yaml'}: ")
    assert expected in message


def test_missing_manifest(tmp_path):
    message = refusal(tmp_path)
    assert message == f"{tmp_path / 'manifest.yaml'}: no manifest: not a capture bundle"


def test_file_reached_through_a_symlink_outside_is_refused(tmp_path):
    outside = tmp_path / "outside.csv"
    outside.write_text(csv_text())
    directory = make_bundle(tmp_path)
    (directory / "pos01.csv").unlink()
    (directory / "pos01.csv").symlink_to(outside)
    message = refusal(directory)
    assert "segments[0] (pos01): field 'file'" in message and "outside" in message
    (directory / "pos01.csv").unlink()
    (directory / "pos01.csv").symlink_to(directory / "rot1p.csv")  # inside: fine
    assert len(read_capture(directory).segments[0].data.t) == 5


def test_sha256_mismatch_is_refused(tmp_path):
    manifest = base_manifest()
    manifest["segments"][0]["sha256"] = hashlib.sha256(b"something else").hexdigest()
    directory = make_bundle(tmp_path, manifest)
    message = refusal(directory)
    assert message.startswith(f"{directory / 'pos01.csv'}: segments[0] (pos01): field 'sha256': ")
    assert "does not match" in message
    manifest["segments"][0]["sha256"] = hashlib.sha256(csv_text().encode()).hexdigest().upper()
    (directory / "manifest.yaml").write_text(yaml.safe_dump(manifest))
    assert read_capture(directory).segments[0].data is not None


def test_samples_mismatch_is_refused(tmp_path):
    manifest = base_manifest()
    manifest["segments"][1]["samples"] = 6
    message = refusal(make_bundle(tmp_path, manifest))
    assert "rot1p.csv: segments[1] (rot1p): field 'samples': has 5 data rows" in message


# ---------------------------------------------------------------------------------------------
# CSV refusals

HEADER = "t,ax,ay,az,gx,gy,gz"


def data_line(k):
    return f"{k / RATE},0.1,0.2,9.8,1,2,3"


def good_lines(n=4):
    return [HEADER] + [data_line(k) for k in range(n)]


def with_line(number, text, n=4):
    """good_lines(n) with line `number` (1-based) replaced by `text`."""
    lines = good_lines(n)
    lines[number - 1] = text
    return "\n".join(lines) + "\n"


CSV_REFUSALS = [
    # (id, content, line, what str(e) must contain)
    ("empty file", "", 1, "empty file"),
    ("only blank lines", "\n\n \n", 1, "empty file"),
    ("no header", "\n".join(good_lines()[1:]) + "\n", 1, "no header"),
    ("missing column", with_line(1, "t,ax,ay,az,gx,gy"), 1, "missing required column(s) 'gz'"),
    ("misspelled column", with_line(1, "time,ax,ay,az,gx,gy,gz"), 1, "'t'"),
    ("duplicate column", with_line(1, HEADER + ",ax"), 1, "duplicate column name(s) 'ax'"),
    ("quoted header", with_line(1, '"t",ax,ay,az,gx,gy,gz'), 1, "quoting"),
    ("quoted value", with_line(3, '0.01,"0.1",0.2,9.8,1,2,3'), 3, "quoting"),
    ("short row", with_line(4, "0.02,0.1,0.2,9.8,1,2"), 4, "6 fields, the header has 7"),
    ("long row", with_line(2, "0.00,0.1,0.2,9.8,1,2,3,4"), 2, "8 fields, the header has 7"),
    ("blank line inside", with_line(3, ""), 3, "blank line"),
    ("whitespace line inside", with_line(3, "  \t"), 3, "blank line"),
    ("text value", with_line(5, "0.03,0.1,0.2,9.8,abc,2,3"), 5, "column 'gx': not a number: 'abc'"),
    ("empty value", with_line(2, "0,0.1,,9.8,1,2,3"), 2, "column 'ay': not a number: ''"),
    ("bad exponent", with_line(3, "0.01,0.1,0.2,9.8,1,2,3e"), 3, "column 'gz'"),
    ("nan", with_line(3, "0.01,nan,0.2,9.8,1,2,3"), 3, "column 'ax': not a finite number: 'nan'"),
    ("inf", with_line(4, "0.02,0.1,0.2,9.8,1,inf,3"), 4, "column 'gy': not a finite number"),
    ("-inf time", with_line(2, "-inf,0.1,0.2,9.8,1,2,3"), 2, "column 't': not a finite number"),
    ("overflow", with_line(5, "0.03,0.1,1e999,9.8,1,2,3"), 5, "column 'ay': not a finite number"),
    ("time repeats", with_line(4, data_line(1)), 4, "time does not increase"),
    ("time goes back", with_line(5, "-1,0.1,0.2,9.8,1,2,3"), 5, "time does not increase"),
    ("header only", HEADER + "\n", 2, "no data rows"),
    ("comment line", with_line(3, "# 0.01,0.1,0.2,9.8,1,2,3"), 3, "column 't': not a number"),
    ("lone CR", with_line(3, "0.01,0.1,0.2,9.8,1,2,3\r0.015,0.1,0.2,9.8,1,2,3"), 3,
     "13 fields"),  # a CR alone does not end a line
    ("NUL byte", with_line(3, "0.01,0.1,0.2,9.8,1\0,2,3"), 3, "column 'gx': not a number"),
]


@pytest.mark.parametrize("content, line, expected", [c[1:] for c in CSV_REFUSALS],
                         ids=[c[0] for c in CSV_REFUSALS])
def test_csv_refusals_name_the_file_and_line(tmp_path, content, line, expected):
    directory = make_bundle(tmp_path, files={"pos01.csv": content})
    message = refusal(directory)
    assert message.startswith(f"{directory / 'pos01.csv'}: segments[0] (pos01): line {line}: ")
    assert expected in message


def test_csv_refusal_of_a_non_utf8_byte(tmp_path):
    content = with_line(4, "0.02,0.1,0.2,9.8,1,2,3").encode().replace(b"9.8,1,2,3\n0.03",
                                                                       b"9.8,1,2,\xff3\n0.03")
    message = refusal(make_bundle(tmp_path, files={"pos01.csv": content}))
    assert "pos01.csv: segments[0] (pos01): line 4: column 'gz': not a number" in message


def test_csv_refusal_is_fast_to_locate_in_a_large_file(tmp_path):
    lines = good_lines(100_000)
    lines[77_777] = lines[77_777].replace(",1,", ",x,")
    message = refusal(make_bundle(tmp_path, files={"pos01.csv": "\n".join(lines)}))
    assert "line 77778: column 'gx': not a number: 'x'" in message


# ---------------------------------------------------------------------------------------------
# Tolerated variations


def expected_rows(n=4):
    return np.array([[k / RATE, 0.1, 0.2, 9.8, 1, 2, 3] for k in range(n)])


TOLERATED_CSV = [
    ("plain", "\n".join(good_lines()) + "\n"),
    ("no final newline", "\n".join(good_lines())),
    ("CRLF", "\r\n".join(good_lines()) + "\r\n"),
    ("trailing empty lines", "\n".join(good_lines()) + "\n\n\r\n  \n\n"),
    ("byte order mark", "\ufeff" + "\n".join(good_lines()) + "\n"),
    ("spaces around names and values",
     "\n".join(" , ".join(f" {v} " for v in line.split(",")) for line in good_lines()) + "\n"),
    ("extra columns anywhere", "\n".join(
        [f"status,{HEADER},comment"] + [f"OK,{data_line(k)},free text x" for k in range(4)])),
    ("reordered columns", "\n".join(
        ["gz,gy,gx,az,ay,ax,t"] + [",".join(reversed(data_line(k).split(","))) for k in range(4)])),
    ("integers and exponents", "\n".join(
        [HEADER, "0,1e-1,.2,98e-1,1,2,3", "1e-2,0.1,0.2,9.8,1,+2,3", "0.02,0.1,0.2,9.8,1.,2,3",
         "0.03,0.1,0.2,9.8,1,2,3E0"])),
]


@pytest.mark.parametrize("content", [c[1] for c in TOLERATED_CSV], ids=[c[0] for c in TOLERATED_CSV])
def test_tolerated_csv_variations(tmp_path, content):
    capture = read_capture(make_bundle(tmp_path, files={"pos01.csv": content}))
    data = capture.segments[0].data
    expected = expected_rows()
    np.testing.assert_array_equal(data.t, expected[:, 0])
    np.testing.assert_array_equal(data.accel, expected[:, 1:4])
    np.testing.assert_array_equal(data.gyro, expected[:, 4:7])
    assert data.temp is None and data.gaps == 0
    assert capture.warnings == []


def test_temp_column_in_any_position(tmp_path):
    content = "temp," + HEADER + "\n" + "\n".join(f"{20 + k},{data_line(k)}" for k in range(4))
    data = read_capture(make_bundle(tmp_path, files={"pos01.csv": content})).segments[0].data
    np.testing.assert_array_equal(data.temp, [20, 21, 22, 23])
    np.testing.assert_array_equal(data.t, expected_rows()[:, 0])


def test_tolerated_manifest_variations(tmp_path):
    text = """\
format: station-capture/1
made_by: someone's script     # unknown top-level key
imu:
  sample_rate_hz: 100          # integer
  accel_unit: g
  gyro_unit: rad/s
  serial: 1234                 # a number, read as text
  firmware: {version: 2}
site:
  gravity_mps2: 10
  latitude_deg: -90
  altitude_m: 300
segments:
  - name: pos01
    kind: static
    file: ./data/pos01.csv
    status: complete
    up_body: [0, 0, -2]          # not unit length
    temperature_c: 25
    table_file: table.log        # need not exist
    operator_comment: fine
  - name: rot1p
    kind: rotation
    file: rot1p.csv
    status: complete
    axis_body: [0.6, 0.8, 0.001]
    rate_dps: 5e1                # YAML 1.2 number, text to PyYAML
    angle_deg: null
  - name: warmup
    kind: warmup                 # any kind
    file: missing.csv            # incomplete: the file may be missing
    status: incomplete
"""
    directory = make_bundle(tmp_path, text, files={"data/pos01.csv": csv_text()})
    capture = read_capture(directory)
    assert capture.extra == {"made_by": "someone's script"}
    assert capture.imu == ImuInfo(100.0, "g", "rad/s", serial="1234",
                                  extra={"firmware": {"version": 2}})
    assert isinstance(capture.imu.sample_rate_hz, float)
    assert capture.site == Site(10.0, -90.0, extra={"altitude_m": 300})
    assert capture.scheme is None
    pos, rot, warmup = capture.segments
    np.testing.assert_array_equal(pos.up_body, [0, 0, -1])
    assert pos.extra == {"temperature_c": 25, "table_file": "table.log",
                         "operator_comment": "fine"}
    np.testing.assert_allclose(np.linalg.norm(rot.axis_body), 1.0)
    assert rot.rate_dps == 50.0 and rot.angle_deg is None
    assert warmup.data is None and "cannot read missing.csv" in warmup.problem
    assert capture.warnings == [f"segments[2] (warmup): incomplete, no data: {warmup.problem}"]


def test_empty_segment_list_is_a_valid_capture(tmp_path):
    manifest = base_manifest()
    manifest["segments"] = []
    assert read_capture(make_bundle(tmp_path, manifest)).segments == []


def test_manifest_path_may_be_given_instead_of_the_directory(tmp_path):
    directory = make_bundle(tmp_path)
    capture = read_capture(directory / "manifest.yaml")
    assert capture.path == directory and len(capture.segments) == 2


def test_load_data_false_reads_no_csv(tmp_path):
    directory = make_bundle(tmp_path, files={"pos01.csv": "garbage"})
    capture = read_capture(directory, load_data=False)
    assert [s.data for s in capture.segments] == [None, None]


def test_gaps_are_counted_and_reported(tmp_path):
    lines = good_lines(10)
    del lines[4:6]  # two samples lost: one step of 3/RATE
    del lines[7]  # one more: a step of 2/RATE
    capture = read_capture(make_bundle(tmp_path, files={"rot1p.csv": "\n".join(lines)}))
    assert capture.segments[1].data.gaps == 2
    assert capture.warnings == ["segments[1] (rot1p): 2 gaps in time in rot1p.csv "
                                "(steps longer than 1.5 periods where the stamps jump: lost samples)"]


def test_read_segment_csv_alone(tmp_path):
    lines = good_lines(10)
    del lines[4:6]
    (tmp_path / "in.csv").write_text("\r\n".join(lines))
    data = read_segment_csv(tmp_path / "in.csv")
    assert len(data.t) == 8 and data.gaps == 1  # against the median step
    assert read_segment_csv(tmp_path / "in.csv", sample_rate_hz=RATE / 4).gaps == 0
    (tmp_path / "bad.csv").write_text(with_line(3, "0.01,0.1,0.2,9.8,1,2"))
    with pytest.raises(CaptureError) as info:
        read_segment_csv(tmp_path / "bad.csv")
    assert str(info.value) == f"{tmp_path / 'bad.csv'}: line 3: 6 fields, the header has 7"
    with pytest.raises(CaptureError, match="missing.csv: cannot read"):
        read_segment_csv(tmp_path / "missing.csv")


# ---------------------------------------------------------------------------------------------
# Incomplete segments never raise


def incomplete_bundle(tmp_path, content):
    manifest = base_manifest()
    manifest["segments"][1]["status"] = "incomplete"
    return read_capture(make_bundle(tmp_path, manifest, {"rot1p.csv": content}))


def test_incomplete_segment_drops_a_truncated_last_line(tmp_path):
    content = "\n".join(good_lines(6)) + "\n0.06,0.1,0.2,9."
    capture = incomplete_bundle(tmp_path, content)
    segment = capture.segments[1]
    assert segment.problem is None and len(segment.data.t) == 6
    assert capture.warnings == ["segments[1] (rot1p): incomplete, 6 readable rows"]


def test_incomplete_segment_keeps_the_rows_before_a_bad_line(tmp_path):
    lines = good_lines(8)
    lines[3] = lines[3].replace("9.8", "nan")
    lines[6] = "garbage"
    segment = incomplete_bundle(tmp_path, "\n".join(lines) + "\n").segments[1]
    assert len(segment.data.t) == 2
    assert "rot1p.csv: segments[1] (rot1p): line 4: column 'az': not a finite number: 'nan'" \
        in segment.problem


@pytest.mark.parametrize("content, problem", [
    ("", "empty file"),
    ("t,ax,a", "empty file"),  # killed while writing the header
    ("0,1,2,3,4,5,6\n", "no header"),
    (b"\xff\xfe\x00garbage\n", "missing required column"),
])
def test_incomplete_segment_without_readable_data(tmp_path, content, problem):
    capture = incomplete_bundle(tmp_path, content)
    segment = capture.segments[1]
    assert segment.data is None and problem in segment.problem
    assert "rot1p.csv: segments[1] (rot1p): line 1" in segment.problem
    assert capture.warnings == [f"segments[1] (rot1p): incomplete, 0 readable rows: "
                                f"{segment.problem}"]


def test_incomplete_segment_with_only_a_header_has_empty_data(tmp_path):
    segment = incomplete_bundle(tmp_path, HEADER + ",temp\n").segments[1]
    assert segment.problem is None
    assert segment.data.t.shape == (0,) and segment.data.accel.shape == (0, 3)
    assert segment.data.temp.shape == (0,)


def test_incomplete_segment_with_a_sha256_mismatch_is_reported(tmp_path):
    manifest = base_manifest()
    manifest["segments"][1].update(status="incomplete", sha256="0" * 64)
    segment = read_capture(make_bundle(tmp_path, manifest)).segments[1]
    assert len(segment.data.t) == 5 and "sha256" in segment.problem


# ---------------------------------------------------------------------------------------------
# Fuzz: whatever the bytes, only CaptureError


csv_bytes = st.one_of(
    st.binary(max_size=300),
    st.lists(st.sampled_from(["t", "ax", "ay", "az", "gx", "gy", "gz", "temp", ",", "\n", "\r",
                              "1", "0.5", "-", "e", "nan", "inf", " ", '"', "\x00", "x", "9"]),
             max_size=80).map(lambda parts: "".join(parts).encode()),
    st.lists(st.lists(st.sampled_from(["0", "1", "2.5", "-1e3", "", "nan", "a", " 3"]),
                      min_size=6, max_size=8).map(",".join),
             max_size=6).map(lambda lines: (HEADER + "\n" + "\n".join(lines)).encode()),
)


@settings(max_examples=300, deadline=None, database=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(content=csv_bytes)
def test_fuzz_csv_reader_raises_only_capture_errors(tmp_path_factory, content):
    directory = tmp_path_factory.mktemp("fuzz")
    manifest = base_manifest()
    manifest["segments"][0]["status"] = "incomplete"
    (directory / "manifest.yaml").write_text(yaml.safe_dump(manifest))
    (directory / "pos01.csv").write_bytes(content)
    (directory / "rot1p.csv").write_bytes(content)
    try:
        capture = read_capture(directory)
    except CaptureError as e:
        assert "rot1p.csv: segments[1] (rot1p): line " in str(e)
        capture = None
    if capture is not None:
        assert capture.segments[1].data.t.size > 0
    manifest["segments"] = manifest["segments"][:1]  # the incomplete one alone never raises
    (directory / "manifest.yaml").write_text(yaml.safe_dump(manifest))
    read_capture(directory)


@settings(max_examples=200, deadline=None, database=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(text=st.text(max_size=200))
def test_fuzz_manifest_raises_only_capture_errors(tmp_path_factory, text):
    directory = tmp_path_factory.mktemp("fuzz")
    (directory / "manifest.yaml").write_text(text)
    try:
        read_capture(directory)
    except CaptureError:
        pass


# ---------------------------------------------------------------------------------------------
# Errors and units


def test_capture_error_text():
    assert str(CaptureError("a/m.yaml", "bad", field="imu.sample_rate_hz")) == \
        "a/m.yaml: field 'imu.sample_rate_hz': bad"
    assert str(CaptureError("a/r.csv", "no\nnewline", line=12, segment="segments[2] (rot1p)")) == \
        "a/r.csv: segments[2] (rot1p): line 12: no newline"
    assert isinstance(CaptureError("f", "m"), UserError)


def test_units():
    assert ACCEL_UNITS == ("m/s^2", "g", "raw") and GYRO_UNITS == ("deg/s", "rad/s", "raw")
    assert accel_to_mps2_factor("g") == STANDARD_GRAVITY == 9.80665
    assert accel_to_mps2_factor("m/s^2") == 1.0 and accel_to_mps2_factor("raw") is None
    assert gyro_to_dps_factor("rad/s") == pytest.approx(57.29577951308232)
    assert gyro_to_dps_factor("deg/s") == 1.0 and gyro_to_dps_factor("raw") is None
    with pytest.raises(ValueError):
        gyro_to_dps_factor("dps")


def test_two_segments_reading_one_file_are_said_to(tmp_path):
    """A manifest entry copied without changing its file: both segments would use the same
    samples; the reader says so (a warning naming both), it does not refuse (the format does
    not forbid it)."""
    manifest = base_manifest()
    twin = dict(manifest["segments"][0], name="pos01-again", file="./pos01.csv")
    manifest["segments"].append(twin)
    capture = read_capture(make_bundle(tmp_path, manifest))
    shared = [w for w in capture.warnings if "reads the same file" in w]
    assert len(shared) == 1 and "(pos01-again)" in shared[0] and "(pos01)" in shared[0], capture.warnings


def test_a_very_long_segment_name_is_shortened_in_messages(tmp_path):
    """Names have no length limit; a message names a 30,000-character one by its start and
    length, not whole."""
    manifest = base_manifest()
    name = "n" * 30_000
    manifest["segments"][0]["name"] = name
    message = refusal(make_bundle(tmp_path, manifest, files={"pos01.csv": "t,ax,ay,az,gx,gy,gz\n0,1,2,3,4,5\n"}))
    assert "(30000 characters)" in message and len(message) < 600, message[:300]


def test_segments_of_a_kind_station_does_not_use_are_said_once_with_the_kind_meant(tmp_path):
    """The format allows any kind (left out of estimation): a typo ("statc") dropped a static
    without a word; one warning now names them, with the kind a typo may have meant."""
    manifest = base_manifest()
    manifest["segments"][0]["kind"] = "statc"
    extra = []
    for k in range(5):
        entry = dict(manifest["segments"][1], name=f"warm{k}", kind="warmup")
        extra.append(entry)
    manifest["segments"] += extra
    capture = read_capture(make_bundle(tmp_path, manifest))
    (warning,) = [w for w in capture.warnings if "kind" in w]
    assert warning.startswith("6 segments of a kind station does not use, left out of estimation")
    assert "kind 'statc' (segments[0] (pos01)): meant 'static'?" in warning
    assert "kind 'warmup' (segments[2] (warm0), segments[3] (warm1), segments[4] (warm2) and 2 more)" in warning
    assert "warmup'" in warning and "meant 'static'?; " in warning
    assert capture.complete("static") == []
