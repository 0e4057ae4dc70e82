"""Hypothesis fuzz of ROS bags as ``station import rosbag`` reads them, structure-aware (issue 26):
a ROS 1 bag, a ROS 2 bag in MCAP and in sqlite3 storage, each written by station's own writer and
then mutated in its real structure (tests/bag_mutations.py: records, headers, connections, chunk
lengths, message bytes; MCAP opcodes, lengths and fields; sqlite rows, types and schema; the
folder's metadata.yaml).  Whatever the mutation, the import (station.api.import_rosbag, the
command's code) writes a capture or raises UserError: one line, naming the bag; never another
exception, never a hang (each import is given HANG_S of wall time, an alarm).

Cheap by design (the suite's budget): EXAMPLES per test (a few hundred ms each); the long run is
``STATION_FUZZ_EXAMPLES=3000 python -m pytest tests/test_fuzz_bags.py --hypothesis-profile explore``
(docs/reliability.md gives its count)."""
import os
import shutil

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from bag_mutations import db3_changes, db3_mutate, db3_tables, mcap_spans, mutated_spans, ros1_spans
from processes import time_limit
from station import api
from station.core.errors import UserError
from test_fuzz_configs import mutated, paths
from test_fuzz_readers import values

EXAMPLES = int(os.environ.get("STATION_FUZZ_EXAMPLES", "10"))
FUZZ = settings(max_examples=EXAMPLES, deadline=None, suppress_health_check=list(HealthCheck))
# a bag of 40 messages reads in ~10 ms; a reader that loops or waits on a damaged length takes
# forever: 20 s is far beyond any honest read even on a machine loaded 10x, and is a hang
HANG_S = 20.0
MESSAGES = 40


@pytest.fixture(scope="module")
def bags(tmp_path_factory):
    """The valid bags the mutations start from: {fmt: path} (a .bag file; ROS 2 bag folders)."""
    from station.io.importers.rosbag import write_imu_bag
    d = tmp_path_factory.mktemp("bags")
    t = np.arange(MESSAGES) / 100.0
    accel = np.tile([0.1, -0.2, 9.8], (MESSAGES, 1))
    gyro = np.tile([0.001, 0.002, -0.003], (MESSAGES, 1))
    bags = {fmt: write_imu_bag(d / (f"{fmt}.bag" if fmt == "rosbag1" else fmt), t, accel, gyro, fmt=fmt)
            for fmt in ("rosbag1", "mcap", "sqlite3")}
    for how in ("bz2", "lz4"):       # chunks compressed, as rosbag record -j / --lz4 writes them
        bags[f"rosbag1-{how}"] = write_imu_bag(d / f"{how}.bag", t, accel, gyro, fmt="rosbag1", compression=how)
    return bags


def imports_or_refuses(bag, out):
    """'imported' or 'refused' (one line naming the bag); any other exception or a hang fails."""
    try:
        with time_limit(HANG_S):
            api.import_rosbag(bag, out)
    except UserError as e:
        msg = str(e)
        assert "\n" not in msg.strip() and len(msg) < 2000, msg
        assert str(bag) in msg or msg.startswith("--"), msg
        return "refused"
    return "imported"


def _copy(src, dst):
    shutil.copytree(src, dst) if src.is_dir() else shutil.copyfile(src, dst)
    return dst


def _storage_file(folder):
    return next(p for p in folder.iterdir() if p.suffix in (".mcap", ".db3"))


def test_the_valid_bags_are_read(bags, tmp_path):
    """The fuzz starts from bags the reader reads (else it would test refusals only): each gives
    its MESSAGES messages (the import then refuses them as too short a recording to be a session,
    one line naming the bag)."""
    from station.io.importers.rosbag import read_rosbag
    for fmt, bag in bags.items():
        rec = read_rosbag(bag)
        assert len(rec.t) == MESSAGES and np.allclose(rec.accel[0], [0.1, -0.2, 9.8]), fmt
        assert imports_or_refuses(bag, tmp_path / fmt) == "refused"


@FUZZ
@given(data=st.data(), which=st.sampled_from(["rosbag1", "rosbag1", "rosbag1-bz2", "rosbag1-lz4"]))
def test_fuzzed_ros1_bag_structure(bags, tmp_path_factory, data, which):
    spans = ros1_spans(bags[which].read_bytes())
    assert len(spans) > 30          # parsed into records and fields, not one blob
    d = tmp_path_factory.mktemp("r1")
    (d / "in.bag").write_bytes(data.draw(mutated_spans(spans)))
    imports_or_refuses(d / "in.bag", d / "cap")


@FUZZ
@given(data=st.data())
def test_fuzzed_mcap_structure(bags, tmp_path_factory, data):
    d = tmp_path_factory.mktemp("mc")
    bag = _copy(bags["mcap"], d / "bag")
    storage = _storage_file(bag)
    spans = mcap_spans(storage.read_bytes())
    assert len(spans) > 50
    storage.write_bytes(data.draw(mutated_spans(spans)))
    imports_or_refuses(bag, d / "cap")


