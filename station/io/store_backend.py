"""What the calibration store asks of its index database: a transaction with a few verbs, and
where the index is (for messages).  Two implementations: station/io/store_sqlite.py (the
embedded default, a file in the store's folder) and station/io/store_postgres.py (a shared
PostgreSQL database, for several benches and workers filing at once).

SQL is written once, with ``?`` placeholders (sqlite3's); the PostgreSQL backend turns them into
psycopg's ``%s``.  No statement of the store contains a literal ``?`` or ``%``.
"""
from __future__ import annotations

import re

POSTGRES_SCHEMES = ("postgresql://", "postgres://")


def is_database_url(location) -> bool:
    return isinstance(location, str) and location.startswith(POSTGRES_SCHEMES)


def redacted(url: str) -> str:
    """A database URL for messages: its password replaced by ***."""
    return re.sub(r"(://[^:/@?]*):[^@/?]*@", r"\1:***@", url)


def one_line(e: Exception) -> str:
    return " ".join(str(e).split()) or type(e).__name__


def shown(value) -> str:
    """A value read from an index, for a one-line message (its repr, at most 40 characters)."""
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


class Tx:
    """An open transaction: ``run`` a statement, ``rows`` of a query, ``many`` rows inserted."""

    def __init__(self, cursor, postgres: bool = False):
        self.cursor = cursor
        self._pg = postgres

    def _sql(self, sql: str) -> str:
        return sql.replace("?", "%s") if self._pg else sql

    def run(self, sql: str, params=()) -> None:
        self.cursor.execute(self._sql(sql), params)

    def rows(self, sql: str, params=()) -> list:
        self.cursor.execute(self._sql(sql), params)
        return self.cursor.fetchall()

    def many(self, sql: str, seq) -> None:
        self.cursor.executemany(self._sql(sql), seq)
