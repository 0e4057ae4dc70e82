"""The data lines of a delimited log found without the blank-and-comment expression when no line
can be one (issue 27, item 2): the same lines, numbers, values and messages as with it."""
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from station.io.importers import delimited
from test_delimited_fast import logs


def read(path, delimiter, header, quick: bool):
    saved = delimited._nothing_skipped
    if not quick:
        delimited._nothing_skipped = lambda text, lines: False
    try:
        table = delimited._Table(path, delimiter, header)
        return ("table", table.names, table.numbers.tolist(), table.width, table.count,
                None if table.values is None else repr(table.values.tolist()),
                None if table.fields is None else table.fields)
    except delimited.UserError as e:
        return ("error", str(e))
    finally:
        delimited._nothing_skipped = saved


# the cases the quick check must send to the expression: a blank or comment line anywhere
EDGES = ["1 2 3\n\n4 5 6\n", "  \n1 2 3\n", "1 2 3\n \t \n", "1 2 3\n4 5 6\n\n", "1 2 3\n% c\n4 5 6\n",
         "# h\n1 2 3\n", "1 2 3\n4 5 6 # x\n", "   1 2 3\n   4 5 6\n", "1 2 3", "1,2,3\n\u2003\n4,5,6\n",
         "t x\n1 2\n\u00a0\n3 4\n", "1 2 3\n4 5 6\n   "]


@pytest.mark.parametrize("text", EDGES)
def test_edges(tmp_path, text):
    path = tmp_path / "log.txt"
    path.write_bytes(text.encode("utf-8"))
    for header in ("auto", "no"):
        assert read(path, None, header, True) == read(path, None, header, False)


@settings(max_examples=200, deadline=None, suppress_health_check=list(HealthCheck))
@given(text=logs(), delimiter=st.sampled_from([None, ",", "space"]), header=st.sampled_from(["auto", "no", "yes"]))
def test_the_quick_check_reads_what_the_expression_reads(tmp_path_factory, text, delimiter, header):
    path = tmp_path_factory.mktemp("log") / "log.txt"
    path.write_bytes(text.encode("utf-8"))
    assert read(path, delimiter, header, True) == read(path, delimiter, header, False)
