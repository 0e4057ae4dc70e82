"""The Python API (station/api.py, docs/api.md): the page's worked example runs as written, the
API gives what the CLI gives on the same capture, `import station` imports nothing heavy, and
bad input raises UserError with the CLI's message."""
from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from station import api, cli

DOC = Path(__file__).resolve().parents[1] / "docs" / "api.md"


def test_the_worked_example_runs_as_written(tmp_path, monkeypatch, capsys):
    blocks = re.findall(r"```python\n(.*?)```", DOC.read_text(), re.S)
    assert len(blocks) >= 5
    monkeypatch.chdir(tmp_path)
    scope: dict = {}
    for block in blocks:
        exec(compile(block, str(DOC), "exec"), scope)
    printed = capsys.readouterr().out
    assert "passes" in printed and "accel_scale_x = " in printed and "refused: " in printed
    # every number printed with its unit (the Monte Carlo line printed bare numbers: issue 26 goal)
    assert re.search(r"error std \S+ ppm, Cramér-Rao bound \S+ ppm", printed), printed
    assert (tmp_path / "run1" / "cal.yaml").is_file() and (tmp_path / "run1" / "imucal.json").exists()


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    """One optimal9 dry run and its estimate through the API, for the tests below to read (the
    bad-input test needs only a calibration file to refuse things with)."""
    bundle = api.simulate("optimal9", tmp_path_factory.mktemp("api") / "cap", seed=4, dwell_s=10.0)
    return bundle, api.estimate(bundle)


