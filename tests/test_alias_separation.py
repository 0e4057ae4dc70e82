"""Issue 28 item 3: every alias diagnose names comes with the `station design --from ...
--separate A,B` command, which works as printed, also for a user's plugin (FILE.py:CLASS); its
segments appended to the dry run's capture (`station run --sim --append`) separate the two
(the hidden effect estimated at the truth, the other at zero, the alias no longer named); and
`--reveal` for what rotations at one rate leave not revealed.  The enumeration over every pair
diagnose names is benchmarks/alias_separation.py (docs/design.md)."""
import json
import shlex

import numpy as np
import yaml

from sim_devices.truth import default_truth, mems_truth
from station import api
from station.cli import main

# a user's plugin: a gyro error in the cube of the rate's size, even like a scale asymmetry
# (|w|): with every turn about a body axis at one rate each gyro sees one |w|, and the two act
# alike; at a second rate they do not
PLUGIN = '''\
from station.model.effect import Effect, Param
from station.model.geometry import analytic_abs


class GyroAbsCubed(Effect):
    id = "gyro_abs_cubed"
    title = "Gyro error in the cube of the rate's size"
    physics = "a rectifying gyro error growing with the cube of the input rate's size"
    term = "gyro_raw_i += c_i 1e-6 |w_i|^3"
    excited_by = "rotations at two or more rates"
    magnitudes = "0.001-0.1 ppm/(deg/s)^2"
    signature = "gyro, rotations: the same sign both ways, growing with |w|^3"
    signature_variable = "rate"
    complex_step = True

    @property
    def params(self):
        return tuple(Param(f"gyro_abs3_{a}", "ppm/(deg/s)^2", 1.0, 0.01, 100.0) for a in "xyz")

    def gyro(self, x, ctx):
        w = ctx.w_p @ ctx.gyro_matrix.T
        a = analytic_abs(w)
        return 1e-6 * x * a * a * a
'''


