"""The table's geometry in the model (issue 24 item 6): station.yaml states it, captures record it,
the fit shares the mounting offset where the geometry makes it one vector and takes gravity along
each axis from the recorded elevation, so that one rate reveals the size effect's cross positions;
station plan --reveals says so beforehand."""
import copy

import numpy as np
import pytest
import yaml

from sim_devices.truth import Truth, mems_truth
from station.bench.config import parse_config
from station.core.errors import UserError
from station.estimate import lsq
from station.estimate.summaries import summarise
from station.io.scheme import scheme_from_text
from station.model import EFFECTS
from station.model.compensate import compensate
from station.simulate import dryrun

G0 = 9.80665
P_MM = np.array([[6.0, -9.0, 12.0], [-4.0, 8.0, 10.0], [11.0, -5.0, -7.0]])     # 4-12 mm, row: element
LEVER_M = [0.03, -0.02, 0.04]
STATICS = "".join(f"  - {{static: pos{i}, up_body: {u}}}\n" for i, u in enumerate(
    ([1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1], [1, 1, 0], [1, 0, 1], [0, 1, 1])))
ROTATIONS = "".join(f"  - {{rotation: rot{n}, axis_body: {a}}}\n" for n, a in (
    ("x", [1, 0, 0]), ("y", [0, 1, 0]), ("z", [0, 0, 1]), ("xy", [1, 1, 0]), ("xz", [1, 0, 1]), ("yz", [0, 1, 1])))
# one rate, 50 deg/s, two revolutions each way
TRAIN = scheme_from_text("name: train50\ndefaults: {dwell_s: 10, rate_dps: 50, rotation_s: 14.4}\nsegments:\n"
                         + STATICS + ROTATIONS, "train50")
# held out: other axes at the same rate
TEST = scheme_from_text("""name: test50
defaults: {dwell_s: 5, rate_dps: 50, rotation_s: 7.2}
segments:
  - {static: t1, up_body: [1, 1, 1]}
  - {rotation: r1, axis_body: [1, -1, 0], pair: false}
  - {rotation: r2, axis_body: [1, 1, 1], pair: false}
  - {rotation: r3, axis_body: [0, -1, 1], pair: false}
  - {rotation: r4, axis_body: [1, 2, -2], pair: false}
""", "test50")
INTERSECTING = {"axes_intersect": True, "level_arcsec": 2.0}


@pytest.fixture(autouse=True)
def one_blas_thread():
    """Small matrices: BLAS threads only contend (an SVD of the fit's Jacobian took 10x longer on
    a loaded machine)."""
    from threadpoolctl import threadpool_limits

    with threadpool_limits(1):
        yield
CROSS = [(i, c) for i in range(3) for c in range(3) if i != c]


def _truth(positions_mm=P_MM):
    t = mems_truth(0)
    t.accel.position_m = np.asarray(positions_mm, float) / 1e3
    t.bench.lever_arm_m = np.array(LEVER_M)
    return t


def _fit(truth, seed, geometry, effects=("accel_lever_arm",)):
    capture = dryrun.simulate_capture(TRAIN, truth, seed, geometry)
    return lsq.estimate(capture, [EFFECTS[e]() for e in effects])


def _positions(cal):
    """Cross positions (mm) and their 1-sigma, keyed (element, coordinate)."""
    values = {n: v for n, v, _ in cal.extra_parameters}
    return {(i, c): (values[f"accel_position_{'xyz'[i]}_{'xyz'[c]}"], cal.sigma[f"accel_position_{'xyz'[i]}_{'xyz'[c]}"])
            for i, c in CROSS}


def _heldout_mg(cal, truth, seed):
    """RMS error (mg) of the compensated specific force of a noise-free held-out capture against
    the truth at the calibration's reference point (each element's own-axis coordinate: the
    convention), from an ideal sensor on the same bench, motion and seed."""
    quiet = copy.deepcopy(truth)
    quiet.accel.noise_density = quiet.gyro.noise_density = 0.0
    doc = copy.deepcopy(truth.to_yaml_dict())
    doc["accelerometer"] = {"noise_density_ug_rthz": 0.0}
    doc["gyroscope"] = {"noise_density_dph_rthz": 0.0}
    doc["bench"]["lever_arm_m"] = list(np.array(LEVER_M) + np.diag(truth.accel.position_m))
    ideal = Truth.from_dict(doc, "ideal")
    measured, true = dryrun.simulate_capture(TEST, quiet, seed), dryrun.simulate_capture(TEST, ideal, seed)
    C_pb = truth.paper_parameters()["C_pb"]
    comp = {"accel_matrix": cal.accel_matrix, "accel_bias": cal.accel_bias, "gyro_matrix": cal.gyro_matrix,
            "gyro_bias": cal.gyro_bias, **cal.compensation_extra}
    errors = []
    for m, t in zip(measured.segments, true.segments):
        if m.kind == "rotation":
            f, _ = compensate(comp, m.data.t, m.data.accel, m.data.gyro)
            errors.append((f - t.data.accel @ C_pb.T)[20:-20])
    return float(np.sqrt(np.mean((np.vstack(errors) / (G0 * 1e-3)) ** 2)))


