"""bias_drift on station apply's clock (issue 25): the fit counts time from the capture's first
segment's mean time, station apply from the first sample of the data it is given.  The drift's
reference time is moved by the difference (kept in the calibration file), so that at any instant of
the capture the term apply subtracts is the one the fit predicted.  Before, apply's reference was
half the first segment early (10 s with 20 s statics: 0.08 deg/h at 30 deg/h per hour)."""
import numpy as np
import pytest

import simhelpers
from station.estimate import lsq
from station.model.bias_drift import BiasDrift
from station.model.effect import SampleContext


def _ctx(t_s, fit: bool):
    n = len(t_s)
    zeros = np.zeros((n, 3))
    return SampleContext(f_p=zeros, w_p=zeros, w_table=zeros, wdot_table=zeros, temp_c=np.full(n, np.nan),
                         accel_matrix=np.eye(3), gyro_matrix=np.eye(3), t_s=np.asarray(t_s, float),
                         turned_s=np.zeros(n) if fit else None)


def test_apply_subtracts_at_each_instant_the_drift_the_fit_predicted():
    _, capture = simhelpers.mems_capture(3, "optimal9", {"dwell_s": 20.0, "rotation_s": 8.0})
    s = lsq.summarise(capture)
    effect = BiasDrift()
    effect.setup(s)
    first_sample = min(float(seg.data.t[0]) for seg in capture.complete())
    t0 = min(x.t_mid_s for x in (*s.statics, *s.rotations))
    assert effect.apply_offset_s == pytest.approx(t0 - first_sample, abs=0.02)   # half a 20 s static
    assert 9.0 < effect.apply_offset_s < 11.0
    x = np.array([300.0, -200.0, 250.0, 30.0, -20.0, 25.0])     # ug/h, deg/h per hour
    instants = np.array([st.t_mid_s for st in s.statics])       # the capture's clock
    in_fit = effect.gyro(x, _ctx(instants - t0, fit=True))
    in_apply = effect.gyro(x, _ctx(instants - first_sample, fit=False))
    np.testing.assert_allclose(in_apply, in_fit, rtol=0, atol=1e-12)
    np.testing.assert_allclose(effect.accel(x, _ctx(instants - first_sample, fit=False)),
                               effect.accel(x, _ctx(instants - t0, fit=True)), rtol=0, atol=1e-15)
    # the state round-trips through the calibration file's compensation block; a file written
    # before the field (no apply_offset_s) is read as it was
    again = BiasDrift()
    again.restore(effect.state())
    assert again.apply_offset_s == effect.apply_offset_s
    old = BiasDrift()
    old.restore({"reference_s": effect.reference_s})
    assert old.apply_offset_s == 0.0
