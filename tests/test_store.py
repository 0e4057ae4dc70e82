"""The calibration store on SQLite and on a real PostgreSQL server (started by the module's
fixture from the system's binaries, stopped in its finalizer; skipped with the reason when none
is installed, unless STATION_REQUIRE_POSTGRES=1 as .ci/run sets): concurrent writers from
several processes lose nothing and duplicate nothing, a writer killed inside its transaction
leaves the store consistent, older indexes migrate."""
import copy
import hashlib
import os
import random
import re
import select
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from hypothesis import given

import test_fuzz_history as fuzz_history
from pg_server import pg  # noqa: F401  (the module's server)
from station.cli import main

DUMPER = getattr(yaml, "CSafeDumper", yaml.SafeDumper)     # libyaml: the test files written fast
from station.core.errors import UserError
from station.io.history import Store

WRITER = Path(__file__).with_name("_store_writer.py")
WRITERS = 4          # processes filing at once (2 cores: more only queue)
UNITS, CAPTURES = 6, 4


@pytest.fixture(params=["sqlite", "postgresql"])
def location(request, tmp_path):
    """(the store's --store value, its files folder)."""
    files = tmp_path / "files"
    if request.param == "sqlite":
        return str(files), files
    name = re.sub(r"[^a-z0-9]", "_", tmp_path.name.lower())[-50:]
    return request.getfixturevalue("pg").create_database(f"t_{name}"), files


@pytest.fixture(scope="module")
def calibrations(optimal9_run, tmp_path_factory):
    """UNITS x CAPTURES calibrations of distinct captures, and of each a re-estimate (the same
    capture and model, other bytes) that must not be filed beside it: (paths, distinct keys)."""
    base = yaml.safe_load((optimal9_run / "calibration.yaml").read_text())
    out = tmp_path_factory.mktemp("cals")
    paths, keys = [], set()
    for u in range(UNITS):
        for c in range(CAPTURES):
            for again in (0, 1):
                doc = copy.deepcopy(base)
                prov = doc["provenance"]
                prov["imu_serial"] = f"SN-{u:03d}"
                prov["capture_sha256"] = hashlib.sha256(f"{u}/{c}".encode()).hexdigest()
                prov["date_utc"] = f"2031-0{c + 1}-01T00:00:0{again}Z"
                doc["parameters"]["accel_bias_x"]["value"] += u + 0.1 * c
                path = out / f"u{u}-c{c}-{again}.yaml"
                path.write_text(yaml.dump(doc, Dumper=DUMPER, sort_keys=False))
                paths.append(path)
            keys.add((prov["imu_serial"], prov["capture_sha256"]))
    return paths, keys


def writer(location, files, paths, listing: Path, *args) -> subprocess.Popen:
    listing.write_text("".join(f"{p}\n" for p in paths))
    return subprocess.Popen([sys.executable, str(WRITER), location, str(files), str(listing), *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)})


def consistent(location, files, orphans=()) -> list:
    """The store's rows, after checking that each names a complete copy of its file, has its 21
    numbers, and that the folder holds no calibration the index does not name but ``orphans``
    (a killed writer's copy: complete, adopted when the same bytes are filed again)."""
    with Store(location, files=files) as store:
        filed = store.filed()
    for f in filed:
        assert hashlib.sha256(f.entry.path.read_bytes()).hexdigest() == f.entry.sha256
        assert len(f.numbers) == 21, (f.entry.id, len(f.numbers))
    on_disk = {p.relative_to(files) for p in files.rglob("*.yaml")}
    named = {f.entry.path.relative_to(files) for f in filed}
    assert on_disk - named == set(orphans) and named <= on_disk, (on_disk, named)
    assert not list(files.rglob("*.tmp"))                   # no half copy left
    return filed