def _scheme(rate: float, seconds: float) -> str:
    """Nine 5 s statics (attitudes unknown, as the design's information assumes) and one ± pair
    about each body axis at one rate."""
    ups = [[0, 0, 1], [0, 0, -1], [1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [1, 1, 0], [0, 1, 1], [1, 0, 1]]
    segs = [{"static": f"s{i}", "up_body": u} for i, u in enumerate(ups)]
    segs += [{"rotation": f"r{a}", "axis_body": v} for a, v in zip("xyz", ([1, 0, 0], [0, 1, 0], [0, 0, 1]))]
    return yaml.safe_dump({"name": "onerate", "defaults": {"dwell_s": 5.0, "rate_dps": rate, "rotation_s": seconds},
                           "segments": segs})


def _truth(path, truth, **sets):
    doc = truth.to_yaml_dict()
    for key, value in sets.items():
        section, name = key.split("__")
        doc[section][name] = value
    path.write_text(yaml.safe_dump(doc))
    return path


ASYM_PPM = np.array([3000.0, -2000.0, 2500.0])


def test_a_plugins_alias_is_named_with_a_command_that_runs_as_printed_and_separates_it(tmp_path, capsys, monkeypatch):
    spec = f"{(tmp_path / 'mine.py').resolve()}:GyroAbsCubed"
    (tmp_path / "mine.py").write_text(PLUGIN)
    (tmp_path / "s.yaml").write_text(_scheme(30.0, 12.0))            # one revolution each way
    truth = _truth(tmp_path / "truth.yaml", mems_truth(0), gyroscope__scale_asymmetry_ppm=ASYM_PPM.tolist())
    monkeypatch.chdir(tmp_path)
    assert main(["run", "--scheme", "s.yaml", "--sim", "--sim-truth", str(truth), "--out", "cap",
                 "--no-history"]) in (0, 3)
    capsys.readouterr()
    assert main(["diagnose", "cap", "--json", "--plugin", "mine.py:GyroAbsCubed"]) == 0
    cands = {c["effect"]: c for c in json.loads(capsys.readouterr().out)["candidates"]}
    assert cands["gyro_scale_asymmetry"]["significant"] and cands["gyro_abs_cubed"]["significant"]
    # the plugin named by its file (a new command would not know the id), both ways round
    mine = [c for c in cands["gyro_scale_asymmetry"]["separate_commands"] if "GyroAbsCubed" in c]
    assert len(mine) == 1, cands["gyro_scale_asymmetry"]["separate_commands"]
    assert any("gyro_scale_asymmetry" in c for c in cands["gyro_abs_cubed"]["separate_commands"])
    command = shlex.split(mine[0])
    assert command[:4] == ["station", "design", "--from", "cap"]
    assert command[command.index("--separate") + 1] == f"gyro_scale_asymmetry,{spec}", command
    # as printed (--json only to read the answer), from another folder: the path is absolute
    monkeypatch.chdir(tmp_path.parent)
    command = [str(tmp_path / "cap") if w == "cap" else w for w in command]
    assert main([*command[1:], "-o", str(tmp_path / "extension.yaml"), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert 1 <= len(report["segments"]) <= 4 and report["correlation_after"] < 0.95
    assert {s["rate_dps"] for s in report["segments"]} != {30.0}       # another rate: what separates them
    monkeypatch.chdir(tmp_path)
    assert main(["run", "--sim", "--append", "cap", "--scheme", "extension.yaml", "--no-history"]) in (0, 3)
    capsys.readouterr()
    est = api.estimate("cap", add=["gyro_scale_asymmetry", spec])
    # the truth within 4.5 sigma (6 parameters, two-sided: a false alarm once in 4e4); the
    # simulated asymmetry acts on |w| scaled by the gyro's scale factor (1 + a few 1000 ppm):
    # 3000 ppm x 0.003 = 9 ppm off at most, below the 1-sigma (~45 ppm predicted)
    for i, a in enumerate("xyz"):
        p = est.parameters[f"gyro_asym_{a}"]
        assert p.sigma is not None and abs(p.value - ASYM_PPM[i]) < 4.5 * p.sigma, (a, p)
        assert abs(p.value) > 10 * p.sigma                                # revealed, and large
        q = est.parameters[f"gyro_abs3_{a}"]
        assert q.sigma is not None and abs(q.value) < 4.5 * q.sigma, (a, q)
        assert q.sigma < 0.01                                            # revealed: below its typical size
    # and diagnose no longer names the two as aliases
    assert main(["diagnose", "cap", "--json", "--plugin", "mine.py:GyroAbsCubed"]) == 0
    after = {c["effect"]: c for c in json.loads(capsys.readouterr().out)["candidates"]}
    assert after["gyro_scale_asymmetry"]["significant"]
    pair = [cmd for e, o in (("gyro_scale_asymmetry", "GyroAbsCubed"), ("gyro_abs_cubed", "gyro_scale_asymmetry"))
            for cmd in after[e]["separate_commands"] if o in cmd]
    assert not pair, pair


def test_a_library_alias_at_one_rate_is_named_with_its_separate_command(tmp_path, capsys, monkeypatch):
    """A rate-squared term and a scale asymmetry at one rate (words.aliases): diagnose names the
    pair with the command, which runs as printed; a pair of bench effects whose parameters the
    segments decide (one per table axis and rate) is refused in one line, exit 2."""
    (tmp_path / "s.yaml").write_text(_scheme(30.0, 12.0))
    # 60 ppm/(deg/s) x 30 deg/s = 1800 ppm of the rate: significant for both with the MEMS noise
    truth = _truth(tmp_path / "truth.yaml", mems_truth(0), gyroscope__rate_squared_ppm_per_dps=[60.0, -45.0, 75.0])
    monkeypatch.chdir(tmp_path)
    assert main(["run", "--scheme", "s.yaml", "--sim", "--sim-truth", str(truth), "--out", "cap",
                 "--no-history"]) in (0, 3)
    capsys.readouterr()
    assert main(["diagnose", "cap", "--json"]) == 0
    cands = {c["effect"]: c for c in json.loads(capsys.readouterr().out)["candidates"]}
    said = cands["gyro_scale_asymmetry"]["separate_commands"]
    assert ("station design --from cap --add gyro_scale_asymmetry --separate "
            "gyro_scale_asymmetry,gyro_rate_nonlinearity -o extension.yaml") in said, said
    command = shlex.split(said[0])
    assert main([*command[1:], "--json"]) == 0                      # as printed
    report = json.loads(capsys.readouterr().out)
    assert report["correlation_after"] < 0.95 and all(p["revealed_after"] for p in report["parameters"])
    assert main(["design", "--from", "cap", "--separate", "accel_nonlinearity,table_wobble"]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and "table_wobble has parameters of its own per table axis" in lines[0], lines


# the accelerometers' positions (m; the diagonal 0, the estimator's convention for the reference point)
POSITIONS_M = np.array([[0.0, 0.005, -0.004], [0.003, 0.0, 0.006], [-0.005, 0.004, 0.0]])


def test_reveal_what_one_rate_leaves_and_the_appended_dry_run_reveals_it(tmp_path, capsys, monkeypatch):
    """Turns about the body axes at 10 deg/s only: the accelerometers' cross positions are not
    revealed (w^2 r = (10 deg/s)^2 x 5 mm = 15 ug, under the statics' noise); diagnose prints the
    --reveal command, which runs as printed; the extension appended to the dry run reveals all
    six at the truth."""
    (tmp_path / "s.yaml").write_text(_scheme(10.0, 36.0))
    truth = _truth(tmp_path / "truth.yaml", default_truth(4), accelerometer__position_m=POSITIONS_M.tolist())
    monkeypatch.chdir(tmp_path)
    assert main(["run", "--scheme", "s.yaml", "--sim", "--sim-truth", str(truth), "--out", "cap",
                 "--no-history"]) in (0, 3)
    capsys.readouterr()
    assert main(["diagnose", "cap", "--add", "accel_lever_arm", "--json"]) == 0
    said = json.loads(capsys.readouterr().out)["design_suggestions"]
    assert len(said) == 1 and all(f"accel_position_{a}" in said[0] for a in ("x_y", "x_z", "y_x", "y_z", "z_x", "z_y"))
    command = shlex.split(said[0].split("reveal them: ")[1])
    assert main([*command[1:], "--json", "--rates", "100,200", "--revolutions", "1", "--dwells", "10"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert all(not p["revealed_before"] and p["revealed_after"] for p in report["parameters"]), report["parameters"]
    assert main(["run", "--sim", "--append", "cap", "--scheme", "extension.yaml", "--no-history"]) in (0, 3)
    capsys.readouterr()
    cal = api.estimate("cap", add=["accel_lever_arm"]).calibration
    assert not [n for n in cal.fit["notes"] if n.startswith("not revealed")], cal.fit["notes"]
    predicted = {p["name"]: p["sigma_after"] for p in report["parameters"]}
    for name, value, _ in cal.extra_parameters:
        if not name.startswith("accel_position_"):
            continue
        i, j = "xyz".index(name[-3]), "xyz".index(name[-1])
        sigma = cal.sigma[name]
        # within 4.5 sigma of the truth (six parameters: a false alarm once in 1e4), the 1-sigma
        # the predicted within 30 % (the prediction: the segments simulated without noise)
        assert abs(value - POSITIONS_M[i, j] * 1e3) < 4.5 * sigma, (name, value, sigma)
        assert abs(sigma / predicted[name] - 1) < 0.3, (name, sigma, predicted[name])


def test_alike_candidates_are_aliases_only_when_the_data_cannot_prefer_one():
    """suggest.alike_candidates: signatures alike to 0.95 AND a difference below the 1 % point
    of chi2 (dof of the smaller) after the over-dispersion."""
    from station.diagnose.core import Candidate
    from station.diagnose.suggest import alike_candidates

    rng = np.random.default_rng(1)
    r = rng.normal(size=400)
    r *= 50.0 / np.linalg.norm(r)                   # a misfit of chi2 2500 that A explains whole

    def cand(name, sig, dof=3, over=1.0, significant=True):
        return Candidate(name, name, float(sig @ sig), dof, 0.0, significant=significant,
                         signature_rows=sig, overdispersion=over)

    tiny = rng.normal(size=400)
    tiny *= 1.0 / np.linalg.norm(tiny)              # a difference of chi2 1: no preference
    assert alike_candidates([cand("a", r), cand("b", r + tiny)]) == {"a": ["b"], "b": ["a"]}
    # alike to 0.97 but the data prefer A by chi2 ~150 (> 11.3, the 1 % point for 3 dof)
    off = r + 12.5 * tiny
    assert float(r @ off) / (np.linalg.norm(r) * np.linalg.norm(off)) > 0.95
    assert alike_candidates([cand("a", r), cand("b", off)]) == {}
    # ... unless the fit fails by as much (over-dispersion 20: 150 / 20 = 7.5 < 11.3)
    assert alike_candidates([cand("a", r, over=20.0), cand("b", off, over=20.0)]) == {"a": ["b"], "b": ["a"]}
    # not significant, or an effect no extension is designed for: never named
    assert alike_candidates([cand("a", r), cand("b", r, significant=False)]) == {}
    assert alike_candidates([cand("a", r), cand("table_wobble", r)]) == {}
