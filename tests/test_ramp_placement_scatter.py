"""Issue 28 (eighteenth session): the recorded ramps' angle 1-sigma from their own scatter.

A recorded ramp's angle carries the placement of the table's reads on the IMU's clock; the bench
states it per window (angle_sigma_deg: w / sqrt 12 per read, not divided by the reads,
station/bench/ramp_angle.py), deliberately conservative: on the twins the windows' errors were
0.22-0.5 of it in rms, and the time offset the ramps inform came out with a 1-sigma 2-4x its
scatter.  The estimator now takes the windows' variance as the gyro's known noise plus k^2 times
the stated placement variance and estimates k from their residuals (lsq._ramp_reweight), where
their degrees of freedom are enough to say (noise_groups.RAMP_MIN_DOF).

The reference shares no code with the estimator: a host written here places each read's answer
in its bracket (two Gamma(2) waits each side of the table's answer, of a scale that changes
from window to window, IMU stamps on a 10 ms grid), the bench's own ramp_angle places the reads
and states the 1-sigma as it does on a bench, and the windows' true timing errors are known.  The
capture is the dry run's (station/simulate/dryrun.py: the IMU's clock 5 ms behind the table's,
the encoder exact): only the ramps' angles and their stated 1-sigma are the host's."""
import copy

import numpy as np
import pytest
from scipy.stats import chi2

from station.bench import ramp_angle

OFFSET_MS = 5.0
PERIOD_S = 0.01          # the dry run's 100 Hz
READS = 6                # reads at the rate per window

STATICS = [[0, 0, 1], [0, 0, -1], [1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0]]
AXES = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]


def _scheme(ramp_axes=AXES, repeats=2):
    """Six faces, a steady pair about each axis (the gyro scale factors), and ``repeats`` times a
    ramp up and a brake pair about each of ``ramp_axes``: 24 recorded ramps."""
    from station.io.scheme import scheme_from_text

    text = "name: many-ramps\ndefaults: {dwell_s: 1, rate_dps: 100, rotation_s: 3.6}\nsegments:\n"
    text += "".join(f"  - {{static: s{i}, up_body: {u}}}\n" for i, u in enumerate(STATICS))
    text += "".join(f"  - {{rotation: st{i}, axis_body: {a}}}\n" for i, a in enumerate(AXES))
    for rep in range(repeats):
        for i, a in enumerate(ramp_axes):
            text += (f"  - {{rotation: up{i}r{rep}, axis_body: {a}, record_ramp: start}}\n"
                     f"  - {{rotation: dn{i}r{rep}, axis_body: {a}, record_ramp: end}}\n")
    return scheme_from_text(text, "many-ramps.yaml")


@pytest.fixture(scope="module")
def base():
    from sim_devices.truth import default_truth
    from station.simulate import dryrun

    truth = default_truth(1)
    truth.bench.time_offset_s = OFFSET_MS * 1e-3
    return dryrun.simulate_capture(_scheme(), truth, 3)


def _host_window(rng, rate, late_s, slow=1.0):
    """One window's reads at the rate on a host: each query at its moment q, the table's answer
    w1 later, back at the computer w2 after that (w1, w2 ~ Gamma(2, scale), the scale the host's
    load during this window); the bracket's ends are the newest IMU stamps before the query and
    after the answer's return.  ``late_s``: every answer's moment that much later than its
    bracket says (an IMU behind a USB adapter's latency timer: its frames reach the computer up
    to 16 ms after their stamps).  ``slow``: the waits' scales times this (a busier host).  (the position error at the window's turning edge, deg; the
    true timing error, s; the bench's stated 1-sigma, deg)."""
    scale = slow * rng.uniform(0.002, 0.015)
    q = np.cumsum(rng.uniform(0.05, 0.15, READS))
    w1, w2 = rng.gamma(2.0, scale, READS), rng.gamma(2.0, scale, READS)
    answer = q + w1
    before = np.floor(q / PERIOD_S) * PERIOD_S
    after = np.floor((answer + w2) / PERIOD_S) * PERIOD_S
    moment = answer + late_s
    marks = [ramp_angle.Mark(position_deg=float(rate * t), rate_dps=rate, t_before=float(b), t_after=float(a))
             for t, b, a in zip(moment, before, after)]
    edge = q[-1] + 0.3
    error = ramp_angle.position_at(marks, edge, rate, PERIOD_S) - rate * edge
    return error, error / rate, ramp_angle.angle_sigma(marks, rate, PERIOD_S)