def test_concurrent_writers_lose_nothing_and_duplicate_nothing(location, calibrations, tmp_path):
    """WRITERS processes file every calibration and every re-estimate, each in its own order:
    one row per capture (the unique constraint), none lost, every copy whole."""
    where, files = location
    paths, keys = calibrations
    procs = []
    for k in range(WRITERS):
        order = list(paths)
        random.Random(k).shuffle(order)
        procs.append(writer(where, files, order, tmp_path / f"list{k}.txt"))
    results = [p.communicate(timeout=240) for p in procs]
    assert all(p.returncode == 0 for p in procs), [r[1][-2000:] for r in results]
    counts = [tuple(map(int, r[0].split()[1:3])) for r in results]
    assert sum(n for n, _ in counts) == len(keys)                    # each filed once, by one writer
    assert sum(a for _, a in counts) == WRITERS * len(paths) - len(keys)
    filed = consistent(where, files)
    assert len(filed) == len(keys)
    assert {(f.entry.serial, yaml.safe_load(f.entry.path.read_text())["provenance"]["capture_sha256"])
            for f in filed} == keys


def _line(p: subprocess.Popen, timeout: float = 120.0) -> str:
    ready, _, _ = select.select([p.stdout], [], [], timeout)
    return p.stdout.readline() if ready else ""


def test_a_writer_killed_inside_its_transaction_leaves_the_store_consistent(location, calibrations, tmp_path):
    where, files = location
    paths, _ = calibrations
    first = writer(where, files, paths[:2], tmp_path / "a.txt")           # the store exists, 1 row
    assert first.communicate(timeout=120)[0].split()[:2] == ["filed", "1"]
    victim = writer(where, files, [paths[2]], tmp_path / "b.txt", "hang")
    after = None
    try:
        assert _line(victim) == "in transaction\n", victim.stderr.read() if victim.poll() is not None else ""
        victims_copy = [p.relative_to(files) for p in files.rglob("*.yaml") if p.name.endswith(
            hashlib.sha256(paths[2].read_bytes()).hexdigest()[:8] + ".yaml")]
        # the next writer starts while the victim holds its transaction (SQLite: the write lock;
        # PostgreSQL: an uncommitted row with the same sha256 as its first calibration): it waits
        after = writer(where, files, paths[2:6], tmp_path / "c.txt")
        victim.kill()                                                      # SIGKILL: no clean-up of its own
        victim.communicate(timeout=60)
        out, err = after.communicate(timeout=120)
    finally:
        for p in (victim, after):
            if p is not None and p.poll() is None:
                p.kill()
    # it filed what the dead one did not, and the dead one left nothing in the index
    assert out.split() == ["filed", "2", "2"], err[-2000:]
    filed = consistent(where, files)
    assert len(filed) == 3 and [f.entry.sha256 for f in filed].count(hashlib.sha256(paths[2].read_bytes()).hexdigest()) == 1
    assert victims_copy        # the victim had copied its file before its transaction: adopted, not doubled
    with Store(where, files=files) as store:
        assert store.count() == 3


