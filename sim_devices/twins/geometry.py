"""Gimbal geometry of a 1-3 axis table: axis angles -> platform attitude, rate and
angular acceleration.

Axes are listed outer -> inner, each by its direction in the local level frame (ENU) when
every axis is at zero.  The IMU sits on the innermost platform; at zero its case axes are
the platform axes, which are ENU (x east, y north, z up).  With R_i = Rot(a_i, theta_i):

    C_nb = R_1 R_2 ... R_k            (platform -> ENU)
    b_i  = R_1 ... R_(i-1) a_i        (axis i now, in ENU)
    w_n  = sum theta_dot_i b_i
    wdot_n = sum (theta_ddot_i b_i + theta_dot_i (W_(i-1) x b_i)),  W_(i-1) = sum_(j<i) theta_dot_j b_j

and w, wdot in body axes are C_bn w_n, C_bn wdot_n (the table rate relative to the Earth,
as ``world.body_kinematics`` wants it).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from sim_devices import world

#: default axis directions at zero (ENU), outer -> inner
DEFAULT_AXES_ENU = {
    1: ((0.0, 0.0, 1.0),),                                   # vertical
    2: ((0.0, 0.0, 1.0), (1.0, 0.0, 0.0)),                   # vertical outer, horizontal inner
    3: ((0.0, 0.0, 1.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0)),  # azimuth, east, north at zero
}


@dataclass(frozen=True)
class TableGeometry:
    axes_enu: tuple[tuple[float, float, float], ...]
    lever_arm_m: np.ndarray = field(default_factory=lambda: np.zeros(3))

    def __post_init__(self):
        if not 1 <= len(self.axes_enu) <= 3:
            raise ValueError("a table has 1 to 3 axes")
        unit = []
        for a in self.axes_enu:
            v = np.asarray(a, dtype=float).reshape(3)
            n = np.linalg.norm(v)
            if not np.isfinite(n) or n < 1e-9:
                raise ValueError(f"axis direction {a!r} must be a non-zero vector")
            unit.append(tuple(v / n))
        object.__setattr__(self, "axes_enu", tuple(unit))
        object.__setattr__(self, "lever_arm_m", np.asarray(self.lever_arm_m, dtype=float).reshape(3))

    @classmethod
    def default(cls, n_axes: int, lever_arm_m=(0.0, 0.0, 0.0)) -> "TableGeometry":
        if n_axes not in DEFAULT_AXES_ENU:
            raise ValueError(f"a table has 1 to 3 axes, got {n_axes}")
        return cls(DEFAULT_AXES_ENU[n_axes], np.asarray(lever_arm_m, dtype=float))

    @property
    def n_axes(self) -> int:
        return len(self.axes_enu)

    def kinematics(self, theta_rad, theta_dot, theta_ddot):
        """(C_bn, w_eb_b, wdot_eb_b) for (N, k) axis angles, rates, accelerations (rad, rad/s,
        rad/s^2).  C_bn stacked (N), rates (N, 3) in body axes."""
        th = np.atleast_2d(np.asarray(theta_rad, dtype=float))
        thd = np.atleast_2d(np.asarray(theta_dot, dtype=float))
        thdd = np.atleast_2d(np.asarray(theta_ddot, dtype=float))
        n, k = th.shape
        axes = [np.asarray(a) for a in self.axes_enu]
        # attitude: inner axis first (C_bn = R_k^T ... R_1^T)
        C_bn = Rotation.identity(n)
        for i in reversed(range(k)):
            C_bn = world.table_attitude(C_bn, axes[i], th[:, i])
        # current axis directions in ENU: b_i = R_1 ... R_(i-1) a_i, the prefix product kept as
        # quaternion arrays (world.quat_product, scalar last) and applied to a_i as
        # v + 2 q_w (q_v x v) + 2 q_v x (q_v x v): scipy's stacked Rotation.__mul__ and apply cost
        # ~1 us a sample (a quarter of the IMU twin's time, eighteenth session)
        q_prefix = None
        w_n = np.zeros((n, 3))
        wd_n = np.zeros((n, 3))
        for i in range(k):
            if q_prefix is None:
                b = np.broadcast_to(axes[i], (n, 3))
            else:
                qv, qw = q_prefix[:, :3], q_prefix[:, 3:]
                t = 2.0 * world.cross3(qv, axes[i])
                b = axes[i] + qw * t + world.cross3(qv, t)
            wd_n += thdd[:, i:i + 1] * b + thd[:, i:i + 1] * world.cross3(w_n, b)
            w_n += thd[:, i:i + 1] * b
            if i + 1 < k:
                q_i = world.axis_angle_quats(axes[i], th[:, i])
                q_prefix = q_i if q_prefix is None else world.quat_product(q_prefix, q_i)
        return C_bn, C_bn.apply(w_n), C_bn.apply(wd_n)
