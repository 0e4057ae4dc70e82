"""Issue 26 (fin26 item 1): one rule for every output on a dangling symbolic link.

Before, ``export``, ``estimate`` and ``diagnose -o`` replaced such a link with a file while
``apply``, ``report``, ``import`` and ``run --out`` refused it.  Now every file or folder a
command writes goes through ``station.core.user_files.output_path``: a symbolic link whose target
does not exist (or a loop of links) is refused in one line naming the link and where it points,
exit status 2, before any work; the link stays and its target is never created
(docs/architecture.md, "Outputs and symbolic links")."""
import argparse
import os
import shutil

import pytest

from station.cli import main
from station.cli.app import OUTPUT_OPTIONS, build_parser
from station.core.errors import UserError
from station.core.user_files import output_path

# every (command, option) that names something written, with the rest of a command line that
# parses (the inputs need not exist: the rule is applied before the command reads anything)
COMMANDS = {
    ("estimate", "-o"): ["estimate", "CAP", "-o", "{out}"],
    ("apply", "-o"): ["apply", "CAL.yaml", "IN.csv", "-o", "{out}"],
    ("diagnose", "-o"): ["diagnose", "CAP", "-o", "{out}"],
    ("diagnose", "--report"): ["diagnose", "CAP", "--report", "{out}"],
    ("diagnose", "--emit-effect"): ["diagnose", "CAP", "--emit-effect", "{out}"],
    ("report", "-o"): ["report", "CAP", "-o", "{out}"],
    ("export", "-o"): ["export", "CAL.yaml", "--to", "json", "-o", "{out}"],
    ("fleet", "-o"): ["fleet", "-o", "{out}"],
    ("history", "--drift"): ["history", "SN1", "--drift", "{out}"],
    ("diff", "--drift"): ["diff", "A.yaml", "B.yaml", "--drift", "{out}"],
    ("import imucal", "-o"): ["import", "imucal", "S.csv", "--rate-hz", "100", "-o", "{out}"],
    ("import csv", "-o"): ["import", "csv", "LOG.csv", "-o", "{out}"],
    ("import rosbag", "-o"): ["import", "rosbag", "X.bag", "-o", "{out}"],
    **{(f"import {k}", "--estimate"): ["import", k, *args, "-o", "NEWCAP", "--estimate", "{out}"]
       for k, args in (("imucal", ("S.csv", "--rate-hz", "100")), ("csv", ("LOG.csv",)), ("rosbag", ("X.bag",)))},
    ("run", "--out"): ["run", "--scheme", "optimal9", "--sim", "--out", "{out}"],
    ("design", "-o"): ["design", "--duration", "600", "-o", "{out}"],
    ("noise", "--plot"): ["noise", "CAP", "--plot", "{out}"],
    ("init", "PATH"): ["init", "{out}"],
    **{(f"batch {c}", opt): ["batch", c, "CAP", opt, "{out}"]
       for c in ("estimate", "diagnose", "report", "export") for opt in ("-o", "--state")},
}
COMMANDS[("batch export", "-o")] += ["--to", "json"]
COMMANDS[("batch export", "--state")] += ["--to", "json"]


def _subcommands(parser, prefix=""):
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _subcommands(sub, f"{prefix} {name}".strip())
    if prefix:
        yield prefix, parser


def test_every_output_option_of_every_command_is_in_the_list():
    """A new command or option that writes a file is covered by this test, or this test fails:
    every option whose ``dest`` is one of the CLI's output options (and no option that looks like
    one outside them)."""
    found = set()
    for command, parser in _subcommands(build_parser()):
        for action in parser._actions:
            if action.dest in OUTPUT_OPTIONS and action.option_strings:
                found.add((command, action.option_strings[0]))
            elif action.option_strings and any(o in ("-o", "--out", "--output", "--report", "--plot", "--drift", "--estimate")
                                               for o in action.option_strings):
                pytest.fail(f"{command} {action.option_strings}: an output option outside OUTPUT_OPTIONS")
    found.add(("init", "PATH"))
    assert found == set(COMMANDS)


@pytest.fixture(scope="module")
def links(tmp_path_factory):
    base = tmp_path_factory.mktemp("links")
    dangling = base / "dangling"
    dangling.symlink_to(base / "nowhere" / "x")
    beside = base / "beside"                  # the target's folder exists: `>` would create it
    beside.symlink_to(base / "made-by-mistake")
    loop = base / "loop"
    loop.symlink_to(base / "loop2")
    (base / "loop2").symlink_to(loop)
    return base, {"dangling": dangling, "beside": beside, "loop": loop}


@pytest.mark.parametrize("key", sorted(COMMANDS), ids=[" ".join(k) for k in sorted(COMMANDS)])
def test_every_command_refuses_an_output_on_a_dangling_link(links, capsys, key, monkeypatch):
    base, made = links
    monkeypatch.chdir(base)
    for kind, link in made.items():
        argv = [a.format(out=link) for a in COMMANDS[key]]
        capsys.readouterr()
        assert main(argv) == 2, (kind, argv)
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "Traceback" not in err, err
        assert f"{link}: cannot write" in err and "symbolic link to" in err, err
        assert ("loop of symbolic links" if kind == "loop" else "which does not exist") in err, err
        assert link.is_symlink()
    assert not (base / "nowhere").exists() and not (base / "made-by-mistake").exists()


def test_the_writers_apply_the_rule_too(links, capture_dir, tmp_path, capsys):
    """The library's writers (the API's callers, and the default paths no option names): the
    calibration written into a capture whose calibration.yaml is a dangling link; a capture
    folder, a report page, a figure."""
    from station.diagnose.report import ReportInput, write_page
    from station.io.calfile import write_new_file

    base, made = links
    cap = shutil.copytree(capture_dir, tmp_path / "cap")
    (cap / "calibration.yaml").unlink()
    (cap / "calibration.yaml").symlink_to(tmp_path / "elsewhere.yaml")
    capsys.readouterr()
    assert main(["estimate", str(cap)]) == 2
    err = capsys.readouterr().err
    assert f"{cap / 'calibration.yaml'}: cannot write the calibration file: a symbolic link to" in err, err
    assert not (tmp_path / "elsewhere.yaml").exists() and (cap / "calibration.yaml").is_symlink()
    for write in (lambda p: write_new_file(p, b"x", what="file"),
                  lambda p: write_page(p, ReportInput(title="t"))):
        with pytest.raises(UserError, match="symbolic link to"):
            write(made["beside"])
    assert not (base / "made-by-mistake").exists()


def test_a_link_to_something_that_exists_and_a_plain_path_pass(tmp_path):
    target = tmp_path / "t.yaml"
    target.write_text("x")
    link = tmp_path / "l.yaml"
    link.symlink_to(target)
    assert output_path(link) == link and output_path(tmp_path / "new.yaml") == tmp_path / "new.yaml"
    assert output_path(str(tmp_path)) == str(tmp_path)
    os.unlink(link)


from test_bad_inputs import capture_dir  # noqa: E402,F401 - the module's capture