def test_an_older_sqlite_index_migrates_with_its_numbers(optimal9_run, tmp_path, capsys):
    """A version-2 index (before schema_version) holding two rows of one capture and model (two
    processes filed at once before the constraint): migrated to the latest version, the first row
    kept, its numbers, IMU model and lot read from its file."""
    root = tmp_path / "old"
    (root / "SIM-13").mkdir(parents=True)
    doc = yaml.safe_load((optimal9_run / "calibration.yaml").read_text())
    doc["provenance"]["imu_lot"] = "L42"
    data = yaml.safe_dump(doc, sort_keys=False).encode()
    digest = hashlib.sha256(data).hexdigest()
    (root / "SIM-13" / "a.yaml").write_bytes(data)
    db = sqlite3.connect(root / "index.sqlite")
    db.execute("""CREATE TABLE calibrations (id INTEGER PRIMARY KEY, serial TEXT NOT NULL, date_utc TEXT NOT NULL,
        scheme TEXT, method TEXT, verdict TEXT, file TEXT NOT NULL, source TEXT, sha256 TEXT NOT NULL UNIQUE,
        filed_utc TEXT NOT NULL, capture_sha256 TEXT, model TEXT)""")
    for n, sha in enumerate((digest, "0" * 64)):
        db.execute("INSERT INTO calibrations (serial, date_utc, verdict, file, sha256, filed_utc, capture_sha256, model)"
                   " VALUES ('SIM-13', '2031', 'passes', 'SIM-13/a.yaml', ?, 'x', 'c', 'lsq:base_triads')", (sha,))
    db.commit()
    db.close()
    (f,) = Store(root).filed()
    assert f.entry.id == 1 and f.entry.lot == "L42" and f.entry.imu_model == "station simulated IMU"
    assert f.numbers["gyro_scale_x"].value == doc["parameters"]["gyro_scale_x"]["value"]
    assert sqlite3.connect(root / "index.sqlite").execute("SELECT version FROM schema_version").fetchall() == [(4,)]
    # a store of a newer station is refused in one line, not misread
    db = sqlite3.connect(root / "index.sqlite")
    db.execute("UPDATE schema_version SET version = 99")
    db.commit()
    db.close()
    capsys.readouterr()
    assert main(["history", "--store", str(root)]) == 2
    err = capsys.readouterr().err
    assert "schema version 99" in err and str(root / "index.sqlite") in err and err.count("\n") == 1


def test_a_foreign_or_unreachable_database_is_one_line(pg, tmp_path, capsys):
    import psycopg

    url = pg.create_database("foreign_db")
    with psycopg.connect(url, autocommit=True) as conn:
        conn.execute("CREATE TABLE calibrations (id INTEGER PRIMARY KEY, name TEXT)")
    bad_host = pg.url("postgres").replace(f"host={pg.dir}", f"host={tmp_path}")
    for store, words in ((url, "not station's calibration store"), (bad_host, "cannot connect")):
        capsys.readouterr()
        assert main(["history", "--store", store]) == 2
        err = capsys.readouterr().err
        assert words in err and "Traceback" not in err and err.count("\n") == 1, err


# ------------------------------------------------------------------ fuzz of a database's rows (issue 26)

_FUZZ_DB = {}


@fuzz_history.FUZZ
@given(changes=fuzz_history.index_changes())
def test_fuzzed_postgres_rows(pg, tmp_path_factory, changes):  # noqa: F811
    """tests/test_fuzz_history.py's mutations of the index (rows, types, schema, version) in a
    PostgreSQL store: every reader answers or says one line naming the database."""
    import psycopg
    if "url" not in _FUZZ_DB:
        _FUZZ_DB["url"] = pg.create_database("fuzz_rows")
        _FUZZ_DB["cals"] = fuzz_history.calibrations(tmp_path_factory.mktemp("fuzzcals"))
    url, cals = _FUZZ_DB["url"], _FUZZ_DB["cals"]
    mp = pytest.MonkeyPatch()
    mp.setenv("STATION_HISTORY_DIR", str(tmp_path_factory.mktemp("pgfiles")))    # this example's files
    try:
        with psycopg.connect(url, autocommit=True) as conn:       # a new store each example
            conn.execute("DROP SCHEMA public CASCADE")
            conn.execute("CREATE SCHEMA public")
        from station import api
        api.history(store=url, add=cals[:3])
        with psycopg.connect(url, autocommit=True) as conn:
            for sql, params in changes:
                try:
                    conn.execute(sql.replace("?", "%s"), params)
                except (psycopg.Error, ValueError, OverflowError):
                    pass         # refused by PostgreSQL or its driver: not a row the store can meet
        fuzz_history.read_everything(url, cals[3])
    finally:
        mp.undo()


