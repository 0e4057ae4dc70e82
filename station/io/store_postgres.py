"""The calibration store's index in PostgreSQL (psycopg 3): one database shared by several
benches and workers (``--store postgresql://USER@HOST/DB`` or ``$STATION_STORE``).

One connection per Store, opened on first use (autocommit: a read is one statement, a write an
explicit transaction).  Each filing is one transaction at READ COMMITTED:
the insert is ``INSERT ... ON CONFLICT DO NOTHING`` against the unique constraints (the file's
sha256; the capture, model and serial), so two writers filing the same calibration at once wait
for each other inside PostgreSQL and exactly one row results.  A writer killed mid-transaction is
rolled back by the server when its connection drops.  The schema is created and migrated under a
transaction-level advisory lock (:data:`MIGRATION_LOCK`): processes opening a new store at once
apply each step once.  psycopg is imported only here, when a database URL is given: the
``postgres`` extra (``pip install 'station[postgres]'``).
"""
from __future__ import annotations

from contextlib import contextmanager

from station.core.errors import UserError
from station.io import store_schema as schema
from station.io.store_backend import Tx, one_line, redacted, shown

MIGRATION_LOCK = 0x5354_4154_494F_4E          # "STATION": the advisory lock key of migrations
CONNECT_TIMEOUT_S = 10


class PostgresIndex:
    dialect = schema.POSTGRES

    def __init__(self, url: str):
        self.url = url
        self.where = redacted(url)
        self._conn = None
        # a new database is a new store (its files' folder may be shared: the SQLite default's
        # folder), so a new database is never refused for the files beside it (SqliteIndex.on_new)
        self.on_new = None
        self.damaged_hint = lambda: ""

    def exists(self) -> bool:
        return True

    def close(self) -> None:
        if self._conn is not None:
            self._conn.close()
            self._conn = None

    def _connect(self, backfill):
        try:
            import psycopg
        except ImportError:
            raise UserError(f"{self.where}: a PostgreSQL store needs psycopg: pip install 'station[postgres]'") from None
        try:
            conn = psycopg.connect(self.url, connect_timeout=CONNECT_TIMEOUT_S, application_name="station",
                                   autocommit=True)
        except psycopg.Error as e:
            raise UserError(f"{self.where}: cannot connect to the calibration store: {one_line(e)}") from None
        except Exception as e:      # a malformed URL (psycopg.ProgrammingError is a psycopg.Error; others)
            raise UserError(f"{self.where}: not a usable PostgreSQL URL: {one_line(e)}") from None
        try:
            with conn.transaction(), conn.cursor() as cur:
                tx = Tx(cur, postgres=True)
                tx.run("SELECT pg_advisory_xact_lock(?)", (MIGRATION_LOCK,))
                version = self._version(tx)
                if version < schema.LATEST:
                    schema.migrate(tx, self.dialect, version, backfill)
        except BaseException:
            conn.close()
            raise
        return conn

    def _version(self, tx: Tx) -> int:
        has_table = tx.rows("SELECT to_regclass('schema_version') IS NOT NULL")[0][0]
        rows = tx.rows("SELECT version FROM schema_version") if has_table else []
        columns = tuple(r[0] for r in tx.rows(
            "SELECT column_name FROM information_schema.columns WHERE table_schema = current_schema() "
            "AND table_name = 'calibrations' ORDER BY ordinal_position"))
        version = rows[0][0] if rows else schema.legacy_version(columns)
        if rows and (not isinstance(version, int) or isinstance(version, bool)):
            raise UserError(f"{self.where}: not station's calibration store: its schema version is "
                            f"{shown(version)}, not a whole number")
        if rows and version > schema.LATEST:
            raise UserError(f"{self.where}: a calibration store of schema version {version}, newer than this "
                            f"station knows ({schema.LATEST}): update station")
        if version is None or schema.legacy_version(columns) is None:
            raise UserError(f"{self.where}: not station's calibration store: its table 'calibrations' has the "
                            f"columns {', '.join(columns)[:200]}")
        return version

    @contextmanager
    def transaction(self, *, write: bool, backfill):
        import psycopg

        try:
            if self._conn is None or self._conn.closed:
                self._conn = self._connect(backfill)
            if write:
                with self._conn.transaction(), self._conn.cursor() as cur:
                    yield Tx(cur, postgres=True)
            else:                   # a read is one statement: no BEGIN/COMMIT round trips
                with self._conn.cursor() as cur:
                    yield Tx(cur, postgres=True)
        except psycopg.Error as e:
            self.close()            # a broken connection is opened again by the next transaction
            raise UserError(f"{self.where}: the calibration store cannot be {'written' if write else 'read'}: "
                            f"{one_line(e)}") from None
