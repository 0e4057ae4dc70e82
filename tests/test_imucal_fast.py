"""imucal sessions parsed by numpy's C reader (issue 27 item 2): the same values as the
line-by-line reader, and on any line it might read otherwise the line-by-line reader's message."""
import numpy as np
import pytest

from station.core.errors import UserError
from station.io.importers import imucal

SECTIONS = '{"x_p": {"start": 0, "end": 10}, "x_rot": {"start": 10, "end": 20}}'
TOKENS = ["0.1", " 0.1", "0.1 ", "+0.1", "-0", "1e3", "1E-3", ".5", "5.", "1_000", "0x10", "", " ", "nan", "inf",
          "-Infinity", "1e400", "abc", "1.5.2", "1,5", "'1'", '"1"', "1d3", "١", "1e", "e1", "+-1", "\t2", "0.1\x0c",
          "9" * 40, "4.9406564584124654e-324", "2.2250738585072011e-308", "0.1000000000000000055511151231257827"]


def session(field: str, line: int = 5, blank: bool = False) -> str:
    rows = ["n_samples,gyr_x,gyr_y,gyr_z,acc_x,acc_y,acc_z"]
    rng = np.random.default_rng(line)
    for i in range(20):
        v = rng.normal(0.0, 3.0, 6)
        rows.append(f"{i}," + ",".join(repr(float(x)) for x in v))
    rows[line - 1] = rows[line - 1].rsplit(",", 1)[0] + "," + field
    if blank:
        rows.insert(8, "")
    return "\n".join(rows) + "\n"


def outcome(tmp_path, text, fast: bool, monkeypatch):
    csv, js = tmp_path / "s.csv", tmp_path / "s.json"
    csv.write_bytes(text.encode("utf-8"))
    js.write_text(SECTIONS)
    with monkeypatch.context() as m:
        if not fast:
            m.setattr(imucal, "_parsed_fast", lambda *a: None)
        try:
            sections, whole = imucal.read_session(csv, js, 102.4)
        except UserError as e:
            return "error", str(e)
    return "ok", (whole.t.tobytes(), whole.accel.tobytes(), whole.gyro.tobytes(),
                  [(s.label, s.first_line, s.t.tobytes()) for s in sections])


@pytest.mark.parametrize("token", TOKENS)
@pytest.mark.parametrize("blank", [False, True])
def test_fast_reader_agrees_with_the_line_reader(tmp_path, monkeypatch, token, blank):
    text = session(token, blank=blank)
    assert outcome(tmp_path, text, True, monkeypatch) == outcome(tmp_path, text, False, monkeypatch)


def test_the_example_session_takes_the_fast_path(tmp_path, monkeypatch):
    """(Else the test above would compare the line reader with itself.)"""
    calls = []
    fast = imucal._parsed_fast
    monkeypatch.setattr(imucal, "_parsed_fast", lambda *a: calls.append(fast(*a)) or calls[-1])
    csv, js = tmp_path / "s.csv", tmp_path / "s.json"
    csv.write_text(session("0.25"))
    js.write_text(SECTIONS)
    imucal.read_session(csv, js, 102.4)
    assert calls and calls[0] is not None and calls[0].shape == (20, 7)
