"""Effects from outside the library: plugins loaded from files, found by diagnose, added, and
compensated by apply; apply compensates every effect by inverting its forward term."""
from pathlib import Path

import numpy as np
import pytest
import yaml

from station.cli import main
from station.core.errors import UserError
from station.diagnose import auto
from station.estimate import lsq
from station.io.calfile import compensation_effects, read_calfile
from station.io.capture import read_capture
from station.model import LIBRARY
from station.model.compensate import compensate_with_effects
from station.model.effect import SampleContext
from station.model.registry import EffectRegistry
import simhelpers

ROOT = Path(__file__).resolve().parents[1]
CROSS = f"{ROOT / 'examples/effects/accel_cross_coupling.py'}:AccelCrossCoupling"
RATE2 = f"{ROOT / 'examples/effects/gyro_rate_squared.py'}:GyroRateSquared"
FAST = {"rate_dps": 100.0, "rotation_s": 36.0}
C_UG = [[0.0, 2000.0, -1500.0], [1800.0, 0.0, 1200.0], [-1600.0, 1400.0, 0.0]]


def mems_capture(seed=3, scheme="optimal9", out=None, **hidden):
    return simhelpers.mems_capture(seed, scheme, FAST, out, **hidden)


# --- loading ------------------------------------------------------------------------------------

def test_plugins_load_from_a_file_and_are_listed_with_their_source(tmp_path, capsys):
    reg = EffectRegistry()
    assert reg.add(CROSS) == ["accel_cross_coupling"]
    assert reg.source("accel_cross_coupling").endswith("accel_cross_coupling.py:AccelCrossCoupling")
    assert reg.add(CROSS) == ["accel_cross_coupling"]          # the same file twice is fine
    assert set(LIBRARY) < set(reg.ids())
    assert main(["effects", "--plugin", RATE2]) == 0
    listing = capsys.readouterr().out
    assert "gyro_rate_squared" in listing and "gyro_rate_squared.py:GyroRateSquared" in listing
    # a folder of plugins
    folder = tmp_path / "fx"
    folder.mkdir()
    (folder / "a.py").write_text((ROOT / "examples/effects/gyro_rate_squared.py").read_text())
    assert main(["effects", "--effects-dir", str(folder), "gyro_rate_squared"]) == 0
    assert "ppm/(deg/s)" in capsys.readouterr().out


BROKEN = {
    "missing.py:X": "no such file",
    "syntax.py:X": "line 1: syntax error",
    "raises.py:X": "fails to load: RuntimeError",
    "nothing.py": "defines no subclass",
    "noclass.py:Missing": "no class 'Missing'",
    "badid.py:Bad": "'id' must be an identifier",
    "clash.py:Clash": "is taken by library",
}


