"""Issue 28, twentieth session: a time offset and the recorded ramps' accelerometer rows.

A rotation's summary took the table's rate at each sample from the gyro scaled to the encoder's mean
rate A / T (station/estimate/summaries._rate: the gyro's scale is not known there), and the model the
centripetal and tangential forces at the mounting offset from that rate.  Under a time offset dt the
samples stamped in the encoder's window [t0, t1] were taken over [t0 + dt, t1 + dt] on the table's
clock and turned A + dt (w(t1) - w(t0)): their true rate is (A + dt dw) / A times the shape, its
square that squared.  The estimator's time_offset took the shift into the gyro integral only: the
ramps' accelerometer rows misfit (noise x 0.01, 10 ms: chi2 ~28,000 on their 60 rows, against ~50
at dt = 0) and pulled the offset low.  Now a recorded ramp's rate is scaled by the table's stated
steady rate, as its phase already was (summaries._ramp_fraction; RotationSummary.rate_from_table):
neither the offset nor the error of the window's placed angle moves it.  Every other rotation keeps
the encoder's scale and the model multiplies its rate by c = I / (I - dt dw) (lsq.Model.
_rate_shape_factor).  And of the offset's term dt (w_end - w_start) only the table rate's change is
kept: the Earth rate's change across the axis between the edge means is the samples' own.

The reference is the device twin's physics (sim_devices/bench.py: the samples taken at table time
t + time_offset_s, the specific force at the lever arm from the table's own ramp profile), which
shares no code with the estimator's summaries or model.  At 400 Hz: at the dry run's 100 Hz the
summaries' rate derivative (a difference of neighbouring samples) leaves a floor at the ramps'
kinks that this noise shows (chi2 ~4x the rows at dt = 0 too; 2,560 on 60 at 50 Hz, ~50 at
400 Hz), which is not the offset's."""
import dataclasses

import numpy as np
import pytest
from scipy.stats import chi2

from test_ramp_placement_scatter import _scheme

OFFSET_MS = 10.0


def _quiet_ramps(offset_ms):
    from sim_devices.truth import default_truth
    from station.estimate.summaries import summarise
    from station.simulate import dryrun

    truth = default_truth(1)
    truth.bench.time_offset_s = offset_ms * 1e-3
    truth.accel.noise_density *= 0.01
    truth.gyro.noise_density *= 0.01
    truth.bench.table_angle_error_arcsec *= 0.01
    truth.sample_rate_hz = 400.0
    capture = dryrun.simulate_capture(_scheme(ramp_axes=[[0, 0, 1]], repeats=1), truth, 3)
    for seg in capture.segments:
        if seg.extra.get("record_ramp"):
            seg.extra["angle_sigma_deg"] = 100.0
    return summarise(capture)


@pytest.fixture(scope="module")
def quiet_ramps():
    """The dry run's six faces, steady pairs about x, y, z and a ramp up and a brake pair about z,
    the IMU 10 ms behind the table, its noise a hundredth of default_truth's, 400 Hz; the ramps'
    angles stated +-100 deg (their reads say nothing along the axis: what is left is the model's
    response to the offset through the other rows)."""
    return _quiet_ramps(OFFSET_MS)


def _untyped():
    from station.model.time_offset import TimeOffset

    class Untyped(TimeOffset):      # no prior to pull it: the data's own estimate
        @property
        def params(self):
            return tuple(dataclasses.replace(p, typical=1e3) for p in super().params)

    return Untyped()


def _ramp_accel_rows(model, x):
    ramps = {r.name for r in model.s.rotations if r.record_ramp}
    r = model.residuals(x)
    return np.array([v for (seg, _, q, _), v in zip(model.row_labels(x), r) if seg in ramps and q.startswith("accel")])


@pytest.fixture(scope="module")
def fitted(quiet_ramps):
    from station.estimate import lsq, noise_groups

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(noise_groups, "RAMP_MIN_DOF", float("inf"))      # the stated +-100 deg kept
        return lsq.fit(quiet_ramps, [_untyped()])


def test_a_time_offset_moves_the_ramps_accelerometer_rows_as_the_twin_does(fitted):
    """The ramps' accelerometer rows at the fit's solution within chi2(rows)'s 99.9 % point (before:
    28,064 on 60, the offset 9.44 +- 0.16 ms; after: 50.7, 10.01 +- 0.17), and the offset within 4
    sigma of the twin's."""
    from station.estimate import lsq

    result = fitted
    rows = _ramp_accel_rows(result.model, result.x)
    assert len(rows) == 60
    assert np.sum(rows ** 2) < chi2.ppf(0.999, len(rows)), np.sum(rows ** 2)
    names, index, factors, _ = lsq._reported_index(result, "m/s^2", "deg/s")
    k = names.index("time_offset")
    value = float(result.x[index[k]]) * factors[k]
    sigma = float(np.sqrt(result.covariance[index[k], index[k]])) * factors[k]
    assert abs(value - OFFSET_MS) < 4.0 * sigma, (value, sigma)


