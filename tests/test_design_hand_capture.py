"""A capture whose turns were made by hand (no table angle or rate: imucal's annotated session,
a real recording) cannot be extended by `station design --from`: the designer weighs a table's
segments against the capture's own.  diagnose printed `--from ... --reveal` commands for it, and
the command ended in a traceback ("candidate chunks with different shared columns")."""
from __future__ import annotations

from pathlib import Path

from station import cli
from station.io.importers import imucal

ANNOTATED = Path(__file__).parent / "data" / "imucal" / "annotated_session.csv"


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
