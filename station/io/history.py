"""The calibration history: every calibration filed per IMU serial in a store.

The store is a folder of files and an index.  ``SERIAL/DATE-SHA8.yaml`` holds a copy of each
calibration file (calibration files stay files); the index holds, per calibration, its serial,
date, scheme, method, verdict, IMU model and lot, and every parameter's value, 1σ and unit (the
numbers ``station fleet`` queries).  The index is ``index.sqlite`` in the folder
(station/io/store_sqlite.py, the default) or a PostgreSQL database (station/io/store_postgres.py),
the same schema and migrations (station/io/store_schema.py).  Its place, first found of: the
``--store`` option, ``$STATION_STORE`` (a folder or a ``postgresql://`` URL), then the folder
``$STATION_HISTORY_DIR``, then the user's data directory (``$XDG_DATA_HOME/station/calibrations``,
default ``~/.local/share/station/calibrations``; ``~/Library/Application
Support/station/calibrations`` on macOS, ``%LOCALAPPDATA%\\station\\calibrations`` on Windows).
With a database URL the files go to that folder (``$STATION_HISTORY_DIR`` or the data directory:
a shared filesystem when several machines file).  Filing the same file twice
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
from dataclasses import dataclass
from pathlib import Path

from station.core.errors import UserError

from station.io.store_backend import is_database_url, one_line as _one_line, shown
from station.io.store_sqlite import INDEX, SqliteIndex

ENV = "STATION_HISTORY_DIR"
STORE_ENV = "STATION_STORE"
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
    imu_model: str | None = None
    lot: str | None = None
    # why the row is not the record of a calibration (None when its file is the one filed):
    # its file missing, outside the store, or changed since filing (Store.verify)
    problem: str | None = None


def default_store() -> Path:
    """$STATION_HISTORY_DIR, else ``calibrations`` in the user's data directory for station
    (platformdirs' user_data_dir: $XDG_DATA_HOME/station or ~/.local/share/station on Linux,
    ~/Library/Application Support/station on macOS, %LOCALAPPDATA%\\station on Windows)."""
    if os.environ.get(ENV):
        return Path(os.environ[ENV])
    import platformdirs

    return Path(platformdirs.user_data_dir("station", appauthor=False)) / "calibrations"


def simulation_store(root=None) -> Path:
    """Where simulated runs are filed when asked: beside the calibrations' store, never in it
    (a folder with its own SQLite index, also when the calibrations' index is a database)."""
    root = root or os.environ.get(STORE_ENV)
    base = Path(root) if root and not is_database_url(root) else default_store()
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


@dataclass
class Rebuilt:
    """:meth:`Store.rebuild`'s result: the index ``where``, the calibrations filed again
    (``filed``), the files not filed with why (``skipped``: (path, reason)), and where the old
    index was kept (``kept_aside``, None when there was none or for a database)."""
    where: str
    filed: list
    skipped: list
    kept_aside: Path | None


@dataclass
class Number:
    """One parameter of a filed calibration, as the index holds it."""
    name: str
    value: float
    sigma: float | None
    unit: str


@dataclass
class Filed:
    """A filed calibration with its numbers (what ``station fleet`` reads)."""
    entry: Entry
    numbers: dict            # name -> Number


def _numbers(doc: dict) -> list[tuple]:
    """(name, value, sigma, unit) of every parameter of a calibration document."""
    params = doc.get("parameters") if isinstance(doc.get("parameters"), dict) else {}
    out = []
    for name, p in params.items():
        if not isinstance(p, dict):
            continue
        value, sigma, unit = p.get("value"), p.get("sigma"), p.get("unit")
        if isinstance(value, (int, float)) and not isinstance(value, bool) and isinstance(unit, str):
            sigma = float(sigma) if isinstance(sigma, (int, float)) and not isinstance(sigma, bool) else None
            out.append((str(name), float(value), sigma, unit))
    return out


def _atomic_copy(data: bytes, target: Path) -> None:
    """The bytes at ``target``, complete or not at all (written beside it, then renamed: a
    writer killed while copying leaves no half file under the name the index gives)."""
    if target.is_file() and target.stat().st_size == len(data) and target.read_bytes() == data:
        return
    tmp = target.with_name(f".{target.name}.{os.getpid()}-{os.urandom(4).hex()}.tmp")
    try:
        with open(tmp, "xb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, target)
    finally:
        tmp.unlink(missing_ok=True)


class Store:
    """The calibration store: files in a folder (``root``) and an index (``index``: SQLite in the
    folder, or PostgreSQL given by URL)."""

    _COLUMNS = "id, serial, date_utc, scheme, method, verdict, file, source, sha256, imu_model, lot"

    def __init__(self, location=None, files=None):
        location = location or os.environ.get(STORE_ENV) or None
        if is_database_url(location):
            from station.io.store_postgres import PostgresIndex

            self.root = Path(files) if files else default_store()
            self.index = PostgresIndex(location)
        else:
            self.root = Path(location) if location else (Path(files) if files else default_store())
            self.index = SqliteIndex(self.root)
        self.where = self.index.where
        self._rebuilding = False
        if isinstance(self.index, SqliteIndex):     # (a PostgreSQL database's folder may be shared)
            self.index.on_new = self._refuse_lost_index
            self.index.damaged_hint = self._damaged_hint

    # ------------------------------------------------------------- an index lost beside its files

    def calibration_files(self) -> list[Path]:
        """The calibration files in the store's folder, where station files them
        (``SERIAL/NAME.yaml``; no dot names: temporaries), sorted."""
        try:
            return sorted(p for p in self.root.glob("*/*.yaml")
                          if not p.name.startswith(".") and not p.parent.name.startswith("."))
        except OSError:
            return []

    def _refuse_lost_index(self, why: str) -> None:
        """An index missing or empty (or a database without the tables) while the store's folder
        holds calibration files: the index was lost (a zero-byte file after a full disk, a copy
        of the folder without it); read as an empty history it would silently drop every entry
        and file new ones beside the lost.  Refused, with the repair."""
        if self._rebuilding:
            return
        files = self.calibration_files()
        if files:
            raise UserError(f"{why}, but the store {self.root} holds {len(files)} calibration file(s): the index "
                            f"was lost; nothing is read from or filed into it until it is rebuilt from the files: "
                            f"station history --rebuild --store {self._store_arg()}")

    def _damaged_hint(self) -> str:
        if self._rebuilding or not self.calibration_files():
            return ""
        return f" (station history --rebuild --store {self._store_arg()} builds a new index from the store's files)"

    def _store_arg(self) -> str:
        return self.where if is_database_url(getattr(self.index, "url", None)) else str(self.root)

    def rebuild(self) -> "Rebuilt":
        """A new index from the calibration files in the store's folder (``station history
        --rebuild``): every ``SERIAL/NAME.yaml`` read again (a symbolic link, a file outside the
        store or one that is not a calibration file is skipped and said); the IMU model and lot
        ``history --add`` gave are kept where the old index can still be read.  SQLite: the new
        index is written beside the old and renamed over it, the old kept as
        ``index.sqlite.before-rebuild-UTC``; PostgreSQL: its rows replaced in one transaction."""
        from station.io.calfile import read_calfile

        root = self.root.resolve() if self.root.exists() else self.root
        kept: dict = {}
        try:
            for digest, imu_model, lot in self._rows("SELECT sha256, imu_model, lot FROM calibrations"):
                kept[digest] = (imu_model, lot)
        except UserError:
            pass                                     # a damaged or empty index: nothing to keep
        rows, skipped = [], []
        for path in self.calibration_files():
            if path.is_symlink() or path.parent.is_symlink():
                skipped.append((str(path), "a symbolic link: the store holds files, not links"))
                continue
            try:
                inside = path.resolve().is_relative_to(root)
            except (OSError, RuntimeError):
                inside = False
            if not inside:
                skipped.append((str(path), f"outside the store {self.root}"))
                continue
            try:
                doc = read_calfile(path)
                data = path.read_bytes()
            except (UserError, OSError) as e:
                skipped.append((str(path), str(e)))
                continue
            digest = hashlib.sha256(data).hexdigest()
            row = self._row(doc, digest, path.relative_to(self.root).as_posix(), "rebuilt from the store")
            if digest in kept:
                row = (*row[:11], kept[digest][0] or row[11], kept[digest][1] or row[12])
            rows.append((row, _numbers(doc), str(path)))
        self._rebuilding = True
        try:
            if isinstance(self.index, SqliteIndex):
                return self._rebuild_sqlite(rows, skipped)
            with self.index.transaction(write=True, backfill=self._backfill) as tx:
                tx.run("DELETE FROM calibrations")
                filed = self._insert_all(tx, rows, skipped)
            return Rebuilt(self.where, filed, skipped, None)
        finally:
            self._rebuilding = False

    def _rebuild_sqlite(self, rows, skipped) -> "Rebuilt":
        stamp = _dt.datetime.now(_dt.timezone.utc).strftime("%Y%m%dT%H%M%SZ")
        try:
            self.root.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            raise UserError(f"{self.root}: cannot create the calibration store: {e.strerror}") from None
        tmp = self.root / f".{INDEX}.rebuild-{os.getpid()}.tmp"
        tmp.unlink(missing_ok=True)
        try:
            new = SqliteIndex(self.root, path=tmp)
            with new.transaction(write=True, backfill=self._backfill) as tx:
                filed = self._insert_all(tx, rows, skipped)
            aside = None
            for suffix in ("", "-journal", "-wal", "-shm"):    # a hot journal would be played into the new one
                old = self.root / (INDEX + suffix)
                if os.path.lexists(old):
                    moved = old.with_name(f"{old.name}.before-rebuild-{stamp}")
                    os.replace(old, moved)
                    aside = aside or moved
            os.replace(tmp, self.index.path)
        except OSError as e:
            raise UserError(f"{self.index.path}: cannot rebuild the calibration history: {e.strerror}") from None
        finally:
            tmp.unlink(missing_ok=True)
        return Rebuilt(self.where, filed, skipped, aside)

    def _insert_all(self, tx, rows, skipped) -> list:
        filed = []
        for row, numbers, path in rows:
            entry = self._insert(tx, row, numbers)
            if entry is None:
                skipped.append((path, "the same calibration as one filed already (its file, or the same capture "
                                      "and model)"))
            else:
                filed.append(entry)
        return filed

    def _insert(self, tx, row, numbers) -> Entry | None:
        new = tx.rows(
            "INSERT INTO calibrations (serial, date_utc, scheme, method, verdict, file, source, sha256, filed_utc, "
            "capture_sha256, model, imu_model, lot) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?) "
            "ON CONFLICT DO NOTHING RETURNING id", row)
        if not new:
            return None
        tx.many("INSERT INTO parameters (calibration_id, name, value, sigma, unit) VALUES (?, ?, ?, ?, ?)",
                [(new[0][0], *n) for n in numbers])
        return self._entry((new[0][0], *row[:8], *row[11:]))

    def _row(self, doc: dict, digest: str, rel: str, source: str, *, lot=None, imu_model=None) -> tuple:
        """The calibrations row of a calibration document (the columns of the INSERT)."""
        prov = doc.get("provenance") if isinstance(doc.get("provenance"), dict) else {}
        serial = _text(prov.get("imu_serial")) or UNKNOWN_SERIAL
        date = _text(prov.get("date_utc")) or _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
        return (serial, date, _text(prov.get("scheme")), _text(prov.get("method")), verdict_of(doc), rel, source,
                digest, _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
                _text(prov.get("capture_sha256")), model_key(doc), imu_model or _text(prov.get("imu_model")),
                lot or _text(prov.get("imu_lot")))

    def close(self) -> None:
        self.index.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def _rows(self, sql: str, params=()) -> list:
        """The rows of a query (none when there is no index yet)."""
        with self.index.transaction(write=False, backfill=self._backfill) as tx:
            if tx is None:                 # (SQLite only: a database always answers)
                self._refuse_lost_index(f"{self.where}: the calibration history has no index")
                return []
            return tx.rows(sql, params)

    def _backfill(self, tx) -> None:
        """Migration step 4: the numbers, IMU model and lot of calibrations filed before the index
        held them, read from their files (a file that is gone or damaged keeps its row without
        numbers)."""
        from station.io.calfile import read_calfile

        for id_, file in tx.rows("SELECT id, file FROM calibrations"):
            try:
                doc = read_calfile(self._inside(str(file), f"{self.where}: row #{shown(id_)}"))
            except (UserError, OSError):
                continue
            prov = doc.get("provenance") if isinstance(doc.get("provenance"), dict) else {}
            tx.run("UPDATE calibrations SET imu_model = ?, lot = ? WHERE id = ?",
                   (_text(prov.get("imu_model")), _text(prov.get("imu_lot")), id_))
            tx.many("INSERT INTO parameters (calibration_id, name, value, sigma, unit) VALUES (?, ?, ?, ?, ?)",
                    [(id_, *n) for n in _numbers(doc)])

    def file(self, cal_path, *, lot: str | None = None, imu_model: str | None = None) -> tuple[Entry, bool]:
        """File a calibration; (its entry, True if new).  ``lot``/``imu_model`` state the IMU's lot
        and model where the file does not (``history --add --lot``), also on an entry filed before."""
        from station.io.calfile import read_calfile

        cal_path = Path(cal_path)
        doc = read_calfile(cal_path)
        data = cal_path.read_bytes()
        digest = hashlib.sha256(data).hexdigest()
        if not self.index.exists():
            # the index is made before the first file is copied into the store (in its own
            # transaction): a store's folder then never holds a file while its index is missing
            # or empty, unless the index was lost (_refuse_lost_index)
            with self.index.transaction(write=True, backfill=self._backfill):
                pass
        row = self._row(doc, digest, "", str(cal_path.resolve()), lot=lot, imu_model=imu_model)
        serial, date, capture_digest, model = row[0], row[1], row[9], row[10]
        key = (digest, capture_digest, model, serial)
        found = self._rows(f"SELECT {self._COLUMNS} FROM calibrations WHERE {self._SAME}", key)
        if found and lot is None and imu_model is None:
            return self._entry(found[0]), False
        rel = Path(serial_folder(serial)) / f"{re.sub(r'[^0-9A-Za-z]', '', date)[:15]}-{digest[:8]}.yaml"
        target = self.root / rel
        if not found:
            try:
                target.parent.mkdir(parents=True, exist_ok=True)
                _atomic_copy(data, target)
            except OSError as e:
                raise UserError(f"{target}: cannot file the calibration: {e.strerror}") from None
        row = (*row[:5], rel.as_posix(), *row[6:])
        with self.index.transaction(write=True, backfill=self._backfill) as tx:
            entry = self._insert(tx, row, _numbers(doc))
            new = entry is not None
            if not new:      # filed before, or by another writer since the look above
                if lot is not None or imu_model is not None:
                    tx.run(f"UPDATE calibrations SET lot = COALESCE(?, lot), imu_model = COALESCE(?, imu_model) "
                           f"WHERE {self._SAME}", (lot, imu_model, *key))
                entry = self._entry(tx.rows(f"SELECT {self._COLUMNS} FROM calibrations WHERE {self._SAME} "
                                            "ORDER BY id", key)[0])
                if entry.sha256 != digest and not found:
                    target.unlink(missing_ok=True)     # our copy of a calibration not filed
        return entry, new

    # the same calibration: the same file, or the same capture and model of the same serial
    _SAME = "sha256 = ? OR (capture_sha256 = ? AND model = ? AND serial = ?)"

    def _entry(self, row, *, strict: bool = True) -> Entry:
        """The entry of an index row.  ``strict``: a row whose file is not inside the store is a
        UserError (a file about to be opened); otherwise the entry is returned marked with that
        ``problem`` (a listing shows it, never opens it)."""
        id_, serial, date, scheme, method, verdict, file, source, digest, imu_model, lot = row
        where = f"{self.where}: row #{shown(id_)}"
        if not isinstance(id_, int) or not all(isinstance(v, str) for v in (serial, date, verdict, file, digest)) \
                or not all(v is None or isinstance(v, str) for v in (scheme, method, source, imu_model, lot)):
            raise UserError(f"{where}: not station's calibration history (a field of another type)")
        try:
            path, problem = self._inside(file, where), None
        except UserError:
            if strict:
                raise
            path, problem = Path(file[:200].replace("\0", "")), f"its file {file[:200]!r} is not inside the store"
        return Entry(id_, serial, date, scheme, method, verdict, path, source, digest, imu_model, lot, problem)

    def verify(self, entries) -> list:
        """Each entry checked against its file: the file must be there (a regular file inside the
        store) and have the sha256 the row was filed with — the index holds the numbers, the
        file is the record, and a row whose path was edited to name another calibration (or
        whose file was edited or removed) is marked with its ``problem``, never counted as the
        calibration it claims.  Every file is read and hashed (about 0.1 ms a file:
        docs/fleet.md, "Verifying the index against its files"); returns ``entries``."""
        from station.core.user_files import read_user_bytes

        for e in entries:
            if e.problem:
                continue
            rel = e.path.relative_to(self.root).as_posix() if e.path.is_relative_to(self.root) else str(e.path)
            if not os.path.lexists(e.path):
                e.problem = f"its file {rel} is missing"
                continue
            if os.path.islink(e.path):
                e.problem = f"its file {rel} is a symbolic link, not the file filed"
                continue
            try:
                data = read_user_bytes(e.path, "calibration file")
            except UserError:
                e.problem = f"its file {rel} cannot be read"
                continue
            if hashlib.sha256(data).hexdigest() != e.sha256:
                e.problem = f"its file {rel} is not the one filed (its sha256 differs from the index's)"
        return entries

    def checked(self, entry: Entry) -> Entry:
        """``entry`` verified; a UserError naming the row when its file is not the one filed
        (``diff #N``, ``history --drift``: a file about to be read as that calibration)."""
        self.verify([entry])
        if entry.problem:
            raise UserError(f"{self.where}: calibration #{entry.id} of IMU {entry.serial}: {entry.problem}; "
                            "not read as that calibration")
        return entry

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

    def get(self, id_: int) -> Entry:
        rows = self._rows(f"SELECT {self._COLUMNS} FROM calibrations WHERE id = ?", (id_,))
        if not rows:
            raise UserError(f"{self.where}: no calibration #{id_} in the history")
        return self.checked(self._entry(rows[0]))

    def list(self, serial: str, *, verify: bool = True) -> list[Entry]:
        """The calibrations of ``serial``, oldest first, each verified against its file (a row
        whose file is missing, outside the store or changed is listed with its ``problem``)."""
        rows = self._rows(f"SELECT {self._COLUMNS} FROM calibrations WHERE serial = ? ORDER BY date_utc, id", (serial,))
        entries = [self._entry(r, strict=False) for r in rows]
        return self.verify(entries) if verify else entries

    def serials(self) -> list[tuple[str, int]]:
        rows = self._rows("SELECT serial, COUNT(*) FROM calibrations GROUP BY serial ORDER BY serial")
        return [(str(serial), int(n)) for serial, n in rows]

    def count(self) -> int:
        rows = self._rows("SELECT COUNT(*) FROM calibrations")
        return int(rows[0][0]) if rows else 0

    def filed(self, *, imu_model: str | None = None, lot: str | None = None, since: str | None = None,
              verify: bool = True) -> list[Filed]:
        """Every filed calibration (of an IMU model, a lot, dated on or after ``since``) with its
        numbers, by serial and date; ``verify``: each entry checked against its file (its
        ``problem`` set when the file is not the one filed: ``station fleet`` does not count it)."""
        where, params = [], []
        for column, value, op in (("imu_model", imu_model, "="), ("lot", lot, "="), ("date_utc", since, ">=")):
            if value is not None:
                where.append(f"c.{column} {op} ?")
                params.append(value)
        cols = ", ".join(f"c.{c.strip()}" for c in self._COLUMNS.split(","))
        rows = self._rows(f"SELECT {cols}, p.name, p.value, p.sigma, p.unit FROM calibrations c "
                          f"LEFT JOIN parameters p ON p.calibration_id = c.id"
                          + (" WHERE " + " AND ".join(where) if where else "")
                          + " ORDER BY c.serial, c.date_utc, c.id, p.name", tuple(params))
        out: dict[int, Filed] = {}
        for row in rows:
            head, (name, value, sigma, unit) = row[:11], row[11:]
            if head[0] not in out:
                out[head[0]] = Filed(self._entry(head, strict=False), {})
            if name is not None:
                if not isinstance(value, (int, float)) or not (sigma is None or isinstance(sigma, (int, float))) \
                        or not isinstance(unit, str):
                    raise UserError(f"{self.where}: row #{shown(head[0])}: parameter {shown(name)}: not station's numbers")
                out[head[0]].numbers[str(name)] = Number(str(name), float(value),
                                                         None if sigma is None else float(sigma), unit)
        if verify:
            self.verify([f.entry for f in out.values()])
        return list(out.values())

    def resolve(self, ref: str) -> Path:
        """A calibration named by a file path or by its id in the history (``#12`` or ``12``)."""
        path = Path(ref)
        if path.exists():
            return path
        m = re.fullmatch(r"#?([0-9]{1,12})", ref)
        if m:
            return self.get(int(m.group(1))).path
        raise UserError(f"{ref}: neither a calibration file nor an id of the history ({self.where})")
