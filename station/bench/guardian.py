"""The table's guardian: a small process that stops the table if ``station run`` dies.

SIGKILL, an out-of-memory kill or a crash of the interpreter cannot be caught: the run's
``finally`` never runs and the table keeps doing what it was told last (a rotation keeps
turning).  No public controller manual offers a watchdog on the command channel
(docs/sequencer.md, "A stop the bench can count on"), so the run starts this guardian when it
opens the table port.  The guardian holds the read end of a pipe whose write end only the run
holds; it never touches the port while the run lives.

* The run ends normally (done, paused, aborted, failed: its own ``finally`` stopped the table)
  and calls :meth:`Guardian.release`: it writes ``done`` and closes the pipe; the guardian exits
  without opening the port.
* The run dies: the kernel closes its end of the pipe, the guardian reads end-of-file without
  ``done``, opens the table port (retrying while the dead run's port is released) and connects,
  which brakes and holds any axis found moving (``RateTable._stop_leftover_motion``: a zero rate
  demand before rate mode, the rest position before position mode).  What it found and did is
  appended to ``guardian.log`` in the capture directory; then it exits.

The guardian runs in a session of its own, so a signal to the run's process group (the
terminal's Ctrl-C, ``kill -- -PGID``) does not reach it, and it leaves nothing running: it exits
as soon as the run has ended either way (at most ``OPEN_RETRY_S`` after a run's death when the
port cannot be opened, saying so in its log).
"""
from __future__ import annotations

import dataclasses
import datetime as _dt
import json
import os
import subprocess
import sys
import time
from pathlib import Path

#: how long the guardian keeps trying to open the port of a run that died (s)
OPEN_RETRY_S = 30.0
DONE = b"done\n"
LOG_NAME = "guardian.log"


class Guardian:
    """The run's handle on its guardian process."""

    def __init__(self, proc: subprocess.Popen):
        self.proc = proc

    def release(self, timeout_s: float = 10.0) -> None:
        """The run ended in its own hands: the guardian exits without touching the table."""
        try:
            self.proc.stdin.write(DONE)
            self.proc.stdin.close()
        except (OSError, ValueError):
            pass
        try:
            self.proc.wait(timeout_s)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()


def start_guardian(url: str, protocol: str, settings, log_dir: Path) -> Guardian:
    """Start the guardian of the table on ``url`` (``settings``: the driver's TableSettings)."""
    spec = json.dumps({"url": url, "protocol": protocol, "settings": dataclasses.asdict(settings),
                       "log": str(Path(log_dir) / LOG_NAME), "run_pid": os.getpid()})
    proc = subprocess.Popen([sys.executable, "-m", "station.bench.guardian", spec],
                            stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True, close_fds=True)
    return Guardian(proc)


def _settings(d: dict):
    from drivers.base import AxisLimits, TableSettings
    from drivers.transport import SerialSettings

    d = dict(d)
    d["serial"] = SerialSettings(**d["serial"])
    d["limits"] = tuple(AxisLimits(**lim) for lim in d["limits"])
    d["dialect"] = tuple(tuple(x) for x in d["dialect"])
    return TableSettings(**d)


def _log(path: str, text: str) -> None:
    """Append to the capture's guardian.log; where the capture directory is not there (the run
    died before it made it) to ``$TMPDIR/station-<uid>/guardian.log`` instead."""
    import tempfile

    stamp = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
    fallback = os.path.join(tempfile.gettempdir(), f"station-{os.getuid()}", LOG_NAME)
    for target in (path, fallback):
        try:
            if target == fallback:
                os.makedirs(os.path.dirname(fallback), mode=0o700, exist_ok=True)
            with open(target, "a", encoding="utf-8") as f:
                f.write(f"{stamp} {text}\n")
            return
        except OSError:
            continue


def guard(spec: dict, stdin=None) -> int:
    """The guardian's life: wait for the run's end; if it died, stop the table."""
    stdin = stdin if stdin is not None else sys.stdin.buffer
    data = b""
    while True:                                  # until end-of-file: the run has ended
        chunk = stdin.read1(64) if hasattr(stdin, "read1") else stdin.read(64)
        if not chunk:
            break
        data += chunk
    if data.startswith(DONE):
        return 0
    from drivers.registry import open_table
    from station.core.errors import UserError

    log = spec["log"]
    _log(log, f"station run (pid {spec['run_pid']}) ended without stopping the table: opening "
              f"{spec['url']} to stop it")
    deadline = time.monotonic() + OPEN_RETRY_S
    while True:
        try:
            with open_table(spec["url"], spec["protocol"], _settings(spec["settings"])) as table:
                note = table.describe_leftover()
                _log(log, note or f"{table.name}: every axis was at rest; nothing done")
                return 0
        except UserError as e:
            if time.monotonic() > deadline:
                _log(log, f"could not stop the table: {e}")
                return 1
            time.sleep(0.5)


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    return guard(json.loads(argv[0]))


if __name__ == "__main__":
    sys.exit(main())
