"""The calibration history: filing per IMU serial (SQLite index), listing, diff in units and in
combined sigma with > 3 sigma flags, the drift plot."""
import sqlite3

import pytest
import yaml

from station.cli import main
from station.io.calcompare import changes
from station.io.calfile import read_calfile
from station.io.history import INDEX, Store, serial_folder


@pytest.fixture
def store(tmp_path, monkeypatch):
    root = tmp_path / "store"
    monkeypatch.setenv("STATION_HISTORY_DIR", str(root))
    return root


def shifted_copy(cal, target, name, n_sigma, date):
    doc = yaml.safe_load(cal.read_text())
    p = doc["parameters"][name]
    p["value"] += n_sigma * p["sigma"]
    doc["provenance"]["date_utc"] = date
    target.write_text(yaml.safe_dump(doc, sort_keys=False))
    return target


def test_estimate_files_the_calibration_and_history_lists_it(optimal9_run, store, tmp_path, capsys):
    target = tmp_path / "again.yaml"
    assert main(["estimate", str(optimal9_run), "-o", str(target)]) == 0
    assert "history: filed as #1 for IMU SIM-13" in capsys.readouterr().out
    assert main(["history", "--add", str(target)]) == 0          # the same bytes: filed once
    assert "already filed: #1" in capsys.readouterr().out
    assert main(["history", "SIM-13"]) == 0
    listing = capsys.readouterr().out
    assert "optimal9" in listing and "lsq" in listing and "#1" in listing
    db = sqlite3.connect(store / INDEX)
    assert db.execute("SELECT serial, scheme, method FROM calibrations").fetchall() == [("SIM-13", "optimal9", "lsq")]
    (entry,) = Store(store).list("SIM-13")
    assert entry.path.read_bytes() == target.read_bytes() and entry.path.parent == store / "SIM-13"


def test_diff_flags_exactly_the_parameter_moved_beyond_3_sigma(optimal9_run, store, tmp_path, capsys):
    cal = optimal9_run / "calibration.yaml"
    moved = shifted_copy(cal, tmp_path / "moved.yaml", "accel_bias_x", 10.0, "2030-01-01T00:00:00Z")
    assert main(["history", "--add", str(cal), "--add", str(moved)]) == 0
    rows, only_a, only_b = changes(read_calfile(cal), read_calfile(moved))
    flagged = [c.name for c in rows if c.flagged]
    assert flagged == ["accel_bias_x"] and not only_a and not only_b
    c = next(c for c in rows if c.name == "accel_bias_x")
    # same sigma on both sides: a 10 sigma move is 10 / sqrt(2) combined sigma
    assert c.z == pytest.approx(10.0 / 2**0.5, rel=1e-9) and c.unit == "ug"
    capsys.readouterr()
    assert main(["diff", "#1", "#2"]) == 0
    text = capsys.readouterr().out
    assert "accel_bias_x" in text and "> 3σ" in text and "1 of 21 parameters" in text
    png = tmp_path / "drift.png"
    assert main(["history", "SIM-13", "--drift", str(png)]) == 0
    assert png.stat().st_size > 20_000
    png2 = tmp_path / "drift2.png"
    assert main(["diff", str(cal), str(moved), "--drift", str(png2)]) == 0
    assert png2.stat().st_size > 20_000


def test_untrusted_serial_stays_inside_the_store(optimal9_run, store, tmp_path):
    doc = yaml.safe_load((optimal9_run / "calibration.yaml").read_text())
    doc["provenance"]["imu_serial"] = "../../etc/passwd"
    cal = tmp_path / "evil.yaml"
    cal.write_text(yaml.safe_dump(doc, sort_keys=False))
    entry, new = Store(store).file(cal)
    assert new and entry.serial == "../../etc/passwd"
    assert entry.path.resolve().is_relative_to(store.resolve())
    assert serial_folder("..") == "_" and serial_folder("a/b") == "a_b"


def test_unknown_serial_and_unknown_id_are_one_line_errors(store, capsys):
    assert main(["history", "NOPE"]) == 2
    assert "NOPE" in capsys.readouterr().err
    assert main(["diff", "#7", "#8"]) == 2
    assert "#7" in capsys.readouterr().err
