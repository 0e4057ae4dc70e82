"""The calibration history: filing per IMU serial (SQLite index), listing, diff in units and in
combined sigma with > 3 sigma flags, the drift plot."""
import sqlite3
import sys
from pathlib import Path

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
    """A later calibration of the same IMU (another capture: a re-estimate of the same capture
    and model would not be filed again)."""
    doc = yaml.safe_load(cal.read_text())
    p = doc["parameters"][name]
    p["value"] += n_sigma * p["sigma"]
    doc["provenance"]["date_utc"] = date
    doc["provenance"]["capture_sha256"] = "f" * 64
    target.write_text(yaml.safe_dump(doc, sort_keys=False))
    return target


def test_estimate_files_only_when_asked_and_simulations_apart(optimal9_run, store, tmp_path, capsys):
    """The history holds real calibrations: `estimate` files nothing unless asked; a simulated
    IMU's calibration (serial SIM-...) goes to the simulations' own store, never the lab's."""
    target = tmp_path / "again.yaml"
    assert main(["estimate", str(optimal9_run), "-o", str(target)]) == 0
    assert "history:" not in capsys.readouterr().out and not (store / INDEX).exists()
    assert main(["estimate", str(optimal9_run), "-o", str(tmp_path / "asked.yaml"), "--history"]) == 0
    assert "history: filed as #1 for IMU SIM-13" in capsys.readouterr().out
    assert not (store / INDEX).exists() and (store.with_name("store-simulations") / INDEX).exists()
    # estimated again (same capture, same model): not filed twice
    assert main(["estimate", str(optimal9_run), "-o", str(tmp_path / "twice.yaml"), "--history"]) == 0
    assert "already filed as #1 (this file, or the same capture and model)" in capsys.readouterr().out
    # asked explicitly, history --add files into the lab's store; the same bytes once
    assert main(["history", "--add", str(target)]) == 0
    assert "filed: #1" in capsys.readouterr().out
    assert main(["history", "--add", str(target)]) == 0
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


def test_bench_runs_file_real_imus_unless_told_not_to(optimal9_run, store, tmp_path, capsys):
    """A bench run's calibration of a real IMU is filed (run._estimate asks unless --no-history);
    not when not asked; one without a serial is never filed by itself."""
    from station.cli.history import file_quietly

    doc = yaml.safe_load((optimal9_run / "calibration.yaml").read_text())
    doc["provenance"]["imu_serial"] = "VN100-0042"
    real = tmp_path / "real.yaml"
    real.write_text(yaml.safe_dump(doc, sort_keys=False))
    file_quietly(real, asked=False)
    assert not (store / INDEX).exists()
    file_quietly(real, asked=True)
    assert "history: filed as #1 for IMU VN100-0042" in capsys.readouterr().out
    doc["provenance"]["imu_serial"] = None
    anonymous = tmp_path / "anonymous.yaml"
    anonymous.write_text(yaml.safe_dump(doc, sort_keys=False))
    file_quietly(anonymous, asked=True)
    assert "not filed: the calibration names no IMU serial" in capsys.readouterr().out
    assert [e.serial for e in Store(store).list("VN100-0042")] == ["VN100-0042"] and Store(store).serials() == [("VN100-0042", 1)]


def test_an_index_from_before_the_capture_columns_is_migrated(store, optimal9_run):
    """An index written before capture_sha256/model existed: opened, the columns added, filed."""
    store.mkdir(parents=True)
    db = sqlite3.connect(store / INDEX)
    db.execute("""CREATE TABLE calibrations (id INTEGER PRIMARY KEY, serial TEXT NOT NULL, date_utc TEXT NOT NULL,
        scheme TEXT, method TEXT, verdict TEXT, file TEXT NOT NULL, source TEXT, sha256 TEXT NOT NULL UNIQUE,
        filed_utc TEXT NOT NULL)""")
    db.commit()
    db.close()
    entry, new = Store(store).file(optimal9_run / "calibration.yaml")
    assert new and entry.id == 1


def test_diff_and_drift_mark_what_is_not_a_calibration(optimal9_run, store, tmp_path, capsys):
    """A parameter without a 1sigma is not counted as 'unchanged' (it is not judged, and said);
    a calibration whose fit fails is marked in diff and drawn apart in the drift plot."""
    cal = optimal9_run / "calibration.yaml"
    doc = yaml.safe_load(cal.read_text())
    doc["parameters"]["accel_bias_x"]["sigma"] = None
    doc["verdict"] = {"result": "fails", "reason": "reduced chi2 4210"}
    doc["provenance"]["date_utc"] = "2031-01-01T00:00:00Z"
    doc["provenance"]["capture_sha256"] = "e" * 64
    bad = tmp_path / "bad.yaml"
    bad.write_text(yaml.safe_dump(doc, sort_keys=False))
    capsys.readouterr()
    assert main(["diff", str(cal), str(bad)]) == 0
    captured = capsys.readouterr()
    assert "of 20 parameters with a 1σ on both sides" in captured.out
    assert "1 of 21 parameters have no 1σ in A or B: their change is not judged (accel_bias_x)" in " ".join(captured.out.split())
    assert "warning: B's fit does not pass (fails)" in captured.err
    assert main(["history", "--add", str(cal), "--add", str(bad)]) == 0
    png = tmp_path / "drift.png"
    capsys.readouterr()
    assert main(["history", "SIM-13", "--drift", str(png)]) == 0
    assert "drawn apart in the drift plot (not passing): #2 fails" in capsys.readouterr().err
    assert png.stat().st_size > 20_000


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the XDG variables are Linux's")
def test_the_store_and_the_configuration_folder_are_platformdirs_own(tmp_path, monkeypatch):
    """platformdirs (a dependency since issue 26) places them: the XDG base directories on Linux."""
    import platformdirs

    from station.bench.config import plugin_config, user_config_dir
    from station.io.history import default_store

    monkeypatch.delenv("STATION_HISTORY_DIR", raising=False)
    monkeypatch.delenv("STATION_CONFIG", raising=False)
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "data"))
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "config"))
    assert default_store() == tmp_path / "data" / "station" / "calibrations"
    assert user_config_dir() == tmp_path / "config" / "station" == Path(platformdirs.user_config_dir("station"))
    assert plugin_config(None) is None                      # no station.yaml of the user's own yet
    (tmp_path / "config" / "station").mkdir(parents=True)
    (tmp_path / "config" / "station" / "station.yaml").write_text("effects: {}\n")
    assert plugin_config(None) == tmp_path / "config" / "station" / "station.yaml"
    monkeypatch.setenv("STATION_HISTORY_DIR", str(tmp_path / "elsewhere"))
    assert default_store() == tmp_path / "elsewhere"
