"""Issue 28, twenty-first session: the table's once-per-revolution vibration over a recorded ramp.

The twin (sim_devices/world.py ``table_vibration_enu``, from the platter's angle: zero at rest,
~ rate^2 at a steady rate, an angular-acceleration part over a ramp) is the reference; the
estimator's table_vibration_once_per_rev (station/model/table_vibration.py, (4) of its derivation)
carries one (P, Q) per table axis and steady rate and scales a recorded ramp's rows from them.  Here
the model's term at a ramp's points is compared with the twin's acceleration turned into the IMU's
case, point by point (the model and the twin share no code): to rounding.  Before this session the
model took a ramp's rows as the steady turn's (off by the whole vibration at rest), and keyed a
ramp by the window's mean rate (a group of its own at a rate the table never held).
"""
from __future__ import annotations

import math
from types import SimpleNamespace as NS

import numpy as np
from scipy.spatial.transform import Rotation

from sim_devices import world
from station.model.effect import SampleContext
from station.model.table_vibration import TableVibration

A_MPS2 = np.array([1.0, 0.5, -0.7]) * 9.80665e-3     # the twin's amplitudes at the reference rate
PHI = math.radians(30.0)
W_REF = math.radians(60.0)                           # the twin's reference rate
W_S = math.radians(100.0)                            # the turns' steady rate


def _model(n: int):
    """A TableVibration set up as for a capture with one steady turn (segment 0), a ramp up (1) and
    its - half (2) about the table axis east (level), the IMU's case the ENU frame at the start:
    frames (l, v_hat = up, u = l x up) as table_revolution.frames gives them there."""
    l, up = np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0])
    frame = (l, up, np.cross(l, up))
    e = TableVibration()
    rot = [NS(index=i, rate_dps=rate, table_axis=None, record_ramp=ramp, table_rate_end_dps=end, table_rate_start_dps=0.0)
           for i, rate, ramp, end in ((0, 100.0, None, None), (1, 84.5, "start", 100.0), (2, -84.5, "start", -100.0))]
    e.frame = {r.index: frame for r in rot}
    e.vframe = {}
    # setup's keying and ramp rates (frames come from the harmonics, set above): as setup does
    import station.model.table_vibration as tv
    key = {r.index: (0, tv._rate_key(r)) for r in rot}
    groups = sorted(set(key.values()))
    e.groups = [[k, rate] for k, rate in groups]
    e.group_of = {i: groups.index(g) for i, g in key.items()}
    e.vertical_axial, e.vertical_across = [], []
    e.ramp_rate = {r.index: math.radians(tv._steady_rate_dps(r)) for r in rot if r.record_ramp}
    return e, l


