"""One diagnosis (station.diagnose.pipeline.run) behind ``station diagnose``, ``station report``
and ``station.api.diagnose``: the same verdict, account of a failing fit and suggestions, with
and without --auto (review of 28a7a67..main, item 1)."""
import html
import json

import numpy as np
import pytest

import simhelpers
from station import api
from station.cli import main
from station.diagnose.as_json import to_json
from station.io.scheme import load_scheme
from station.simulate import dryrun

# optimal9 with short dwells and rotations fast enough to excite a lever arm: ~0.3 s to record
FAST = {"rate_dps": 100.0, "rotation_s": 36.0, "dwell_s": 10.0}
# a lever arm of ~1 cm: the base model's fit fails by a reduced chi2 of hundreds
POSITIONS_M = np.array([[0.012, 0.004, -0.006], [-0.005, 0.009, 0.007], [0.006, -0.008, -0.014]])


@pytest.fixture(scope="module")
def captures(tmp_path_factory):
    root = tmp_path_factory.mktemp("pipeline")
    truth = dryrun.load_truth(None, 0)
    scheme = load_scheme("optimal9", FAST)
    return {"passing": dryrun.record_scheme(scheme, truth, 3, root / "passing"),
            "failing": dryrun.record_scheme(scheme, simhelpers.hide(truth, accel__position_m=POSITIONS_M), 3,
                                            root / "failing")}


def _said(doc) -> dict:
    """What the three must agree on: the verdict, the account of a failing fit, the suggestions."""
    return {"verdict": doc["verdict"], "failure_account": doc["failure_account"],
            "design_suggestions": doc["design_suggestions"], "not_revealed": doc["not_revealed"],
            "effects": doc["effects"],
            "candidates": [(c["effect"], c["significant"], c["design_command"], c["separate_commands"])
                           for c in doc["candidates"]]}


@pytest.mark.parametrize("which", ["failing", "passing"])
def test_diagnose_report_and_the_api_say_the_same_without_auto(captures, which, tmp_path, capsys):
    cap = captures[which]
    assert main(["diagnose", str(cap), "--json"]) == 0
    cli = _said(json.loads(capsys.readouterr().out))
    from_api = _said(to_json(api.diagnose(cap), []))
    assert from_api == cli

    # station report --no-auto: the page's diagnosis is the same one (station.diagnose.report
    # builds the page from it); its words are on the page
    from station.diagnose.report import report_input
    from station.io.capture import read_capture

    inp = report_input(read_capture(cap, load_data=False), auto=False)
    assert _said(to_json(inp.final, inp.steps)) == cli
    page = tmp_path / "report.html"
    assert main(["report", str(cap), "--no-auto", "-o", str(page)]) == 0
    text = page.read_text()
    for line in [cli["verdict"], *cli["failure_account"], *cli["design_suggestions"]]:
        assert html.escape(line) in text, line

    if which == "failing":
        # the account of a fit that fails (auto.conclude) is there: the comparison above can fail
        assert "does not explain the data" in cli["verdict"] and cli["failure_account"]
    else:
        assert "explains the data" in cli["verdict"] and not cli["failure_account"]


def test_with_auto_the_three_say_the_same(captures, capsys):
    cap = captures["failing"]
    assert main(["diagnose", str(cap), "--auto", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    cli = _said(doc)
    assert [s["added"] for s in doc["steps"]] == ["accel_lever_arm"]
    final = api.diagnose(cap, auto=True)
    assert _said(to_json(final, final.steps)) == cli
    from station.diagnose.report import report_input
    from station.io.capture import read_capture

    inp = report_input(read_capture(cap, load_data=False), auto=True)
    assert _said(to_json(inp.final, inp.steps)) == cli
