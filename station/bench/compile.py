"""Scheme compiler: body-frame requirements -> table commands for the configured table.

Each static attitude (``up_body``, and a heading if the scheme gives one) and each rotation
(``axis_body`` at ``axis_elevation_deg``) is solved for the table's angles by gimbal inverse
kinematics (station/bench/gimbal.py) for the present mounting of the IMU, taking the solution with
the least travel from where the table is.  A rotation turns one continuous axis whose rate limit
allows the rate; its direction in the IMU is ``axis_body`` or its opposite (the table then turns
the other way).  When the table cannot reach a requirement with the IMU as mounted, the compiler
asks the operator to remount the IMU on another face, choosing the mounting that serves the
longest run of the following segments (the fewest remounts for the scheme's order).  Unattended
(``run.operator: false``) it cannot remount: a rotation is then run at another elevation if one
is reachable (the least-squares estimator fits the elevation), with a note; a static attitude is
an error.  Schemes done by hand (``table: none``) compile to operator instructions.
"""
from __future__ import annotations

import math

import numpy as np

from station.bench.config import Config
from station.core.errors import UserError
from station.bench.gimbal import Gimbal, right_angle_mountings
from station.bench.plan import (Chamber, Checkpoint, Dwell, HandRotation, HandStatic, MoveTo, Operator, Plan, Rotate,
                          Settle, WarmUp)
from station.io.scheme import RAMP_REST_S, RotationSpec, Scheme, StaticSpec

MOVE_SETTLE_S = 1.0      # estimate of a move's settling (driver polls), device s
CARDINAL = {"up": (0, 0, 1), "down": (0, 0, -1), "east": (1, 0, 0), "west": (-1, 0, 0),
            "north": (0, 1, 0), "south": (0, -1, 0)}
CASE_AXES = {"+X": (1, 0, 0), "-X": (-1, 0, 0), "+Y": (0, 1, 0), "-Y": (0, -1, 0),
             "+Z": (0, 0, 1), "-Z": (0, 0, -1)}


