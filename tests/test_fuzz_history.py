"""Hypothesis fuzz of the calibration history's index, structure-aware (issue 26): a store with
three real calibrations of two IMUs filed, then its index mutated in its structure — a row's
field set to a value of another type or an absurd one (a path out of the store, a NUL, a huge
integer, a blob, NULL), rows deleted or duplicated, the schema's version changed, tables dropped,
columns renamed or added, indexes dropped — in the SQLite file (``index.sqlite``) here, and in a real
PostgreSQL database (the same mutations through psycopg) in tests/test_store.py, whose server it
shares (a server's start is seconds: one per module).  Every reader of the
history (history, history SERIAL, diff #A #B, fleet, filing a new calibration, the drift plot's
rows) either answers or raises UserError: one line naming the index; never another exception,
never a hang (an alarm of HANG_S per example)."""
import os
import sqlite3

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from processes import time_limit
from station import api
from station.core.errors import UserError
from station.io.history import Store

from test_fuzz_readers import VALID_CAL

EXAMPLES = int(os.environ.get("STATION_FUZZ_EXAMPLES", "10"))
FUZZ = settings(max_examples=EXAMPLES, deadline=None, suppress_health_check=list(HealthCheck))
# reading a three-row index takes ~5 ms; an index that makes a reader loop or wait takes forever:
# 20 s is far beyond an honest read on a machine loaded 10x, and is a hang
HANG_S = 20.0

TABLES = {"calibrations": ["id", "serial", "date_utc", "scheme", "method", "verdict", "file", "source", "sha256",
                           "filed_utc", "capture_sha256", "model", "imu_model", "lot"],
          "parameters": ["calibration_id", "name", "value", "sigma", "unit"],
          "schema_version": ["version"]}
INDEXES = ["calibrations_capture_model", "calibrations_serial_date", "calibrations_model_lot"]

field_values = st.one_of(
    st.sampled_from([None, 0, -1, 1, 2, 5, 99, 2 ** 63 - 1, -2 ** 63, 1.5, 1e308, float("inf"), float("-inf"), "",
                     "A1", "B2", "unknown", "passes", "fails", "2026-13-45", "x" * 5000,
                     "/etc/passwd", "../outside.yaml", "A1/../../outside.yaml", "A1/\x00.yaml", "A1",
                     "A1/missing.yaml", ".", "~/x.yaml", "C:\\x.yaml", b"A1/20260101-abc.yaml", b"\xff\x00"]),
    st.integers(-2 ** 63, 2 ** 63 - 1), st.floats(allow_nan=False), st.text(max_size=16), st.binary(max_size=16))


@st.composite
def index_changes(draw):
    """Up to three structural changes of the index: (statement, parameters) in the SQL both
    databases speak (``?`` placeholders)."""
    out = []
    for _ in range(draw(st.integers(1, 3))):
        table = draw(st.sampled_from(sorted(TABLES)))
        col = draw(st.sampled_from(TABLES[table]))
        row = draw(st.integers(1, 4))
        what = draw(st.sampled_from(["set", "set", "set", "set", "set_all", "delete", "duplicate", "drop_table",
                                     "rename", "add_column", "drop_index", "version"]))
        key = "calibration_id" if table == "parameters" else "id"
        if what == "set":
            where = f" WHERE {key} = ?" if table != "schema_version" else ""
            out.append((f"UPDATE {table} SET {col} = ?{where}",
                        (draw(field_values), row) if where else (draw(field_values),)))
        elif what == "set_all":
            out.append((f"UPDATE {table} SET {col} = ?", (draw(field_values),)))
        elif what == "delete":
            out.append((f"DELETE FROM {table} WHERE {col} = ?" if table != "schema_version"
                        else f"DELETE FROM {table}", (row,) if table != "schema_version" else ()))
        elif what == "duplicate":
            cols = ", ".join(c for c in TABLES[table] if c != "id")
            out.append((f"INSERT INTO {table} ({cols}) SELECT {cols} FROM {table}", ()))
        elif what == "drop_table":
            out.append((f"DROP TABLE {table}", ()))
        elif what == "rename":
            out.append((f"ALTER TABLE {table} RENAME COLUMN {col} TO {col}_x", ()))
        elif what == "add_column":
            out.append((f"ALTER TABLE {table} ADD COLUMN extra TEXT", ()))
        elif what == "drop_index":
            out.append((f"DROP INDEX {draw(st.sampled_from(INDEXES))}", ()))
        else:
            out.append(("UPDATE schema_version SET version = ?",
                        (draw(st.sampled_from([0, 1, 2, 3, 5, -1, 2 ** 62, None, "4", 4.5, b"4"])),)))
    return out


