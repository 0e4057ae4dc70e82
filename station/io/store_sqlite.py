"""The calibration store's index in SQLite (stdlib sqlite3): ``index.sqlite`` in the store's
folder, the embedded default.

Writers from several processes are serialised by SQLite's own lock: every filing is one
``BEGIN IMMEDIATE`` transaction (the write lock taken before the first read, so that the
dedup check and the insert see the same index), waiting up to :data:`BUSY_TIMEOUT_S` for another
writer.  A writer killed mid-transaction leaves a hot journal that the next connection rolls
back.  A damaged or foreign index is a UserError naming the file, never an sqlite3 traceback.
"""
from __future__ import annotations

import sqlite3
from contextlib import contextmanager
from pathlib import Path

from station.core.errors import UserError
from station.io import store_schema as schema
from station.io.store_backend import Tx, one_line, shown

INDEX = "index.sqlite"
# a writer waits this long for the others: 8 processes filing at once each hold the lock for a
# few ms per calibration, so a minute is never reached unless a writer hangs
BUSY_TIMEOUT_S = 60.0


class SqliteIndex:
    dialect = schema.SQLITE

    def __init__(self, root: Path, path: Path | None = None):
        self.root = Path(root)
        self.path = Path(path) if path is not None else self.root / INDEX
        self.where = str(self.path)
        # called with a reason before an index without station's tables is created (a missing
        # or empty index of a store that holds calibration files: history.Store refuses it)
        self.on_new = None
        self.damaged_hint = lambda: ""

    def exists(self) -> bool:
        return self.path.exists()

    def close(self) -> None:
        pass

    def _open(self, create: bool) -> sqlite3.Connection | None:
        if not create and not self.path.exists():
            return None
        if create:
            try:
                self.root.mkdir(parents=True, exist_ok=True)
            except OSError as e:
                raise UserError(f"{self.root}: cannot create the calibration store: {e.strerror}") from None
        if self.path.exists() and not self.path.is_file():
            raise UserError(f"{self.path}: not a regular file: cannot open the calibration history")
        db = sqlite3.connect(self.path, timeout=BUSY_TIMEOUT_S, isolation_level=None)
        db.execute("PRAGMA foreign_keys = ON")
        return db

    def _version(self, tx: Tx) -> int:
        has_table = tx.rows("SELECT 1 FROM sqlite_master WHERE type = 'table' AND name = 'schema_version'")
        rows = tx.rows("SELECT version FROM schema_version") if has_table else []
        columns = tuple(r[1] for r in tx.rows("PRAGMA table_info(calibrations)"))
        if rows:
            version = rows[0][0]
            if not isinstance(version, int) or version > schema.LATEST:
                raise UserError(f"{self.path}: a calibration history of schema version {shown(version)}, "
                                + ("newer than this station knows" if isinstance(version, int) else "not a version")
                                + f" ({schema.LATEST}): " + ("update station" if isinstance(version, int)
                                                             else "not station's calibration history"))
            if schema.legacy_version(columns) is None:
                raise UserError(self._foreign(columns))
            return version
        version = schema.legacy_version(columns)
        if version is None:
            raise UserError(self._foreign(columns))
        return version

    def _foreign(self, columns) -> str:
        return (f"{self.path}: not station's calibration history: its table 'calibrations' has the columns "
                f"{', '.join(map(str, columns))[:200]}")

    @contextmanager
    def transaction(self, *, write: bool, backfill):
        """A Tx on an index at the latest schema (migrated first, under the write lock, when it is
        older), or None when there is no index and ``write`` is false."""
        try:
            db = self._open(create=write)
        except (OSError, sqlite3.Error) as e:
            raise UserError(f"{self.path}: cannot open the calibration history: {one_line(e)}") from None
        if db is None:
            yield None
            return
        try:
            tx = Tx(db.cursor())
            db.execute("BEGIN IMMEDIATE" if write else "BEGIN")
            try:
                version = self._version(tx)
                if version < schema.LATEST:
                    if not write:        # take the write lock to migrate, then read on
                        db.execute("ROLLBACK")
                        db.execute("BEGIN IMMEDIATE")
                        version = self._version(tx)
                    if version == 0 and self.on_new is not None:
                        size = self.path.stat().st_size
                        self.on_new(f"{self.path}: the calibration history's index is empty"
                                    + (" (0 bytes)" if size == 0 else " (no table of calibrations)"))
                    if version < schema.LATEST:
                        schema.migrate(tx, self.dialect, version, backfill)
                yield tx
                db.execute("COMMIT")
            except BaseException:
                if db.in_transaction:
                    db.execute("ROLLBACK")
                raise
        except sqlite3.Error as e:
            raise UserError(f"{self.path}: the calibration history cannot be {'written' if write else 'read'}: "
                            f"{one_line(e)}{self.damaged_hint()}") from None
        finally:
            db.close()