def test_a_schema_version_of_another_type_in_the_database_is_one_line(pg, tmp_path):  # noqa: F811
    """A PostgreSQL store whose schema_version holds text: TypeError comparing it (the fuzz's find)."""
    import psycopg
    url = pg.create_database("text_version")
    with psycopg.connect(url, autocommit=True) as conn:
        conn.execute("CREATE TABLE schema_version (version TEXT NOT NULL)")
        conn.execute("INSERT INTO schema_version VALUES ('4')")
    with pytest.raises(UserError, match="schema version is '4', not a whole number"):
        with Store(url, files=tmp_path) as st:
            st.serials()


# ------------------------------------------------------------------ an index lost or tampered with (fin26, issue 26)

def _three(optimal9_run, tmp_path) -> list:
    """Three calibrations of three IMUs (distinct bytes, captures and serials)."""
    base = yaml.safe_load((optimal9_run / "calibration.yaml").read_text())
    paths = []
    for k in range(3):
        doc = copy.deepcopy(base)
        doc["provenance"].update(imu_serial=f"SN-L{k}", capture_sha256=f"{k:064x}", imu_lot="L1")
        paths.append(tmp_path / f"c{k}.yaml")
        paths[-1].write_text(yaml.dump(doc, Dumper=DUMPER, sort_keys=False))
    return paths


def _one_line(argv, capsys, code, *words) -> str:
    capsys.readouterr()
    assert main([str(a) for a in argv]) == code
    out, err = capsys.readouterr()
    assert "Traceback" not in err, err
    for w in words:
        assert w in err + out, (w, out, err)
    return err


def test_an_index_lost_beside_its_files_is_refused_and_rebuilt(location, optimal9_run, tmp_path, capsys,
                                                              monkeypatch):
    """A store whose SQLite index is gone while its folder holds calibration files is refused in
    one line with the repair, for reading and for filing (before, it was read as an empty history
    and new filings started a second one); `history --rebuild` files the store's files again.  A
    PostgreSQL database emptied is a new store (its files' folder may be shared with others: not
    refused), and `history --rebuild` fills it from the folder."""
    where, files = location
    monkeypatch.setenv("STATION_HISTORY_DIR", str(files))       # a database's files: this folder
    paths = _three(optimal9_run, tmp_path)
    assert main(["history", "--store", where, "--add", str(paths[0]), "--add", str(paths[1])]) == 0
    if where == str(files):
        (files / "index.sqlite").unlink()
    else:
        import psycopg
        with psycopg.connect(where, autocommit=True) as conn:
            conn.execute("DROP TABLE parameters; DROP TABLE calibrations; DROP TABLE schema_version")
    for argv in (["history", "--store", where], ["fleet", "--store", where],
                 ["history", "--store", where, "--add", paths[2]]):
        if where != str(files):
            break
        err = _one_line(argv, capsys, 2, "holds 2 calibration file(s)", "station history --rebuild --store")
        assert err.count("\n") == 1
    _one_line(["history", "--rebuild", "--store", where], capsys, 0, "history rebuilt: 2 calibration(s) of 2 IMU(s)")
    with Store(where, files=files) as store:
        filed = store.filed()
        assert sorted(f.entry.serial for f in filed) == ["SN-L0", "SN-L1"] and not any(f.entry.problem for f in filed)
        assert all(len(f.numbers) == 21 and f.entry.lot == "L1" for f in filed)
    assert main(["history", "--store", where, "--add", str(paths[2])]) == 0


