"""Issue 28 (sixteenth session), items 3 and 4: `station montecarlo` and the designer's
verification (designer.verify_one) are one code path (montecarlo.run_one); its dry runs ramp at
the configured table's rate_accel_dps2 as `station run --sim` does (before: the dry run's 50
deg/s^2 whatever station.yaml said), and it takes the effects `station estimate` and `station
design` take (a plugin file, an unlisted effect), not library ids only."""
import json

from station import api
from station.cli import main
from station.design import designer
from station.design.noise import Noise
from station.io.scheme import scheme_from_text
from station.simulate import dryrun, montecarlo

FACES = [[0, 0, 1], [0, 0, -1], [1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0]]
SMALL = "name: small\ndefaults: {dwell_s: 2, rate_dps: 90, rotation_s: 4}\nsegments:\n" + "".join(
    f"  - {{static: s{i}, up_body: {u}}}\n" for i, u in enumerate(FACES)) + "".join(
    f"  - {{rotation: r{a}, axis_body: {v}}}\n" for a, v in zip("xyz", [[1, 0, 0], [0, 1, 0], [0, 0, 1]]))
RAMP = SMALL.replace("rotation: rx, axis_body: [1, 0, 0]", "rotation: rx, axis_body: [1, 0, 0], record_ramp: start")
CONFIG = """\
version: 1
table:
  axes: 3
  limits: [{max_rate_dps: 300, max_accel_dps2: 300, rate_accel_dps2: 20}]
"""


def _spy(monkeypatch) -> list:
    """The ramps' acceleration of every capture the simulated bench records in this process (the
    manifest's ramp_accel_dps2 of the recorded ramp up)."""
    seen = []
    real = dryrun.simulate_capture

    def spy(*args, **kw):
        capture = real(*args, **kw)
        seen.extend(s.extra.get("ramp_accel_dps2") for s in capture.segments if s.extra.get("record_ramp"))
        return capture
    monkeypatch.setattr(dryrun, "simulate_capture", spy)
    return seen


def test_the_designers_verification_ramps_at_the_configured_tables_acceleration(monkeypatch):
    """verify_one with the table's 20 deg/s^2 (designer.verify passes information.ramp_accel_of(config),
    the prediction's): the recorded window holds the turn and a ramp of 90^2 / (2 x 20) = 202.5 deg."""
    seen = _spy(monkeypatch)
    names, errors, sigmas, _ = designer.verify_one(scheme_from_text(RAMP, "r.yaml"), (), Noise(), 1000,
                                                   ramp_accel_dps2=20.0)
    assert seen == [20.0, 20.0], seen            # the ramp pair's two windows
    assert len(names) == len(errors) == len(sigmas) == 21
    seen.clear()
    designer.verify_one(scheme_from_text(RAMP, "r.yaml"), (), Noise(), 1000)
    assert seen == [dryrun.RAMP_ACCEL_DPS2] * 2   # no table configured: the dry run's default


def test_station_montecarlo_ramps_at_the_configured_tables_acceleration(tmp_path, monkeypatch):
    """api.montecarlo with --config: every dry run and the bound's capture at the table's 20 deg/s^2
    (one worker: the runs in this process, where the spy sees them); the configured warm-up is
    waited before each run and said in the result's settings (--json's "settings")."""
    (tmp_path / "station.yaml").write_text(CONFIG + "warmup: {duration_s: 30}\n")
    (tmp_path / "r.yaml").write_text(RAMP)
    seen = _spy(monkeypatch)
    mc = api.montecarlo(str(tmp_path / "r.yaml"), 2, workers=1, config=str(tmp_path / "station.yaml"))
    assert mc.runs == 2 and seen and set(seen) == {20.0}, seen
    assert len(seen) == 2 * (2 + len(montecarlo.GEOMETRY_SEEDS))      # 2 runs + the bound's geometries
    assert mc.settings["warmup_s"] == 30.0


PLUGIN = '''\
from station.model.unlisted import GyroScaleTemperatureSquared


class MySquared(GyroScaleTemperatureSquared):
    id = "my_squared"
'''


def test_station_montecarlo_takes_a_plugin_as_estimate_and_design_do(tmp_path, capsys):
    """`station montecarlo --add FILE.py:CLASS` (before: "unknown effect"): the runs on two worker
    processes (the plugin's instances pickled to them), its parameters' spread, bound and mean 1σ
    reported, finite and positive, as a library effect's."""
    (tmp_path / "plug.py").write_text(PLUGIN)
    (tmp_path / "s.yaml").write_text(SMALL)
    rc = main(["montecarlo", "--scheme", str(tmp_path / "s.yaml"), "--runs", "2", "--add",
               f"{tmp_path / 'plug.py'}:MySquared", "--json"])
    out = capsys.readouterr()
    assert rc == 0, out.err
    report = json.loads(out.out)
    assert report["effects"] == ["my_squared"]
    from station.model.unlisted import GyroScaleTemperatureSquared

    wanted = [p.name for p in GyroScaleTemperatureSquared().params]
    rows = {r["name"]: r for r in report["parameters"]}
    # each fitted in every run: estimated (a row: spread, bound and mean 1σ finite and positive),
    # or not revealed by the capture (held by its prior, not written since issue 28's eighteenth
    # session: counted in not_revealed, not reported as an estimate with an error)
    held = report["not_revealed"]
    assert set(wanted) <= set(rows) | set(held), (sorted(rows), held)
    for n in wanted:
        if n in rows and n not in held:
            assert rows[n]["std"] > 0 and rows[n]["crlb"] > 0 and rows[n]["mean_sigma"] > 0, rows[n]
        elif n in rows:         # revealed in one run: its row over both, no mean 1σ (api.montecarlo)
            assert rows[n]["revealed_runs"] == 2 - held[n] == 1 and rows[n]["mean_sigma"] is None, rows[n]
        else:
            assert held[n] == 2, held


def test_an_unknown_effect_is_one_line(capsys):
    assert main(["montecarlo", "--runs", "2", "--add", "no_such_effect"]) == 2
    assert "no_such_effect" in capsys.readouterr().err
