"""Columns of whole numbers (raw counts) are formatted with "%d" (twice as fast: issue 27, item 2),
which must give the very text "%.12g" gives: the segment files' bytes and hashes do not depend on
which format wrote them.  Checked against the "%.12g" text itself, value by value."""
import hashlib

import numpy as np
import yaml
from hypothesis import given, settings, strategies as st

from station.io.capture import CaptureWriter, FormattedRows, ImuInfo, Site

# whole numbers where "%.12g" changes form (1e12: "1e+12"), the signed zeros, and fractions
EDGES = [0.0, -0.0, 1.0, -1.0, 32768.0, 65535.0, 999999999999.0, -999999999999.0, 1e12, -1e12,
         2.0 ** 53, 1e15, 0.5, -32767.5, 1e-7, 123456.25]


def reference(t, a, g) -> bytes:
    """The rows as "%.15g" (time) and "%.12g" (every other column) write them."""
    return "".join("%.15g," % t[i] + ",".join("%.12g" % v for v in (*a[i], *g[i])) + "\n"
                   for i in range(len(t))).encode("ascii")


@settings(max_examples=150, deadline=None)
@given(st.data(), st.integers(1, 6))
def test_formatted_rows_are_the_12g_text(data, n):
    # each of the six columns drawn whole, from the edges or any float, value by value
    kinds = [data.draw(st.sampled_from(["whole", "edges", "any"])) for _ in range(6)]
    draw = {"whole": st.integers(-2 ** 40, 2 ** 40).map(float), "edges": st.sampled_from(EDGES),
            "any": st.floats(-1e13, 1e13, allow_nan=False, allow_infinity=False)}
    values = np.array([[data.draw(draw[k]) for k in kinds] for _ in range(n)], dtype=np.float64)
    t = np.arange(n) * 0.01 + 0.02984
    rows = FormattedRows(t, values[:, :3], values[:, 3:])
    assert rows.data == reference(t, values[:, :3], values[:, 3:])


def test_a_segment_of_raw_counts_is_the_12g_file(tmp_path):
    rng = np.random.default_rng(5)
    n = 500
    t = np.arange(n) * 0.01 + 0.02984
    a = rng.integers(0, 65536, (n, 3)).astype(float)
    g = rng.integers(0, 65536, (n, 3)).astype(float)
    a[7, 1] = -0.0                      # a negative zero keeps its column on "%.12g" ("-0")
    writer = CaptureWriter(tmp_path / "c", ImuInfo(100.0, "raw", "raw"), Site(9.8))
    with writer.begin_segment("s", "static") as seg:
        seg.write(t[:200], a[:200], g[:200])
        seg.write(t[200:], a[200:], g[200:])
        seg.close()
    expected = b"t,ax,ay,az,gx,gy,gz\n" + reference(t, a, g)
    assert (tmp_path / "c" / "s.csv").read_bytes() == expected
    assert b",-0," in expected
    entry = yaml.safe_load((tmp_path / "c" / "manifest.yaml").read_text())["segments"][0]
    assert entry["sha256"] == hashlib.sha256(expected).hexdigest()
