"""Delimited logs read by numpy's C reader give what the line-by-line reader gives (issue 27,
item 2): the same values, line numbers, header, and for bad input the same one-line error."""
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from station.core.errors import UserError
from station.io.importers import delimited

NUMBER = st.one_of(st.integers(-40000, 70000).map(str),
                   st.floats(allow_nan=False, allow_infinity=False, width=64).map(lambda v: f"{v:.10g}"),
                   st.sampled_from(["nan", "inf", "-1e-3", "+5", "1_0", "0x10", "", " 7 ", "1.5d3", "x"]))
DELIM = st.sampled_from([",", ";", "\t", " ", "  "])


@st.composite
def logs(draw):
    delim = draw(DELIM)
    width = draw(st.integers(1, 5))
    out = []
    if draw(st.booleans()):
        out.append(delim.join(f"c{k}" for k in range(width)))
    for _ in range(draw(st.integers(0, 12))):
        kind = draw(st.sampled_from(["data"] * 6 + ["blank", "comment", "short", "indent"]))
        if kind == "blank":
            out.append(draw(st.sampled_from(["", "  ", "\t"])))
        elif kind == "comment":
            out.append(draw(st.sampled_from(["# note", "  % x", "#"])))
        else:
            n = width - 1 if kind == "short" and width > 1 else width
            fields = [draw(NUMBER) for _ in range(n)]
            out.append(("  " if kind == "indent" else "") + delim.join(fields))
    end = draw(st.sampled_from(["\n", "", "\r\n"]))
    return end.join(out) + (end if draw(st.booleans()) else "")


def read(path, fast: bool, delimiter, header):
    saved = delimited._Table._parse_whole
    if not fast:
        delimited._Table._parse_whole = lambda self, *a: None
    try:
        table = delimited._Table(path, delimiter, header)
        return ("table", table.names, table.numbers.tolist(), table.width, table.count, table.delimiter,
                [_column(table, j) for j in range(table.width)])
    except UserError as e:
        return ("error", str(e))
    finally:
        delimited._Table._parse_whole = saved


def _column(table, j):
    try:
        return table.column("ax", j).tolist()
    except UserError as e:
        return str(e)


@settings(max_examples=250, deadline=None, suppress_health_check=list(HealthCheck))
@given(text=logs(), delimiter=st.sampled_from([None, ",", "space"]), header=st.sampled_from(["auto", "no", "yes"]))
def test_the_c_reader_reads_what_the_line_reader_reads(tmp_path_factory, text, delimiter, header):
    path = tmp_path_factory.mktemp("log") / "log.txt"
    path.write_bytes(text.encode("utf-8"))
    assert read(path, True, delimiter, header) == read(path, False, delimiter, header)


def test_a_plain_numeric_log_takes_the_c_reader(tmp_path):
    rng = np.random.default_rng(1)
    data = np.column_stack([np.arange(2000) * 0.01, 32768 + rng.integers(-500, 500, (2000, 3))])
    path = tmp_path / "acc.txt"
    np.savetxt(path, data, fmt="%.7f %d %d %d", header="comment line", comments="# ")
    table = delimited._Table(path, "space", "no")
    assert table.values is not None and table.fields is None
    assert table.numbers[0] == 2 and table.count == 2000
    np.testing.assert_array_equal(np.column_stack([table.column("x", j) for j in range(4)]), np.round(data, 7))