class Compiler:
    """Compiles one scheme for one table configuration (see the module doc)."""

    def __init__(self, scheme: Scheme, config: Config, *, sample_rate_hz: float | None = None):
        self.scheme = scheme
        self.config = config
        t = config.table
        self.limits = t.axis_limits()
        self.gimbal0 = Gimbal(tuple(map(tuple, t.axis_list())), t.mounting_matrix(),
                              tuple(lim.angle_limits for lim in self.limits))
        self.load_deg = np.array(t.load_position_deg or [0.0] * t.axes, dtype=float)
        self.operator = config.run.operator
        self.settle_s = config.run.settle_s
        self._feasible: dict = {}

    # ------------------------------------------------------------------ entry point
    def compile(self) -> Plan:
        if not self.scheme.table:
            return self._manual()
        plan = Plan(self.scheme.name)
        gimbal, theta = self.gimbal0, self.load_deg.copy()
        specs = list(self.scheme.segments)
        for spec in specs:
            self._check_rate(spec)
        if self.operator:
            if self._solve(specs[0], gimbal, theta, free_elevation=not self._exact(specs[0])) is None:
                gimbal = gimbal.remounted(self._best_mounting(specs, 0))
            plan.steps.append(self._move(theta, self.load_deg, None, "to the load position"))
            plan.steps.append(self._mount_step(gimbal.mounting, None,
                                               check=gimbal is self.gimbal0))
        plan.steps.extend(self._warmup())
        self._check_chamber()
        chamber_c = self.config.chamber.ambient_c if self.config.chamber is not None else None
        for i, spec in enumerate(specs):
            if spec.chamber_c is not None:
                plan.steps.append(self._chamber_step(spec, chamber_c))
                chamber_c = spec.chamber_c
            solution = self._solve(spec, gimbal, theta)
            relaxed = False
            if solution is None and isinstance(spec, RotationSpec) and not self._exact(spec):
                relaxed = True
                solution = self._solve(spec, gimbal, theta, free_elevation=True)
            if solution is None and self.operator:
                mounting = self._best_mounting(specs, i)
                plan.steps.append(self._move(theta, self.load_deg, spec.name, "to the load position"))
                theta = self.load_deg.copy()
                plan.steps.append(self._mount_step(mounting, spec.name))
                gimbal = gimbal.remounted(mounting)
                solution = self._solve(spec, gimbal, theta, free_elevation=relaxed)
            if solution is None:
                raise UserError(self._unreachable(spec, gimbal))
            if relaxed and abs(solution[3] - spec.axis_elevation_deg) > 1e-6:
                why = ("with the IMU on any face" if self.operator
                       else "without a remount (unattended run)")
                plan.notes.append(
                    f"{spec.name}: the table cannot turn about IMU axis {_vec(spec.axis_body)} at "
                    f"{spec.axis_elevation_deg:g} deg elevation {why}: it turns at "
                    f"{solution[3]:.4g} deg elevation instead (the estimator fits the elevation)")
            plan.mounting_of[spec.name] = mounting_names(gimbal.mounting)
            theta = self._emit(plan, spec, solution, theta)
        return plan

    # ------------------------------------------------------------------ solving
    def _solve(self, spec, gimbal: Gimbal, theta, *, free_elevation: bool = False):
        """Static: the angles.  Rotation: (angles, axis, sign, elevation).  None if unreachable."""
        if isinstance(spec, StaticSpec):
            return gimbal.solve_static(spec.up_body, theta, spec.heading_body, spec.heading_deg)
        best, best_travel = None, math.inf
        for axis, lim in enumerate(self.limits, 1):
            if lim.angle_limits is not None or abs(spec.rate_dps) > lim.max_rate_dps:
                continue
            for sign in (1.0, -1.0):
                angles = gimbal.solve_rotation(spec.axis_body, None if free_elevation else spec.axis_elevation_deg,
                                               theta, axis, sign)
                if angles is None:
                    continue
                travel = gimbal.travel(theta, angles)
                if travel < best_travel - 1e-9:
                    b_enu, _ = gimbal.axis_now(angles, axis)
                    elevation = math.degrees(math.asin(max(-1.0, min(1.0, sign * b_enu[2]))))
                    # to 1e-9 deg (the solver's own precision), so that a level axis is 0, not
                    # -0 or 7e-15 (which the plan and the manifest would print)
                    elevation = round(elevation, 9) + 0.0
                    best, best_travel = (angles, axis, sign, elevation), travel
        return best

    def _reachable(self, spec, mounting: np.ndarray, *, exact: bool | None = None) -> bool:
        """Whether ``spec`` can be reached with ``mounting`` (cached on what the table sees: the
        requirement in platform axes).  Rotations at their elevation if any mounting reaches
        that (or ``exact``), else at any elevation."""
        if isinstance(spec, StaticSpec):
            key = ("s", _key(mounting @ spec.up_body),
                   None if spec.heading_body is None else (_key(mounting @ spec.heading_body), spec.heading_deg))
            free = False
        else:
            free = not (self._exact_anywhere(spec) if exact is None else exact)
            key = ("r", _key(mounting @ np.asarray(spec.axis_body)),
                   None if free else spec.axis_elevation_deg, abs(spec.rate_dps))
        if key not in self._feasible:
            gimbal = self.gimbal0.remounted(mounting)
            self._feasible[key] = self._solve(spec, gimbal, self.load_deg, free_elevation=free) is not None
        return self._feasible[key]

    def _exact(self, spec) -> bool:
        """Whether ``spec`` is to be reached as written: statics always; rotations at their
        elevation when the IMU is already mounted for it, or an operator can remount it so."""
        if isinstance(spec, StaticSpec):
            return True
        if self._solve(spec, self.gimbal0, self.load_deg) is not None:
            return True
        return self.operator and self._exact_anywhere(spec)

    def _exact_anywhere(self, spec: RotationSpec) -> bool:
        """Whether some mounting lets the table turn about ``spec``'s axis at its elevation."""
        return any(self._reachable(spec, m, exact=True) for m in right_angle_mountings())

    def _check_rate(self, spec) -> None:
        if not isinstance(spec, RotationSpec):
            return
        usable = [lim.max_rate_dps for lim in self.limits if lim.angle_limits is None]
        if not usable:
            raise UserError(f"scheme {self.scheme.name}: rotation {spec.name} needs a continuous axis; "
                            "every axis of this table has angle limits")
        if abs(spec.rate_dps) > max(usable):
            raise UserError(f"scheme {self.scheme.name}: rotation {spec.name} at {abs(spec.rate_dps):g} deg/s "
                            f"is beyond the table's max_rate_dps ({max(usable):g}); lower it with "
                            "--rate-dps or raise table.limits in the configuration")

    def _best_mounting(self, specs, i) -> np.ndarray:
        """The mounting reaching specs[i] and the most of those after it, in order."""
        best, reach = None, 0
        for m in right_angle_mountings():
            n = 0
            while i + n < len(specs) and self._reachable(specs[i + n], m):
                n += 1
            if n > reach:
                best, reach = m, n
        if best is None:                  # no face will do: a fixture holding the IMU askew
            for m in self._fixtures(specs[i]):
                n = 0
                while i + n < len(specs) and self._reachable(specs[i + n], m):
                    n += 1
                if n > reach:
                    best, reach = m, n
        if best is None:
            raise UserError(self._unreachable(specs[i], None))
        return best

    def _fixtures(self, spec) -> list:
        """Mountings that put what ``spec`` needs where the table reaches it at zero: a static's
        up (and heading) on the platform's up (and that heading); a rotation's axis along the
        innermost continuous axis that can turn at its rate, either way."""
        if isinstance(spec, StaticSpec):
            if spec.heading_body is None:
                return [_align(spec.up_body, (0, 0, 1))]
            return [_align(spec.up_body, (0, 0, 1), spec.heading_body, _heading(spec.heading_deg))]
        out = []
        for axis, lim in reversed(list(enumerate(self.limits))):
            if lim.angle_limits is None and abs(spec.rate_dps) <= lim.max_rate_dps:
                a = np.asarray(self.gimbal0.axes_enu[axis])
                out += [_align(spec.axis_body, a), _align(spec.axis_body, -a)]
        return out

    def _unreachable(self, spec, gimbal) -> str:
        t = self.config.table
        table = f"{t.axes}-axis table (axes at zero, east-north-up: {t.axis_list()})"
        if isinstance(spec, StaticSpec):
            what = f"static {spec.name} (up_body {_vec(spec.up_body)}"
            if spec.heading_body is not None:
                what += f", {_vec(spec.heading_body)} towards {spec.heading_deg:g} deg"
            what += ")"
        else:
            what = (f"rotation {spec.name} (axis_body {_vec(spec.axis_body)} at {spec.axis_elevation_deg:g} "
                    f"deg elevation, {abs(spec.rate_dps):g} deg/s)")
        how = ("with the IMU mounted on any face" if gimbal is None or self.operator else
               f"with the IMU mounted as configured ({', '.join(mounting_names(gimbal.mounting))}); "
               "an operator could remount it (run.operator: true)")
        return f"scheme {self.scheme.name}: the {table} cannot reach {what} {how}"

    # ------------------------------------------------------------------ steps
    def _emit(self, plan: Plan, spec, solution, theta):
        if isinstance(spec, StaticSpec):
            plan.steps.append(self._move(theta, solution, spec.name, f"{spec.name}: up_body {_vec(spec.up_body)} up"))
            plan.steps.append(Settle(f"{spec.name}: table and IMU at rest", spec.name, self.settle_s,
                                     duration_s=self.settle_s))
            plan.steps.append(Dwell(_static_purpose(spec), spec.name, spec.dwell_s, spec=spec,
                                    table_deg=tuple(float(x) for x in solution)))
            theta = solution
        else:
            angles, axis, sign, elevation = solution
            target = [float(x) for x in angles]
            target[axis - 1] = None                           # the turning axis starts where it is
            plan.steps.append(self._move(theta, angles, spec.name,
                                         f"{spec.name}: table axis {axis} along IMU axis {_vec(sign * np.asarray(spec.axis_body))}",
                                         positions=tuple(target)))
            lim = self.limits[axis - 1]
            rate = sign * spec.rate_dps
            revolutions = max(1, round(abs(spec.rate_dps) * spec.duration_s / 360.0))
            ramp = abs(rate) / lim.rate_accel_dps2
            recorded = spec.record_ramp
            step = Rotate(f"about IMU axis {_vec(spec.axis_body)} at {spec.rate_dps:+g} deg/s, "
                          f"{elevation:.4g} deg elevation"
                          + (f", its ramp at the {recorded} recorded" if recorded else ""),
                          spec.name, 0.0, spec=spec, axis=axis,
                          table_rate_dps=rate, revolutions=revolutions, accel_dps2=lim.rate_accel_dps2,
                          settle_s=self.settle_s, elevation_deg=elevation,
                          table_deg=tuple(float(x) for x in angles), record_ramp=recorded,
                          rest_s=RAMP_REST_S if recorded else 0.0)
            # the settling (at the rate; a recorded ramp up: at rest, after the move) and the ramps;
            # a recorded ramp and its rest are in capture_s
            plan.steps.append(_with_estimate(step, (1 if recorded else 2) * ramp + self.settle_s + step.capture_s))
            theta = angles
        plan.steps.append(Checkpoint(f"{spec.name} saved", spec.name, 0.0))
        return theta

    def _move(self, theta_from, theta_to, segment, purpose, positions=None) -> MoveTo:
        positions = positions or tuple(float(x) for x in theta_to)
        longest = 0.0
        for p_from, p_to, lim in zip(theta_from, positions, self.limits):
            if p_to is None:
                continue
            d = abs(float(p_to - p_from)) if lim.angle_limits else abs((p_to - p_from + 180.0) % 360.0 - 180.0)
            v, a = lim.move_rate_dps, lim.move_accel_dps2
            longest = max(longest, d / v + v / a if d > v * v / a else 2.0 * math.sqrt(d / a))
        return MoveTo(purpose, segment, longest + MOVE_SETTLE_S, positions_deg=positions)

    def _mount_step(self, mounting, segment, *, check: bool = False) -> Operator:
        gimbal = self.gimbal0.remounted(mounting)
        C = gimbal.frames(self.load_deg)[0][0]                  # case -> ENU at the load position
        level = [d for d in ("east", "north", "west", "south") if _case_axis(C.T @ CARDINAL[d])] or ["east"]
        placement = (f"with its {_imu_direction(C.T @ CARDINAL['up'])} pointing up and its "
                     f"{_imu_direction(C.T @ CARDINAL[level[0]])} pointing {level[0]}")
        if not _case_axis(C.T @ CARDINAL["up"]) or not _case_axis(C.T @ CARDINAL[level[0]]):
            placement = "on a fixture, " + placement
        where = f"at the load position ({', '.join(f'{x:g}' for x in self.load_deg)}) deg"
        centred = (", its reference point on the table's axes (centred scheme)"
                   if self.scheme.centred else "")
        if check:
            text = f"check the IMU is mounted {placement}{centred} ({where})"
        elif segment is None:
            text = f"mount the IMU {placement}{centred} ({where}; the first segment needs it)"
        else:
            text = f"remount the IMU {placement}{centred} ({where})"
        return Operator(text, segment, self.config.run.operator_s, instruction=text, remount=True,
                        mounting=mounting_names(mounting))

    def _check_chamber(self) -> None:
        """A scheme that sets the chamber needs one configured, an operator for a manual one, and
        setpoints within its range (UserError, one line)."""
        steps = self.scheme.chamber_steps
        if not steps:
            return
        c = self.config.chamber
        spec, setpoint = steps[0]
        if c is None:
            raise UserError(f"scheme {self.scheme.name}: segment {spec.name!r} sets the chamber (chamber_c: "
                            f"{setpoint:g}) but the configuration ({self.config.source}) has no chamber (add a "
                            "chamber: section to station.yaml: kind, range_c, ramp_c_per_min)")
        for spec, setpoint in steps:
            if not c.in_range(setpoint):
                raise UserError(f"scheme {self.scheme.name}: segment {spec.name!r}: chamber_c {setpoint:g} C is "
                                f"outside the chamber's range {c.range_c[0]:g}..{c.range_c[1]:g} C "
                                f"({self.config.source}: chamber.range_c)")
        if c.kind == "manual" and not self.operator:
            raise UserError(f"scheme {self.scheme.name}: sets a manual chamber, which needs an operator "
                            "(run.operator: true, not --unattended)")

    def _chamber_step(self, spec, from_c: float) -> Chamber:
        c = self.config.chamber
        to = spec.chamber_c
        text = (f"set the temperature chamber to {to:g} C and start it (it ramps at about "
                f"{c.ramp_c_per_min:g} C/min); press Enter when it is set")
        estimate = self.config.run.operator_s + c.step_s(from_c, to)
        return Chamber(f"{spec.name}: chamber at {to:g} C", spec.name, estimate, setpoint_c=to, from_c=from_c,
                       ramp_s=c.ramp_s(from_c, to), soak_s=c.soak_s,
                       slope_c_per_min=None if c.soak_s is not None else c.settle_slope_c_per_min,
                       window_s=c.settle_window_s, max_s=c.settle_max_s, agree_c=c.agree_c, instruction=text)

    def _warmup(self) -> list:
        w = self.config.warmup
        if w.duration_s <= 0 and w.temp_slope_c_per_h is None:
            return []
        estimate = max(w.duration_s, w.max_s or 0.0) if w.temp_slope_c_per_h is not None else w.duration_s
        return [WarmUp("let the IMU reach a steady temperature", None, estimate, min_s=w.duration_s,
                       max_s=w.max_s, slope_c_per_h=w.temp_slope_c_per_h, window_s=w.window_s)]

    # ------------------------------------------------------------------ by hand
    def _manual(self) -> Plan:
        plan = Plan(self.scheme.name, manual=True)
        intro = ("hand calibration: put the IMU on a flat, level bench beside a straight edge; the "
                 "recording runs continuously; follow each instruction, the data tell when it is done")
        plan.steps.append(Operator(intro, None, 0.0, instruction=intro))
        plan.steps.extend(self._warmup())
        for spec in self.scheme.segments:
            if isinstance(spec, StaticSpec):
                text = (f"{spec.name}: put the IMU on the bench with {_axis_name(spec.up_body)} "
                        f"pointing up and keep it still for {spec.dwell_s:g} s")
                plan.steps.append(HandStatic(text, spec.name, spec.dwell_s + self.config.run.operator_s / 4,
                                             spec=spec, instruction=text))
            else:
                plan.steps.append(HandRotation(_hand_turn(spec), spec.name, spec.duration_s + 10.0,
                                               spec=spec, instruction=_hand_turn(spec)))
        return plan


