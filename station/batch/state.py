"""The batch state file: one JSON line per item finished, appended (and flushed) as each result
arrives, so that a batch killed at any moment has recorded everything it finished.  A batch
started again with the same command, options and outputs hands each item its earlier record;
the worker skips the item when the capture's fingerprint and the output's sha256 still match
(station.batch.tasks.run).  Items that failed are always run again.

Default place: ``DIR/.station-batch-COMMAND.jsonl`` with ``-o DIR``, else
``.station-batch-COMMAND.jsonl`` in the working folder (``--state FILE`` chooses).  A line cut
short by a kill, or one that is not a record, is ignored (that item runs again)."""
from __future__ import annotations

import dataclasses
import hashlib
import json
import os
from pathlib import Path

from station.core.errors import UserError


def default_path(command: str, out_dir=None) -> Path:
    return (Path(out_dir) if out_dir else Path(".")) / f".station-batch-{command}.jsonl"


def options_key(command: str, options: dict) -> str:
    return hashlib.sha256(json.dumps([command, options], sort_keys=True, default=str).encode()).hexdigest()[:16]


def item_key(options_key_: str, source: str, output: str) -> str:
    """An item's key: the options and the absolute paths (a batch started again from another
    folder finds its records)."""
    return f"{options_key_}:{os.path.abspath(source)}:{os.path.abspath(output)}"


class State:
    def __init__(self, path, *, fresh: bool = False):
        self.path = Path(path)
        self.records: dict = {}
        if fresh or not self.path.exists():
            return
        if not self.path.is_file():
            raise UserError(f"{self.path}: not a regular file: cannot be the batch state file")
        try:
            text = self.path.read_text(errors="replace")
        except OSError as e:
            raise UserError(f"{self.path}: cannot read the batch state file: {e.strerror}") from None
        for line in text.splitlines():
            try:
                rec = json.loads(line)
            except ValueError:
                continue                        # a line cut short by a kill: that item runs again
            if isinstance(rec, dict) and isinstance(rec.get("key"), str):
                self.records[rec["key"]] = rec

    def previous(self, key: str) -> dict | None:
        rec = self.records.get(key)
        return rec if rec and rec.get("status") in ("done", "poor fit", "skipped") else None

    def __enter__(self):
        from station.core.user_files import output_path

        output_path(self.path, "the batch state file")
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._file = open(self.path, "w" if not self.records else "a", encoding="utf-8")
        except OSError as e:
            raise UserError(f"{self.path}: cannot write the batch state file: {e.strerror}") from None
        return self

    def record(self, key: str, outcome) -> None:
        rec = {"key": key, **dataclasses.asdict(outcome)}
        self.records[key] = rec
        self._file.write(json.dumps(rec) + "\n")
        self._file.flush()                      # in the kernel: a killed batch keeps it

    def __exit__(self, *exc):
        self._file.close()