def _placed(base, seed, late_s=0.0, keep=None, slow=1.0):
    """The capture with every ramp window's angle placed by the host (its error added, its
    stated 1-sigma written as a bench writes it); (capture, {name: (timing error s, stated 1-sigma
    in s)}).  ``keep``: the ramp windows kept (None: all)."""
    capture = copy.deepcopy(base)
    rng = np.random.default_rng(seed)
    if keep is not None:
        capture.segments = [s for s in capture.segments if not s.extra.get("record_ramp") or s.name in keep]
    truth = {}
    for seg in capture.segments:
        kind = seg.extra.get("record_ramp")
        if kind:
            rate = seg.extra["rate_end_dps" if kind == "start" else "rate_start_dps"]
            error, tau, sigma = _host_window(rng, rate, late_s, slow)
            seg.angle_deg += error if kind == "start" else -error      # the turning edge ends or starts it
            seg.extra["angle_sigma_deg"] = sigma
            truth[seg.name] = (tau, sigma / abs(rate))
    return capture, truth


def _fit(capture, effect=None):
    from station.estimate import lsq
    from station.estimate.summaries import summarise
    from station.model.time_offset import TimeOffset

    result = lsq.fit(summarise(capture), [effect or TimeOffset()])
    names, index, factors, _ = lsq._reported_index(result, "m/s^2", "deg/s")
    k = names.index("time_offset")
    value = float(result.x[index[k]]) * factors[k]
    sigma = float(np.sqrt(result.covariance[index[k], index[k]])) * factors[k]
    return result, value, sigma


def _window_z(truth, k):
    """The windows' timing errors about their common part (what the time offset takes: their
    mean weighted by the stated 1-sigma) over their 1-sigma k times the stated one: rms."""
    tau, sigma = np.array(list(truth.values())).T
    w = 1.0 / sigma ** 2
    common = float(np.sum(w * tau) / np.sum(w))
    return float(np.sqrt(np.mean(((tau - common) / (k * sigma)) ** 2))), common


def _bounds(n):
    """rms z's 0.1 % and 99.9 % points for n windows less their common part (chi2(n - 1))."""
    return tuple(np.sqrt(chi2.ppf([0.001, 0.999], n - 1) / (n - 1)))


