"""The calibration history: every calibration filed per IMU serial in a store.

The store is a folder: ``SERIAL/DATE-SHA8.yaml`` holds a copy of each calibration file, and
``index.sqlite`` (stdlib sqlite3) indexes them by serial, date, scheme, method and verdict.  Its
place, first found of: the ``--store`` option, the ``STATION_HISTORY_DIR`` environment variable,
the user's data directory (``$XDG_DATA_HOME/station/calibrations``, default
``~/.local/share/station/calibrations``; ``~/Library/Application Support/station/calibrations``
on macOS, ``%LOCALAPPDATA%\\station\\calibrations`` on Windows).  Filing the same file twice
files it once (by its sha256), and a calibration of a capture and model already filed (the same
capture's sha256, method and effects: a re-estimate) is not filed again.  What is filed at all is
the CLI's policy (station/cli/history.py): real IMUs (a serial), simulations only when asked and
then in their own store (:func:`simulation_store`).

The index is data from outside like any file: a damaged one, one of another schema, or a row
with other types is a UserError naming the index (never an sqlite3 traceback), and the path a
row gives must be a relative one inside the store (a tampered row cannot make ``diff`` or
``history --drift`` open a file elsewhere).
"""
from __future__ import annotations

import datetime as _dt
import hashlib
import os
import re
import sqlite3
from dataclasses import dataclass
from pathlib import Path

from station.core.errors import UserError

ENV = "STATION_HISTORY_DIR"
INDEX = "index.sqlite"
SCHEMA = """CREATE TABLE IF NOT EXISTS calibrations (
    id INTEGER PRIMARY KEY,
    serial TEXT NOT NULL,
    date_utc TEXT NOT NULL,
    scheme TEXT,
    method TEXT,
    verdict TEXT,
    file TEXT NOT NULL,
    source TEXT,
    sha256 TEXT NOT NULL UNIQUE,
    filed_utc TEXT NOT NULL,
    capture_sha256 TEXT,
    model TEXT)"""
ADDED_COLUMNS = (("capture_sha256", "TEXT"), ("model", "TEXT"))    # index files written before them
UNKNOWN_SERIAL = "unknown"
SIMULATED_PREFIX = "SIM-"           # the serial station's simulated IMUs carry (station.simulate.dryrun)
COLUMNS = ("id", "serial", "date_utc", "scheme", "method", "verdict", "file", "source", "sha256", "filed_utc")


@dataclass
class Entry:
    id: int
    serial: str
    date_utc: str
    scheme: str | None
    method: str | None
    verdict: str
    path: Path                   # the copy in the store
    source: str | None           # where it was filed from
    sha256: str


def default_store() -> Path:
    """$STATION_HISTORY_DIR, else ``calibrations`` in the user's data directory for station
    (platformdirs' user_data_dir: $XDG_DATA_HOME/station or ~/.local/share/station on Linux,
    ~/Library/Application Support/station on macOS, %LOCALAPPDATA%\\station on Windows)."""
    if os.environ.get(ENV):
        return Path(os.environ[ENV])
    import platformdirs

    return Path(platformdirs.user_data_dir("station", appauthor=False)) / "calibrations"


def simulation_store(root=None) -> Path:
    """Where simulated runs are filed when asked: beside the calibrations' store, never in it."""
    base = Path(root) if root else default_store()
    return base.with_name(base.name + "-simulations")


def real_serial(doc: dict) -> str | None:
    """The IMU serial a calibration states, if it names a real IMU (not unknown, not simulated)."""
    prov = doc.get("provenance") if isinstance(doc.get("provenance"), dict) else {}
    serial = _text(prov.get("imu_serial"))
    if not serial or not serial.strip() or serial == UNKNOWN_SERIAL or serial.startswith(SIMULATED_PREFIX):
        return None
    return serial


def model_key(doc: dict) -> str:
    """What a calibration modelled: its method and effects (a re-estimate with another model is
    another calibration of the same capture)."""
    prov = doc.get("provenance") if isinstance(doc.get("provenance"), dict) else {}
    effects = doc.get("effects") if isinstance(doc.get("effects"), list) else []
    return f"{_text(prov.get('method')) or '?'}:{','.join(sorted(str(e) for e in effects))}"