@FUZZ
@given(data=st.data())
def test_fuzzed_db3_rows_and_schema(bags, tmp_path_factory, data):
    d = tmp_path_factory.mktemp("db")
    bag = _copy(bags["sqlite3"], d / "bag")
    storage = _storage_file(bag)
    db3_mutate(storage, data.draw(db3_changes(db3_tables(storage))))
    imports_or_refuses(bag, d / "cap")


@FUZZ
@given(data=st.data(), fmt=st.sampled_from(["mcap", "sqlite3"]))
def test_fuzzed_ros2_metadata_yaml(bags, tmp_path_factory, data, fmt):
    d = tmp_path_factory.mktemp("md")
    bag = _copy(bags[fmt], d / "bag")
    doc = yaml.safe_load((bag / "metadata.yaml").read_text())
    changes = data.draw(st.lists(st.tuples(st.sampled_from(paths(doc, depth=5)), values, st.booleans()),
                                 min_size=1, max_size=3))
    (bag / "metadata.yaml").write_text(yaml.safe_dump(mutated(doc, changes)))
    imports_or_refuses(bag, d / "cap")


# ------------------------------------------------------------------ what the fuzz found (regressions)

def _with_metadata_count(bags, folder, fmt, count):
    bag = _copy(bags[fmt], folder / fmt)
    doc = yaml.safe_load((bag / "metadata.yaml").read_text())
    doc["rosbag2_bagfile_information"]["topics_with_message_count"][0]["message_count"] = count
    (bag / "metadata.yaml").write_text(yaml.safe_dump(doc))
    return bag


@pytest.mark.parametrize("count", ["0.0", [1], -5, 2.5, None])
def test_a_message_count_that_is_not_a_whole_number_is_one_line(bags, tmp_path, count):
    """metadata.yaml's message_count of a topic as text, a list, negative: TypeError and
    ValueError from numpy escaped the import (the fuzz's first finds)."""
    bag = _with_metadata_count(bags, tmp_path, "mcap", count)
    with pytest.raises(UserError, match="message count") as e:
        api.import_rosbag(bag, tmp_path / "cap")
    assert str(bag) in str(e.value) and "\n" not in str(e.value)


@pytest.mark.parametrize("count", [3, 19_999_999])
def test_a_message_count_the_bag_does_not_hold_neither_drops_nor_allocates(bags, tmp_path, count):
    """The count a bag states is a hint: a bag that states 3 of its 40 messages is read whole (it
    was refused as "more messages than the index says"), and one that states 20 million (within
    the limit) does not make the reader allocate for them (a ~1 GB allocation before)."""
    import tracemalloc
    from station.io.importers.rosbag import read_rosbag
    bag = _with_metadata_count(bags, tmp_path, "sqlite3", count)
    tracemalloc.start()          # numpy reports its arrays' memory to tracemalloc
    try:
        rec = read_rosbag(bag)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert len(rec.t) == MESSAGES
    # 20 M messages x 7 numbers x 8 bytes = 1.1 GB had the stated count been allocated; the
    # first block of the arrays is 65,536 x 56 bytes = 3.7 MB, the reader's own a few MB
    assert peak < 50e6, peak


@pytest.mark.parametrize("name", [[], 7, None, "/imu\ndata", "/a\n", "\x1b[31m/imu"])
def test_a_topic_name_that_is_not_one_line_of_text_is_refused_or_shown_quoted(bags, tmp_path, name):
    """metadata.yaml's topic name as a list (TypeError: unhashable, the fuzz's find), a number or
    none: refused naming the bag; a name with a newline or an escape is shown quoted, the message
    stays one line."""
    bag = _copy(bags["mcap"], tmp_path / "bag")
    doc = yaml.safe_load((bag / "metadata.yaml").read_text())
    doc["rosbag2_bagfile_information"]["topics_with_message_count"][0]["topic_metadata"]["name"] = name
    (bag / "metadata.yaml").write_text(yaml.safe_dump(doc))
    try:
        api.import_rosbag(bag, tmp_path / "cap")
    except UserError as e:
        msg = str(e)
        assert str(bag) in msg and "\n" not in msg and "\x1b" not in msg, msg
        if not isinstance(name, str):
            assert "a connection's topic is" in msg, msg
    else:
        raise AssertionError("a 40-message bag was imported as a session")


@pytest.mark.parametrize("command", ["import", "noise"])
def test_the_commands_say_one_line_and_exit_2_on_what_the_fuzz_found(bags, tmp_path, capsys, command):
    """The fuzz calls the library (station.api, the commands' code); the commands themselves on
    its finds: `station import rosbag` and `station noise BAG` exit 2 with one line naming the bag."""
    from test_bad_inputs import one_line_exit_2
    bag = _with_metadata_count(bags, tmp_path, "mcap", "0.0")
    argv = ["import", "rosbag", bag, "-o", tmp_path / "cap"] if command == "import" else ["noise", bag]
    one_line_exit_2(argv, capsys, str(bag), "message count")
