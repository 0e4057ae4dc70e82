"""The streaming capture reader (station/io/capture.py, read_csv_pieces) and the one-pass
estimate (station/estimate/summaries.py): every file read once, in pieces, by the CSV engine, with
the same values and the same refusals as the line-by-line reader; summaries one segment at a time."""
import hashlib

import numpy as np
import pytest

from station.core.errors import CaptureError
from station.estimate import estimate_capture, estimate_with, summaries
from station.io import capture as capture_io
from station.io.capture import CaptureWriter, ImuInfo, Site, read_capture
from test_capture import CSV_REFUSALS, TOLERATED_CSV, base_manifest, expected_rows, make_bundle, refusal


@pytest.mark.parametrize("piece_bytes", [1, 7, 50])
def test_any_piece_size_reads_and_refuses_as_the_line_reader(tmp_path, monkeypatch, piece_bytes):
    """Pieces that cut lines, the header, a CRLF or a BOM anywhere: the same rows, the same
    messages (file, segment, line, what) as whole-file reading."""
    monkeypatch.setattr(capture_io, "PIECE_BYTES", piece_bytes)
    for k, (_, content) in enumerate(TOLERATED_CSV):
        (tmp_path / f"ok{k}").mkdir()
        data = read_capture(make_bundle(tmp_path / f"ok{k}", files={"pos01.csv": content})).segments[0].data
        np.testing.assert_array_equal(np.column_stack([data.t, data.accel, data.gyro]), expected_rows())
    for k, (what, content, line, expected) in enumerate(CSV_REFUSALS):
        (tmp_path / f"bad{k}").mkdir()
        directory = make_bundle(tmp_path / f"bad{k}", files={"pos01.csv": content})
        message = refusal(directory)
        assert message.startswith(f"{directory / 'pos01.csv'}: segments[0] (pos01): line {line}: "), what
        assert expected in message, what


FIELDS = ["1.", ".5", "+2", "-.5e-3", "1E0", " 3", "3 ", "\t3", "00012", "1e-400", "4.9e-324",
          "1.7976931348623157e308", "-0", "nan", "NaN", "-nan", "nan(1)", "inf", "Infinity", "1e999",
          "1e300", "0x10", "1_0", "1d3", "1e", "+", ".e5", "1..2", "1 2", "\xa01", "1\u2003", "\x0c1",
          "\u0661", "\uff10", "1e5.5"]


@pytest.mark.parametrize("field", FIELDS)
def test_engine_accepts_a_field_only_as_the_line_reader_does(tmp_path, field):
    """Whatever a field holds, read_capture (engine first) and the line-by-line reader alone
    give the same values or the same message."""
    lines = ["t,ax,ay,az,gx,gy,gz"] + [f"{k / 100},0.1,0.2,9.8,1,2,3" for k in range(4)]
    lines[3] = f"0.02,0.1,0.2,9.8,{field},2,3"
    content = ("\n".join(lines) + "\n").encode()
    directory = make_bundle(tmp_path, files={"pos01.csv": content})
    path = directory / "pos01.csv"
    reference, problem, _ = capture_io._parse_csv_file(path, 100.0, path, "segments[0] (pos01)")
    if problem is not None:
        assert refusal(directory) == str(problem)
        return
    data = read_capture(directory).segments[0].data
    np.testing.assert_array_equal(data.gyro, reference.gyro)


def written_segment(tmp_path, n, seed=3):
    """A segment CSV as the station's writer makes it (%.15g time, %.12g values, temp column)."""
    rng = np.random.default_rng(seed)
    t = 1e5 + np.cumsum(rng.uniform(0.5e-3, 2e-3, n))
    accel = rng.normal(size=(n, 3)) * 10.0 ** rng.integers(-6, 4, size=(n, 3))
    gyro = rng.normal(size=(n, 3)) * 10.0 ** rng.integers(-9, 3, size=(n, 3))
    temp = 25 + rng.normal(size=n)
    writer = CaptureWriter(tmp_path / "cap", ImuInfo(1000.0, "m/s^2", "deg/s"), Site(9.8))
    with writer.begin_segment("pos01", "static") as seg:
        seg.write(t, accel, gyro, temp)
    return tmp_path / "cap" / "pos01.csv"