def _text(v) -> str | None:
    return v if isinstance(v, str) else None


def verdict_of(doc: dict) -> str:
    """The fit verdict a calibration file states, in a few words ("not stated" if none)."""
    fit = doc.get("fit") if isinstance(doc.get("fit"), dict) else {}
    for v in (doc.get("verdict"), fit.get("verdict")):
        if isinstance(v, str) and v:
            return v
        if isinstance(v, dict):
            word = next((v[k] for k in ("result", "status", "verdict") if isinstance(v.get(k), str)), None)
            if word is None and isinstance(v.get("passes"), bool):
                word = "passes" if v["passes"] else "fails"
            if word:
                reason = v.get("reason")
                return f"{word}: {reason}" if isinstance(reason, str) and reason else word
    chi2 = fit.get("reduced_chi2")
    if isinstance(chi2, (int, float)) and not isinstance(chi2, bool):
        return f"not stated (reduced chi2 {chi2:.3g})"
    return "not stated"


def serial_folder(serial: str) -> str:
    """A folder name for an untrusted serial: letters, digits, '.', '_', '-' only, no dot names."""
    name = re.sub(r"[^A-Za-z0-9._-]", "_", serial)[:64].lstrip(".")
    return name or "_"


def _one_line(e: Exception) -> str:
    return " ".join(str(e).split()) or type(e).__name__


