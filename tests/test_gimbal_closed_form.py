"""The closed-form inverse kinematics (station/bench/gimbal.py, Paden-Kahan subproblems; issue 26)
against the iterative solve it stands in for (Gauss-Newton from a grid of starts, slid to the
least travel: gimbal.CLOSED_FORM = False), on random tables (axes, mountings, angle limits) and
random targets, and on compiled plans."""
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

import station.bench.gimbal as gimbal
from station.bench.compile import compile_scheme
from station.bench.config import Config, RunConfig, TableConfig
from station.bench.gimbal import Gimbal
from station.io.scheme import load_scheme

# Both solvers end on exact solutions: the closed form to round-off (~1e-14 deg), Gauss-Newton
# stops when its step is below 1e-12 deg and the least-travel slide below 1e-9 deg; a decoupled
# axis is slid onto its present angle in one exact step.  So the same solution agrees far inside
# 1e-9 deg (the bound the brief sets), and a different one would differ by degrees.
ANGLE_TOL_DEG = 1e-9

unit = st.tuples(*[st.floats(-1, 1)] * 3).map(np.array).filter(lambda v: 0.1 < np.linalg.norm(v)).map(
    lambda v: v / np.linalg.norm(v))
vertical = st.sampled_from([np.array([0.0, 0.0, 1.0]), np.array([0.0, 0.0, -1.0])])
coordinate = st.sampled_from([np.eye(3)[0], np.eye(3)[1], -np.eye(3)[0], -np.eye(3)[1]])
limit = st.one_of(st.none(), st.tuples(st.floats(-180, 0), st.floats(60, 340)).map(lambda t: (t[0], t[0] + t[1])))


@st.composite
def tables(draw):
    """A 1-3 axis table: the outer axis vertical or not, the others coordinate axes or any; a
    right-angle or an arbitrary mounting; each axis continuous or limited."""
    k = draw(st.integers(1, 3))
    axes = [draw(st.one_of(vertical, unit))] + [draw(st.one_of(coordinate, unit)) for _ in range(k - 1)]
    if draw(st.booleans()):
        mounting = draw(st.sampled_from(gimbal.right_angle_mountings()))
    else:
        q = draw(unit)                          # a rotation: axis q by angle
        angle = draw(st.floats(-math.pi, math.pi))
        K = np.array([[0, -q[2], q[1]], [q[2], 0, -q[0]], [-q[1], q[0], 0]])
        mounting = np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K
    return Gimbal(tuple(map(tuple, axes)), mounting, tuple(draw(limit) for _ in range(k)))


def both(solve, *args):
    """(closed form, iterative) answers of one solve; neither remembered."""
    memo, closed = gimbal.MEMO, gimbal.CLOSED_FORM
    try:
        gimbal.MEMO = False
        gimbal.CLOSED_FORM = True
        a = solve(*args)
        gimbal.CLOSED_FORM = False
        b = solve(*args)
    finally:
        gimbal.MEMO, gimbal.CLOSED_FORM = memo, closed
    return a, b


def same(g, theta0, a, b, reaches):
    """The same answer, or (where the iterative solve cannot tell) a better one, checked by
    forward kinematics (``reaches``) and the limits: when no free axis moves the target (a
    vertical axis under an up-only static, say) the Jacobian's column is round-off (1e-17), its
    pseudo-inverse can turn that into 30-degree steps and Gauss-Newton stop at any angle; an
    angle slid onto a lower limit can end 1e-16 below it and be refused.  The closed form keeps
    such an axis exactly where it is."""
    if b is not None:
        assert a is not None, b                 # the closed form never misses a solution
        ta, tb = g.travel(theta0, a), g.travel(theta0, b)
        assert ta <= tb + ANGLE_TOL_DEG, (a, b)
        if ta > tb - ANGLE_TOL_DEG:
            d = np.where([lim is None for lim in g.angle_limits_deg], gimbal.wrap180(a - b), a - b)
            assert np.max(np.abs(d)) < ANGLE_TOL_DEG, (a, b)
            return
    if a is not None:                           # better than the iterative's: a true solution
        assert reaches(a), a
        for t, lim in zip(a, g.angle_limits_deg):
            assert (0.0 <= t < 360.0) if lim is None else (lim[0] <= t <= lim[1] + 1e-9), a