@pytest.mark.parametrize("spec", sorted(BROKEN))
def test_a_broken_plugin_is_one_line_and_exit_2(tmp_path, spec, capsys):
    files = {
        "syntax.py": "def (:\n",
        "raises.py": "raise RuntimeError('boom')\n",
        "nothing.py": "x = 1\n",
        "noclass.py": "from station.model.effect import Effect\nclass A(Effect):\n    id = 'a_fine'\n",
        "badid.py": "from station.model.effect import Effect\nclass Bad(Effect):\n    id = 'has space'\n",
        "clash.py": "from station.model.effect import Effect\nclass Clash(Effect):\n    id = 'time_offset'\n",
    }
    for name, text in files.items():
        (tmp_path / name).write_text(text)
    assert main(["effects", "--plugin", str(tmp_path / spec)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and BROKEN[spec] in err and "Traceback" not in err


# --- compensation inverts the forward model ----------------------------------------------------

def test_compensation_inverts_every_library_effect_and_a_plugin():
    """Forward model with every effect at 10x a MEMS size, then apply: the specific force and
    rate come back to 1e-9 relative (the fixed-point iteration converges)."""
    rng = np.random.default_rng(1)
    n = 400
    t = np.arange(n) * 0.01
    w_p = 150.0 * np.column_stack([np.sin(2 * t), np.cos(3 * t), np.sin(t + 1)])   # deg/s
    f_p = 9.8 * np.column_stack([np.cos(t), np.sin(t) * 0.6, np.sin(t) * 0.8]) + rng.normal(0, 0.1, (n, 3))
    temp = 25.0 + 3.0 * t / t[-1]
    Ma = np.diag([1.01, 0.99, 1.002]) @ (np.eye(3) + 1e-3 * rng.normal(size=(3, 3)))
    Mg = np.diag([0.98, 1.02, 1.0]) @ (np.eye(3) + 1e-3 * rng.normal(size=(3, 3)))
    ba, bg = np.array([0.05, -0.03, 0.02]), np.array([0.1, -0.2, 0.05])
    reg = EffectRegistry()
    reg.add(RATE2)
    reg.add(CROSS)
    sizes = {"accel_lever_arm": 0.05, "accel_nonlinearity": 3000.0, "gyro_g_sensitivity": 300.0,
             "gyro_scale_asymmetry": 3000.0, "temperature_bias": 300.0, "time_offset": 0.004,
             "gyro_rate_squared": 50.0, "accel_cross_coupling": 3000.0, "accel_cubic": 3000.0,
             "scale_temperature": 3000.0, "temperature_bias_quadratic": 100.0,
             "gyro_anisoelastic": 300.0, "accel_cross_axis": 3000.0,
             "gyro_rate_nonlinearity": 50.0, "bias_drift": 1000.0, "bias_step": 300.0}
    effects = []
    for eid, size in sizes.items():
        e = reg.create(eid)
        if eid in ("temperature_bias", "scale_temperature", "temperature_bias_quadratic"):
            e.reference_c = 26.0
        if eid == "bias_step":
            e.locate(2.005, "set by the test")    # mid-run, between two samples (0.01 s apart)
        effects.append((e, size * rng.uniform(-1, 1, len(e.params))))      # internal units
    # forward: what the sensors output at the true (table-clock) times
    w_rad = np.radians(w_p)
    ctx = SampleContext(f_p=f_p, w_p=w_p, w_table=w_rad, wdot_table=np.gradient(w_rad, t, axis=0),
                        temp_c=temp, accel_matrix=Ma, gyro_matrix=Mg, t_s=t - t[0])
    a = f_p @ Ma.T + ba + sum(e.accel(x, ctx) for e, x in effects if e.accel(x, ctx) is not None)
    g = w_p @ Mg.T + bg + sum(e.gyro(x, ctx) for e, x in effects if e.gyro(x, ctx) is not None)
    dt = next(x for e, x in effects if e.id == "time_offset")[0]
    comp = {"accel_matrix": np.linalg.inv(Ma), "gyro_matrix": np.linalg.inv(Mg), "accel_bias": ba,
            "gyro_bias": bg, "raw_units": {"accel": "m/s^2", "gyro": "deg/s"}}
    # the sample taken at table time t is stamped t - dt (time_offset: stamp + dt is the table's time)
    t_c, f, w = compensate_with_effects(comp, effects, t - dt, a, g, temp)
    assert np.allclose(t_c, t, atol=1e-12)
    # the rate derivative of the size effect comes from the compensated rate (np.gradient): the
    # same operation on the same values as the forward model above, so it cancels exactly
    assert np.max(np.abs(f - f_p)) < 1e-9 * 9.8 and np.max(np.abs(w - w_p)) < 1e-9 * 150


# --- the loop with a plugin: find, add, compensate, held-out error falls ----------------------

@pytest.fixture(scope="module")
def cross_coupled(tmp_path_factory):
    d = tmp_path_factory.mktemp("cross")
    truth, train = mems_capture(seed=3, out=d / "train", accel__cross_coupling_ug_per_g2=C_UG)
    _, test = mems_capture(seed=11, scheme="chatfield18", out=d / "test", accel__cross_coupling_ug_per_g2=C_UG)
    return truth, train, test


def test_diagnose_finds_the_plugin_effect_and_estimates_it(cross_coupled):
    truth, train, _ = cross_coupled
    reg = simhelpers.registry_without(simhelpers.CROSS_AXIS)    # the library's own a_i f_j term
    reg.add(CROSS)
    steps, final = auto.run(lsq.summarise(read_capture(train)), registry=reg)
    assert steps and steps[0].added == "accel_cross_coupling", [s.added for s in steps]
    assert steps[0].before.candidates[0].source.endswith(":AccelCrossCoupling")
    assert final.reduced_chi2 < 1.5, final.reduced_chi2
    truth_by_name = {f"accel_cross_{'xyz'[i]}{'xyz'[j]}": C_UG[i][j] for i in range(3) for j in range(3) if i != j}
    for name, value, sigma, unit in steps[0].estimate:
        assert unit == "ug/g^2" and abs(value - truth_by_name[name]) < 4 * sigma, (name, value, sigma)


def _static_norm_error(out_csvs, g):
    errs = []
    for path in out_csvs:
        d = np.loadtxt(path, delimiter=",", skiprows=1)
        errs.append(np.linalg.norm(d[:, 1:4].mean(axis=0)) - g)
    return float(np.sqrt(np.mean(np.square(errs))))


def test_estimate_apply_with_a_plugin_cuts_the_held_out_error(cross_coupled, tmp_path, capsys):
    truth, train, test = cross_coupled
    base, plug = tmp_path / "base.yaml", tmp_path / "plug.yaml"
    # the base model fails on this capture (exit status 3, the file says so); with the plugin it passes
    assert main(["estimate", str(train), "-o", str(base)]) == 3
    assert main(["estimate", str(train), "--add", CROSS, "-o", str(plug)]) == 0
    doc = read_calfile(plug)
    entry = doc["compensation"]["effects"][0]
    assert entry["id"] == "accel_cross_coupling" and entry["source"].endswith(":AccelCrossCoupling")
    # apply refuses a plugin effect it was not given, naming how to load it
    seg = next(test.glob("*.csv"))
    capsys.readouterr()
    same_imu = ["--serial", "SIM-3"]      # the test capture is the same simulated IMU, another seed
    assert main(["apply", str(plug), str(seg), "-o", str(tmp_path / "x.csv"), *same_imu]) == 2
    assert "--plugin" in capsys.readouterr().err
    statics = [test / f"{s['name']}.csv" for s in yaml.safe_load((test / "manifest.yaml").read_text())["segments"]
               if s["kind"] == "static"]
    outs = {}
    for label, cal, extra in (("base", base, []), ("plugin", plug, ["--plugin", CROSS])):
        outs[label] = []
        for k, seg in enumerate(statics):
            out = tmp_path / f"{label}{k}.csv"
            assert main(["apply", str(cal), str(seg), "-o", str(out), *same_imu, *extra]) == 0
            outs[label].append(out)
    assert "compensated: accel_cross_coupling" in capsys.readouterr().err
    g = yaml.safe_load((test / "manifest.yaml").read_text())["site"]["gravity_mps2"]
    before, after = _static_norm_error(outs["base"], g), _static_norm_error(outs["plugin"], g)
    # the noise of a static mean's norm: 200 µg/√Hz over a dwell of thousands of samples is a few
    # µg; the cross-coupling leaves up to ~1 mg at the 45° attitudes of chatfield18
    assert after < 0.2 * before, (before, after)
    assert after < 50e-6 * g, after


@pytest.fixture(scope="module")
def k2_calibration(tmp_path_factory):
    """A capture with the accelerometers' K2 and `station estimate --add accel_nonlinearity`'s
    calibration of it (read by the tests below, never changed)."""
    d = tmp_path_factory.mktemp("k2")
    _, train = mems_capture(seed=5, out=d / "k2", accel__nonlinearity_ug_per_g2=[3000.0, -2000.0, 4000.0])
    cal = d / "k2.yaml"
    assert main(["estimate", str(train), "--add", "accel_nonlinearity", "-o", str(cal)]) == 0
    return train, cal


def test_apply_compensates_library_effects_and_refuses_missing_inputs(tmp_path, capsys, k2_calibration):
    train, cal = k2_calibration
    reg = EffectRegistry()
    (effect, x), = compensation_effects(read_calfile(cal), reg)
    assert effect.id == "accel_nonlinearity" and np.allclose(x, [3000, -2000, 4000], atol=200)
    statics = [s["name"] for s in yaml.safe_load((train / "manifest.yaml").read_text())["segments"]
               if s["kind"] == "static"]
    g = yaml.safe_load((train / "manifest.yaml").read_text())["site"]["gravity_mps2"]
    outs = []
    for name in statics:
        out = tmp_path / f"{name}.csv"
        assert main(["apply", str(cal), str(train / f"{name}.csv"), "-o", str(out)]) == 0
        outs.append(out)
    assert "compensated: accel_nonlinearity (library)" in capsys.readouterr().err
    # with K2 up to 4 mg/g^2 uncompensated the norms at ±1 g would be off by up to 4 mg
    assert _static_norm_error(outs, g) < 30e-6 * g
    # temperature compensation needs a temp column
    truth, warm = mems_capture(seed=6, out=tmp_path / "warm", accel__bias_tempco=[60.0, -40.0, 50.0],
                               temperature__warmup_delta_c=6.0)
    tcal = tmp_path / "t.yaml"
    assert main(["estimate", str(warm), "--add", "temperature_bias", "-o", str(tcal)]) == 0
    seg = tmp_path / "notemp.csv"
    d = np.loadtxt(next(warm.glob("*.csv")), delimiter=",", skiprows=1)
    np.savetxt(seg, d[:, :7], delimiter=",", header="t,ax,ay,az,gx,gy,gz", comments="")
    capsys.readouterr()
    assert main(["apply", str(tcal), str(seg), "-o", str(tmp_path / "o.csv")]) == 2
    err = capsys.readouterr().err
    assert "no temp column" in err and "temperature_bias" in err and len(err.strip().splitlines()) == 1


def test_a_calibration_file_with_a_bad_effects_block_is_one_line(tmp_path, k2_calibration):
    cal = tmp_path / "c.yaml"                  # a calibration with an effects block, to spoil
    doc = yaml.safe_load(k2_calibration[1].read_text())
    assert doc["compensation"]["effects"][0]["id"] == "accel_nonlinearity"
    for bad in ([{"id": 3}], "x", [{"id": "accel_nonlinearity", "parameters": {"accel_k2_x": "a"}}],
                [{"id": "accel_nonlinearity", "parameters": {}}]):
        doc["compensation"]["effects"] = bad
        cal.write_text(yaml.safe_dump(doc))
        with pytest.raises(UserError, match="compensation.effects"):
            compensation_effects(read_calfile(cal), EffectRegistry(), cal)


# --- installed packages' entry points (group station.effects) ----------------------------------

ENTRY_POINTS = """
import json, sys
from station.model.registry import EffectRegistry
reg = EffectRegistry()
created = "importlib.metadata" in sys.modules      # the installed distributions not scanned yet
try:
    ids = reg.ids()
    print(json.dumps([created, "gyro_rate_squared" in ids, reg.source("gyro_rate_squared")]))
except Exception as e:
    print(json.dumps([created, type(e).__name__, str(e)]))
"""


def _installed(tmp_path, module_text, target="rate2mod:GyroRateSquared"):
    """A folder holding an installed distribution whose entry point (station.effects) is target."""
    (tmp_path / "rate2mod.py").write_text(module_text)
    info = tmp_path / "rate2pkg-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: rate2pkg\nVersion: 1.0\n")
    (info / "entry_points.txt").write_text(f"[station.effects]\nrate2 = {target}\n")
    return tmp_path


def _registry_in(path):
    import json
    import os
    import subprocess
    import sys

    env = {**os.environ, "PYTHONPATH": f"{path}{os.pathsep}{os.environ.get('PYTHONPATH', '')}"}
    r = subprocess.run([sys.executable, "-c", ENTRY_POINTS], capture_output=True, text=True, env=env,
                       timeout=120)
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout.strip().splitlines()[-1])


def test_an_installed_package_adds_its_effect_by_entry_point_when_effects_are_asked_for(tmp_path):
    text = (ROOT / "examples/effects/gyro_rate_squared.py").read_text()
    scanned_at_creation, listed, source = _registry_in(_installed(tmp_path, text))
    assert not scanned_at_creation          # found when asked for, not when the registry is made
    assert listed and source == "entry point rate2mod:GyroRateSquared"


def test_an_entry_point_that_takes_a_library_id_is_refused(tmp_path):
    text = (ROOT / "examples/effects/gyro_rate_squared.py").read_text()
    text += "\n\nclass Clash(GyroRateSquared):\n    id = 'accel_nonlinearity'\n"
    _, error, message = _registry_in(_installed(tmp_path, text, "rate2mod:Clash"))
    assert error == "UserError" and "taken by library" in message