@pytest.mark.parametrize("piece_bytes", [1000, capture_io.PIECE_BYTES])
def test_engine_values_are_bit_identical_to_the_line_reader(tmp_path, monkeypatch, piece_bytes):
    monkeypatch.setattr(capture_io, "PIECE_BYTES", piece_bytes)
    path = written_segment(tmp_path, 3000)
    fast, digest = capture_io.read_csv_pieces(path, 1000.0)
    assert fast is not None                                   # the engine read it, no fallback
    raw = path.read_bytes()
    assert digest == hashlib.sha256(raw).hexdigest()
    slow, problem, slow_digest = capture_io._parse_csv_file(path, 1000.0, path, None)
    assert problem is None and slow_digest == digest
    for name in ("t", "accel", "gyro", "temp"):
        np.testing.assert_array_equal(getattr(fast, name), getattr(slow, name))
        assert getattr(fast, name).flags.writeable
    assert fast.gaps == slow.gaps > 0


def test_a_changed_file_is_refused_when_its_samples_are_read(tmp_path):
    manifest = base_manifest()
    manifest["segments"][0]["sha256"] = "0" * 64
    capture = read_capture(make_bundle(tmp_path, manifest), load_data=False)   # manifest only
    with pytest.raises(CaptureError, match=r"pos01.csv: segments\[0\] \(pos01\): field 'sha256': file content"):
        capture.read_samples(capture.segments[0])


class _Reads(list):
    """Paths given to read_csv_pieces, in order, by this process and by the processes it forks
    (estimate reads a capture in a forked child): each read is appended to a file as well."""

    def __init__(self, log):
        super().__init__()
        self.log = log

    def every_process(self) -> list:
        return self.log.read_text().split() if self.log.exists() else []


@pytest.fixture
def counted_reads(monkeypatch, tmp_path):
    paths = _Reads(tmp_path / "reads.log")
    real = capture_io.read_csv_pieces

    def counting(path, rate):
        paths.append(path.name)
        with open(paths.log, "a") as log:
            log.write(path.name + "\n")
        return real(path, rate)

    monkeypatch.setattr(capture_io, "read_csv_pieces", counting)
    return paths


def test_summaries_stream_one_segment_at_a_time_and_match_loaded_samples(optimal9_run, counted_reads):
    eager = summaries.summarise(read_capture(optimal9_run))
    counted_reads.clear()
    lazy_capture = read_capture(optimal9_run, load_data=False)
    held = []          # segments holding samples whenever a file is read: one at a time
    real_read = lazy_capture.read_samples
    lazy_capture.read_samples = lambda seg, **kw: (held.append(sum(s.data is not None for s in lazy_capture.segments)),
                                                   real_read(seg, **kw))[1]
    lazy = summaries.summarise(lazy_capture)
    assert held == [0] * len(held) and len(held) > 0
    files = [seg.file for seg in lazy_capture.complete() if seg.kind in ("static", "rotation")]
    assert sorted(counted_reads) == sorted(files)               # each file once
    assert all(seg.data is None for seg in lazy_capture.segments)   # nothing kept
    assert summaries.summarise(lazy_capture).rotations[0].accel_cos is not lazy.rotations[0].accel_cos
    assert len(counted_reads) == len(files)                     # a second summarise reads nothing
    for a, b in zip(eager.statics + eager.rotations, lazy.statics + lazy.rotations):
        for name, value in vars(a).items():
            if isinstance(value, np.ndarray):
                np.testing.assert_array_equal(value, getattr(b, name))
    np.testing.assert_array_equal(eager.accel_sigma, lazy.accel_sigma)


