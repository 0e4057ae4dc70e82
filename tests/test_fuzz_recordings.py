"""Hypothesis fuzz of recordings as ``station import csv`` reads them, structure-aware (issue 26
goal: "the structure-aware mutations of every input format ... recordings"): a hand session of
ten poses that imports, written as ``t,ax,ay,az,gx,gy,gz``, then changed in its structure —
the header's names (renamed, dropped, doubled), cells (nan, inf, 1e300, text, empty, NUL, a
quote), rows (dropped, doubled, cut short, given an extra cell, another delimiter), the time
column (a step back, a repeat, a gap), line ends — up to three at a time, and imported with
options drawn as a user gives them (preset, units, time unit or rate, column map, delimiter,
header).  station.api.import_csv (the command's code) writes a capture or raises UserError:
one line; never another exception, never a hang (an alarm of HANG_S)."""
import json
import os
from pathlib import Path

import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from station import api
from station.core.errors import UserError
from test_fuzz_bags import time_limit
from test_fuzz_configs import mutated, paths
from test_fuzz_readers import values

EXAMPLES = int(os.environ.get("STATION_FUZZ_EXAMPLES", "5"))
FUZZ = settings(max_examples=EXAMPLES, deadline=None, suppress_health_check=list(HealthCheck))
# the import of this 4,259-line log takes ~70 ms of CPU; 20 s is a hang on any machine
HANG_S = 20.0

CELLS = ["nan", "inf", "-inf", "1e300", "-1e300", "", " ", "x", "\x00", '"', "1e-320", "0x10", "1_0", "9.8",
         "0", "-0", "1,5", "\xff"]


@pytest.fixture(scope="module")
def log_lines(tmp_path_factory):
    from test_import_recordings import session, write_csv
    _, hs = session(poses=10, dwell_s=(2.5, 3.0))
    path = write_csv(tmp_path_factory.mktemp("log") / "log.csv", hs)
    return path.read_text().splitlines()


@st.composite
def mutated_log(draw, lines):
    header, rows = lines[0].split(","), [r.split(",") for r in lines[1:]]
    ending = "\n"
    for _ in range(draw(st.integers(1, 3))):
        what = draw(st.sampled_from(["header", "cell", "cell", "row", "time", "ending", "delimiter"]))
        r = draw(st.integers(0, len(rows) - 1))
        if what == "header":
            i = draw(st.integers(0, len(header) - 1))
            how = draw(st.sampled_from(["rename", "drop", "double"]))
            if how == "rename":
                header[i] = draw(st.sampled_from(["t", "ax", "gz", "temp", "", "x", "T", "time", "ax "]))
            elif how == "drop":
                del header[i]
            else:
                header.insert(i, header[i])
        elif what == "cell":
            c = draw(st.integers(0, 6))
            if c < len(rows[r]):
                rows[r][c] = draw(st.one_of(st.sampled_from(CELLS), st.text(max_size=5)))
        elif what == "row":
            how = draw(st.sampled_from(["drop", "double", "short", "extra", "block"]))
            if how == "drop":
                del rows[r]
            elif how == "double":
                rows.insert(r, list(rows[r]))
            elif how == "short":
                rows[r] = rows[r][:draw(st.integers(0, 6))]
            elif how == "extra":
                rows[r] = rows[r] + ["1"]
            else:                                   # a block of rows gone: a gap in the time
                del rows[r:r + draw(st.integers(2, 400))]
        elif what == "time":
            t = float(rows[r][0]) if rows[r] and rows[r][0].replace(".", "", 1).isdigit() else 0.0
            rows[r][0:1] = [repr(draw(st.sampled_from([t - 1.0, t - 1e-6, 0.0, t + 1e4, t * 1e9, -t])))]
            if len(rows) > r + 1 and draw(st.booleans()):
                rows[r + 1][0:1] = rows[r][0:1]      # a repeated stamp
        elif what == "ending":
            ending = draw(st.sampled_from(["\r\n", "\r", "\n\n"]))
        else:
            rows[r] = [";".join(rows[r])]
    return ending.join([",".join(header)] + [",".join(map(str, row)) for row in rows]) + ending


