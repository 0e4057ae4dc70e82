"""The commands `station diagnose` prints to reproduce and apply its calibration (issue 26, item 2:
"every diagnosis that finds something prints the exact estimate/apply commands") are commands
the shell runs as printed: a capture, a plugin or an output path with a space or a quote stays
one argument (they were joined with spaces, unquoted, and a double space was left where no
plugin was given)."""
import argparse
import shlex

from station.cli.diagnose import commands


def test_the_printed_commands_split_back_into_the_arguments():
    args = argparse.Namespace(capture="my runs/cap 1", output="out dir/it's.yaml", plugin=["p l.py:Cls"],
                              effects_dir=["effects dir"])
    estimate, apply = commands(args, ["accel_nonlinearity"], "out dir/it's-discovered.py", True)
    assert estimate.startswith("to estimate it: ") and apply.startswith("to apply it: ")
    assert shlex.split(estimate[len("to estimate it: "):]) == [
        "station", "estimate", "my runs/cap 1", "--plugin", "p l.py:Cls", "--effects-dir", "effects dir",
        "--add", "accel_nonlinearity", "--add", "out dir/it's-discovered.py:DiscoveredTerms", "-o", "out dir/it's.yaml"]
    assert shlex.split(apply[len("to apply it: "):]) == [
        "station", "apply", "out dir/it's.yaml", "RAW.csv", "-o", "COMPENSATED.csv",
        "--plugin", "out dir/it's-discovered.py", "--plugin", "p l.py:Cls", "--effects-dir", "effects dir"]


def test_without_plugins_or_effects_no_empty_arguments():
    args = argparse.Namespace(capture="cap", output=None, plugin=[], effects_dir=[])
    estimate, apply = commands(args, [], None, False)
    assert estimate == "to estimate it: station estimate cap -o CAL.yaml"
    assert apply == "to apply it: station apply CAL.yaml RAW.csv -o COMPENSATED.csv"
