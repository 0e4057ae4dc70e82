"""imucal's annotated session (a real recording, turns by hand): what diagnose says of it.

A capture whose turns were made by hand (no table angle or rate: imucal's annotated session,
a real recording) cannot be extended by `station design --from`: the designer weighs a table's
segments against the capture's own.  diagnose printed `--from ... --reveal` commands for it, and
the command ended in a traceback ("candidate chunks with different shared columns")."""
from __future__ import annotations

from pathlib import Path

from station import cli
from station.io.importers import imucal

DATA = Path(__file__).parent / "data" / "imucal"
ANNOTATED = DATA / "annotated_session.csv"
SESSION = DATA / "example_ferraris_session.csv"
SECTIONS = DATA / "example_ferraris_session_list.json"


def test_hand_turns_get_no_design_command_and_the_command_refuses_in_one_line(tmp_path, capsys):
    path = imucal.import_imucal(ANNOTATED, tmp_path / "a", rate_hz=204.8)
    capsys.readouterr()
    assert cli.main(["diagnose", str(path)]) == 0
    out = capsys.readouterr()
    printed = " ".join((out.out + out.err).split())
    assert "--reveal" not in printed and "--separate" not in printed     # no command is printed
    assert "no `station design --from` command: x_rot, y_rot, z_rot turned without a table's angle" in printed
    rc = cli.main(["design", "--from", str(path), "--add", "time_offset", "--reveal", "time_offset",
                   "-o", str(tmp_path / "ext.yaml")])
    err = capsys.readouterr().err
    assert rc == 2 and "Traceback" not in err
    assert "x_rot, y_rot, z_rot turned without a table's angle and rate (by hand)" in err
    assert not (tmp_path / "ext.yaml").exists()


def test_a_diagnosis_whose_fit_stopped_at_its_limit_says_not_converged_first(tmp_path, capsys, monkeypatch):
    """The same session's base fit stops at the solver's evaluation limit (lsq.MAX_EVALUATIONS)
    short of its minimum; the diagnosis printed "the model does not explain the data (reduced chi2
    10.1)" as if that were the model's chi2.  It now says first that the fit did not converge, on
    screen and in --json, and keeps the solver's note.  A fit given enough evaluations to converge
    does not say it (the other side)."""
    import json

    from station.estimate import lsq

    path = imucal.import_imucal(ANNOTATED, tmp_path / "a", rate_hz=204.8)
    capsys.readouterr()
    monkeypatch.setattr(lsq, "MAX_EVALUATIONS", 40)        # stops short, whatever the solver's path
    assert cli.main(["diagnose", str(path), "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["verdict"].startswith("not converged: the fit stopped at its evaluation limit")
    assert any(n.startswith("the fit stopped at its limit of 40 evaluations") for n in d["notes"])
    # the other side: a session whose fit converges (imucal's Ferraris session, whole turns)
    monkeypatch.undo()
    good = imucal.import_imucal(SESSION, tmp_path / "b", rate_hz=102.4, sections_path=SECTIONS, turn_deg=360.0)
    capsys.readouterr()
    assert cli.main(["diagnose", str(good), "--json"]) == 0
    assert not json.loads(capsys.readouterr().out)["verdict"].startswith("not converged")