def test_one_rate_reveals_the_cross_positions_on_intersecting_axes():
    truth = _truth()
    z = []
    for seed in (1, 2, 3):
        cal = _fit(truth, seed, INTERSECTING)
        assert cal.fit["reduced_chi2"] < 1.5
        assert not any("not revealed" in n for n in cal.fit["notes"]), cal.fit["notes"]
        assert any("0 by convention" in n for n in cal.fit["notes"])
        for (i, c), (value, sigma) in _positions(cal).items():
            # positions from the reference point the convention defines (own-axis coordinates)
            true = P_MM[i, c] - P_MM[c, c]
            assert sigma < 2.0                       # mm: revealed against 4-12 mm positions
            z.append((value - true) / sigma)
    z = np.array(z)
    assert np.max(np.abs(z)) < 3.5, z
    assert 0.3 < np.sqrt(np.mean(z**2)) < 1.8, z     # the 1-sigma is honest, neither side


def test_without_the_geometry_the_same_capture_reveals_none_and_the_held_out_error_falls():
    truth = _truth()
    before = _fit(truth, 1, None)
    after = _fit(truth, 1, INTERSECTING)
    assert any("not revealed by this capture" in n and "accel_position_x_y" in n for n in before.fit["notes"])
    # the floor: the same fit of an IMU whose elements sit at one point (no size effect)
    floor = _heldout_mg(_fit(_truth(np.zeros((3, 3))), 1, INTERSECTING, ()), _truth(np.zeros((3, 3))), 101)
    e_before, e_after = _heldout_mg(before, truth, 101), _heldout_mg(after, truth, 101)
    assert e_before > 4 * e_after, (e_before, e_after, floor)
    assert e_after < 2 * floor + 0.01, (e_after, floor)       # mg: at the calibration's own error


def test_axes_that_do_not_intersect_need_an_offset_per_axis():
    truth = _truth(np.zeros((3, 3)))
    truth.bench.axis_offsets_m = np.array([[0, 15, -10], [20, 0, 12], [-8, 14, 0]]) / 1e3
    shared = lsq.estimate(dryrun.simulate_capture(TRAIN, truth, 1, {"axes_intersect": True}))
    per_axis = lsq.estimate(dryrun.simulate_capture(TRAIN, truth, 1, {"axes_intersect": False}))
    assert shared.fit["reduced_chi2"] > 10             # one vector cannot be every axis' offset
    assert per_axis.fit["reduced_chi2"] < 1.5
    assert len(per_axis.fit["mounting_offsets_mm"]) == 6 and "mounting_offset_mm" not in per_axis.fit
    # the x rotation's offset across its axis: the lever arm plus the x axis' own line
    rotx = np.array(per_axis.fit["mounting_offsets_mm"][0])
    expected = (np.array(LEVER_M) + truth.bench.axis_offsets_m[0]) * 1e3
    assert np.allclose(rotx[1:], expected[1:], atol=1.0) and abs(rotx[0]) < 1.0


def test_captures_without_the_geometry_fit_as_before_and_a_remount_splits_the_offset():
    truth = _truth(np.zeros((3, 3)))
    plain = dryrun.simulate_capture(TRAIN, truth, 1)
    s = summarise(plain)
    assert s.geometry is not None and not s.geometry.stated
    model = lsq.Model(s, [])
    assert model.layout["mounting_offset"].stop - model.layout["mounting_offset"].start == 3
    assert model.level_groups == []
    before = lsq.estimate(plain)
    # stated, one mounting, no level: the same model and the same calibration
    same = lsq.estimate(dryrun.simulate_capture(TRAIN, truth, 1, {"axes_intersect": True}))
    assert np.array_equal(same.accel_matrix, before.accel_matrix)
    assert same.fit["mounting_offset_mm"] == before.fit["mounting_offset_mm"]
    # remounted half way (the rotations about y and yz on another face): two offsets
    remounted = dryrun.simulate_capture(TRAIN, truth, 1, {"axes_intersect": True})
    for seg in remounted.segments:
        seg.extra["mounting"] = ["+y", "-x", "+z"] if seg.name.startswith(("roty", "rotyz")) else ["+x", "+y", "+z"]
    model = lsq.Model(summarise(remounted), [])
    assert [k for k in model.layout.blocks if k.startswith("mounting_offset")] == ["mounting_offset0",
                                                                                  "mounting_offset1"]


