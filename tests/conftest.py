"""Shared fixtures: every test files calibrations into a temporary history store, never into the
user's data directory; one short optimal9 dry run for the export, history and report tests."""
import os
import sys

# One BLAS thread per test process, as `station` itself runs (station/core/blas.py):
# the fits' matrices are small, and two test workers each spinning two OpenBLAS threads on two
# cores took 3-4x the CPU (tests/test_effects_recovered.py: 41-50 s of CPU against 12.5 s, at a
# load of 12).  Set before numpy is loaded (OpenBLAS reads it then), inherited by the commands
# the tests start; threadpool_limits below for a library some plugin loaded first.
for _name in ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

# Bytecode written for this run's modules even where PYTHONDONTWRITEBYTECODE is set (some machines
# set it): the suite starts hundreds of `station` processes, and without cached bytecode each of
# them compiled every module it imports from source (~0.1 s of CPU per command), and each test
# worker rewrote every test file's assertions again (6.3 s of CPU per worker against 2.3 s).
# tests/test_cli.py, test_report.py and test_sequencer.py together: 24.9 -> 22.0-23.0 s of CPU.
# The files go to __pycache__ folders (.gitignore); set here, before the test files are imported,
# and inherited by the commands the tests start.
os.environ.pop("PYTHONDONTWRITEBYTECODE", None)
sys.dont_write_bytecode = False

import pytest  # noqa: E402
from threadpoolctl import threadpool_limits as _threadpool_limits  # noqa: E402

from station.cli import main  # noqa: E402

_BLAS_LIMIT = _threadpool_limits(limits=1, user_api="blas")

SHORT = ["--dwell-s", "20", "--rotation-s", "36"]   # one revolution at 10 deg/s: a quick run


@pytest.fixture(autouse=True, scope="session")
def _history_store(tmp_path_factory):
    mp = pytest.MonkeyPatch()
    mp.setenv("STATION_HISTORY_DIR", str(tmp_path_factory.mktemp("history-store")))
    mp.setenv("XDG_CONFIG_HOME", str(tmp_path_factory.mktemp("user-config")))   # not the user's own
    mp.setenv("STATION_CACHE_DIR", str(tmp_path_factory.mktemp("user-cache")))   # compiled plans: not the user's
    mp.delenv("STATION_CONFIG", raising=False)
    mp.delenv("STATION_STORE", raising=False)       # not a database of the user's
    yield
    mp.undo()


@pytest.fixture(scope="session")
def optimal9_run(tmp_path_factory):
    """A short optimal9 dry run (seed 13): capture bundle with calibration.yaml."""
    out = tmp_path_factory.mktemp("optimal9") / "cap"
    assert main(["run", "--scheme", "optimal9", "--sim", "--seed", "13", "--out", str(out), *SHORT]) == 0
    return out


# Hypothesis: derandomised unless asked otherwise, so that a run of the suite is repeatable on
# any machine and a failure in CI is the same failure here (`pytest --hypothesis-profile explore`
# searches with fresh random examples, and prints the seed of a failure to reproduce it).
from hypothesis import settings as _hypothesis_settings  # noqa: E402

_hypothesis_settings.register_profile("repeatable", derandomize=True, database=None, print_blob=True)
_hypothesis_settings.register_profile("explore", derandomize=False, print_blob=True)
_hypothesis_settings.load_profile("repeatable")
