"""The scheme compiler, checked by forward kinematics written here independently with scipy:
the commanded angles put "up" (and the heading) and the rotation axis where the scheme says,
within 0.01 deg, for every built-in scheme on a two-axis and a three-axis table."""
import math
import re

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from station.bench.compile import compile_scheme
from station.bench.config import AXIS_NAMES, AxisConfig, Config, RunConfig, TableConfig
from station.core.errors import UserError
from station.bench.gimbal import Gimbal
from station.bench.plan import Dwell, HandRotation, HandStatic, MoveTo, Operator, Rotate
from station.io.scheme import builtin_names, load_scheme, scheme_from_text

TOL_DEG = 0.01
FAST = AxisConfig(max_rate_dps=1000, max_accel_dps2=1000)       # the screwdriver turns at 720 deg/s
ENU = {"up": (0, 0, 1), "down": (0, 0, -1), "east": (1, 0, 0), "west": (-1, 0, 0), "north": (0, 1, 0),
       "south": (0, -1, 0)}


def attitude(axes, mounting_names, theta_deg):
    """C_nb (case -> ENU): the axes' rotations, outer first, then the mounting."""
    r = Rotation.identity()
    for a, th in zip(axes, theta_deg):
        r = r * Rotation.from_rotvec(np.radians(th) * np.asarray(a, float))
    mounting = np.column_stack([AXIS_NAMES[n] if isinstance(n, str) else n for n in mounting_names]).astype(float)
    return r * Rotation.from_matrix(mounting)


def axis_enu(axes, theta_deg, i):
    """Axis i (0 = outer) now, in ENU: the outer axes' rotations applied to its zero direction."""
    r = Rotation.identity()
    for a, th in zip(axes[:i], theta_deg[:i]):
        r = r * Rotation.from_rotvec(np.radians(th) * np.asarray(a, float))
    return r.apply(np.asarray(axes[i], float))


def angle_deg(u, v):
    u, v = np.asarray(u, float), np.asarray(v, float)
    return math.degrees(math.atan2(np.linalg.norm(np.cross(u, v)), u @ v))


def described_directions(text):
    """(IMU direction, where it points) pairs in an operator instruction."""
    out = [(np.array(AXIS_NAMES[n.lower()], float), d)
           for n, d in re.findall(r"its ([+-][XYZ]) axis pointing (\w+)", text)]
    out += [(np.array([float(x) for x in v.split(",")]), d)
            for v, d in re.findall(r"its direction \(([-0-9., ]+)\) \(IMU axes\) pointing (\w+)", text)]
    return out


def check_plan(plan, config):
    """Every recording step against forward kinematics; returns the number of steps checked."""
    axes = config.table.axis_list()
    mounting = config.table.mounting
    checked = 0
    for step in plan:
        if isinstance(step, Operator) and step.mounting is not None:
            mounting = step.mounting
        elif isinstance(step, MoveTo):
            assert len(step.positions_deg) == len(axes)
        elif isinstance(step, Dwell):
            spec, C = step.spec, attitude(axes, mounting, step.table_deg)
            assert angle_deg(C.apply(spec.up_body), [0, 0, 1]) < TOL_DEG, spec.name
            if spec.heading_body is not None:
                h = math.radians(spec.heading_deg)
                assert angle_deg(C.apply(spec.heading_body), [math.sin(h), math.cos(h), 0]) < TOL_DEG, spec.name
            assert tuple(mounting) == tuple(plan.mounting_of[spec.name])
            checked += 1
        elif isinstance(step, Rotate):
            spec, C = step.spec, attitude(axes, mounting, step.table_deg)
            b = axis_enu(axes, step.table_deg, step.axis - 1)
            sign = step.table_rate_dps / spec.rate_dps
            assert abs(abs(sign) - 1.0) < 1e-12
            # the table axis, signed, is the scheme's axis seen in the IMU ...
            assert angle_deg(C.inv().apply(sign * b), spec.axis_body) < TOL_DEG, spec.name
            # ... at the elevation the step says, which is the scheme's unless a note says why not
            elevation = math.degrees(math.asin(np.clip(sign * b[2], -1, 1)))
            assert abs(elevation - step.elevation_deg) < TOL_DEG, spec.name
            noted = any(n.startswith(f"{spec.name}:") for n in plan.notes)
            assert noted or abs(elevation - spec.axis_elevation_deg) < TOL_DEG, spec.name
            lim = config.table.axis_limits()[step.axis - 1]
            assert abs(step.table_rate_dps) <= lim.max_rate_dps and lim.angle_limits is None
            assert step.revolutions == max(1, round(abs(spec.rate_dps) * spec.duration_s / 360.0))
            checked += 1
    return checked