# ---------------------------------------------------------------------------------- helpers

def compile_scheme(scheme: Scheme, config: Config) -> Plan:
    return Compiler(scheme, config).compile()


def mounting_step(scheme: Scheme, config: Config, names, *, check: bool = True) -> Operator:
    """The operator step asking to check (or make) the mounting ``names`` (as ``mounting_names``
    gives it), at the load position."""
    return Compiler(scheme, config)._mount_step(mounting_matrix(names), None, check=check)


def mounting_names(mounting: np.ndarray) -> tuple:
    """The platform directions of the case axes x, y, z (the columns of ``mounting``): names
    such as ('+x', '+y', '+z') for a box on a face, else the three unit vectors (a fixture)."""
    m = np.asarray(mounting, float)
    if not np.allclose(m, np.round(m), atol=1e-9):
        return tuple(tuple(float(round(c, 12)) + 0.0 for c in m[:, j]) for j in range(3))
    out = []
    for j in range(3):
        col = np.round(m[:, j]).astype(int)
        i = int(np.flatnonzero(col)[0])
        out.append(("+" if col[i] > 0 else "-") + "xyz"[i])
    return tuple(out)


def mounting_matrix(names) -> np.ndarray:
    """The inverse of ``mounting_names``."""
    from station.bench.config import AXIS_NAMES

    return np.column_stack([AXIS_NAMES[n] if isinstance(n, str) else n for n in names]).astype(float)


