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
"""
from __future__ import annotations

import datetime as _dt
import hashlib
import os
import re
import sqlite3
import sys
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
    if os.environ.get(ENV):
        return Path(os.environ[ENV])
    home = Path.home()
    if sys.platform == "darwin":
        base = home / "Library" / "Application Support"
    elif os.name == "nt":
        base = Path(os.environ.get("LOCALAPPDATA") or home / "AppData" / "Local")
    else:
        base = Path(os.environ.get("XDG_DATA_HOME") or home / ".local" / "share")
    return base / "station" / "calibrations"


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


class Store:
    def __init__(self, root=None):
        self.root = Path(root) if root else default_store()

    def _connect(self, create: bool) -> sqlite3.Connection | None:
        index = self.root / INDEX
        if not create and not index.exists():
            return None
        try:
            if create:
                self.root.mkdir(parents=True, exist_ok=True)
            db = sqlite3.connect(index)
            db.execute(SCHEMA)
            have = {row[1] for row in db.execute("PRAGMA table_info(calibrations)")}
            for name, kind in ADDED_COLUMNS:
                if name not in have:
                    db.execute(f"ALTER TABLE calibrations ADD COLUMN {name} {kind}")
            return db
        except (OSError, sqlite3.Error) as e:
            raise UserError(f"{index}: cannot open the calibration history: {e}") from None

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
        db.close()
        return self.get(new_id), True

    def _entry(self, row) -> Entry:
        id_, serial, date, scheme, method, verdict, file, source, digest = row
        return Entry(id_, serial, date, scheme, method, verdict, self.root / file, source, digest)

    _COLUMNS = "id, serial, date_utc, scheme, method, verdict, file, source, sha256"

    def get(self, id_: int) -> Entry:
        db = self._connect(create=False)
        row = db.execute(f"SELECT {self._COLUMNS} FROM calibrations WHERE id = ?", (id_,)).fetchone() if db else None
        if row is None:
            raise UserError(f"{self.root / INDEX}: no calibration #{id_} in the history")
        return self._entry(row)

    def list(self, serial: str) -> list[Entry]:
        db = self._connect(create=False)
        if db is None:
            return []
        rows = db.execute(f"SELECT {self._COLUMNS} FROM calibrations WHERE serial = ? "
                          "ORDER BY date_utc, id", (serial,)).fetchall()
        db.close()
        return [self._entry(r) for r in rows]

    def serials(self) -> list[tuple[str, int]]:
        db = self._connect(create=False)
        if db is None:
            return []
        rows = db.execute("SELECT serial, COUNT(*) FROM calibrations GROUP BY serial ORDER BY serial").fetchall()
        db.close()
        return rows

    def resolve(self, ref: str) -> Path:
        """A calibration named by a file path or by its id in the history (``#12`` or ``12``)."""
        path = Path(ref)
        if path.exists():
            return path
        m = re.fullmatch(r"#?([0-9]{1,12})", ref)
        if m:
            return self.get(int(m.group(1))).path
        raise UserError(f"{ref}: neither a calibration file nor an id of the history ({self.root})")