def test_many_ramp_windows_take_their_placement_1sigma_from_their_scatter(base):
    """24 windows: the estimated factor k puts the windows' true errors at rms z within chi2's
    0.1-99.9 % points (0.62-1.46 for 23); the stated 1-sigma alone (k = 1, before) gives ~0.25,
    below them (the test fails without the estimate), and a k half or twice the right one would
    fail too.  The 5 ms time offset is recovered within 4 of its 1-sigma and revealed (before: its
    1-sigma ~1.2 ms, 3-4x its scatter; benchmarks/ramp_placement_scatter.py for the Monte Carlo),
    the group is named and left out of the verdict's test (its noise is estimated).  The offset
    is given a typical size of 1 ms here, between its 1-sigma at the stated placement (~1.2 ms:
    held by its prior, not revealed) and at the estimated one (~0.6 ms): the fit must release it
    once k is estimated and say so (lsq._revealed_by_ramps)."""
    import dataclasses

    from station.estimate import lsq
    from station.model.time_offset import TimeOffset

    class TightOffset(TimeOffset):
        @property
        def params(self):
            return tuple(dataclasses.replace(p, typical=1.0) for p in super().params)

    capture, truth = _placed(base, 100)
    result, value, sigma = _fit(capture, TightOffset())
    est = result.model.ramp_estimate
    low, high = _bounds(len(truth))
    stated, _ = _window_z(truth, 1.0)
    assert stated < low, stated         # the host's stated 1-sigma is conservative: k = 1 fails
    assert est["estimated"] and est["windows"] == 24 and est["dof"] >= 10.0, est
    rms, _ = _window_z(truth, est["k"])
    assert low < rms < high, (rms, est)
    assert abs(value - OFFSET_MS) < 4.0 * sigma and "time_offset" not in result.model.unobservable, (value, sigma)
    assert "ramp gyro" in lsq.verdict_test(result)["left_out"]
    cal = lsq.to_calibration(result, "m/s^2", "deg/s")
    group = next(g for g in cal.fit["noise_groups"] if g["group"] == "ramp gyro")
    assert group["placement_k"] == pytest.approx(est["k"]) and group["placement_estimated"]
    assert any(n.startswith("the 24 recorded ramps scatter") for n in cal.fit["notes"]), cal.fit["notes"]
    assert any(n.startswith("revealed once the recorded ramps' placement") and n.endswith("time_offset")
               for n in cal.fit["notes"]), cal.fit["notes"]


def test_reads_all_late_by_16_ms_go_to_the_time_offset_and_the_windows_stay_honest(base):
    """The review's first host: every read's moment 16 ms after where its bracket places it.
    The common part is the time offset's to take: the fitted offset moves from the IMU's 5 ms
    toward 5 - 16 = -11 ms (the rotations' accelerometer rows, which see the IMU's own 5 ms, pull
    it back by their weight: -8 to -10 ms measured), and the windows' scatter about it is
    not overconfident: their true errors about their common part over k times the stated
    1-sigma within chi2's 0.1-99.9 % points (before the review's fix of the placement was taken
    back, 45 of 100 such windows were refused and the rest off by up to 1000 of their 1-sigma)."""
    capture, truth = _placed(base, 200, late_s=0.016)
    result, value, sigma = _fit(capture)
    est = result.model.ramp_estimate
    rms, common = _window_z(truth, est["k"])
    assert common == pytest.approx(0.016, abs=0.004)
    low, high = _bounds(len(truth))
    assert est["estimated"] and low < rms < high, (rms, est)
    assert -11.0 - 4.0 * sigma < value < OFFSET_MS - 0.5 * 16.0, (value, sigma)


def test_few_ramp_windows_keep_their_stated_1sigma(base):
    """Four windows (a ramp up and a brake pair about z, as the twins' capture): k's degrees of
    freedom are too few to say, so the stated (conservative) 1-sigma is kept, the file says so
    and the group is tested against it like any other."""
    from station.estimate import lsq

    capture, truth = _placed(base, 300, keep={"up2r0_p", "up2r0_m", "dn2r0_p", "dn2r0_m"})
    assert len(truth) == 4
    result, _, _ = _fit(capture)
    est = result.model.ramp_estimate
    assert not est["estimated"] and est["k"] == 1.0 and est["dof"] < 10.0 and result.model.ramp_k2 == 1.0, est
    assert "ramp gyro" not in lsq.verdict_test(result)["left_out"]
    assert any(n.startswith("the 4 recorded ramps' angles keep their stated placement 1-sigma")
               for n in result.model.notes), result.model.notes


