"""Issue 26, item 5: bad inputs that were tracebacks, hangs or a way to run code.  Every one is
one line naming the file, line, field or option and exit status 2 (docs/reliability.md)."""
import os
import sys
from pathlib import Path

import pytest
import yaml

from station.cli import main
from test_bad_inputs import capture_dir, one_line_exit_2, run_child  # noqa: F401 - fixtures

DEEP = "a: " + "[" * 3000 + "]" * 3000 + "\n"
DEEP_BLOCK = "a:\n" + "".join(" " * i + "-\n" for i in range(1, 400))


# ------------------------------------------------------------------ deeply nested YAML

@pytest.mark.parametrize("text", [DEEP, DEEP_BLOCK], ids=["flow", "block"])
@pytest.mark.parametrize("argv", [
    ["plan", "--scheme", "{f}"],
    ["plan", "--config", "{f}"],
    ["plan", "--reveals", "--sim-truth", "{f}"],
    ["sim", "serve", "--faults", "{f}"],
    ["export", "{cal}", "--to", "kalibr", "--noise", "{f}", "-o", "{out}"],
], ids=["scheme", "station.yaml", "sim-truth", "faults", "noise"])
def test_deeply_nested_yaml_is_one_line_naming_the_file(capture_dir, tmp_path, capsys, argv, text):
    deep = tmp_path / "deep.yaml"
    deep.write_text(text)
    argv = [a.format(f=deep, cal=capture_dir / "calibration.yaml", out=tmp_path / "k.yaml") for a in argv]
    one_line_exit_2(argv, capsys, str(deep), "deeper than")


# ------------------------------------------------------------------ schemes

@pytest.mark.parametrize("defaults", ["[1, 2]", "5", "abc"])
def test_scheme_defaults_not_a_mapping(tmp_path, capsys, defaults):
    scheme = tmp_path / "s.yaml"
    scheme.write_text(f"name: s\ndefaults: {defaults}\nsegments:\n  - static: a\n    up_body: [0, 0, 1]\n"
                      "    dwell_s: 1\n")
    one_line_exit_2(["plan", "--scheme", scheme], capsys, str(scheme), "defaults", "mapping")