@settings(max_examples=40, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.filter_too_much])
@given(g=tables(), data=st.data())
def test_closed_form_statics_are_the_iterative_solution(g, data):
    """Up only (and up with a heading): reachable targets (the attitude of random angles) and
    random ones; whenever the closed form answers, the same angles or none as the iterative."""
    theta = data.draw(st.lists(st.floats(-180, 180), min_size=g.n_axes, max_size=g.n_axes))
    theta0 = g.unwrap(data.draw(st.lists(st.floats(-180, 180), min_size=g.n_axes, max_size=g.n_axes)))
    C = g.frames(theta)[0][0]
    up = C.T @ gimbal.UP_ENU if data.draw(st.integers(0, 3)) else data.draw(unit)
    pairs = [(up, gimbal.UP_ENU)]
    args = (up, theta0)
    if data.draw(st.booleans()):                # with a heading the attitude is whole
        heading_deg = data.draw(st.floats(0, 360))
        heading = C.T @ gimbal.heading_enu(heading_deg)
        heading = heading - up * (up @ heading)
        assume(np.linalg.norm(heading) > 0.1)
        heading /= np.linalg.norm(heading)
        pairs.append((heading, gimbal.heading_enu(heading_deg)))
        args = (up, theta0, heading, heading_deg)
    assume(g._closed_static(pairs, g.unwrap(theta0)) is not None)      # a case the closed form solves
    def reaches(th):
        C = g.frames(th)[0][0]
        return all(np.linalg.norm(C @ body - enu) < 1e-9 for body, enu in pairs)

    same(g, theta0, *both(g.solve_static, *args), reaches)


@settings(max_examples=40, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.filter_too_much])
@given(g=tables(), data=st.data())
def test_closed_form_rotations_are_the_iterative_solution(g, data):
    """A table axis along an IMU direction, at an elevation (or any): the direction and elevation
    that random angles give the axis (reachable), or random ones."""
    theta = data.draw(st.lists(st.floats(-180, 180), min_size=g.n_axes, max_size=g.n_axes))
    theta0 = g.unwrap(data.draw(st.lists(st.floats(-180, 180), min_size=g.n_axes, max_size=g.n_axes)))
    axis = data.draw(st.integers(1, g.n_axes))
    sign = data.draw(st.sampled_from([1.0, -1.0]))
    b_enu, b_case = g.axis_now(theta, axis)
    turning = sign * b_case if data.draw(st.integers(0, 3)) else data.draw(unit)
    elevation = data.draw(st.one_of(st.none(), st.just(math.degrees(math.asin(np.clip(sign * b_enu[2], -1, 1)))),
                                    st.floats(-90, 90)))
    assume(g._closed_rotation(turning, elevation, g.unwrap(theta0), axis - 1, sign) is not None)
    def reaches(th):
        b_enu, b_case = g.axis_now(th, axis)
        return (np.linalg.norm(sign * b_case - turning) < 1e-9
                and (elevation is None or abs(sign * b_enu[2] - math.sin(math.radians(elevation))) < 1e-9))

    same(g, theta0, *both(g.solve_rotation, turning, elevation, theta0, axis, sign), reaches)


@pytest.mark.parametrize("name, config", [
    ("sizeeffect", Config()),
    ("optimal9", Config(table=TableConfig(axes=2), run=RunConfig(operator=True))),
])
def test_compiled_plans_are_those_of_the_iterative_solve(name, config):
    """The same steps, segments, axes and operator instructions; the angles within 1e-9 deg (all
    49 plans of the built-in schemes on 7 tables: benchmarks/ik_closed_form.py, largest difference
    4e-14 deg)."""
    def compiled(closed):
        memo = gimbal.CLOSED_FORM
        gimbal._SOLVED.clear()
        try:
            gimbal.CLOSED_FORM = closed
            return compile_scheme(load_scheme(name), config)
        finally:
            gimbal.CLOSED_FORM = memo
            gimbal._SOLVED.clear()

    a, b = compiled(True), compiled(False)
    assert a.notes == b.notes and a.mounting_of == b.mounting_of
    close(a.steps, b.steps, name)


def close(x, y, where):
    """Equal, but floats (angles in deg, durations in s) within 1e-9."""
    assert type(x) is type(y), where
    if isinstance(x, (list, tuple)):
        assert len(x) == len(y), where
        for i, (u, v) in enumerate(zip(x, y)):
            close(u, v, f"{where}[{i}]")
    elif isinstance(x, (float, np.floating)):
        assert abs(x - y) < ANGLE_TOL_DEG * max(1.0, abs(x)), (where, x, y)
    elif isinstance(x, np.ndarray):
        np.testing.assert_allclose(x, y, rtol=0, atol=ANGLE_TOL_DEG, err_msg=where)
    elif hasattr(x, "__dict__"):
        assert vars(x).keys() == vars(y).keys(), where
        for k in vars(x):
            close(vars(x)[k], vars(y)[k], f"{where}.{k}")
    else:
        assert x == y, (where, x, y)
