"""Samples formatted once and written as runs of rows (an import's session and its parts, issue
27 item 2) give the same files, hashes and manifest as write() of the same samples."""
import numpy as np
import pytest
import yaml

from station.io.capture import CaptureWriter, FormattedRows, ImuInfo, Site


def bundle(path, t, a, g, temp, runs, formatted: bool):
    writer = CaptureWriter(path, ImuInfo(100.0, "raw", "raw"), Site(9.8))
    rows = FormattedRows(t, a, g, temp) if formatted else None
    for k, (start, stop) in enumerate(runs):
        with writer.begin_segment(f"s{k}", "static") as seg:
            if formatted:
                seg.write_rows(rows, start, stop)
            else:
                seg.write(t[start:stop], a[start:stop], g[start:stop], None if temp is None else temp[start:stop])
            seg.close()
    return {p.name: p.read_bytes() for p in sorted(path.iterdir()) if p.suffix == ".csv"}, \
        [{k: v for k, v in s.items() if k != "started_utc"} for s in yaml.safe_load((path / "manifest.yaml").read_text())["segments"]]


@pytest.mark.parametrize("with_temp", [False, True])
def test_runs_of_formatted_rows_are_the_same_bytes_as_writes(tmp_path, with_temp):
    rng = np.random.default_rng(3)
    n = 1000
    t = 1e5 + np.cumsum(rng.uniform(0.009, 0.011, n))
    a = 32768 + rng.normal(size=(n, 3)) * 1e3
    g = rng.normal(size=(n, 3)) * 1e-7
    temp = 25 + rng.normal(size=n) if with_temp else None
    runs = [(0, n), (0, 1), (10, 400), (400, 401), (999, 1000)]
    assert bundle(tmp_path / "a", t, a, g, temp, runs, True) == bundle(tmp_path / "b", t, a, g, temp, runs, False)


def test_bad_samples_and_runs_are_refused(tmp_path):
    with pytest.raises(ValueError):
        FormattedRows([0.0, 1.0], [[1, 2, 3], [1, 2, np.nan]], [[0, 0, 0]] * 2)
    with pytest.raises(ValueError):
        FormattedRows([1.0, 1.0], [[1, 2, 3]] * 2, [[0, 0, 0]] * 2)
    rows = FormattedRows([0.0, 1.0, 2.0], [[1, 2, 3]] * 3, [[0, 0, 0]] * 3)
    writer = CaptureWriter(tmp_path / "c", ImuInfo(100.0, "raw", "raw"), Site(9.8))
    with writer.begin_segment("s", "static") as seg:
        with pytest.raises(ValueError):
            seg.write_rows(rows, 2, 4)
        seg.write_rows(rows, 1, 3)
        with pytest.raises(ValueError):        # time must go on increasing within a segment
            seg.write_rows(rows, 0, 1)
        seg.close()
