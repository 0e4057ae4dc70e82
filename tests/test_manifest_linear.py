"""A dry run's and an import's bundle: the manifest written a fixed number of times, not twice a
segment (issue 27 item 4: a run's writer rewrites the whole manifest at every segment's start
and end, quadratic in the segments); a dry run stopped mid-way still leaves a readable bundle."""
import pytest

from station.io import capture
from station.io.capture import read_capture
from station.io.scheme import load_scheme
from station.simulate import dryrun


def _scheme(tmp_path, statics):
    lines = ["name: short", "title: short statics", "reference: test", "defaults:", "  dwell_s: 0.2",
             "segments:"]
    ups = ([0, 0, 1], [0, 0, -1], [1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0])
    lines += [f"  - {{static: s{i:03d}, up_body: {ups[i % 6]}}}" for i in range(statics)]
    path = tmp_path / "short.yaml"
    path.write_text("\n".join(lines) + "\n")
    return load_scheme(str(path))


def _manifest_writes(monkeypatch):
    writes = []
    real = capture._atomic_write

    def counted(path, data):
        if path.name == capture.MANIFEST:
            writes.append(len(data))
        return real(path, data)

    monkeypatch.setattr(capture, "_atomic_write", counted)
    return writes


@pytest.mark.parametrize("statics", [6, 24])
def test_a_dry_run_writes_its_manifest_twice_whatever_its_segments(tmp_path, monkeypatch, statics):
    writes = _manifest_writes(monkeypatch)
    out = dryrun.record_scheme(_scheme(tmp_path, statics), dryrun.load_truth(None, 0), 1, tmp_path / "cap")
    assert len(writes) == 2            # created, finished (a run's writer: 1 + 2 a segment)
    cap = read_capture(out, load_data=False)
    assert [s.name for s in cap.segments] == [f"s{i:03d}" for i in range(statics)]
    assert all(s.status == "complete" and s.extra["samples"] > 0 for s in cap.segments)


def test_a_dry_run_stopped_midway_leaves_a_readable_bundle(tmp_path, monkeypatch):
    def stop_at_fourth(name, i, n):
        if i == 3:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        dryrun.record_scheme(_scheme(tmp_path, 6), dryrun.load_truth(None, 0), 1, tmp_path / "cap",
                             progress=stop_at_fourth)
    cap = read_capture(tmp_path / "cap")
    assert [(s.name, s.status) for s in cap.segments] == [(f"s{i:03d}", "complete") for i in range(3)]