def _align(body, platform, body2=None, platform2=None) -> np.ndarray:
    """The mounting (case -> platform) taking the body vector onto the platform vector exactly,
    and ``body2`` onto ``platform2`` as well as it can; without them, a case axis perpendicular
    to ``body`` (if there is one) onto a platform axis, so the operator can line it up."""
    from scipy.spatial.transform import Rotation

    body, platform = np.asarray(body, float), np.asarray(platform, float)
    if body2 is None:
        square = [np.array(c, float) for c in CASE_AXES.values() if abs(np.dot(c, body)) < 1e-9]
        level = [np.array(c, float) for c in CARDINAL.values() if abs(np.dot(c, platform)) < 1e-9]
        if square and level:
            body2, platform2 = square[0], level[0]
    if body2 is None:
        r, _ = Rotation.align_vectors(platform[None, :], body[None, :])
    else:
        r, _ = Rotation.align_vectors([platform, np.asarray(platform2, float)],
                                      [body, np.asarray(body2, float)], weights=[1e6, 1.0])
    return r.as_matrix()


def _heading(deg: float) -> tuple:
    h = math.radians(deg)
    return (math.sin(h), math.cos(h), 0.0)


def _case_axis(v) -> str | None:
    for name, c in CASE_AXES.items():
        if np.dot(v, c) > math.cos(math.radians(0.01)):
            return name
    return None


