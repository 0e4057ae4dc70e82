"""Hypothesis fuzz of a real calibration file and a real capture manifest through every command
that consumes them, structure-aware (issue 26 goal; thirteenth session).  tests/test_fuzz_readers.py
mutates a small hand-written calibration and manifest and calls the readers only; a file the
reader accepts can still break what comes after it (a matrix that inverts to inf, a bias of
1e308, an effect's parameter of another type, a manifest whose segment's field is a list).  Here
the documents are the ones station itself writes for a dry run (a full calibration: both triads,
effects, verdict, provenance; a manifest of 12 segments), every field found by walking them (4
levels deep) is set to another type or an absurd value (NaN, inf, 1e300, huge integers, text,
unicode, lists, mappings) or deleted, up to three at a time, and the commands run as the user
runs them (station.cli.main, in this process): show, apply, export to every format, diff and
diagnose --calib for the calibration; estimate for the manifest.  Each answers (0, or 3 for a fit
that fails) or refuses in one line with exit status 2; never a traceback, never a hang (an alarm
of HANG_S per example).

The long run: ``STATION_FUZZ_EXAMPLES=2000 python -m pytest tests/test_fuzz_consumers.py -n 0
--hypothesis-profile explore`` (benchmarks/fuzz_consumers.py counts the cases; docs/reliability.md)."""
import os
import shutil
from pathlib import Path

import pytest
import yaml
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from station.cli import main
from station.io.exporters import FORMATS
from test_bad_inputs import capture_dir  # noqa: F401 - a fixture: a small dry run, estimated
from test_fuzz_bags import time_limit
from test_fuzz_configs import mutated, paths
from test_fuzz_readers import values

EXAMPLES = int(os.environ.get("STATION_FUZZ_EXAMPLES", "6"))
FUZZ = settings(max_examples=EXAMPLES, deadline=None, suppress_health_check=list(HealthCheck))
# an example here is up to ~12 commands of 10-200 ms of CPU each; 60 s is a hang on a machine
# loaded 10x
HANG_S = 60.0
EXTRA = [1e308, -1e308, float("nan"), float("inf"), 0.0, -0.0, 10**400, "\u212a\u0000\ud7ff", [], {}, [[]], ""]
mutations = st.one_of(values, st.sampled_from(EXTRA))


@pytest.fixture(scope="module")
def noisy_capture(capture_dir, tmp_path_factory):  # noqa: F811
    """A copy of the dry run whose calibration carries noise figures (`station noise`): Kalibr's
    export needs them, and the fuzz mutates them too."""
    cap = Path(shutil.copytree(capture_dir, tmp_path_factory.mktemp("noisy") / "cap"))
    assert main(["noise", str(cap)]) == 0
    return cap


def commands(cal, cap, out: Path, good):
    yield ["show", cal]
    yield ["apply", cal, cap / "pos01.csv", "-o", out / "applied.csv", "--force"]
    for fmt in FORMATS:
        yield ["export", cal, "--to", fmt, "-o", out / f"export-{fmt}"]
    yield ["diff", cal, good]
    yield ["diagnose", cap, "--calib", cal, "--force"]


def runs_as_a_user_expects(argv, capsys, allowed=(0, 2), count=True):
    capsys.readouterr()
    with time_limit(HANG_S):
        code = main([str(a) for a in argv])
    err = capsys.readouterr().err
    assert code in allowed, (argv, code, err)
    if code == 2:
        lines = [ln for ln in err.splitlines() if ln.strip() and not ln.startswith("note:")]
        assert len(lines) == 1 and len(lines[0]) < 3000, (argv, err)
    if count:
        event(f"{argv[0]}: exit {code}")
    return code


@FUZZ
@given(data=st.data())
def test_fuzzed_calibration_through_every_command(noisy_capture, tmp_path_factory, capsys, data):
    capture_dir = noisy_capture
    good = capture_dir / "calibration.yaml"
    doc = yaml.safe_load(good.read_text())
    changes = data.draw(st.lists(st.tuples(st.sampled_from(paths(doc, depth=4)), mutations, st.booleans()),
                                 min_size=1, max_size=3))
    work = tmp_path_factory.mktemp("cal")
    cal = work / "cal.yaml"
    cal.write_text(yaml.safe_dump(mutated(doc, changes), allow_unicode=True))
    for argv in commands(cal, capture_dir, work, good):
        runs_as_a_user_expects(argv, capsys)


@FUZZ
@given(data=st.data())
def test_fuzzed_manifest_through_estimate(noisy_capture, tmp_path_factory, capsys, data):
    capture_dir = noisy_capture
    doc = yaml.safe_load((capture_dir / "manifest.yaml").read_text())
    changes = data.draw(st.lists(st.tuples(st.sampled_from(paths(doc, depth=4)), mutations, st.booleans()),
                                 min_size=1, max_size=3))
    cap = Path(shutil.copytree(capture_dir, tmp_path_factory.mktemp("m") / "cap"))
    (cap / "calibration.yaml").unlink()
    (cap / "manifest.yaml").write_text(yaml.safe_dump(mutated(doc, changes), allow_unicode=True))
    runs_as_a_user_expects(["estimate", cap, "-o", cap / "out.yaml"], capsys, allowed=(0, 2, 3))


def test_the_unmutated_files_are_answered(noisy_capture, tmp_path, capsys):
    """The fuzz starts from files every command answers (else it would test refusals only)."""
    capture_dir = noisy_capture
    good = capture_dir / "calibration.yaml"
    for argv in commands(good, capture_dir, tmp_path, good):
        assert runs_as_a_user_expects(argv, capsys, count=False) == 0, argv
    cap = Path(shutil.copytree(capture_dir, tmp_path / "cap"))
    assert runs_as_a_user_expects(["estimate", cap, "-o", cap / "out.yaml"], capsys, count=False) == 0
