"""A ROS bag whose compressed chunk inflates far beyond any real one (a decompression bomb) is
refused with one line naming the bag, before it exhausts the machine (issue 26;
station/core/memory_cap.py).  rosbags decompresses a chunk whole, so the bound is on the memory
the reading may take; the bombs here are written by rosbags' own writer with its compressor
swapped for one that returns the bomb (the chunk's lengths and the index stay consistent).

The budget is lowered from 1 GiB to BUDGET for the test, so that the bombs stay small to build and
fast to refuse: a bz2 or lz4 chunk of BOMB_BYTES of zeros, 4x the budget."""
import bz2
import resource
import sys

import numpy as np
import pytest

from station.core import memory_cap
from station.core.errors import UserError

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"),
                                reason="RLIMIT_AS is enforced on Linux only (the message still comes elsewhere)")

BUDGET = 64 << 20
BOMB_BYTES = 4 * BUDGET


def _bz2_bomb() -> bytes:
    # bz2.decompress reads concatenated streams: 16 streams of 16 MiB of zeros, a few hundred bytes
    block = bz2.compress(b"\0" * (BOMB_BYTES // 16), 9)
    return block * 16


def _lz4_bomb() -> bytes:
    import lz4.frame
    return lz4.frame.compress(b"\0" * BOMB_BYTES)


def _bag(path, how, bomb, monkeypatch):
    import rosbags.rosbag1.writer as w

    from station.io.importers.rosbag import write_imu_bag
    with monkeypatch.context() as m:
        m.setattr(w, "bz2_compress" if how == "bz2" else "lz4_compress", lambda data, *a, **k: bomb)
        n = 50
        t = np.arange(n) / 100.0
        return write_imu_bag(path, t, np.tile([0.0, 0.0, 9.8], (n, 1)), np.zeros((n, 3)),
                             fmt="rosbag1", compression=how)


@pytest.mark.parametrize("how", ["bz2", "lz4"])
def test_a_bag_whose_chunk_inflates_beyond_the_budget_is_refused_naming_it(tmp_path, monkeypatch, how):
    from station.io.importers.rosbag import read_rosbag
    bomb = _bz2_bomb() if how == "bz2" else _lz4_bomb()
    assert len(bomb) < BOMB_BYTES // 200             # a bomb: lz4 inflates ~250x at most, bz2 far more
    bag = _bag(tmp_path / f"{how}.bag", how, bomb, monkeypatch)
    monkeypatch.setattr(memory_cap, "BASE_BUDGET_BYTES", BUDGET)
    before = resource.getrlimit(resource.RLIMIT_AS)
    with pytest.raises(UserError) as e:
        read_rosbag(bag)
    msg = str(e.value)
    assert str(bag) in msg and "decompression bomb" in msg and "\n" not in msg, msg
    assert resource.getrlimit(resource.RLIMIT_AS) == before      # the process's limit is given back


def test_a_real_compressed_bag_reads_within_the_budget_and_the_limit_comes_back(tmp_path, monkeypatch):
    """The same small budget passes an honest bz2 bag: the cap refuses only what inflates beyond it."""
    from station.io.importers.rosbag import read_rosbag, write_imu_bag
    monkeypatch.setattr(memory_cap, "BASE_BUDGET_BYTES", BUDGET)
    n = 2000
    t = np.arange(n) / 100.0
    bag = write_imu_bag(tmp_path / "ok.bag", t, np.tile([0.0, 0.0, 9.8], (n, 1)), np.zeros((n, 3)),
                        fmt="rosbag1", compression="bz2")
    before = resource.getrlimit(resource.RLIMIT_AS)
    rec = read_rosbag(bag)
    assert len(rec.t) == n and np.allclose(rec.accel[:, 2], 9.8)
    assert resource.getrlimit(resource.RLIMIT_AS) == before


def test_a_memory_error_inside_the_cap_names_the_file_and_the_limit_is_restored():
    before = resource.getrlimit(resource.RLIMIT_AS)
    with pytest.raises(UserError, match=r"^some\.bag: reading it needs more than 1 MiB"):
        with memory_cap.memory_cap(1 << 20, "some.bag"):
            assert resource.getrlimit(resource.RLIMIT_AS)[0] != resource.RLIM_INFINITY   # lowered inside
            raise MemoryError
    assert resource.getrlimit(resource.RLIMIT_AS) == before