def _imu_direction(v) -> str:
    name = _case_axis(v)
    if name:
        return f"{name} axis"
    return "direction (" + ", ".join(f"{x:.6f}" for x in np.round(np.asarray(v, float), 6) + 0.0) + ") (IMU axes)"


def _with_estimate(step, estimate_s):
    from dataclasses import replace

    return replace(step, estimate_s=estimate_s)


def _key(v) -> tuple:
    return tuple(np.round(np.asarray(v, float), 9) + 0.0)


def _vec(v) -> str:
    return "(" + ", ".join(f"{x:.4g}" for x in np.asarray(v, float) + 0.0) + ")"


def _direction(v_enu) -> str:
    for name, c in CARDINAL.items():
        if np.dot(v_enu, c) > math.cos(math.radians(0.01)):
            return name
    e, n, u = v_enu
    return f"towards (east, north, up) = ({e:.3f}, {n:.3f}, {u:.3f})"


def _axis_name(v) -> str:
    v = np.asarray(v, float)
    for name, c in CASE_AXES.items():
        if np.allclose(v, c, atol=1e-9):
            return f"its {name} axis"
    return f"its direction {_vec(v)} (IMU axes)"


def _static_purpose(spec: StaticSpec) -> str:
    text = f"up_body {_vec(spec.up_body)}"
    if spec.heading_body is not None:
        text += f", {_vec(spec.heading_body)} towards {spec.heading_deg:g} deg from north"
    return text


def _hand_turn(spec: RotationSpec) -> str:
    turn = spec.turn_deg or 360.0
    what = "one whole turn" if abs(turn - 360.0) < 1e-9 else f"{turn:g} deg"
    sense = "counter-clockwise" if spec.rate_dps > 0 else "clockwise"
    if spec.axis_elevation_deg >= 89.999:
        return (f"{spec.name}: with {_axis_name(spec.axis_body)} pointing up, turn the IMU flat on the "
                f"bench {what} {sense} seen from above, back against the same edge, then keep it still")
    return (f"{spec.name}: holding {_axis_name(spec.axis_body)} at {spec.axis_elevation_deg:g} deg "
            f"elevation, turn the IMU {what} about it, {sense} seen from its tip, then keep it still")