@pytest.mark.parametrize("axes", [2, 3])
@pytest.mark.parametrize("name", builtin_names())
def test_every_builtin_scheme_compiles_for_two_and_three_axis_tables(name, axes):
    config = Config(table=TableConfig(axes=axes, limits=(FAST,)), run=RunConfig(operator=True))
    scheme = load_scheme(name)
    plan = compile_scheme(scheme, config)
    if not scheme.table:
        assert plan.manual and len([s for s in plan if isinstance(s, (HandStatic, HandRotation))]) == len(scheme.segments)
        return
    assert check_plan(plan, config) == len(scheme.segments)
    assert plan.segments == [s.name for s in scheme.segments]
    for op in (s for s in plan if isinstance(s, Operator)):       # each says exactly how to mount it
        C = attitude(config.table.axis_list(), op.mounting, [0.0] * axes)
        described = described_directions(op.instruction)
        assert len(described) == 2, op.instruction
        for v, direction in described:
            assert angle_deg(C.apply(v), ENU[direction]) < 1e-3, op.instruction
    assert plan.duration_s > scheme.duration_s


def test_unattended_three_axis_optimal9_turns_the_diagonals_it_cannot_lay_flat_about_a_vertical_axis():
    config = Config(table=TableConfig(axes=3), run=RunConfig(operator=False))
    plan = compile_scheme(load_scheme("optimal9"), config)
    assert not any(isinstance(s, Operator) for s in plan)
    check_plan(plan, config)
    # the inner axis is the IMU's y, the middle one any direction in its x-z plane: body (1,1,0) and
    # (0,1,1) cannot be horizontal without a remount
    relaxed = {s.spec.name: s.elevation_deg for s in plan if isinstance(s, Rotate) and s.elevation_deg != 0}
    assert set(relaxed) == {"rotxy_p", "rotxy_m", "rotyz_p", "rotyz_m"}
    assert all(abs(abs(e) - 90.0) < TOL_DEG for e in relaxed.values())
    assert len(plan.notes) == 4


def test_with_an_operator_three_axis_optimal9_remounts_for_horizontal_diagonals():
    config = Config(table=TableConfig(axes=3), run=RunConfig(operator=True))
    plan = compile_scheme(load_scheme("optimal9"), config)
    assert not plan.notes
    remounts = [s for s in plan if isinstance(s, Operator) and s.segment is not None]
    assert 1 <= len(remounts) <= 3
    assert check_plan(plan, config) == 21


@pytest.mark.parametrize("axes", [1, 2, 3])
def test_operator_instructions_describe_the_mounting_they_ask_for(axes):
    config = Config(table=TableConfig(axes=axes), run=RunConfig(operator=True))
    scheme = load_scheme("sizeeffect" if axes == 1 else "optimal9")
    if axes == 1:                   # one vertical axis: each face up needs a remount ...
        scheme = scheme_from_text("name: faces\ndefaults: {dwell_s: 5}\nsegments:\n"
                                  + "".join(f"  - {{static: s{i}, up_body: {v}}}\n" for i, v in
                                            enumerate(([1, 0, 0], [0, -1, 0], [0, 0, -1]))), "faces.yaml")
    plan = compile_scheme(scheme, config)
    ops = [s for s in plan if isinstance(s, Operator)]
    assert ops
    for op in ops:
        C = attitude(config.table.axis_list(), op.mounting, [0.0] * axes)    # at the load position
        described = described_directions(op.instruction)
        assert len(described) == 2
        for axis, direction in described:
            assert angle_deg(C.apply(axis), ENU[direction]) < 1e-3, op.instruction
    if axes == 1:
        assert check_plan(plan, config) == 3 and len(ops) == 3   # one (re)mount per face


def test_least_travel():
    g = Gimbal(((0, 0, 1), (1, 0, 0), (0, 1, 0)), np.eye(3))
    # already there: nothing moves, whatever the free outer (azimuth) angle
    np.testing.assert_allclose(g.solve_static([0, 0, 1], [37.0, 0.0, 0.0]), [37.0, 0.0, 0.0], atol=1e-9)
    # x up: the inner axis at 270 (or the middle at 90 and the inner at ...): from (0, 0, 250) the
    # nearest is 20 deg away
    sol = g.solve_static([1, 0, 0], [0.0, 0.0, 250.0])
    assert g.travel([0.0, 0.0, 250.0], sol) == pytest.approx(20.0, abs=1e-6)