def test_a_ramp_s_rows_are_the_twin_s_vibration_and_a_steady_turn_s_unchanged():
    n = 64
    e, l = _model(n)
    # a ramp's mean rate (84.5) is keyed by its steady edge, 100 deg/s: one group for all three
    assert e.groups == [[0, 100.0]] and e.ramp_rate == {1: W_S, 2: W_S}
    p = 2.0 * np.pi * np.arange(n) / n
    acc = W_S ** 2 / (4.0 * np.pi)                        # reaches W_S after one revolution
    rate_up = np.sqrt(2.0 * acc * p)                      # theta = acc t^2 / 2 at the phase points
    cases = [(W_S * np.ones(n), np.zeros(n)), (rate_up, acc * np.ones(n)), (-rate_up, -acc * np.ones(n))]
    thd = np.concatenate([c[0] for c in cases])
    thdd = np.concatenate([c[1] for c in cases])
    seg = np.repeat([0.0, 1.0, 2.0], n)
    theta = np.tile(p, 3)           # the signed angle mod 2 pi (the - half's grid point -2 pi (n - j) / n)
    # the twin's acceleration at each point, ENU, turned into the case (C_bn0 = I: the case turns by
    # Rot(l, -theta))
    want = np.empty((3 * n, 3))
    for k in range(3):
        s = slice(k * n, (k + 1) * n)
        a_enu = world.table_vibration_enu(l, theta[s], thd[s], thdd[s], A_MPS2, W_REF, PHI)
        want[s] = world.table_attitude(Rotation.identity(), l, theta[s]).apply(a_enu)
    # the model's (P, Q) of the group: the twin at the steady rate W_S, cos(p + phi) (W_S / W_REF)^2 D
    D = A_MPS2[0] * l + A_MPS2[1] * np.array([0.0, 0.0, 1.0]) + A_MPS2[2] * np.cross(l, [0.0, 0.0, 1.0])
    frame = np.array(e.frame[0])
    P = (W_S / W_REF) ** 2 * math.cos(PHI) * frame @ D
    Q = -(W_S / W_REF) ** 2 * math.sin(PHI) * frame @ D
    x = np.concatenate([P, Q])                            # axis, gravity, third; cos then sin
    w_table = thd[:, None] * l
    ctx = SampleContext(f_p=np.zeros((3 * n, 3)), w_p=np.zeros((3 * n, 3)), w_table=w_table,
                        wdot_table=thdd[:, None] * l, temp_c=np.full(3 * n, np.nan), accel_matrix=np.eye(3),
                        gyro_matrix=np.eye(3), segment_index=seg, turned_s=np.zeros(3 * n), wsq_table=thd * thd,
                        axis_table=np.tile(l, (3 * n, 1)))
    got = e.accel(x, ctx)
    scale = np.abs(want).max()
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12 * scale)
    # the ramp's first point (rate 0): the angular acceleration's part alone, not the steady turn's
    assert np.abs(got[n] - got[0]).max() > 0.1 * scale
    # the same without wsq_table (|w_table|^2)
    np.testing.assert_allclose(e.accel(x, SampleContext(**{**vars(ctx), "wsq_table": None})), want,
                               rtol=0, atol=1e-12 * scale)
    # the batch form (B rows of x, a batch context) gives the same per row
    X = np.stack([x, 2.0 * x])
    batch = SampleContext(**{**vars(ctx), "f_p": np.zeros((2, 3 * n, 3)), "w_table": np.stack([w_table] * 2),
                             "wdot_table": np.stack([thdd[:, None] * l] * 2), "accel_matrix": np.stack([np.eye(3)] * 2),
                             "wsq_table": np.stack([thd * thd] * 2)})
    np.testing.assert_allclose(e.accel_batch(X, batch), np.stack([want, 2.0 * want]), rtol=0, atol=2e-12 * scale)
    # (5): with the fit's products (SampleContext.ramp_products, here the points' own values of w^2 and
    # dw/dt times 1, cos p, sin p, cos 2p, sin 2p; none on the steady turn) the term is taken from them
    # alone: w_table's square and wdot_table zeroed, the same twin
    basis = np.stack([np.ones(3 * n), np.cos(theta), np.sin(theta), np.cos(2 * theta), np.sin(2 * theta)], axis=1)
    products = np.stack([(thd * thd)[:, None] * basis, thdd[:, None] * basis], axis=1)       # (N, 2, 5)
    products[:n] = np.nan
    blind = SampleContext(**{**vars(ctx), "wsq_table": np.zeros(3 * n), "wdot_table": np.zeros((3 * n, 3)),
                             "ramp_products": products})
    np.testing.assert_allclose(e.accel(x, blind), want, rtol=0, atol=1e-12 * scale)
    blind_batch = SampleContext(**{**vars(batch), "wsq_table": np.zeros((2, 3 * n)),
                                   "wdot_table": np.zeros((2, 3 * n, 3)), "ramp_products": products})
    np.testing.assert_array_equal(e.accel_batch(X, blind_batch)[1], e.accel(X[1], blind))
    np.testing.assert_allclose(e.accel_batch(X, blind_batch), np.stack([want, 2.0 * want]), rtol=0, atol=2e-12 * scale)