def test_windows_scattering_beyond_their_stated_placement_are_not_absorbed_into_it(base):
    """The other side: the stated placement already puts every read anywhere in its bracket, so
    windows scattering beyond it are not the placement's doing (an encoder angle off, a table
    that slipped, a missing effect) and must not be absorbed by a k above 1: the stated 1-sigma
    is kept, the group stays in the verdict's test, which names it, and the note says why.  Here
    the bench understated its placement ten times (each window's stated 1-sigma a tenth of the
    host's): the windows scatter ~2.5 of it (before this rule k came out ~2.5 and the group left
    the verdict)."""
    from station.estimate import lsq

    capture, truth = _placed(base, 400)
    for seg in capture.segments:
        if seg.extra.get("record_ramp"):
            seg.extra["angle_sigma_deg"] *= 0.1
    result, _, _ = _fit(capture)
    est = result.model.ramp_estimate
    assert not est["estimated"] and est["k"] == 1.0 and result.model.ramp_k2 == 1.0, est
    tested = lsq.verdict_test(result)
    assert "ramp gyro" not in tested["left_out"]
    assert any(n.startswith("the 24 recorded ramps' angles keep their stated placement 1-sigma (angle_sigma_deg): "
                            "they scatter") for n in result.model.notes), result.model.notes
    cal = lsq.to_calibration(result, "m/s^2", "deg/s")
    group = next(g for g in cal.fit["noise_groups"] if g["group"] == "ramp gyro")
    assert group["p_value"] < 1e-3, group          # named: beyond its stated noise


def test_an_effect_parameter_the_estimated_ramps_still_do_not_reveal_stays_held_without_a_crash(base):
    """Review of the eighteenth session: lsq._revealed_by_ramps examines a held parameter without
    its prior and puts the prior back when the ramps do not reveal it either; the model's data
    rows must then be the ones with the prior (an IndexError in lsq.fit before: 391 residuals
    against 390 data rows).  Eleven windows (k estimated from ~10.6 degrees of freedom) and the
    offset given a typical size of 1 ms, below its 1-sigma even at the estimated placement: held,
    not written, the fit ends and says so."""
    import dataclasses

    from station.estimate import lsq
    from station.model.time_offset import TimeOffset

    class TightOffset(TimeOffset):
        @property
        def params(self):
            return tuple(dataclasses.replace(p, typical=1.0) for p in super().params)

    names = [s.name for s in base.segments if s.extra.get("record_ramp")][:11]
    capture, _ = _placed(base, 100, keep=set(names))
    result, _, _ = _fit(capture, TightOffset())
    assert result.model.ramp_estimate["estimated"], result.model.ramp_estimate
    assert result.model.unobservable == ["time_offset"]
    cal = lsq.to_calibration(result, "m/s^2", "deg/s")
    assert "time_offset" not in dict((n, v) for n, v, _ in cal.parameters())
    assert np.isfinite(result.chi2) and result.dof > 0


def test_ramps_not_estimated_again_after_a_release_go_back_to_their_stated_1sigma(base, monkeypatch):
    """Review of the eighteenth session: once a held parameter is released (lsq._revealed_by_ramps)
    the placement is estimated again, and the released offset takes a degree of freedom from the
    windows: eleven windows have ~10.6 before it and ~10.1 after.  With the threshold between the
    two (monkeypatched to 10.3: the same happens at 10 for a capture whose windows sit there),
    the second estimate says too little: the windows must then be weighted at their stated
    1-sigma as the note says (before: k^2 stayed at the first estimate, ~0.25, while the note and
    the file said "keep their stated placement 1-sigma"), and the offset, held at those weights,
    held again and not written (before: written at 4.3 +/- 1.3 ms, "revealed")."""
    import dataclasses

    from station.estimate import lsq, noise_groups
    from station.model.time_offset import TimeOffset

    class MidOffset(TimeOffset):
        @property
        def params(self):
            return tuple(dataclasses.replace(p, typical=1.5) for p in super().params)

    monkeypatch.setattr(noise_groups, "RAMP_MIN_DOF", 10.3)
    names = [s.name for s in base.segments if s.extra.get("record_ramp")][:11]
    capture, _ = _placed(base, 100, keep=set(names))
    result, _, _ = _fit(capture, MidOffset())
    est = result.model.ramp_estimate
    assert not est["estimated"] and est["k"] == 1.0 and result.model.ramp_k2 == 1.0, (est, result.model.ramp_k2)
    assert result.model.unobservable == ["time_offset"]
    assert not any(n.startswith("revealed once the recorded ramps") for n in result.model.notes), result.model.notes
    cal = lsq.to_calibration(result, "m/s^2", "deg/s")
    assert "time_offset" not in dict((n, v) for n, v, _ in cal.parameters())