def test_estimate_reads_each_file_once_and_digests_the_hashes(optimal9_run, counted_reads):
    cal, capture, provenance = estimate_capture(optimal9_run)
    complete = capture.complete()
    assert sorted(counted_reads.every_process()) == sorted(seg.file for seg in complete)
    digest = hashlib.sha256((optimal9_run / "manifest.yaml").read_bytes())
    for seg in complete:      # the documented definition, from the files themselves
        digest.update(hashlib.sha256((optimal9_run / seg.file).read_bytes()).digest())
    assert provenance["capture_sha256"] == digest.hexdigest()
    loaded, _ = estimate_with(read_capture(optimal9_run), "lsq")
    np.testing.assert_allclose(cal.accel_scale, loaded.accel_scale, rtol=1e-12)
    np.testing.assert_allclose(cal.gyro_T, loaded.gyro_T, rtol=0, atol=1e-15)
    assert cal.sigma == pytest.approx(loaded.sigma, rel=1e-9)


def _lines_with_faults(faults: dict, n=12) -> bytes:
    """A segment CSV of n rows (line k + 2 is row k), with the given lines replaced."""
    lines = ["t,ax,ay,az,gx,gy,gz"] + [f"{k / 100},0.1,0.2,9.8,1,2,3" for k in range(n)]
    for line, text in faults.items():
        lines[line - 1] = text
    return ("\n".join(lines) + "\n").encode()


FAULTS = {5: "0.03,0.1,0.2,9.8,nan,2,3",            # not finite
          8: "0.06,0.1,0.2,9.8,1,2",                 # a field missing
          10: "0.01,0.1,0.2,9.8,1,2,3",              # time goes back
          12: "0.10,0.1,0.2,x,1,2,3"}                # not a number


@pytest.mark.parametrize("piece_bytes", [1, 7, 50, 10**6])
@pytest.mark.parametrize("first", sorted(FAULTS))
def test_the_line_reader_names_the_first_bad_line_of_the_file_whatever_the_pieces(tmp_path, monkeypatch,
                                                                                    piece_bytes, first):
    """Several faults: the first in the file's order is named (not the first of a kind of
    check), however the file is cut into pieces; an incomplete segment keeps the rows before it
    and says what is wrong with it."""
    monkeypatch.setattr(capture_io, "PIECE_BYTES", piece_bytes)
    faults = {line: text for line, text in FAULTS.items() if line >= first}
    content = _lines_with_faults(faults)
    message = refusal(make_bundle(tmp_path, files={"pos01.csv": content}))
    assert f": line {first}: " in message, message
    manifest = base_manifest()
    manifest["segments"][0]["status"] = "incomplete"
    (tmp_path / "inc").mkdir()
    seg = read_capture(make_bundle(tmp_path / "inc", manifest, files={"pos01.csv": content})).segments[0]
    assert len(seg.data.t) == first - 2 and f"line {first}: " in seg.problem


def test_a_refused_line_near_the_end_of_a_long_file_is_found_in_bounded_memory(tmp_path, monkeypatch):
    """The line-by-line reader (after the engine refused) holds a piece of the file's text at a
    time and the samples read so far as numbers (what a successful read returns), not the whole
    text and its lines (3.7 times the file's size: 1.66 GB for a 450 MB recording)."""
    import tracemalloc

    monkeypatch.setattr(capture_io, "PIECE_BYTES", 1 << 16)
    n = 60_000
    rows = "".join(f"{k / 1000:.3f},0.123456789,0.223456789,9.80665,0.00123,0.00223,0.00323\n" for k in range(n))
    content = "t,ax,ay,az,gx,gy,gz\n" + rows[:-60] + "x" * 59 + "\n"
    path = tmp_path / "long.csv"
    path.write_text(content)
    tracemalloc.start()
    try:
        data, problem, _ = capture_io._parse_csv_file(path, 1000.0, path, None)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert data is None and f"line {n + 1}: " in str(problem), problem
    samples = n * 7 * 8                          # the float64 values of the rows
    assert peak < 1.25 * samples + 8 * capture_io.PIECE_BYTES < len(content) * 2, (peak, samples, len(content))