def calibrations(folder):
    """Three valid calibration files: two of IMU A1 (a day apart), one of B2; and a fourth to file."""
    out = []
    for k, (serial, day) in enumerate([("A1", "2026-01-01"), ("A1", "2026-01-02"), ("B2", "2026-01-03"),
                                       ("B2", "2026-01-04")]):
        doc = yaml.safe_load(yaml.safe_dump(VALID_CAL))
        doc["provenance"] = {"imu_serial": serial, "date_utc": f"{day}T00:00:00Z", "method": "lsq",
                             "scheme": "optimal9", "capture_sha256": f"{k:064x}", "imu_model": "M", "imu_lot": "L"}
        doc["parameters"]["accel_scale_x"]["value"] = 1.0 + 1e-5 * k
        doc["compensation"]["accel_matrix"][0][0] = 1.0 / (1.0 + 1e-5 * k)     # the matrix with it
        path = folder / f"cal{k}.yaml"
        path.write_text(yaml.safe_dump(doc))
        out.append(path)
    return out


def read_everything(store, fourth):
    """What the commands read from a history: 'answered', or 'refused' with one line naming the
    index (or a file of the store it points to)."""
    from station.diagnose.figures import drift_status
    from station.diagnose.fleet import fleet, to_json
    try:
        with time_limit(HANG_S):
            h = api.history("A1", store=store)
            for serial, _ in h.serials:
                for e in api.history(serial, store=store).entries:
                    drift_status(e.verdict)
            with Store(store) as st:
                filed = st.filed(imu_model="M")
            if filed:
                to_json(fleet(filed, {"store": "x", "model": "M", "lot": None, "since": None}))
            try:
                api.diff("#1", "#2", store=store)
            finally:
                api.history(store=store, add=[fourth])
    except UserError as e:
        msg = str(e)
        assert "\n" not in msg.strip() and len(msg) < 2000, msg
        return "refused"
    return "answered"


@pytest.fixture(scope="module")
def cal_files(tmp_path_factory):
    return calibrations(tmp_path_factory.mktemp("cals"))


def _sqlite_store(folder, cal_files):
    api.history(store=folder, add=cal_files[:3])
    return folder


def test_the_unmutated_store_answers(cal_files, tmp_path):
    """The fuzz starts from a store that answers every reader (else it would test refusals only)."""
    store = _sqlite_store(tmp_path / "s", cal_files)
    assert read_everything(store, cal_files[3]) == "answered"


@FUZZ
@given(changes=index_changes())
def test_fuzzed_sqlite_index(cal_files, tmp_path_factory, changes):
    store = _sqlite_store(tmp_path_factory.mktemp("s"), cal_files)
    db = sqlite3.connect(store / "index.sqlite", isolation_level=None)
    for sql, params in changes:
        try:
            db.execute(sql, params)
        except sqlite3.Error:
            pass                 # a change SQLite itself refuses (a constraint) is not a mutation
    db.close()
    read_everything(store, cal_files[3])


# ------------------------------------------------------------------ what the fuzz found (regressions)

@pytest.mark.parametrize("sql, params, words", [
    ("UPDATE schema_version SET version = ?", ("x" * 5000,), "schema version 'xxxx"),
    ("UPDATE schema_version SET version = ?", ("v4",), "not a version"),
    ("UPDATE parameters SET unit = ?, name = ? WHERE calibration_id = 1", (b"\x00", "n" * 5000), "parameter 'nnn"),
])
def test_a_long_or_mistyped_field_of_the_index_is_one_short_line(cal_files, tmp_path, sql, params, words):
    """A schema version of 5,000 characters was echoed whole (one 5 kB line), a version of
    another type called newer; a parameter's name likewise."""
    store = _sqlite_store(tmp_path / "s", cal_files)
    db = sqlite3.connect(store / "index.sqlite", isolation_level=None)
    db.execute(sql, params)
    db.close()
    with pytest.raises(UserError) as e:
        with Store(store) as st:
            st.filed()
    msg = str(e.value)
    assert words in msg and str(store / "index.sqlite") in msg and len(msg) < 300, msg