class Store:
    def __init__(self, root=None):
        self.root = Path(root) if root else default_store()

    def _connect(self, create: bool) -> sqlite3.Connection | None:
        index = self.root / INDEX
        if not create and not index.exists():
            return None
        db = None
        try:
            if create:
                self.root.mkdir(parents=True, exist_ok=True)
            if index.exists() and not index.is_file():
                raise UserError(f"{index}: not a regular file: cannot open the calibration history")
            db = sqlite3.connect(index)
            db.execute(SCHEMA)
            columns = tuple(row[1] for row in db.execute("PRAGMA table_info(calibrations)"))
            added = tuple(name for name, _ in ADDED_COLUMNS)
            if columns[:len(COLUMNS)] != COLUMNS or not set(columns[len(COLUMNS):]) <= set(added):
                raise UserError(f"{index}: not station's calibration history: its table 'calibrations' has "
                                f"the columns {', '.join(map(str, columns))[:200]}")
            for name, kind in ADDED_COLUMNS:        # an index written before they existed
                if name not in columns:
                    db.execute(f"ALTER TABLE calibrations ADD COLUMN {name} {kind}")
            return db
        except (OSError, sqlite3.Error, UserError) as e:
            if db is not None:
                db.close()
            if isinstance(e, UserError):
                raise
            raise UserError(f"{index}: cannot open the calibration history: {_one_line(e)}") from None

    def _rows(self, sql: str, params=(), *, create: bool = False) -> list:
        """The rows of a query (none when there is no index and ``create`` is false); an sqlite3
        error is a UserError naming the index."""
        db = self._connect(create)
        if db is None:
            return []
        try:
            with db:
                return db.execute(sql, params).fetchall()
        except sqlite3.Error as e:
            raise UserError(f"{self.root / INDEX}: the calibration history cannot be read: {_one_line(e)}") from None
        finally:
            db.close()

    def file(self, cal_path) -> tuple[Entry, bool]:
        """File a calibration; (its entry, True if new)."""
        from station.io.calfile import read_calfile

        cal_path = Path(cal_path)
        doc = read_calfile(cal_path)
        data = cal_path.read_bytes()
        digest = hashlib.sha256(data).hexdigest()
        prov = doc.get("provenance") if isinstance(doc.get("provenance"), dict) else {}
        serial = _text(prov.get("imu_serial")) or UNKNOWN_SERIAL
        date = _text(prov.get("date_utc")) or _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
        capture_digest = _text(prov.get("capture_sha256"))
        model = model_key(doc)
        db = self._connect(create=True)
        try:
            return self._file(db, doc, data, digest, cal_path, prov, serial, date, capture_digest, model)
        except sqlite3.Error as e:
            raise UserError(f"{self.root / INDEX}: cannot file the calibration: {_one_line(e)}") from None
        finally:
            db.close()

    def _file(self, db, doc, data, digest, cal_path, prov, serial, date, capture_digest, model) -> tuple[Entry, bool]:
        with db:
            row = db.execute("SELECT id FROM calibrations WHERE sha256 = ?", (digest,)).fetchone()
            if row is None and capture_digest:
                row = db.execute("SELECT id FROM calibrations WHERE capture_sha256 = ? AND model = ? AND serial = ?",
                                 (capture_digest, model, serial)).fetchone()
            if row:
                return self.get(row[0]), False
            rel = Path(serial_folder(serial)) / f"{re.sub(r'[^0-9A-Za-z]', '', date)[:15]}-{digest[:8]}.yaml"
            target = self.root / rel
            try:
                target.parent.mkdir(parents=True, exist_ok=True)
                with open(target, "xb") as f:
                    f.write(data)
            except FileExistsError:
                pass   # a crash between copy and index: the same bytes, adopt them
            except OSError as e:
                raise UserError(f"{target}: cannot file the calibration: {e.strerror}") from None
            cur = db.execute(
                "INSERT INTO calibrations (serial, date_utc, scheme, method, verdict, file, source, "
                "sha256, filed_utc, capture_sha256, model) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                (serial, date, _text(prov.get("scheme")), _text(prov.get("method")), verdict_of(doc),
                 rel.as_posix(), str(cal_path.resolve()), digest,
                 _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"), capture_digest, model))
            new_id = cur.lastrowid
        return self.get(new_id), True

    def _entry(self, row) -> Entry:
        id_, serial, date, scheme, method, verdict, file, source, digest = row
        where = f"{self.root / INDEX}: row #{id_}"
        if not isinstance(id_, int) or not all(isinstance(v, str) for v in (serial, date, verdict, file, digest)) \
                or not all(v is None or isinstance(v, str) for v in (scheme, method, source)):
            raise UserError(f"{where}: not station's calibration history (a field of another type)")
        return Entry(id_, serial, date, scheme, method, verdict, self._inside(file, where), source, digest)

    def _inside(self, file: str, where: str) -> Path:
        """The store's file a row names: a relative path that stays inside the store (a row
        naming /etc/passwd, ../x or a link out of the store is refused)."""
        rel = Path(file)
        bad = rel.is_absolute() or rel.drive or ".." in rel.parts or not rel.parts or "\0" in file
        path = self.root / rel
        if not bad:
            try:
                bad = not path.resolve().is_relative_to(self.root.resolve())
            except (OSError, RuntimeError, ValueError):
                bad = True
        if bad:
            raise UserError(f"{where}: field 'file': {file[:200]!r} is not a file inside the store {self.root}")
        return path

    _COLUMNS = "id, serial, date_utc, scheme, method, verdict, file, source, sha256"

    def get(self, id_: int) -> Entry:
        rows = self._rows(f"SELECT {self._COLUMNS} FROM calibrations WHERE id = ?", (id_,))
        if not rows:
            raise UserError(f"{self.root / INDEX}: no calibration #{id_} in the history")
        return self._entry(rows[0])

    def list(self, serial: str) -> list[Entry]:
        rows = self._rows(f"SELECT {self._COLUMNS} FROM calibrations WHERE serial = ? ORDER BY date_utc, id", (serial,))
        return [self._entry(r) for r in rows]

    def serials(self) -> list[tuple[str, int]]:
        rows = self._rows("SELECT serial, COUNT(*) FROM calibrations GROUP BY serial ORDER BY serial")
        return [(str(serial), int(n)) for serial, n in rows]

    def resolve(self, ref: str) -> Path:
        """A calibration named by a file path or by its id in the history (``#12`` or ``12``)."""
        path = Path(ref)
        if path.exists():
            return path
        m = re.fullmatch(r"#?([0-9]{1,12})", ref)
        if m:
            return self.get(int(m.group(1))).path
        raise UserError(f"{ref}: neither a calibration file nor an id of the history ({self.root})")
