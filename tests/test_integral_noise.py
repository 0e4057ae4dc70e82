"""The 1-sigma the estimator states for a rotation's gyro integral, checked from both sides against
the device twins' physics (issue 29: "noise overestimated" on short twin captures).

The twins (sim_devices/twins: the table twin's motion profile, the IMU twin's sample clock
t_k = k / rate and its white noise by density) record a small capture in this process, as the
bench does at 50 Hz: six statics (the poses of tests/test_multi_imu.py) and +/- rotations of one
revolution at 180 deg/s (100 samples, 2 s) about the three case axes.  The estimator reads it
as any capture (station.io.capture, summaries, lsq.Model) and states each integral's covariance
(lsq.Model.gyro_whiten: the white noise sigma^2 T / rate, the bias instability (B T)^2, the table
angle error along the axis).

The reference shares no code with the product: the true integral over each rotation's window
[t_0 - dt/2, t_{N-1} + dt/2] is the noise-free twin output (sim_devices' Truth.measure with the
noise densities set to 0, at the table twin's kinematics) integrated by scipy's Simpson rule on a
grid 40 times finer than the samples, and the angle the table truly turned over the window is the
table twin's own position at the window's ends.  Each integral's error is then

    e = I_measured - I_true - M_g a (A_recorded - A_true)      (deg, per gyro axis)

(M_g the twin's gyro matrix, a the rotation's case axis: what a wrong recorded angle does to the
fit's comparison), and z = W e with W the estimator's whitening of that integral.  Under an honest
1-sigma each z is N(0, 1); the along-axis and the across-axis components are tested apart (the
table angle error is stated along the axis only), each sum of squares against chi2 with as many
degrees of freedom as components: inside [0.1 %, 99.9 %] points.  A 1-sigma too large fails the
lower bound as one too small fails the upper: checked on the same errors with the sigma stated
2x and 0.5x (and with the station.yaml default table angle error, 2 arcsec, which is 40 times what
the twin's table does along the axis: see test_a_stated_table_error_the_twin_has_not_is_found).

Sizes: R rotations give R along-axis and 2R across-axis components; for a sigma wrong by a factor
c the expected chi2 is n / c^2.  With n = 24 along the axis, chi2(24)'s 0.1 % and 99.9 % points are
8.1 and 51.2: a sigma 2x too large puts the expected sum at 6.0 (below 8.1), 2x too small at 96
(above 51.2); across the axis (n = 48: 22.4 and 86.7) the same factors give 12 and 192.  Sampling
alone fails an honest check with probability 0.2 % per group.  The capture: 6 x 2 s statics and
24 x 2 s rotations at 50 Hz, about 2 s of CPU in all.

The same rotations' accelerometer harmonics (mean, first and second harmonic: the rows that held
81 % of the misfit of the resumed multi-IMU capture of issue 29 that failed at reduced chi2 1.504)
are checked the same way against the noise-free twin output on the angle the table truly turned
(test_the_rotations_accelerometer_harmonics_scatter_as_the_estimator_states): 360 components,
both sides; an accelerometer sampled 50 us off its stamps (0.009 deg at 180 deg/s) fails it.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy import integrate, stats

from sim_devices import world
from sim_devices.truth import default_truth
from sim_devices.twins.clock import ManualClock
from sim_devices.twins.geometry import TableGeometry
from sim_devices.twins.imu import ImuTwin
from sim_devices.twins.table import TableTwin
from station.estimate import lsq
from station.estimate.summaries import summarise
from station.io.capture import CaptureWriter, ImuInfo, Site, read_capture

RATE_HZ = 50.0
SAMPLES = 100                   # one revolution at 180 deg/s
TABLE_RATE = 180.0
REPEATS = 4                     # each +/- pair about each case axis: 3 x 2 x 4 = 24 rotations
FINE = 40                       # reference grid points per sample interval
P_BOUND = 1e-3
# the poses and rotations of tests/test_multi_imu.py's tiny12 on the twins' 3-axis table (the
# table's angles as station's compiler gives them: table axes ENU z, x, y, outer first)
POSES = [("pos01", [1, 0, 0], [0.0, 0.0, 270.0]), ("pos02", [-1, 0, 0], [0.0, 0.0, 90.0]),
         ("pos03", [0, 1, 0], [0.0, 90.0, 90.0]), ("pos04", [0, -1, 0], [0.0, 270.0, 90.0]),
         ("pos05", [0, 0, 1], [0.0, 0.0, 0.0]), ("pos06", [0, 0, -1], [0.0, 0.0, 180.0])]
TURNS = [("rotx", [1, 0, 0], 2, [0.0, 0.0, 180.0]), ("roty", [0, 1, 0], 3, [0.0, 0.0, 180.0]),
         ("rotz", [0, 0, 1], 2, [0.0, 0.0, 90.0])]
SETTLE_S = 8.0                  # after a move: the twin's overshoot decays as exp(-5 t) (1e-17)
SPIN_S = 3.0                    # 180 deg/s at the twin's 100 deg/s^2: 1.8 s


def _truth():
    truth = default_truth(29)
    truth.temperature.warmup_delta_c = 0.0      # one temperature: the estimator's base model
    truth.temperature.drift_c_per_h = 0.0
    return dataclasses.replace(truth, sample_rate_hz=RATE_HZ)


def _quiet(truth):
    """The same sensor without noise (sim_devices' own forward model: the reference)."""
    return dataclasses.replace(truth, gyro=dataclasses.replace(truth.gyro, noise_density=0.0),
                               accel=dataclasses.replace(truth.accel, noise_density=0.0))


class TwinBench:
    """The table and IMU twins on a manual clock (no pseudo-terminal: the physics only)."""

    def __init__(self, truth, seed: int):
        self.clock = ManualClock(0.0)
        self.table = TableTwin(TableGeometry.default(3, truth.bench.lever_arm_m), self.clock,
                               interlocks_closed=True)
        self.imu = ImuTwin(self.table, truth, seed=seed)
        self.truth, self.quiet = truth, _quiet(truth)

    def move(self, table_deg):
        for axis, deg in enumerate(table_deg, start=1):
            self.table.set_mode(axis, "position")
            self.table.demand_position(axis, deg)
        self.clock.advance(SETTLE_S)

    def samples(self, n):
        k0 = int(np.floor(self.clock.now() * RATE_HZ)) + 1
        t = (k0 + np.arange(n)) / RATE_HZ
        accel, gyro, temp = self.imu.measure(t)
        self.clock.t = float(t[-1])
        return t, accel, gyro, temp

    def true_output(self, t, accel: bool = False):
        """The noise-free gyro output (deg/s) at times t: the table twin's kinematics through
        the twin's sensor model (``accel``: the accelerometer's, m/s^2)."""
        C_bn, w_b, wd_b = self.table.kinematics_at(t)
        f_b, w_ib = world.body_kinematics(C_bn, w_b, wd_b, self.imu.lever_arm_m, self.imu.site)
        acc, gyro = self.quiet.measure(f_b, np.degrees(w_ib), np.full(len(t), self.truth.temperature.reference_c),
                                       None, w_eb_b=w_b, wdot_eb_b=wd_b, t=t)
        return acc if accel else gyro


@pytest.fixture(scope="module")
def errors(tmp_path_factory):
    """(the gyro integrals' errors e, the rotations' axes, the model, the summaries, the
    accelerometer harmonics' errors (R, 5, 3)) of every rotation of a twin capture, the capture
    stating the twin's own table error."""
    truth = _truth()
    bench = TwinBench(truth, seed=29)
    path = tmp_path_factory.mktemp("integral") / "capture"
    # what the twin's table turns wrong over a window: nothing (its rate is exactly the 180 deg/s
    # demanded, a whole number of its readback's 1e-5 deg/s steps, so the recorded angle, the
    # readback x the window, is the angle turned): stated as such
    stated_arcsec = 0.0
    writer = CaptureWriter(path, ImuInfo(RATE_HZ, "m/s^2", "deg/s", model="twin", serial="29"),
                           Site(world.local_gravity(truth.bench.latitude_deg, truth.bench.height_m),
                                truth.bench.latitude_deg), "integral-honesty",
                           extra={"table": {"angle_error_arcsec": float(stated_arcsec),
                                            "geometry": {"axes_intersect": True}}})
    for name, up, table_deg in POSES:
        bench.move(table_deg)
        t, a, g, c = bench.samples(SAMPLES)
        with writer.begin_segment(name, "static", up_body=up, table_deg=table_deg) as out:
            out.write(t, a, g, c)
            out.close("complete")
    truths, harmonics = [], []
    for repeat in range(REPEATS):
        for name, axis_body, table_axis, table_deg in TURNS:
            for sign, suffix in ((1, "p"), (-1, "m")):
                bench.move(table_deg)
                bench.table.set_mode(table_axis, "rate")
                bench.table.demand_rate(table_axis, sign * TABLE_RATE)
                bench.clock.advance(SPIN_S + 0.013 * repeat)      # other start phases
                t, a, g, c = bench.samples(SAMPLES)
                window = (t[0] - 0.5 / RATE_HZ, t[-1] + 0.5 / RATE_HZ)
                # the body axis it turns about, and the angle the bench records (the table's
                # rate read back x the frames' window: station/bench/sequencer.py)
                w_mid = bench.table.kinematics_at(np.array([t[SAMPLES // 2]]))[1][0]
                along = float(np.dot(w_mid, axis_body)) / np.linalg.norm(w_mid)
                recorded = np.sign(along) * abs(bench.table.read_rate(table_axis)) * (window[1] - window[0])
                theta = bench.table.axis_states(np.array(window))[0][:, table_axis - 1]
                true_angle = np.sign(along) * abs(theta[1] - theta[0])
                fine = np.linspace(*window, SAMPLES * FINE + 1)
                reference = integrate.simpson(bench.true_output(fine), x=fine, axis=0)
                with writer.begin_segment(f"{name}{repeat}_{suffix}", "rotation", axis_body=axis_body,
                                          rate_dps=sign * TABLE_RATE, table_axis=table_axis) as out:
                    out.write(t, a, g, c)
                    out.close("complete", angle_deg=float(recorded))
                truths.append((reference, recorded - true_angle, np.asarray(axis_body, float)))
                harmonics.append(_true_harmonics(bench, t, window, table_axis, along, a))
                bench.table.demand_rate(table_axis, 0.0)
                bench.clock.advance(SPIN_S)
    s = summarise(read_capture(path))
    model = lsq.Model(s, [])
    e, axes = [], []
    for r, (reference, angle_error, axis) in zip(s.rotations, truths):
        e.append(r.gyro_integral - reference - truth.gyro.matrix @ axis * angle_error)
        axes.append(axis)
    measured = np.array([[r.accel_dc, r.accel_cos, r.accel_sin, r.accel_cos2, r.accel_sin2] for r in s.rotations])
    return np.array(e), np.array(axes), model, s, measured - np.array(harmonics)


def _true_harmonics(bench, t, window, table_axis, along, accel):
    """The reference for a rotation's accelerometer harmonics (numpy only): the noise-free twin
    output at the samples' times projected by least squares on 1, cos, sin, cos 2, sin 2 of the
    angle the body truly turned about its axis since the window's start (the table twin's own
    positions), (5, 3) in m/s^2."""
    theta = bench.table.axis_states(np.concatenate([[window[0]], t]))[0][:, table_axis - 1]
    phase = np.sign(along) * np.radians(np.abs(theta[1:] - theta[0]))
    basis = np.column_stack([np.ones_like(phase), np.cos(phase), np.sin(phase), np.cos(2 * phase), np.sin(2 * phase)])
    return np.linalg.lstsq(basis, bench.true_output(t, accel=True), rcond=None)[0]


def _z(e, axes, covariances):
    """Whitened along-axis and across-axis components of the errors under the given covariances."""
    along, across = [], []
    for err, a, cov in zip(e, axes, covariances):
        u = np.linalg.svd(a[None, :])[2][1:]            # two unit vectors across the axis
        along.append(a @ err / np.sqrt(a @ cov @ a))
        for v in u:
            across.append(v @ err / np.sqrt(v @ cov @ v))
    return np.array(along), np.array(across)


def _stated(model):
    """The estimator's covariance of every integral (the inverse of its whitening's square)."""
    return [np.linalg.inv(W.T @ W) for W in model.gyro_whiten]


def _inside(z) -> tuple[bool, float, float, float]:
    n = len(z)
    lo, hi = stats.chi2.ppf(P_BOUND, n), stats.chi2.ppf(1.0 - P_BOUND, n)
    chi2 = float(z @ z)
    return lo <= chi2 <= hi, chi2, lo, hi


def test_the_stated_sigma_of_a_gyro_integral_is_what_the_twins_scatter(errors):
    e, axes, model, s, _ = errors
    assert len(e) == 6 * REPEATS and not model.s.skipped
    along, across = _z(e, axes, _stated(model))
    for what, z in (("along the axis", along), ("across the axis", across)):
        ok, chi2, lo, hi = _inside(z)
        assert ok, f"{what}: chi2 {chi2:.1f} of {len(z)} outside [{lo:.1f}, {hi:.1f}]"


@pytest.mark.parametrize("factor", [2.0, 0.5])
def test_a_sigma_too_large_fails_like_one_too_small(errors, factor):
    """The same errors against the stated covariance scaled by factor^2: both components fail."""
    e, axes, model, _, _ = errors
    along, across = _z(e, axes, [cov * factor**2 for cov in _stated(model)])
    for what, z in (("along", along), ("across", across)):
        ok, chi2, lo, hi = _inside(z)
        assert not ok, f"{what}: chi2 {chi2:.1f} inside [{lo:.1f}, {hi:.1f}] with the sigma x{factor}"
        assert (chi2 < lo) == (factor > 1.0)


def test_a_stated_table_error_the_twin_has_not_is_found(errors):
    """The station.yaml default, table angle error 2 arcsec (a bench run writes it into the
    capture), against the twin's table, which turns the angle its rate readback says: along the
    axis the integral's 1-sigma is then 2.0005 arcsec where the twin scatters 0.045 arcsec (the
    white noise, sigma sqrt(T / rate)): too large by 40x, found; across the axis nothing changes."""
    e, axes, model, s, _ = errors
    s2 = dataclasses.replace(s, table_angle_sigma_deg=2.0 / 3600.0, noise_model=None)
    along, across = _z(e, axes, _stated(lsq.Model(s2, [])))
    ok, chi2, lo, _ = _inside(along)
    assert not ok and chi2 < lo
    assert _inside(across)[0]


def _harmonic_z(model, errors):
    """The accelerometer harmonics' errors (R, 5, 3) whitened as the fit whitens its rows
    (lsq.Model: the arc's Gram matrix's square root, times sqrt(samples) / sigma per axis)."""
    return np.einsum("rij,rjc->ric", model._rot_whiten, errors) * model._rot_weight


def test_the_rotations_accelerometer_harmonics_scatter_as_the_estimator_states(errors):
    """Issue 29 (a resumed twin capture failed at reduced chi2 1.504, 81 % of its misfit in the
    rotations' accelerometer harmonics; said earlier: "the twins' short steady turns' harmonics
    scatter 1.08-1.29 x their noise").  Each rotation's mean, first and second harmonics of the
    accelerometer, as the estimator summarises them, less the reference (_true_harmonics: the
    noise-free twin output on the angle the table twin truly turned), whitened by the covariance
    the estimator states for them (sigma^2 / samples x the Gram matrix's inverse, sigma from the
    statics' first differences): 24 rotations x 5 coefficients x 3 axes = 360 components, N(0, 1)
    each under an honest 1-sigma.  chi2(360)'s 0.1 % and 99.9 % points are 276 and 453; a sigma
    2x too large puts the sum at 90, 2x too small at 1,440: both fail, checked on the same errors.
    The first harmonic alone (144: where the failing capture had 46 % of its misfit) as well."""
    _, _, model, _, harmonic_errors = errors
    z = _harmonic_z(model, harmonic_errors)
    assert z.shape == (6 * REPEATS, 5, 3)
    for what, part in (("all coefficients", z), ("first harmonic", z[:, 1:3])):
        ok, chi2, lo, hi = _inside(part.ravel())
        assert ok, f"{what}: chi2 {chi2:.1f} of {part.size} outside [{lo:.1f}, {hi:.1f}]"
    for factor in (2.0, 0.5):
        ok, chi2, lo, hi = _inside(z.ravel() / factor)
        assert not ok and (chi2 < lo) == (factor > 1.0), (factor, chi2, lo, hi)


# ---------------------------------------------------------------------------------------------
# The twin's table with an angle error (issue 29, item 2): station.yaml's table.angle_error_arcsec
# given to the twin (TableConfig.angle_error_arcsec; `station sim serve` takes the truth's
# bench.table_angle_error_arcsec), the capture stating the same figure.
#
# The twin's encoder errs by e(p), a sum of harmonics 1..16 of the axis angle with coefficients
# c_h, d_h ~ N(0, sigma^2 / 32) (sim_devices/twins/table.py, EncoderError: rms sigma / sqrt 2); the
# bench records readback rate x window, while the axis truly turns that less e(end) - e(start).  Over
# a half turn only the odd harmonics are left: D(p) = e(p + 180) - e(p) = -2 sum_{h odd} (c_h cos hp
# + d_h sin hp).  At N = 32 start angles 11.25 deg apart (the odd harmonics 1..15 below the lattice's
# Nyquist harmonic 16: orthogonal, no aliasing) sum_j D_j^2 = 2 N sum_{h odd} (c_h^2 + d_h^2) =
# 2 sigma^2 chi2(16): each D_j^2 is sigma^2 on average (the 1-sigma the capture states), and the
# sum of the 32 squares over sigma^2, halved, is chi2(16) exactly for one table (its 16 random
# coefficients are all a table axis has: more windows add no degrees of freedom).  One continuous
# spin per table axis at 56.25 deg/s (1.125 deg a sample at 50 Hz) cut into windows of 160 samples
# (180 deg) 170 samples apart (191.25 deg = 17 x 11.25: 17 j mod 32 visits all 32 start angles).
# Slowly: the encoder's error makes the rate ripple at up to 16 x the turn rate, 2.5 Hz here, which
# the IMU's samples (every 20 ms) integrate to within 1 %; at 281 deg/s (12.5 Hz) the sampled
# integral missed a part of the ripple's angle comparable with the error itself.
# Two table axes: half the sum of the 64 along-axis z^2 is chi2(32) under an honest 1-sigma (the
# white noise, 0.03 arcsec, is 2e-4 of the variance); chi2(32)'s 0.1 % and 99.9 % points are 13.2
# and 62.5: a sigma 2x too large puts the expected value at 8, 2x too small at 128.  (Whole turns
# cancel the encoder's error, as on a real table: the first capture's whole-turn windows see none.)
# Checked on 4,000 simulated tables (the encoder model alone): half the sum per axis has mean 16.2,
# variance 33.9 (chi2(16): 16, 32).

ANGLE_ARCSEC = 2.0
HALF_RATE = 56.25                # deg/s: 1.125 deg a sample at 50 Hz
HALF_SAMPLES, GAP = 160, 10      # 180 deg windows; 170 samples = 191.25 deg from start to start
HALF_FINE = 8                    # reference grid points per sample (the encoder's ripple is below 2.5 Hz)
WINDOWS = 32
STATIC_ROUNDS = 4                # 24 statics of 2 s: 72 static gyro means
SPINS = [("hx", [1, 0, 0], 2, [0.0, 0.0, 180.0], 2), ("hy", [0, 1, 0], 3, [0.0, 0.0, 180.0], 3)]


@pytest.fixture(scope="module")
def angle_errors(tmp_path_factory):
    """(errors e, axes, model, recorded angle errors) of 64 half-turn windows on a twin table with
    a 2 arcsec angle error, the capture stating 2 arcsec."""
    return angle_capture(tmp_path_factory.mktemp("angle") / "capture", seed=30)


def angle_capture(path, seed: int):
    from sim_devices.twins.table import TableConfig

    truth = _truth()
    bench = TwinBench(truth, seed=seed)
    bench.table = TableTwin(TableGeometry.default(3, truth.bench.lever_arm_m), bench.clock,
                            config=TableConfig(angle_error_arcsec=ANGLE_ARCSEC),
                            rng=np.random.default_rng(seed), interlocks_closed=True)
    bench.imu = ImuTwin(bench.table, truth, seed=seed)
    writer = CaptureWriter(path, ImuInfo(RATE_HZ, "m/s^2", "deg/s", model="twin", serial=str(seed)),
                           Site(world.local_gravity(truth.bench.latitude_deg, truth.bench.height_m),
                                truth.bench.latitude_deg), "angle-error-honesty",
                           extra={"table": {"angle_error_arcsec": ANGLE_ARCSEC,
                                            "geometry": {"axes_intersect": True}}})
    static_errors = []
    for rnd in range(STATIC_ROUNDS):
        for name, up, table_deg in POSES:
            bench.move(table_deg)
            t, a, g, c = bench.samples(SAMPLES)
            # the reference: the noise-free twin output at the table's true attitude and motion
            static_errors.append(g.mean(axis=0) - bench.true_output(t).mean(axis=0))
            with writer.begin_segment(f"{name}r{rnd}", "static", up_body=up, table_deg=table_deg) as out:
                out.write(t, a, g, c)
                out.close("complete")
    truths = []
    for name, axis_body, table_axis, table_deg, _ in SPINS:
        bench.move(table_deg)
        bench.table.set_mode(table_axis, "rate")
        bench.table.demand_rate(table_axis, HALF_RATE)
        bench.clock.advance(SPIN_S)
        k = int(np.floor(bench.clock.now() * RATE_HZ)) + 1
        for j in range(WINDOWS):
            k += GAP                                            # between the windows: not recorded
            t = (k + np.arange(HALF_SAMPLES)) / RATE_HZ         # sample indices kept whole: the
            a, g, c = bench.imu.measure(t)                      # windows exactly on the lattice
            bench.clock.t = float(t[-1])
            k += HALF_SAMPLES
            window = (t[0] - 0.5 / RATE_HZ, t[-1] + 0.5 / RATE_HZ)
            w_mid = bench.table.kinematics_at(np.array([t[HALF_SAMPLES // 2]]))[1][0]
            along = float(np.dot(w_mid, axis_body)) / np.linalg.norm(w_mid)
            recorded = np.sign(along) * abs(bench.table.read_rate(table_axis)) * (window[1] - window[0])
            theta = bench.table.axis_states(np.array(window))[0][:, table_axis - 1]
            true_angle = np.sign(along) * abs(theta[1] - theta[0])
            fine = np.linspace(*window, HALF_SAMPLES * HALF_FINE + 1)
            reference = integrate.simpson(bench.true_output(fine), x=fine, axis=0)
            with writer.begin_segment(f"{name}{j:02d}", "rotation", axis_body=axis_body,
                                      rate_dps=HALF_RATE, table_axis=table_axis) as out:
                out.write(t, a, g, c)
                out.close("complete", angle_deg=float(recorded))
            truths.append((reference, recorded - true_angle, np.asarray(axis_body, float)))
        bench.table.demand_rate(table_axis, 0.0)
        bench.clock.advance(SPIN_S)
    s = summarise(read_capture(path))
    model = lsq.Model(s, [])
    e = [r.gyro_integral - reference - truth.gyro.matrix @ axis * angle_error
         for r, (reference, angle_error, axis) in zip(s.rotations, truths)]
    return (np.array(e), np.array([x[2] for x in truths]), model, np.array([x[1] for x in truths]),
            np.array(static_errors))


def test_the_twin_table_errs_by_its_configured_angle_error_and_the_stated_sigma_holds(angle_errors):
    e, axes, model, angle_errors_deg, _ = angle_errors
    assert len(e) == 2 * WINDOWS and not model.s.skipped
    # the recorded angles err (the encoder's error over half a turn): not the exact twin of before
    assert np.sqrt(np.mean(angle_errors_deg**2)) * 3600.0 > 0.5
    along, across = _z(e, axes, _stated(model))
    ok, half, lo, hi = _half_inside(along)
    assert ok, f"along the axis: half the chi2 {half:.1f} outside chi2(32)'s [{lo:.1f}, {hi:.1f}]"
    assert _inside(across)[0]           # across the axis: white noise only, independent per window
    for factor in (2.0, 0.5):                     # a sigma too large fails as one too small
        s2 = dataclasses.replace(model.s, table_angle_sigma_deg=factor * ANGLE_ARCSEC / 3600.0, noise_model=None)
        ok, half, lo, hi = _half_inside(_z(e, axes, _stated(lsq.Model(s2, [])))[0])
        assert not ok and (half < lo) == (factor > 1.0), (factor, half, lo, hi)


def _half_inside(z):
    """Half the sum of squares against chi2(32) (2 table axes x 16 coefficients: above)."""
    dof = len(SPINS) * EncoderErrorDof
    lo, hi = stats.chi2.ppf(P_BOUND, dof), stats.chi2.ppf(1.0 - P_BOUND, dof)
    half = float(z @ z) / 2.0
    return lo <= half <= hi, half, lo, hi


EncoderErrorDof = 16             # the odd harmonics' coefficients of one axis's encoder error


def test_the_twins_static_gyro_means_scatter_as_the_estimator_states(angle_errors):
    """Issue 29, item 1 (static gyro means said to scatter 1.5-1.9x their white noise on short
    twin captures).  Each static's mean gyro output less the noise-free twin output at the table's
    true attitude (Truth.measure without noise: bias, Earth rate at the attitude the table truly
    holds, the encoder's error included, any residual motion of the table) over the same samples,
    divided by the 1-sigma the estimator states for that mean (lsq.Model's pose weight: the white
    noise from the statics' first differences over root n, and the noise model's per-pose terms):
    N(0, 1) each under an honest 1-sigma.  72 of them (24 statics x 3 axes): chi2(72)'s 0.1 % and
    99.9 % points are 40.4 and 113.2; a sigma 2x too large puts the expected sum at 18, 2x too
    small at 288: both fail, checked on the same errors."""
    _, _, model, _, static_errors = angle_errors
    stated = 1.0 / model._st_weight[:, 3:]                    # deg/s, each static's gyro mean
    assert static_errors.shape == stated.shape == (6 * STATIC_ROUNDS, 3)
    z = (static_errors / stated).ravel()
    ok, chi2, lo, hi = _inside(z)
    assert ok, f"static gyro means: chi2 {chi2:.1f} of {len(z)} outside [{lo:.1f}, {hi:.1f}]"
    for factor in (2.0, 0.5):
        ok, chi2, lo, hi = _inside(z / factor)
        assert not ok and (chi2 < lo) == (factor > 1.0), (factor, chi2, lo, hi)
