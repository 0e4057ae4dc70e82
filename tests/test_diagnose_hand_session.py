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


def test_an_imported_capture_gets_no_design_command_and_the_command_refuses_in_one_line(tmp_path, capsys,
                                                                                         monkeypatch):
    """imucal's Ferraris session imported with its turns' nominal 360 deg has a rate and an angle
    for every turn, so the hand rule does not apply: diagnose printed `station design --from`
    commands and the designer proposed segments on the built-in simulated bench's 3-axis table
    (no run.yaml in the capture) -- a table the user may not have, for a capture that `station
    run --append` cannot record into (it needs a run's run.yaml).  Both now say so instead (issue
    28, eighteenth session).  The other side: a dry run's capture is still extended, on the
    table station.yaml describes when there is one (named as such: "the built-in simulated
    bench's" was said whatever was read)."""
    from station.design import sequential
    from station.io.capture import read_capture

    path = imucal.import_imucal(SESSION, tmp_path / "b", rate_hz=102.4, sections_path=SECTIONS, turn_deg=360.0)
    capsys.readouterr()
    assert cli.main(["diagnose", str(path)]) == 0
    printed = " ".join("".join(capsys.readouterr()).split())
    assert "--reveal" not in printed and "--separate" not in printed
    assert "no `station design --from` command: this capture was imported (imucal)" in printed
    rc = cli.main(["design", "--from", str(path), "--add", "temperature_bias", "--reveal", "accel_bias_tempco_*",
                   "-o", str(tmp_path / "ext.yaml")])
    err = capsys.readouterr().err
    assert rc == 2 and "Traceback" not in err
    assert f"{path}: imported (imucal), not a capture of station run" in " ".join(err.split())
    assert not (tmp_path / "ext.yaml").exists()
    # the other side, without a design: a dry run's capture is not "imported"; its table is
    # ./station.yaml's when there is one, named so
    from station.diagnose.suggest import imported
    from station.simulate import dryrun

    dry = dryrun.record_scheme(_two_statics(), dryrun.load_truth(None, 1), 1, tmp_path / "dry")
    assert imported(read_capture(dry, load_data=False)) is None
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("STATION_CONFIG", raising=False)
    assert sequential.capture_config(dry, None)[1].startswith("the built-in simulated bench's table")
    (tmp_path / "station.yaml").write_text("version: 1\n")
    assert sequential.capture_config(dry, None)[1] == "the table of station.yaml (a dry run's capture: no run.yaml in it)"


def _two_statics():
    from station.io.scheme import scheme_from_text

    return scheme_from_text("name: two\nsegments:\n"
                            "  - {static: up, up_body: [0, 0, 1], dwell_s: 2}\n"
                            "  - {static: down, up_body: [0, 0, -1], dwell_s: 2}\n", "two.yaml")