class _HalfStepGimbal(Gimbal):
    """The inverse kinematics as it was before the solver was sped up (issue 26): every start
    iterated until all converge, the solutions slid along their solution set by half steps (35
    slides to 1e-9 deg), the first of the least travel kept.  The reference the faster solver
    must agree with.  (Iterative only: no closed form.)"""

    def _closed_static(self, pairs, theta0):
        return None

    def _closed_rotation(self, axis_body, elevation_deg, theta0, i, sign):
        return None

    def _least_travel(self, residual, theta, theta0, free):
        continuous = np.array([lim is None for lim in self.angle_limits_deg])
        for _ in range(40):
            _, J = residual(theta)
            Jf = J[:, :, free]
            null = np.eye(len(free)) - np.linalg.pinv(Jf, rcond=1e-9) @ Jf
            d = theta - theta0
            d = np.where(continuous, (d + 180.0) % 360.0 - 180.0, d)[:, free]
            step = -0.5 * np.einsum("sij,sj->si", null, d)
            if np.all(np.abs(step) < 1e-9):
                break
            theta = theta.copy()
            theta[:, free] += np.clip(step, -30.0, 30.0)
            for _ in range(40):
                r, J = residual(theta)
                s = np.clip(np.degrees(-np.einsum("sij,sj->si", np.linalg.pinv(J[:, :, free], rcond=1e-9), r)),
                            -30.0, 30.0)
                theta = theta.copy()
                theta[:, free] += s
                if np.all(np.abs(s) < 1e-12):
                    break
        return theta


@pytest.mark.parametrize("axes", [1, 2, 3])
def test_the_faster_inverse_kinematics_finds_the_same_least_travel(axes):
    """Whole slides instead of half steps and each start stopped when it converges: the same
    reachability and the same travel as the reference (tolerance 1e-6 deg: both solve to 1e-9
    deg, SOLVE_TOL is 2e-5 arcsec); where two attitudes tie (gimbal lock), either is right."""
    rng = np.random.default_rng(axes)
    all_axes = ((0, 0, 1), (1, 0, 0), (0, 1, 0))[:axes]
    limits = (None,) * (axes - 1) + ((-100.0, 100.0),) if axes > 1 else ()
    fast, slow = Gimbal(all_axes, np.eye(3), limits), _HalfStepGimbal(all_axes, np.eye(3), limits)
    cases = 0
    for k in range(12):
        theta0 = rng.uniform(-90, 90, axes)
        # mostly attitudes the table reaches (forward kinematics of random angles), some not
        C, b = fast.frames(fast.unwrap(rng.uniform(-180, 180, axes)))
        up = C[0].T @ [0.0, 0.0, 1.0] if k % 4 else rng.normal(size=3)
        up = up / np.linalg.norm(up)
        heading = None
        if axes == 3 and k % 2:
            heading = np.cross(up, rng.normal(size=3))
            heading /= np.linalg.norm(heading)
        args = (up, theta0) if heading is None else (up, theta0, heading, rng.uniform(0, 360))
        a, b_ = fast.solve_static(*args), slow.solve_static(*args)
        assert (a is None) == (b_ is None), args
        if a is not None:
            cases += 1
            assert fast.travel(theta0, a) == pytest.approx(slow.travel(theta0, b_), abs=1e-6), args
            np.testing.assert_allclose(fast.frames(a)[0][0] @ up, [0, 0, 1], atol=1e-9)
        axis = 1 + k % axes
        turning = C[0].T @ b[0, axis - 1]                        # that table axis, in case axes
        elevation = float(np.degrees(np.arcsin(np.clip(b[0, axis - 1, 2], -1, 1))))
        for sign in (1.0, -1.0):
            a = fast.solve_rotation(sign * turning, sign * elevation, theta0, axis, sign)
            b_ = slow.solve_rotation(sign * turning, sign * elevation, theta0, axis, sign)
            assert (a is None) == (b_ is None), (turning, theta0, axis, sign)
            if a is not None:
                cases += 1
                assert fast.travel(theta0, a) == pytest.approx(slow.travel(theta0, b_), abs=1e-6)
    assert cases >= 20         # the comparison compared something


def test_an_exact_tie_in_travel_has_one_answer():
    """Gimbal lock (outer and inner axes aligned): a line of attitudes with the same travel; the
    answer does not depend on the order the solutions were found in: the least squared travel,
    then the smallest angles."""
    g = Gimbal(((0, 0, 1), (1, 0, 0), (0, 1, 0)), np.eye(3))
    sol = g.solve_static([0, -1, 0], [135.0, 90.0, 315.0], [0, 0, 1], 0.0)
    np.testing.assert_allclose(sol, [45.0, 270.0, 45.0], atol=1e-6)
    assert g.travel([135.0, 90.0, 315.0], sol) == pytest.approx(360.0, abs=1e-6)