@pytest.mark.parametrize("geometry, field", [
    ("{axes_intersect: maybe}", "table.geometry.axes_intersect"),
    ("{level_arcsec: -2}", "table.geometry.level_arcsec"),
    ("{level_arcsec: 7200}", "table.geometry.level_arcsec"),
    ("{intersect: true}", "table.geometry.intersect"),
    ("[true]", "table.geometry"),
    ("{axes_intersect: false}, imu_offset_m: [0, 0, 0.1]", "table.imu_offset_m"),
])
def test_bad_geometry_in_station_yaml_is_named_with_exit_2(tmp_path, capsys, geometry, field):
    from station.cli import main

    config = tmp_path / "station.yaml"
    config.write_text(f"table: {{geometry: {geometry}}}\n")
    assert main(["plan", "--scheme", "noise", "--config", str(config)]) == 2
    assert f"field '{field}'" in capsys.readouterr().err


def test_the_geometry_is_recorded_and_read_back(tmp_path):
    from station.cli.run import table_geometry
    from station.io.capture import read_capture

    config = parse_config({"table": {"geometry": {"axes_intersect": False, "level_arcsec": 3}}}, "station.yaml")
    assert table_geometry(config.table) == {"axes_intersect": False, "level_arcsec": 3.0}
    assert table_geometry(parse_config({}, "x").table) == {"axes_intersect": True}
    short = scheme_from_text("name: s\ndefaults: {dwell_s: 2, rate_dps: 50, rotation_s: 7.2}\nsegments:\n"
                             + STATICS + ROTATIONS, "s")
    path = dryrun.record_scheme(short, _truth(), 1, tmp_path / "cap", geometry=table_geometry(config.table))
    capture = read_capture(path)
    assert capture.extra["table"]["geometry"] == {"axes_intersect": False, "level_arcsec": 3.0}
    s = summarise(capture)
    assert s.geometry.stated and not s.geometry.axes_intersect
    assert s.geometry.level_sigma_rad == pytest.approx(3.0 / 206264.806, rel=1e-6)
    assert s.geometry.elevation_deg == {k: 0.0 for k in range(6)}
    bad = yaml.safe_load((path / "manifest.yaml").read_text())
    bad["table"]["geometry"]["level_arcsec"] = "level"
    (path / "manifest.yaml").write_text(yaml.safe_dump(bad))
    with pytest.raises(UserError, match="table.geometry.level_arcsec"):
        summarise(read_capture(path))


def test_station_plan_reveals_lists_what_the_scheme_reveals(tmp_path, capsys):
    from station.cli import main

    scheme = tmp_path / "one_rate.yaml"
    scheme.write_text("name: one_rate\ndefaults: {dwell_s: 10, rate_dps: 50, rotation_s: 14.4}\nsegments:\n"
                      + STATICS + ROTATIONS)
    lines = {}
    for name, geometry in (("free", "{axes_intersect: true}"), ("level", "{axes_intersect: true, level_arcsec: 2}")):
        config = tmp_path / f"{name}.yaml"
        # one mounting for the whole scheme: a 3-axis table reaches every attitude and axis
        config.write_text(f"table: {{axes: 3, geometry: {geometry}}}\nrun: {{operator: false}}\n")
        assert main(["plan", "--scheme", str(scheme), "--config", str(config), "--reveals"]) == 0
        out = capsys.readouterr().out
        lines[name] = {line.split(":")[0].strip(): line for line in out.splitlines() if line.startswith("  ")}
    # unattended, the table turns the xy and yz diagonals about vertical axes (gravity along a
    # vertical axis is g: known without the level), the xz diagonal about a horizontal one
    assert "accel_position_x_z" in lines["free"]["not revealed"]
    assert "accel_position_x_x" in lines["free"]["0 by convention (not estimated)"]
    revealed = lines["level"]["revealed (1 sigma)"]
    for i, c in CROSS:
        assert f"accel_position_{'xyz'[i]}_{'xyz'[c]} +/- " in revealed
    assert "accel_scale_x +/- " in revealed


@pytest.mark.parametrize("intersect", [True, False])
def test_the_jacobian_of_the_geometry_terms_is_exact(intersect):
    """Per-axis offsets and the level rows: the complex-step Jacobian (dense and sparse, with its
    column groups) against central differences."""
    cap = dryrun.simulate_capture(TRAIN, _truth(), 1, {"axes_intersect": intersect, "level_arcsec": 2.0})
    model = lsq.Model(summarise(cap), [EFFECTS["accel_lever_arm"]()])
    x = model.x0
    J = model.jacobian(x)
    assert np.array_equal(J, model.sparse_jacobian(x).toarray())
    for j in range(model.layout.size):
        h = 1e-6 * max(abs(x[j]), 1e-2)
        e = np.zeros_like(x)
        e[j] = h
        column = (model.residuals(x + e) - model.residuals(x - e)) / (2 * h)
        assert np.linalg.norm(J[:, j] - column) <= 1e-5 * np.linalg.norm(J[:, j]) + 1e-6, j
