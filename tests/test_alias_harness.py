"""benchmarks/alias_separation.py counts an alias "named" only by the pair's own printed command
(issue 28, sixteenth session): on the axes' offsets' capture diagnose prints the vibration's
command against the size effect, which mentions the offsets' rival but is not their pair; the
harness counted it and ran it ("separated" through the size effect's segments)."""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import alias_separation as bench  # noqa: E402


def test_only_the_pairs_own_command_names_it():
    offsets = bench.BY_NAME["axis_offsets"]          # hidden: the offsets; rival: the vibration
    assert bench.is_the_pair("rotation_axis_offsets,table_vibration_once_per_rev", offsets)
    assert bench.is_the_pair("table_vibration_once_per_rev,rotation_axis_offsets", offsets)
    # the vibration's own command against the size effect: mentions the rival, not the pair
    assert not bench.is_the_pair("table_vibration_once_per_rev,accel_lever_arm", offsets)
    assert not bench.is_the_pair("accel_lever_arm,table_vibration_once_per_rev", offsets)
    lever = bench.BY_NAME["lever_arm"]
    assert bench.is_the_pair("accel_lever_arm,table_vibration_once_per_rev", lever)
    assert not bench.is_the_pair("accel_lever_arm,rotation_axis_offsets", lever)
    # a plugin named by its file (FILE.py:CLASS, the file named after its id)
    plugin = bench.BY_NAME["plugin_abs_cubed"]
    assert bench.is_the_pair("gyro_scale_asymmetry,/tmp/x/gyro_abs_cubed.py:GyroAbsCubed", plugin)
    assert bench.is_the_pair("gyro_abs_cubed,gyro_scale_asymmetry", plugin)
    assert not bench.is_the_pair("gyro_scale_asymmetry,gyro_rate_nonlinearity", plugin)