def test_the_windows_lag1_correlation_is_taken_in_their_reads_timing():
    """noise_groups.placement_component's lag-1 correlation of the windows' placement residuals,
    in the capture's order, is their reads' timing error's: a pair turned each way (and a ramp up
    against a brake) has angle errors of opposite sign for the same late reads.  Synthetic rows
    (one window a row of its own, a common column the fit takes): timing errors drifting along the
    session (AR(1), rho 0.95) give a lag-1 far above independent windows' 1 / sqrt(n), whatever the
    windows' signs; independent ones stay near 0; with the signs left out the alternating pairs
    read as anticorrelated (what the check saw before it took the signs)."""
    from station.estimate.noise_groups import placement_component

    rng = np.random.default_rng(7)
    n = 60
    names = [f"w{i}" for i in range(n)]
    signs = {name: (1.0 if i % 2 == 0 else -1.0) * (1.0 if i % 4 < 2 else -1.0) for i, name in enumerate(names)}
    windows = {name: np.array([1.0, 0.0, 0.0]) for name in names}
    labels = [(name, "rotation", f"gyro_{a}", a) for name in names for a in "xyz"]
    J = np.zeros((3 * n, 1))
    J[0::3, 0] = [signs[name] for name in names]        # a common timing offset: the time offset's
    drift = np.zeros(n)
    for i in range(1, n):
        drift[i] = 0.95 * drift[i - 1] + np.sqrt(1 - 0.95 ** 2) * rng.normal()
    def residuals_of(timing):
        out = np.zeros(3 * n)
        out[0::3] = timing * np.array([signs[name] for name in names])
        return out

    drifting = placement_component(labels, residuals_of(drift), J, windows, signs=signs)["lag1"] * np.sqrt(n)
    independent = placement_component(labels, residuals_of(rng.normal(size=n)), J, windows, signs=signs)["lag1"]
    unsigned = placement_component(labels, residuals_of(drift), J, windows)["lag1"] * np.sqrt(n)
    assert drifting > 4.0 and abs(independent) * np.sqrt(n) < 2.33 and abs(unsigned) < 4.0, \
        (drifting, independent, unsigned)


def test_the_earth_rate_across_the_ramps_does_not_pull_the_time_offset_toward_zero(monkeypatch):
    """Nineteenth session: over many dry runs the fitted offset sat below its truth (sum z^2 48-55
    where chi2(20)'s 99.9 % point is 45.3), with or without the ramps' placement.  The cause: the
    offset's term, dt (w_end - w_start), takes the measured rates at the window's ends, the Earth
    rate across the axis included, while the Earth rate's integral is already taken over the
    samples' own phases (RotationSummary.earth_weights_s: the samples' window, already shifted by
    dt); the Earth's change was counted twice, and across the axis it said dt = 0 whatever the
    truth.  Here the ramps' angles say nothing along their axis (stated +-100 deg) and the sensors'
    noise is a hundredth of default_truth's, so what is left shows the model's response to the
    offset alone: 1.09 +- 0.04 ms for the twin's 5 ms before (a fifth of it), 5.2 +- 0.17 after."""
    import dataclasses

    from sim_devices.truth import default_truth
    from station.estimate import noise_groups
    from station.model.time_offset import TimeOffset
    from station.simulate import dryrun

    class Untyped(TimeOffset):      # no prior to pull it: the data's own estimate
        @property
        def params(self):
            return tuple(dataclasses.replace(p, typical=1e3) for p in super().params)

    monkeypatch.setattr(noise_groups, "RAMP_MIN_DOF", float("inf"))      # the stated +-100 deg kept
    truth = default_truth(1)
    truth.bench.time_offset_s = OFFSET_MS * 1e-3
    truth.accel.noise_density *= 0.01
    truth.gyro.noise_density *= 0.01
    truth.bench.table_angle_error_arcsec *= 0.01
    capture = dryrun.simulate_capture(_scheme(ramp_axes=[[0, 0, 1]], repeats=1), truth, 3)
    for seg in capture.segments:
        if seg.extra.get("record_ramp"):
            seg.extra["angle_sigma_deg"] = 100.0
    _, value, sigma = _fit(capture, Untyped())
    assert sigma < 1.0 and abs(value - OFFSET_MS) < 4.0 * sigma, (value, sigma)


