"""One station process at a time talks to a table (drivers.table.TableLock): a second process
waits while the first holds it (a guardian stopping the table of a run that died) and gets it
when the first lets go; past its wait it says who holds the table."""
from __future__ import annotations

import subprocess
import sys
import time

import pytest

from drivers.base import TableSettings
from drivers.errors import DeviceError
from drivers.registry import open_table
from drivers.table import TableLock
from sim_devices.truth import default_truth
from sim_devices.twins.serve import BenchOptions, BenchServer

HOLDER = """
import sys, time
from drivers.registry import open_table
with open_table(sys.argv[1]) as table:
    print("holding", flush=True)
    time.sleep(float(sys.argv[2]))
"""


def _hold(path, seconds):
    proc = subprocess.Popen([sys.executable, "-c", HOLDER, path, str(seconds)],
                            stdout=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "holding"
    return proc


def test_a_second_process_waits_for_the_table_then_gets_it():
    with BenchServer(default_truth(3), BenchOptions(speed=50, axes=1)) as server:
        proc = _hold(server.table_path, 1.5)
        try:
            t0 = time.monotonic()
            with open_table(server.table_path, "acutrol", TableSettings()) as table:
                waited = time.monotonic() - t0
                assert table.n_axes == 1
            assert proc.wait(10) == 0
            assert waited > 0.5           # it did wait for the holder (which held 1.5 s from its print)
        finally:
            proc.kill()
            proc.wait()


def test_past_its_wait_it_names_the_holder():
    with BenchServer(default_truth(3), BenchOptions(speed=50, axes=1)) as server:
        proc = _hold(server.table_path, 30)
        try:
            lock = TableLock(server.table_path, "table X")
            with pytest.raises(DeviceError, match=rf"table X: in use by another station process \(pid {proc.pid}\) "
                                                  r"for over 0.3 s"):
                lock.acquire(wait_s=0.3)
        finally:
            proc.kill()
            proc.wait()
        lock.acquire(wait_s=5)            # a holder that died let go with its process
        lock.release()


def test_within_one_process_the_lock_is_shared():
    with BenchServer(default_truth(3), BenchOptions(speed=50, axes=1)) as server:
        with open_table(server.table_path) as a, open_table(server.table_path) as b:
            assert a.n_axes == b.n_axes == 1


def test_the_lock_lives_in_a_private_directory_and_never_follows_a_link(tmp_path, monkeypatch):
    """Another user (or anything) may plant a link where a lock file would go in the shared
    temporary directory: the lock lives in a 0700 directory of this user's, and its file is
    never opened through a link (a truncate through one would clobber the link's target)."""
    import os
    import tempfile

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    lock = TableLock("/dev/ttyUSB9", "table T")
    target = tmp_path / "precious"
    target.write_text("keep me")
    os.makedirs(lock.dir, mode=0o700)
    os.symlink(target, lock.path)
    with pytest.raises(DeviceError, match="cannot open the table lock"):
        lock.acquire(wait_s=0.1)
    assert target.read_text() == "keep me"
    os.unlink(lock.path)
    os.chmod(lock.dir, 0o777)                       # not private: refused with what to do
    with pytest.raises(DeviceError, match="is not a private directory of this user: remove it"):
        lock.acquire(wait_s=0.1)
    os.chmod(lock.dir, 0o700)
    lock.acquire(wait_s=0.1)
    assert oct(os.stat(lock.path).st_mode & 0o777) == "0o600"
    lock.release()