def test_the_digest_of_a_capture_not_read_hashes_its_files_as_reading_would(optimal9_run):
    """capture_digest of a capture whose samples were never read hashes each file itself (a
    buffer at a time): the same digest as after reading them."""
    from station.estimate import capture_digest

    unread = read_capture(optimal9_run, load_data=False)
    assert all(seg.content_sha256 is None for seg in unread.complete())
    assert capture_digest(unread) == capture_digest(read_capture(optimal9_run))


def test_estimate_warns_of_an_incomplete_segment_as_a_loaded_read_does(optimal9_run, tmp_path, capsys):
    """A run stopped during its last segment: `station estimate` (which reads the capture a
    segment at a time, in a child process) says what the incomplete segment holds, as reading
    the capture whole does, and estimates from the complete ones."""
    import shutil

    import yaml

    from station.cli import main

    cap = tmp_path / "cap"
    shutil.copytree(optimal9_run, cap)
    manifest = yaml.safe_load((cap / "manifest.yaml").read_text())
    content = (cap / "pos01.csv").read_bytes()
    (cap / "extra.csv").write_bytes(content[:content.rfind(b"\n", 0, len(content) // 2) + 1] + b"12.3,4")
    manifest["segments"].append({"name": "extra", "kind": "static", "file": "extra.csv", "status": "incomplete",
                                 "up_body": [0, 0, 1]})
    (cap / "manifest.yaml").write_text(yaml.safe_dump(manifest, sort_keys=False))
    expected = read_capture(cap).warnings
    assert any("segments[21] (extra): incomplete, " in w and "readable rows" in w for w in expected), expected
    assert main(["estimate", str(cap), "-o", str(tmp_path / "cal.yaml")]) == 0
    err = capsys.readouterr().err
    assert all(f"warning: {w}" in " ".join(err.split()) for w in expected), (err, expected)


def test_lossy_segments_and_resolution_are_checked_on_a_capture_read_without_its_samples(optimal9_run, tmp_path):
    """exclude_lossy_segments and check_resolution read each segment in turn when the capture was
    read without its samples (they found nothing to check: no segment excluded, silently)."""
    import shutil

    import yaml

    from station.estimate import check_resolution, exclude_lossy_segments

    cap = tmp_path / "cap"
    shutil.copytree(optimal9_run, cap)
    lines = (cap / "pos02.csv").read_bytes().splitlines(keepends=True)
    lossy = lines[:1] + lines[1::2]                       # every other frame lost
    (cap / "pos02.csv").write_bytes(b"".join(lossy))
    manifest = yaml.safe_load((cap / "manifest.yaml").read_text())
    seg = next(s for s in manifest["segments"] if s["name"] == "pos02")
    seg["samples"], seg["sha256"] = len(lossy) - 1, hashlib.sha256(b"".join(lossy)).hexdigest()
    (cap / "manifest.yaml").write_text(yaml.safe_dump(manifest, sort_keys=False))
    want = exclude_lossy_segments(read_capture(cap))
    streamed = read_capture(cap, load_data=False)
    assert exclude_lossy_segments(streamed) == want and len(want) == 1 and "pos02" in want[0]
    assert [s.name for s in streamed.segments if s.status == "excluded"] == ["pos02"]
    assert all(s.data is None for s in streamed.segments)          # each read in turn, none kept
    check_resolution(read_capture(cap, load_data=False))            # no AttributeError: checked


@pytest.mark.parametrize("piece_bytes", [7, 1 << 16])
def test_an_incomplete_segment_is_counted_for_its_warnings_not_kept(tmp_path, monkeypatch, piece_bytes):
    """What `estimate` reads an incomplete segment for (its readable rows, its gaps, what is
    wrong with its last line) is said as a loaded read says it, from its rows counted a piece
    at a time: no sample kept (it held 162 bytes a sample of samples never used: 1.6 GB for a
    stopped 10 M-row recording)."""
    import tracemalloc

    monkeypatch.setattr(capture_io, "PIECE_BYTES", piece_bytes)
    n = 40_000 if piece_bytes > 100 else 400
    times = np.delete(np.arange(n + 5), [10, 11, n // 2]) / 100.0          # two gaps
    rows = "".join(f"{t:.2f},0.1,0.2,9.8,0.01,0.02,0.03\n" for t in times)
    content = "t,ax,ay,az,gx,gy,gz\n" + rows + "12.3,4"                 # stopped mid-line
    manifest = base_manifest()
    manifest["segments"][0]["status"] = "incomplete"
    bundle = make_bundle(tmp_path, manifest, files={"pos01.csv": content})
    loaded = read_capture(bundle)
    streamed = read_capture(bundle, load_data=False)
    seg = streamed.segments[0]
    tracemalloc.start()
    try:
        streamed.check_incomplete(seg)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert seg.data is None and seg.problem == loaded.segments[0].problem
    assert streamed.warnings == loaded.warnings
    assert any(f"incomplete, {len(times)} readable rows" in w for w in loaded.warnings), loaded.warnings
    assert any("2 gaps in time" in w for w in loaded.warnings), loaded.warnings
    if piece_bytes > 100:
        assert peak < 16 * piece_bytes < len(times) * 7 * 8, peak   # pieces, not the samples


@pytest.mark.parametrize("status", ["complete", "incomplete"])
def test_a_line_without_end_is_refused_at_its_start_not_read_to_its_end(tmp_path, monkeypatch, status):
    """Hundreds of megabytes without a line end took time quadratic in their size and seven
    times it in memory: a line longer than MAX_LINE_BYTES is refused as soon as it is seen,
    naming its line, after the lines before it (an incomplete segment keeps them)."""
    monkeypatch.setattr(capture_io, "PIECE_BYTES", 1000)
    monkeypatch.setattr(capture_io, "MAX_LINE_BYTES", 5000)
    rows = "".join(f"{k / 100:.2f},0.1,0.2,9.8,0.01,0.02,0.03\n" for k in range(200))
    content = "t,ax,ay,az,gx,gy,gz\n" + rows + "1" * 10**6          # line 202: no end
    manifest = base_manifest()
    manifest["segments"][0]["status"] = status
    bundle = make_bundle(tmp_path, manifest, files={"pos01.csv": content})
    if status == "complete":
        message = refusal(bundle)
        assert ": line 202: a line longer than 5000 bytes" in message, message
    else:
        seg = read_capture(bundle).segments[0]
        assert len(seg.data.t) == 200 and "line 202: a line longer than 5000 bytes" in seg.problem


def test_jittering_stamps_are_no_gaps_but_a_lost_frame_is(tmp_path):
    """Host stamps jittering by ±0.3 period made steps of 1.6 periods, each warned of as a gap
    ("lost samples": a stress test found 133 in one segment); a frame really lost through the
    jitter is still a gap (station.io.capture.stamp_gaps)."""
    rng = np.random.default_rng(2)
    n = 3000
    times = np.arange(n) / 100.0 + rng.uniform(-0.3, 0.3, n) / 100.0
    assert np.diff(times).max() > 1.5 / 100.0
    for name, t in (("jitter", times), ("lost", np.delete(times, 1500))):
        rows = "".join(f"{x:.5f},0.1,0.2,9.8,0.01,0.02,0.03\n" for x in t)
        directory = tmp_path / name
        directory.mkdir()
        capture = read_capture(make_bundle(directory, files={"pos01.csv": "t,ax,ay,az,gx,gy,gz\n" + rows}))
        gaps = capture.segments[0].data.gaps
        assert gaps == (0 if name == "jitter" else 1), (name, gaps, capture.warnings)
        assert any("gaps in time" in w for w in capture.warnings) == (name == "lost")