def test_the_offsets_column_of_a_rate_scaled_to_the_encoder_is_the_residuals_derivative(quiet_ramps, fitted):
    """Where a rotation's rate shape is scaled to the encoder's mean rate (every turn but a recorded
    ramp's: rate_from_table False, here forced on the ramps), the time offset scales it by
    c = I / (I - dt dw): Model.jacobian (complex step) of the offset against central differences of
    the residual (tolerance as tests/test_jacobian_complex_step.py: 1e-6 of the column's norm plus
    the differences' rounding), and not zero on the accelerometer rows: 1 ms of offset moves them by
    more than their noise (16.9 against sqrt 60 = 7.7; before: 0, no rotation's accelerometer rows
    depended on the offset).  A recorded ramp's own rate (from the table's stated rate) does not
    move with it: its column there is 0."""
    from station.estimate import lsq

    ramps = {r.name for r in quiet_ramps.rotations if r.record_ramp}
    assert all(r.rate_from_table for r in quiet_ramps.rotations if r.name in ramps)
    x = fitted.x.copy()         # at the solution: a mounting offset (at the start's 0 no rate is seen)
    encoder = dataclasses.replace(quiet_ramps, rotations=[dataclasses.replace(r, rate_from_table=False)
                                                          for r in quiet_ramps.rotations])
    for s, moved in ((encoder, True), (quiet_ramps, False)):
        model = lsq.Model(s, [_untyped()])
        c = model.layout["effect:time_offset"].start
        J = model.jacobian(x)[:, c]
        assert model.complex_step
        h = 1e-4 * model._sizes(x)[c]
        xp, xm = x.copy(), x.copy()
        xp[c] += h
        xm[c] -= h
        central = (model.residuals(xp) - model.residuals(xm)) / (2 * h)
        size = np.maximum(np.abs(model.residuals(x)), 1.0)
        tolerance = 1e-6 * np.linalg.norm(central) + 4 * np.finfo(float).eps * size / h
        assert np.all(np.abs(J - central) <= tolerance), np.max(np.abs(J - central) / tolerance)
        accel = np.array([seg in ramps and q.startswith("accel") for seg, _, q, _ in model.row_labels(x)])
        if moved:   # 1 ms of offset moves those rows by more than their noise (whitened: 1 per row)
            assert np.linalg.norm(J[accel]) * 1e-3 > np.sqrt(accel.sum()), np.linalg.norm(J[accel]) * 1e-3
        else:
            assert np.all(J[accel] == 0.0)


def _pull(s, offset_s):
    """The fit with the time offset held at offset_s (its free part's prior 1e-6 ms): the data's
    Gauss-Newton step on the offset from there (ms; the other parameters' columns projected out of
    its column, the prior's row left out), and its 1-sigma."""
    from station.estimate import lsq, noise_groups
    from station.model.time_offset import TimeOffset

    class Held(TimeOffset):
        @property
        def params(self):
            return tuple(dataclasses.replace(p, typical=1e-6) for p in super().params)

        def integral(self, x, rotation):
            return super().integral(x + offset_s, rotation)

        def integral_batch(self, X, rotations):
            return super().integral_batch(X + offset_s, rotations)

        def window_shift_s(self, x):
            return x[0] + offset_s

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(noise_groups, "RAMP_MIN_DOF", float("inf"))
        result = lsq.fit(s, [Held()])
    model, c = result.model, result.model.layout["effect:time_offset"].start
    rows = np.array([q != "effect_prior" for _, _, q, _ in model.row_labels(result.x)])
    J, r = model.jacobian(result.x)[rows], model.residuals(result.x)[rows]
    others = np.delete(J, c, axis=1)
    j = J[:, c] - others @ np.linalg.lstsq(others, J[:, c], rcond=None)[0]
    return -(j @ r) / (j @ j) * 1e3, 1e3 / np.sqrt(j @ j)


def test_an_offset_the_model_holds_at_its_truth_leaves_the_datas_pull_as_without_one(quiet_ramps):
    """The same dry run (seed, noise draws) with the IMU 0 and 10 ms behind, each fitted with the
    offset held at its truth: the data's step on the offset from there is the noise's alone in both,
    the same to a tenth of its 1-sigma when the model takes the shift as the twin makes it.  Before:
    -0.571 ms between them (3.3 of its 1-sigma, 0.17 ms: the ramps' accelerometer rows); with the
    rates at c times the encoder's but the Earth's change taken at the phases 0 and A of part turns
    only, -0.071 ms; now +0.0002 ms."""
    step0, sigma = _pull(_quiet_ramps(0.0), 0.0)
    step10, _ = _pull(quiet_ramps, OFFSET_MS * 1e-3)
    assert abs(step10 - step0) < 0.1 * sigma, (step10, step0, sigma)


def test_the_per_segment_reference_takes_the_shift_as_the_vectorised_model(quiet_ramps, fitted):
    """tests/lsq_reference.PerSegmentModel (one segment at a time, written apart) and lsq.Model give
    the same residuals with a time offset on a capture of ramps (at the fit's solution and with the
    offset 30 ms further)."""
    from lsq_reference import PerSegmentModel
    from station.estimate import lsq
    from test_lsq_vectorised import cancelling_size

    effects = [_untyped()]
    model, ref = lsq.Model(quiet_ramps, effects), PerSegmentModel(quiet_ramps, effects)
    for extra in (0.0, 0.03):
        x = fitted.x.copy()
        x[model.layout["effect:time_offset"].start] += extra
        r, r_ref = model.residuals(x), ref.residuals(x)
        # tests/test_lsq_vectorised.check's bound, and the rounding of the whitened numbers that
        # cancel in a row (a gyro integral's datum and prediction: ~1e9 of their 1-sigma here)
        tolerance = (1e-9 * np.abs(r_ref) + 1e-9 * max(1.0, np.max(np.abs(r_ref)))
                     + 16 * np.finfo(float).eps * cancelling_size(ref, x, r_ref))
        assert np.all(np.abs(r - r_ref) <= tolerance), (extra, np.max(np.abs(r - r_ref) / tolerance))