def test_a_drifting_host_is_found_more_often_than_by_lag1_and_an_independent_one_rarely():
    """Nineteenth session: noise_groups.drift_test, the restricted likelihood's ratio of an AR(1)
    drift of the reads' timing along the session beside the windows' independent scatter, p from
    its own null distribution.  Synthetic rows (one window a row of its own, the common part the
    fit takes; the timing signs of placement_component's lag-1 test): 96 windows, independent
    timing errors of 1 and a drift of 0.53 at rho 0.9 between neighbours (the review's 2 ms beside
    the test host's 3.8 ms).  Without drift it fires at its stated rate (p < 0.01: at most 3 of 60
    sessions; P(4 or more) = 0.3 %); with it in about half (the lag-1 rule in a third;
    benchmarks/ramp_drift_power.py: no statistic of the residuals does much better against it)."""
    from station.estimate.noise_groups import RAMP_DRIFT_P, placement_component

    rng = np.random.default_rng(11)
    n = 96
    names = [f"w{i}" for i in range(n)]
    sign = np.array([(1.0 if i % 2 == 0 else -1.0) * (1.0 if i % 4 < 2 else -1.0) for i in range(n)])
    signs = dict(zip(names, sign))
    windows = {name: np.array([1.0, 0.0, 0.0]) for name in names}
    labels = [(name, "rotation", f"gyro_{a}", a) for name in names for a in "xyz"]
    J = np.zeros((3 * n, 1))
    J[0::3, 0] = sign

    def session(drift):
        d = np.empty(n)
        d[0] = rng.normal(0.0, drift)
        for i in range(1, n):
            d[i] = 0.9 * d[i - 1] + np.sqrt(1 - 0.9 ** 2) * rng.normal(0.0, drift)
        out = np.zeros(3 * n)
        out[0::3] = (rng.normal(size=n) + d) * sign
        return out

    counts = {}
    for drift in (0.0, 2.0 / 3.8):
        comps = [placement_component(labels, session(drift), J, windows, signs=signs, drift=True) for _ in range(60)]
        counts[drift] = (sum(c["drift_p"] < RAMP_DRIFT_P for c in comps),
                         sum(c["lag1"] > 2.33 / np.sqrt(n) for c in comps))
    (clean, _), (drifting, lag1) = counts[0.0], counts[2.0 / 3.8]
    assert clean <= 3 and drifting >= 20 and drifting > lag1, counts