def test_the_api_gives_what_the_cli_gives(tmp_path, simulated):
    bundle, est = simulated
    assert cli.main(["estimate", str(bundle), "-o", str(tmp_path / "cli.yaml")]) == 0
    doc = yaml.safe_load((tmp_path / "cli.yaml").read_text())
    assert est.verdict["result"] == doc["verdict"]["result"] == "passes"
    assert set(est.parameters) == set(doc["parameters"])
    for name, p in est.parameters.items():
        assert p.value == pytest.approx(doc["parameters"][name]["value"], rel=1e-9, abs=1e-12), name
        assert p.sigma == pytest.approx(doc["parameters"][name]["sigma"], rel=1e-6), name
        assert p.unit == doc["parameters"][name]["unit"]
    # apply on arrays: the same numbers as `station apply` on the segment's CSV
    seg = next(s for s in api.read_capture(bundle).segments if s.kind == "rotation")
    t, f, w = api.apply(tmp_path / "cli.yaml", seg.data.t, seg.data.accel, seg.data.gyro, seg.data.temp)
    assert cli.main(["apply", str(tmp_path / "cli.yaml"), str(bundle / seg.file), "-o", str(tmp_path / "c.csv")]) == 0
    written = np.loadtxt(tmp_path / "c.csv", delimiter=",", skiprows=1)
    np.testing.assert_allclose(written[:, 1:4], f, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(written[:, 4:7], w, rtol=1e-9, atol=1e-9)
    # an estimate saved is the file the CLI writes (but for the time it was written)
    est.save(tmp_path / "api.yaml")
    mine = yaml.safe_load((tmp_path / "api.yaml").read_text())
    assert mine["parameters"] == doc["parameters"] and mine["verdict"] == doc["verdict"]


def test_import_station_is_instant_and_the_api_light():
    """`import station` imports nothing else; `from station import api` no estimator (each
    function imports what it uses when called)."""
    code = ("import sys, station; a = [m for m in ('numpy', 'scipy', 'station.api') if m in sys.modules]; "
            "from station import api; b = [m for m in ('scipy', 'station.estimate', 'station.diagnose') "
            "if m in sys.modules]; print(a, b, sorted(api.__all__) == sorted(n for n in api.__all__ if hasattr(api, n)))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[] [] True"


def test_bad_input_raises_the_clis_message(tmp_path, simulated):
    with pytest.raises(api.UserError, match="no-such"):
        api.estimate(tmp_path / "no-such")
    bundle, est = simulated
    with pytest.raises(api.UserError, match="unknown effect|no effect"):
        api.estimate(bundle, add=["no_such_effect"])
    est.save(tmp_path / "cal.yaml")
    with pytest.raises(api.UserError, match=r"\(5, 3\)"):
        api.apply(tmp_path / "cal.yaml", np.zeros(5), np.zeros((5, 2)), np.zeros((5, 3)))
    with pytest.raises(api.UserError, match="unknown format"):
        api.export(tmp_path / "cal.yaml", "nope", tmp_path / "x")
    with pytest.raises(api.UserError, match="unknown option"):
        api.import_csv(tmp_path / "log.csv", tmp_path / "imp", colour="red")
    # arguments the CLI's options check, checked by the API too (ValueError/TypeError escaped)
    with pytest.raises(api.UserError, match="apply: t: not numbers"):
        api.apply(tmp_path / "cal.yaml", np.array(["a", "b"]), np.zeros((2, 3)), np.zeros((2, 3)))
    with pytest.raises(api.UserError, match="seed: a whole number >= 0, not -1"):
        api.simulate("optimal9", tmp_path / "neg", seed=-1)
    with pytest.raises(api.UserError, match="runs: a whole number >= 2, not '3'"):
        api.montecarlo("sizeeffect", runs="3")
    # a DataFrame with a column of text (a CSV read without its header): ValueError from numpy
    # escaped; apply_frame takes config= as apply does (it raised TypeError) (issue 26 goal)
    import pandas as pd         # the dev extra (docs/api.md)
    frame = pd.DataFrame({c: np.zeros(3) for c in ("t", "ax", "ay", "az", "gx", "gy", "gz")})
    assert len(api.apply_frame(tmp_path / "cal.yaml", frame, config=None)) == 3
    frame["gy"] = ["gy", "0.1", "0.2"]
    with pytest.raises(api.UserError, match="column 'gy' is not numbers"):
        api.apply_frame(tmp_path / "cal.yaml", frame)


class _Called(Exception):
    """Raised by a stand-in for an API function: the command got that far through the API."""


@pytest.mark.parametrize("function, argv, first", [
    ("estimate", ["estimate", "CAP"], "CAP"),
    ("load_calibration", ["show", "CAL.yaml"], "CAL.yaml"),
    ("apply_file", ["apply", "CAL.yaml", "IN.csv", "-o", "OUT.csv"], "CAL.yaml"),
    ("export", ["export", "CAL.yaml", "--to", "kalibr"], "CAL.yaml"),
    ("characterise_noise", ["noise", "CAP"], "CAP"),
    ("report", ["report", "CAP"], "CAP"),
    ("diagnose", ["diagnose", "CAP", "--auto"], "CAP"),
    ("effects", ["effects"], None),
    ("effect", ["effects", "scale_temperature"], "scale_temperature"),
    ("import_csv", ["import", "csv", "LOG.csv", "-o", "CAP"], "LOG.csv"),
    ("import_rosbag", ["import", "rosbag", "BAG", "-o", "CAP"], "BAG"),
    ("import_imucal", ["import", "imucal", "S.csv", "--rate-hz", "100", "-o", "CAP"], "S.csv"),
    ("montecarlo", ["montecarlo", "--scheme", "sizeeffect", "--runs", "3"], "sizeeffect"),
    ("history", ["history", "SER-1", "--store", "STORE"], "SER-1"),
    ("diff", ["diff", "A.yaml", "B.yaml"], "A.yaml"),
    ("plan", ["plan", "--scheme", "sizeeffect"], "sizeeffect"),
    ("schemes", ["schemes"], None),
])
def test_the_command_does_its_work_through_the_api(monkeypatch, tmp_path, function, argv, first):
    """The CLI is a thin layer over station.api (issue 26 item 1): each analysis command parses
    its options and calls the documented function, which does the work (here a stand-in that
    records its arguments and stops the command before anything is read)."""
    seen = {}

    def stand_in(*args, **kwargs):
        seen.update(args=args, kwargs=kwargs)
        raise _Called

    monkeypatch.setattr(api, function, stand_in)
    monkeypatch.chdir(tmp_path)
    with pytest.raises(_Called):
        cli.main(argv)
    assert (str(seen["args"][0]) if seen["args"] else None) == first


def test_the_fitting_functions_run_with_one_blas_thread_and_give_the_callers_back(monkeypatch):
    """station/core/blas.py: inside api.estimate BLAS runs with one thread (STATION_BLAS_THREADS
    for more); the caller's own setting is back when it returns."""
    from threadpoolctl import threadpool_info, threadpool_limits

    import station.estimate

    def blas_threads_now():
        return {i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"}

    seen = []

    def fake_estimate_capture(*args, **kwargs):
        seen.append(blas_threads_now())
        raise api.UserError("stop here")

    monkeypatch.setattr(station.estimate, "estimate_capture", fake_estimate_capture)
    with threadpool_limits(limits=2, user_api="blas"):
        assert blas_threads_now() == {2}
        for variable, expected in ((None, {1}), ("2", {2})):
            if variable is None:
                monkeypatch.delenv("STATION_BLAS_THREADS", raising=False)
            else:
                monkeypatch.setenv("STATION_BLAS_THREADS", variable)
            with pytest.raises(api.UserError, match="stop here"):
                api.estimate("no-such-capture")
            assert seen[-1] == expected
            assert blas_threads_now() == {2}