@pytest.mark.parametrize("damage", ["zero bytes", "garbage"])
def test_a_damaged_sqlite_index_is_refused_and_rebuilt_with_the_old_kept_aside(optimal9_run, tmp_path, capsys, damage):
    root = tmp_path / "store"
    paths = _three(optimal9_run, tmp_path)
    assert main(["history", "--store", str(root), "--add", str(paths[0]), "--lot", "kept"]) == 0
    index = root / "index.sqlite"
    index.write_bytes(b"" if damage == "zero bytes" else b"not a database " * 100)
    _one_line(["history", "--store", root, "SN-L0"], capsys, 2, str(index), "--rebuild")
    (root / "SN-L0" / "stray.txt").write_text("not a calibration")       # not *.yaml: not looked at
    (root / "SN-L0" / "notes.yaml").write_text("just: notes\n")          # not a calibration file: skipped, said
    (root / "SN-L1").mkdir()
    (root / "SN-L1" / "link.yaml").symlink_to(paths[1])                  # a link out of the store: refused
    err = _one_line(["history", "--rebuild", "--store", root], capsys, 0, "1 calibration(s) of 1 IMU(s)",
                    "2 file(s) not filed")
    assert "link.yaml: a symbolic link" in err and "notes.yaml" in err
    aside = list(root.glob("index.sqlite.before-rebuild-*"))
    assert len(aside) == 1 and aside[0].read_bytes() == (b"" if damage == "zero bytes" else b"not a database " * 100)
    (f,) = Store(root).filed()
    assert f.entry.serial == "SN-L0" and f.entry.lot == "L1"        # the file's own lot (the old index unreadable)
    # a new store and an empty zero-byte index with no files beside it: simply empty
    (tmp_path / "new").mkdir()
    (tmp_path / "new" / "index.sqlite").write_bytes(b"")
    assert Store(tmp_path / "new").filed() == []


def test_fleet_history_and_diff_check_every_row_against_its_file(location, optimal9_run, tmp_path, capsys,
                                                                monkeypatch):
    """The index holds the numbers, the file is the record: a row whose file path was edited to
    name another calibration of the store, whose file was edited or removed, is marked and not
    counted (fleet: JSON "not_counted", one line each on stderr; history: the row marked; diff
    of it: refused) — before, fleet counted the index's numbers without opening any file."""
    import json

    where, files = location
    monkeypatch.setenv("STATION_HISTORY_DIR", str(files))
    paths = _three(optimal9_run, tmp_path)
    assert main(["history", "--store", where, *[a for p in paths for a in ("--add", str(p))]]) == 0
    with Store(where, files=files) as store:
        rows = {f.entry.serial: f.entry for f in store.filed()}
    sql = "UPDATE calibrations SET file = ? WHERE id = ?"
    if where == str(files):
        db = sqlite3.connect(files / "index.sqlite")
        db.execute(sql, (rows["SN-L1"].path.relative_to(files).as_posix(), rows["SN-L0"].id))
        db.commit()
        db.close()
    else:
        import psycopg
        with psycopg.connect(where, autocommit=True) as conn:
            conn.execute(sql.replace("?", "%s"), (rows["SN-L1"].path.relative_to(files).as_posix(), rows["SN-L0"].id))
    rows["SN-L2"].path.write_text(rows["SN-L2"].path.read_text().replace("passes", "passes "))   # edited after filing
    capsys.readouterr()
    assert main(["fleet", "--store", where, "--json"]) == 0
    out, err = capsys.readouterr()
    view = json.loads(out)
    assert view["calibrations"] == 1 and view["units"] == 1
    assert sorted(r["serial"] for r in view["not_counted"]) == ["SN-L0", "SN-L2"]
    assert all("not the one filed" in r["problem"] for r in view["not_counted"]) and err.count("not counted") == 2
    _one_line(["history", "SN-L0", "--store", where], capsys, 0, "NOT THE FILE FILED")
    _one_line(["diff", f"#{rows['SN-L0'].id}", f"#{rows['SN-L1'].id}", "--store", where], capsys, 2,
              "not the one filed", "not read as that calibration")
    rows["SN-L1"].path.unlink()
    with Store(where, files=files) as store:
        problems = {f.entry.serial: f.entry.problem for f in store.filed()}
    assert "is missing" in problems["SN-L1"] and "is missing" in problems["SN-L0"] and "differs" in problems["SN-L2"]