def test_a_one_axis_table_runs_optimal9_with_remounts_fixtures_and_vertical_turns():
    config = Config(table=TableConfig(axes=1), run=RunConfig(operator=True))
    plan = compile_scheme(load_scheme("optimal9"), config)
    assert check_plan(plan, config) == 21
    fixtures = [s for s in plan if isinstance(s, Operator) and "fixture" in s.instruction]
    assert len(fixtures) == 6                         # the 45-degree statics and rotation axes
    assert all(abs(abs(s.elevation_deg) - 90) < TOL_DEG for s in plan if isinstance(s, Rotate))
    assert len(plan.notes) == 12


def test_what_a_table_cannot_do_is_a_clear_error():
    limited = Config(table=TableConfig(axes=1, limits=(AxisConfig(angle_min_deg=-170, angle_max_deg=170),)))
    with pytest.raises(UserError, match="rotx_p needs a continuous axis"):
        compile_scheme(load_scheme("optimal9"), limited)
    with pytest.raises(UserError, match="720 deg/s is beyond the table's max_rate_dps"):
        compile_scheme(load_scheme("screwdriver"), Config())
    unattended_two = Config(table=TableConfig(axes=2), run=RunConfig(operator=False))
    with pytest.raises(UserError, match=r"pos01 .* mounted as configured \(\+x, \+y, \+z\); an operator could"):
        compile_scheme(load_scheme("optimal9"), unattended_two)


def test_axes_with_angle_limits_are_respected_and_never_turned():
    limits = (AxisConfig(), AxisConfig(angle_min_deg=-100, angle_max_deg=100), AxisConfig())
    config = Config(table=TableConfig(axes=3, limits=limits), run=RunConfig(operator=True))
    plan = compile_scheme(load_scheme("chatfield18"), config)
    check_plan(plan, config)
    for step in plan:
        if isinstance(step, MoveTo) and step.positions_deg[1] is not None:
            assert -100 <= step.positions_deg[1] <= 100
        if isinstance(step, Rotate):
            assert step.axis != 2


def test_steps_carry_estimates_from_the_limits():
    config = Config(table=TableConfig(axes=3), run=RunConfig(operator=False, settle_s=5))
    plan = compile_scheme(load_scheme("optimal9", {"dwell_s": 20, "rotation_s": 36}), config)
    rot = next(s for s in plan if isinstance(s, Rotate))
    assert rot.estimate_s == pytest.approx(2 * 10 / 50 + 5 + 36)        # ramps at 50 deg/s^2, settle, 1 rev
    move = next(s for s in plan if isinstance(s, MoveTo) and s.segment == "pos02")   # 180 deg at 60 deg/s
    assert move.estimate_s == pytest.approx(180 / 60 + 60 / 60 + 1.0)


def test_station_plan_prints_the_steps_and_the_total(tmp_path, capsys):
    from station.cli import main

    config = tmp_path / "station.yaml"
    config.write_text("table: {axes: 2}\nrun: {operator: true, settle_s: 5}\n")
    assert main(["plan", "--scheme", "optimal9", "--config", str(config), "--dwell-s", "20"]) == 0
    captured = capsys.readouterr()
    lines = captured.out.splitlines()
    assert lines[0].startswith("scheme optimal9: 21 segments, 2340 s of recording; 2-axis table")
    plan = compile_scheme(load_scheme("optimal9", {"dwell_s": 20}),
                          Config(table=TableConfig(axes=2), run=RunConfig(operator=True, settle_s=5)))
    assert sum("OPERATOR: " in line for line in lines) == sum(isinstance(s, Operator) for s in plan)
    assert sum(" record " in line for line in lines) == 21
    assert lines[-1].startswith(f"total: {plan.duration_s:.0f} s")
    assert "rotxy_p: the table cannot turn" in captured.err      # what the compiler had to change


def test_remembered_solves_give_the_plans_bit_for_bit(monkeypatch):
    """The inverse kinematics remembers its solves by their exact inputs (station/bench/gimbal.py,
    _SOLVED; fin26): a compilation with it gives the very plans, pickled byte for byte, that one
    without it gives.  (All 7 built-in schemes on 7 tables were compared once, before and after:
    49 of 49 plans identical, docs/performance.md; here sizeeffect, 61 solves of which 42 distinct.)"""
    import pickle

    import station.bench.gimbal as gimbal

    config = Config(table=TableConfig(axes=2), run=RunConfig(operator=True))
    for name in ("sizeeffect",):
        scheme = load_scheme(name)
        monkeypatch.setattr(gimbal, "MEMO", False)
        plain = pickle.dumps(compile_scheme(scheme, config), protocol=5)
        monkeypatch.setattr(gimbal, "MEMO", True)
        gimbal._SOLVED.clear()
        remembered = [pickle.dumps(compile_scheme(scheme, config), protocol=5) for _ in range(2)]
        assert remembered == [plain, plain], name          # the first fills the memory, the second reads it
        assert gimbal._SOLVED
