"""`station estimate` into a pipe prints no parameter table unless asked (issue 27, item 1): the
file holds the parameters, and rich's table machinery is not imported."""
import os
import subprocess
import sys


def run(*argv):
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    code = ("import sys, runpy; sys.argv = ['station', *sys.argv[1:]]\n"
            "from station.cli.app import main\n"
            "status = main(sys.argv[1:])\n"
            "print('RICH_TABLE', 'rich.table' in sys.modules)\n"
            "sys.exit(status)\n")
    return subprocess.run([sys.executable, "-c", code, *map(str, argv)], capture_output=True, text=True,
                          env=env, timeout=120)


def test_a_pipe_gets_one_line_and_the_table_only_when_asked(optimal9_run, tmp_path):
    plain = run("estimate", optimal9_run, "-o", tmp_path / "a.yaml")
    assert plain.returncode == 0, plain.stderr
    assert "parameters written (station show" in plain.stdout
    assert "accel_scale_x" not in plain.stdout and "RICH_TABLE False" in plain.stdout
    asked = run("estimate", optimal9_run, "-o", tmp_path / "b.yaml", "--table")
    assert asked.returncode == 0, asked.stderr
    assert "accel_scale_x" in asked.stdout and "RICH_TABLE True" in asked.stdout
    # the same file either way
    assert (tmp_path / "a.yaml").read_text().split("provenance:")[0] == \
        (tmp_path / "b.yaml").read_text().split("provenance:")[0]