def test_the_drift_test_does_not_call_residuals_it_cannot_read_a_drift():
    """Review of the nineteenth session: drift_test's statistic is scale-free (lambda profiled),
    but it took log(y'y) as it came: residuals all zero, or so small (large) that y'y under-
    (over-)flows, made the ratio NaN, and a NaN ratio counted no null draw at or above it -- p =
    1/401, below RAMP_DRIFT_P: the fit kept the stated 1-sigma and its note said the windows
    "drift along the session (likelihood ratio nan, p = 0.0025)".  Residuals that say nothing
    (zero) or nothing readable (NaN) are no evidence of a drift, and the residuals' units do not
    change the verdict."""
    from station.estimate.noise_groups import RAMP_DRIFT_P, drift_test

    rng = np.random.default_rng(4)
    n = 24
    A = rng.normal(size=(n, n + 6))
    G = A @ A.T / (n + 6)
    timing = np.where(np.arange(n) % 2 == 0, 1.0, -1.0)
    s = rng.multivariate_normal(np.zeros(n), G)
    plain = drift_test(G, s, timing)
    assert np.isfinite(plain["drift_lr"]), plain
    for scale in (1e-170, 1e170):
        scaled = drift_test(G, s * scale, timing)
        assert scaled["drift_p"] == plain["drift_p"], (scale, scaled, plain)
    zero = drift_test(G, np.zeros(n), timing)
    assert zero["drift_lr"] == 0.0 and zero["drift_p"] == 1.0, zero
    unreadable = drift_test(G, np.where(np.arange(n) == 5, np.nan, s), timing)
    assert not unreadable["drift_p"] < RAMP_DRIFT_P, unreadable


def test_a_common_placement_is_not_read_as_a_drift_where_the_windows_stated_1sigma_differ(base):
    """Review of the nineteenth session: a common timing error tau (the reads all late; the time
    offset held by its prior leaves it in the residuals) is, in window i's placement residual,
    sign_i tau |rate_i| / (k angle_sigma_i), i.e. sign_i tau / sigma_t,i -- not sign_i tau:
    drift_test took out the direction of ``signs`` (+-1), so where the stated 1-sigma changes
    along the session (a host growing busier: 2 -> 6 ms over 24 windows) a common 8 ms read as a
    drift in 119 of 200 sessions of independent windows (2 of 200 with it equal).  Synthetic rows
    (the fit's parameters touch no window): with the windows' timing scale in ``signs`` (sign
    times |rate| / angle_sigma, what lsq.Model.ramp_signs must carry) it fires at its stated rate
    (at most 3 of 60; P(4 or more) = 0.3 %), and the model built on a capture whose windows state
    different 1-sigma carries that scale."""
    from station.estimate import lsq
    from station.estimate.noise_groups import RAMP_DRIFT_P, placement_component
    from station.estimate.summaries import summarise

    rng = np.random.default_rng(8)
    n = 24
    names = [f"w{i}" for i in range(n)]
    sign = np.array([(1.0 if i % 2 == 0 else -1.0) * (1.0 if i % 4 < 2 else -1.0) for i in range(n)])
    sigma_t = np.linspace(2.0, 6.0, n)
    windows = {name: np.array([1.0, 0.0, 0.0]) for name in names}
    labels = [(name, "rotation", f"gyro_{a}", a) for name in names for a in "xyz"] + [("s", "static", "accel", "x")]
    J = np.zeros((3 * n + 1, 1))
    J[-1, 0] = 1.0
    fired = 0
    for _ in range(60):
        tau = 8.0 + rng.normal(size=n) * sigma_t
        r = np.zeros(3 * n + 1)
        r[0:3 * n:3] = sign * tau / sigma_t
        comp = placement_component(labels, r, J, windows, signs=dict(zip(names, sign / sigma_t)), drift=True)
        fired += comp["drift_p"] < RAMP_DRIFT_P
    assert fired <= 3, fired

    capture = copy.deepcopy(base)
    ramps = [seg for seg in capture.segments if seg.extra.get("record_ramp")]
    for i, seg in enumerate(ramps):
        seg.extra["angle_sigma_deg"] = 0.2 * (1 + i % 3)
    model = lsq.Model(summarise(capture), [])
    scale = {}
    for r in model.s.rotations:
        if r.name in model.ramp_signs:
            rate = r.table_rate_end_dps if r.record_ramp == "start" else r.table_rate_start_dps
            scale[r.name] = model.ramp_signs[r.name] * r.angle_sigma_deg / abs(rate)
    values = np.array(list(scale.values()))
    assert len(values) == len(ramps) and np.allclose(np.abs(values), np.abs(values[0]), rtol=1e-9), scale
