"""A real PostgreSQL server for the store's tests and benchmark, started from the system's
binaries (Debian: /usr/lib/postgresql/VERSION/bin) in a temporary folder, listening only on a
unix socket in that folder (no port to collide with another session's server).

PostgreSQL refuses to run as root: as root, the data folder is given to an unprivileged user
(``nobody``) and initdb, pg_ctl and the server run as that user (``runuser``).  ``stop()``
stops the server (fast shutdown, waited for) and removes the folder; the fixtures call it in
their finalizer, so nothing is left running.  A pytest killed before its finalizers run (SIGKILL)
leaves nothing either: a guard (tests/server_guard.py), armed before ``pg_ctl start`` on the
data folder's ``postmaster.pid``, shuts the server down immediately (SIGQUIT, as ``pg_ctl stop -m
immediate``; SIGKILL after 5 s) and removes the folder when the test process ends first.
"""
from __future__ import annotations

import glob
import os
import pwd
import re
import shutil
import signal
import subprocess
import tempfile
from pathlib import Path

import pytest

from server_guard import guard

SUPERUSER = "station"


def binaries() -> Path | None:
    """The folder of initdb and pg_ctl: the newest /usr/lib/postgresql/N/bin, else PATH's."""
    found = [Path(d) for d in glob.glob("/usr/lib/postgresql/*/bin") if (Path(d) / "initdb").exists()]
    found.sort(key=lambda d: int(re.sub(r"\D", "", d.parent.name) or 0), reverse=True)
    if found:
        return found[0]
    initdb, pg_ctl = shutil.which("initdb"), shutil.which("pg_ctl")
    return Path(initdb).parent if initdb and pg_ctl else None


def unavailable() -> str | None:
    """Why no server can be started here (None: it can)."""
    try:
        import psycopg  # noqa: F401
    except ImportError:
        return "psycopg is not installed (pip install -e '.[dev]')"
    if binaries() is None:
        return "no PostgreSQL server binaries (initdb, pg_ctl) installed (apt-get install postgresql; .ci/run does)"
    if os.geteuid() == 0 and shutil.which("runuser") is None:
        return "running as root without runuser: PostgreSQL refuses to run as root"
    return None


class Server:
    def __init__(self, fsync: bool = False):
        self.bindir = binaries()
        self.fsync = fsync
        self.dir: Path | None = None
        self.started = False
        self.guard = None

    def _run(self, *argv, timeout=120) -> subprocess.CompletedProcess:
        cmd = [str(self.bindir / argv[0]), *map(str, argv[1:])]
        if os.geteuid() == 0:
            cmd = ["runuser", "-u", "nobody", "--", *cmd]
        return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, cwd=self.dir,
                              stdin=subprocess.DEVNULL)

    def start(self) -> "Server":
        self.dir = Path(tempfile.mkdtemp(prefix="station-pg-"))
        if os.geteuid() == 0:
            nobody = pwd.getpwnam("nobody")
            os.chown(self.dir, nobody.pw_uid, nobody.pw_gid)
        data = self.dir / "data"
        r = self._run("initdb", "-D", data, "-U", SUPERUSER, "--auth=trust", "--no-locale", "-E", "UTF8",
                      *(() if self.fsync else ("--no-sync",)))
        if r.returncode != 0:
            raise RuntimeError(f"initdb failed: {r.stderr[-2000:]}")
        # guarded from before the start: a pytest killed while pg_ctl waits leaves no server either
        self.guard = guard(pidfiles=[data / "postmaster.pid"], sig=signal.SIGQUIT, grace_s=5.0, remove=[self.dir])
        options = f"-k {self.dir} -c listen_addresses='' -c max_connections=50" + ("" if self.fsync else " -c fsync=off")
        r = self._run("pg_ctl", "-D", data, "-l", self.dir / "server.log", "-o", options, "-w", "-t", "120", "start")
        self.started = True        # stop() is worth trying even when pg_ctl said it failed
        if r.returncode != 0:
            log = (self.dir / "server.log").read_text(errors="replace")[-2000:] if (self.dir / "server.log").exists() else ""
            raise RuntimeError(f"pg_ctl start failed: {r.stderr[-1000:]} {log}")
        return self

    def url(self, database: str = "postgres") -> str:
        return f"postgresql://{SUPERUSER}@/{database}?host={self.dir}"

    def create_database(self, name: str) -> str:
        import psycopg

        with psycopg.connect(self.url(), autocommit=True) as conn:
            conn.execute(f'CREATE DATABASE "{name}"')
        return self.url(name)

    def stop(self) -> None:
        if self.dir is None:
            return
        try:
            if self.started:
                r = self._run("pg_ctl", "-D", self.dir / "data", "-m", "fast", "-w", "-t", "60", "stop")
                if r.returncode != 0 and (self.dir / "data" / "postmaster.pid").exists():
                    self._run("pg_ctl", "-D", self.dir / "data", "-m", "immediate", "-w", "-t", "60", "stop")
        finally:
            if self.guard is not None:
                self.guard.release()
                self.guard = None
            shutil.rmtree(self.dir, ignore_errors=True)
            self.dir = None
            self.started = False


@pytest.fixture(scope="module")
def pg():
    """A running server for the module (import this fixture into a test module), or the test
    skipped with the reason when none can be started here (failed instead with
    STATION_REQUIRE_POSTGRES=1, as .ci/run sets)."""
    why = unavailable()
    if why:
        if os.environ.get("STATION_REQUIRE_POSTGRES") == "1":
            pytest.fail(f"STATION_REQUIRE_POSTGRES=1 but {why}")
        pytest.skip(why)
    server = Server()
    try:
        server.start()
        yield server
    finally:
        server.stop()
