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


def test_run_and_show_give_a_scale_factor_the_same_units(capsys):
    """issue 26 (smaller): scale factors were shown three ways — `run --sim` put "ppm" in the unit
    column of a value of 1.000560836 (its error's and 1σ's unit), `show` unit 1 and its 1σ in ppm.
    Both now: the value in unit 1, the error and 1σ with "ppm" beside them; a missing 1σ "—",
    explained under the table, in both."""
    import copy
    import re

    from station.cli.output import print_errors, print_parameters
    from station.simulate import dryrun

    truth = dryrun.truth_calibration(dryrun.load_truth(None, 1))
    est = copy.deepcopy(truth)
    est.sigma = {"accel_scale_x": 3.3e-6 * truth.parameters()[0][1], "accel_bias_x": 1e-4}
    print_errors(est, truth)
    run_table = capsys.readouterr().out
    print_parameters([(n, v, u, est.sigma.get(n)) for n, v, u in est.parameters()], "show")
    show_table = capsys.readouterr().out

    def row(table, name):
        line = next(ln for ln in table.splitlines() if f" {name} " in ln)
        return [c.strip() for c in line.strip("│ ").split("│")]

    run_x, show_x = row(run_table, "accel_scale_x"), row(show_table, "accel_scale_x")
    assert run_x[-1] == show_x[-1] == "1", (run_x, show_x)
    assert run_x[1] == show_x[1] and re.fullmatch(r"1\.\d{9}", run_x[1])
    assert run_x[4].endswith(" ppm") and show_x[2].endswith(" ppm") and run_x[3].endswith(" ppm")
    assert float(run_x[4].split()[0]) == 3.3 and float(show_x[2].split()[0]) == 3.3
    assert row(run_table, "accel_scale_y")[4] == row(show_table, "accel_scale_y")[2] == "—"
    assert "—: no 1σ" in run_table and "—: no 1σ" in show_table
