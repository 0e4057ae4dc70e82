"""A batch worker keeps its effects registry between tasks (station.batch.tasks._effects) only
while the plugin folders it loaded hold the same ``*.py`` files, unmodified (review of
28a7a67..main, item 2): a plugin file dropped into a folder is seen by the next task."""
import os
from pathlib import Path

import pytest

from station.batch import tasks

EXAMPLES = Path(__file__).resolve().parents[1] / "examples" / "effects"


@pytest.fixture
def worker(monkeypatch):
    """A worker's cache, empty; no plugin path from the environment but the test's own."""
    monkeypatch.setattr(tasks, "_EFFECTS", {})
    monkeypatch.delenv("STATION_EFFECTS_PATH", raising=False)
    return monkeypatch


def _drop(folder: Path, name: str, example: str) -> Path:
    path = folder / name
    path.write_text((EXAMPLES / example).read_text())
    return path


@pytest.mark.parametrize("named_by", ["effects_dirs", "environment"])
def test_a_plugin_dropped_into_a_folder_is_seen_by_the_next_task(worker, tmp_path, named_by):
    folder = tmp_path / "fx"
    folder.mkdir()
    _drop(folder, "rate.py", "gyro_rate_squared.py")
    if named_by == "environment":
        worker.setenv("STATION_EFFECTS_PATH", str(folder))
        options = {}
    else:
        options = {"effects_dirs": [str(folder)]}
    registry, _ = tasks._effects(options)
    assert "gyro_rate_squared" in registry and "accel_cross_coupling" not in registry
    assert tasks._effects(options)[0] is registry          # kept while the folder is unchanged

    added = _drop(folder, "coupling.py", "accel_cross_coupling.py")
    again, _ = tasks._effects(options)
    assert again is not registry and "accel_cross_coupling" in again and "gyro_rate_squared" in again
    assert tasks._effects(options)[0] is again

    # a file rewritten (its modification time moves on) or taken out: built again
    st = added.stat()
    os.utime(added, ns=(st.st_atime_ns, st.st_mtime_ns + 1_000_000_000))
    rewritten, _ = tasks._effects(options)
    assert rewritten is not again
    added.unlink()
    removed, _ = tasks._effects(options)
    assert removed is not rewritten and "accel_cross_coupling" not in removed


def test_a_folder_the_configuration_names_is_watched_too(worker, tmp_path):
    """The configuration file is unchanged (the key's stamp of it holds): the folder its effects
    section names is what changes."""
    folder = tmp_path / "fx"
    folder.mkdir()
    config = tmp_path / "station.yaml"
    config.write_text("effects:\n  folders: [fx]\n")
    worker.setenv("STATION_CONFIG", str(config))
    registry, _ = tasks._effects({})
    assert "gyro_rate_squared" not in registry
    assert tasks._effects({})[0] is registry
    _drop(folder, "rate.py", "gyro_rate_squared.py")
    assert "gyro_rate_squared" in tasks._effects({})[0]