options = st.fixed_dictionaries({}, optional={
    "preset": st.sampled_from(["station", "t-a-g", "imu_tk", "imucal"]),
    "accel_unit": st.sampled_from(["m/s^2", "g", "mg", "raw", "rad/s", "x"]),
    "gyro_unit": st.sampled_from(["deg/s", "rad/s", "raw", "g"]),
    "time_unit": st.sampled_from(["s", "ms", "us", "ns", "h"]),
    "rate_hz": st.sampled_from([100.0, 0.0, -1.0, 1e-3, 1e7, float("nan"), 99.0]),
    "header": st.sampled_from(["auto", "yes", "no", "maybe"]),
    "delimiter": st.sampled_from([",", ";", "\t", "", "ab"]),
    "columns": st.dictionaries(st.sampled_from(["t", "ax", "ay", "az", "gx", "gy", "gz", "temp", "q"]),
                               st.integers(-2, 9), max_size=8),
})


@FUZZ
@given(data=st.data(), opts=options)
def test_fuzzed_recording(log_lines, tmp_path_factory, data, opts):
    d = tmp_path_factory.mktemp("rec")
    (d / "log.csv").write_text(data.draw(mutated_log(log_lines)), errors="surrogateescape")
    try:
        with time_limit(HANG_S):
            api.import_csv(d / "log.csv", d / "cap", **opts)
        event("imported")
    except UserError as e:
        assert "\n" not in str(e).strip() and len(str(e)) < 2000, str(e)
        event("refused")


def test_the_valid_log_imports(log_lines, tmp_path):
    """The fuzz starts from a log that imports (else it would test refusals only)."""
    (tmp_path / "log.csv").write_text("\n".join(log_lines) + "\n")
    report = api.import_csv(tmp_path / "log.csv", tmp_path / "cap")
    assert (tmp_path / "cap" / "manifest.yaml").is_file() and report.lines


# ------------------------------------------------------------------ imucal sessions (station import imucal)

IMUCAL = Path(__file__).parent / "data" / "imucal"


@pytest.fixture(scope="module")
def imucal_session():
    """imucal's own Ferraris example session (tests/data/imucal, MIT): its CSV lines and its
    sections list (JSON)."""
    return ((IMUCAL / "example_ferraris_session.csv").read_text().splitlines(),
            json.loads((IMUCAL / "example_ferraris_session_list.json").read_text()))


section_values = st.one_of(values, st.sampled_from([-1, 0, 9511, 9512, 10 ** 9, 2 ** 63, 1.5, "540", None]))

imucal_options = st.fixed_dictionaries({"rate_hz": st.sampled_from([102.4] * 6 + [0.5, 1e7, 0.0, float("inf"), -1.0])},
                                       optional={"turn_deg": st.sampled_from([360.0, -360.0, 0.0, 1e300, float("nan")]),
                                                 "fmt": st.sampled_from(["auto", "auto", "session", "annotated", "x"]),
                                                 "accel_unit": st.sampled_from(["m/s^2", "g", "x"]),
                                                 "gyro_unit": st.sampled_from(["deg/s", "rad/s", "x"])})


@FUZZ
@given(data=st.data(), opts=imucal_options, csv_too=st.booleans())
def test_fuzzed_imucal_session(imucal_session, tmp_path_factory, data, opts, csv_too):
    """The sections list's fields (every section's start and end, the names; set to another type,
    an absurd index, or deleted, up to three) and/or the session CSV's structure, with the
    options drawn (mostly the session's own rate)."""
    lines, sections = imucal_session
    d = tmp_path_factory.mktemp("imucal")
    changes = data.draw(st.lists(st.tuples(st.sampled_from(paths(sections)), section_values, st.booleans()),
                                 min_size=0, max_size=3))
    csv_too = csv_too or not changes
    (d / "sections.json").write_text(json.dumps(mutated(sections, changes)))
    text = data.draw(mutated_log(lines)) if csv_too else "\n".join(lines) + "\n"
    (d / "session.csv").write_text(text, errors="surrogateescape")
    try:
        with time_limit(HANG_S):
            api.import_imucal(d / "session.csv", d / "cap", sections_path=d / "sections.json", **opts)
        event("imported")
    except UserError as e:
        assert "\n" not in str(e).strip() and len(str(e)) < 2000, str(e)
        event("refused")


def test_the_valid_imucal_session_imports(imucal_session, tmp_path):
    lines, sections = imucal_session
    (tmp_path / "s.json").write_text(json.dumps(sections))
    (tmp_path / "s.csv").write_text("\n".join(lines) + "\n")
    assert (api.import_imucal(tmp_path / "s.csv", tmp_path / "cap", rate_hz=102.4, sections_path=tmp_path / "s.json")
            / "manifest.yaml").is_file()
