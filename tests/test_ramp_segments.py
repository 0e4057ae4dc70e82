"""Issue 28 item 3 (fifteenth session): a rotation whose recorded window keeps the table's ramp
(``record_ramp: start | end``), so that a time offset between the IMU's stamps and the table's
encoder can be designed and separated: the scheme key, its compiled step on 1-, 2- and 3-axis
tables, the simulated bench's ramp, the manifest's rates at the window's edges, the estimate of a
simulated time offset (honest 1σ over seeds) and the designer's proposal."""
import numpy as np
import pytest
import yaml

from station.bench.compile import compile_scheme
from station.bench.config import AxisConfig, Config, RunConfig, TableConfig
from station.bench.plan import Rotate
from station.core.errors import UserError
from station.io.scheme import RAMP_REST_S, scheme_from_text
from test_compile import check_plan

RAMPS = """\
name: ramps
defaults: {dwell_s: 2, rate_dps: 100, rotation_s: 3.6}
segments:
  - {static: s1, up_body: [0, 0, 1]}
  - {rotation: up, axis_body: [1, 0, 0], record_ramp: start}
  - {rotation: down, axis_body: [0, 1, 1], record_ramp: end}
  - {rotation: steady, axis_body: [0, 0, 1]}
"""
# steady pairs about the three axes (the gyro scale factors) beside the ramps (the time offset: a
# ramp alone moves the integral by S A + dt w, the scale and the offset together)
STEADY_XY = """\
  - {rotation: steady_x, axis_body: [1, 0, 0]}
  - {rotation: steady_y, axis_body: [0, 1, 0]}
"""


def test_the_scheme_key_is_checked():
    scheme = scheme_from_text(RAMPS, "ramps.yaml")
    ramps = {s.name: s.record_ramp for s in scheme.segments if s.kind == "rotation"}
    assert ramps == {"up_p": "start", "up_m": "start", "down_p": "end", "down_m": "end",
                     "steady_p": None, "steady_m": None}
    for bad, said in (("record_ramp: both", "must be start or end"), ("record_ramp: [start]", "must be start or end"),
                      ("record_ramp: start, encoder: false", "only for a table's turns")):
        text = RAMPS.replace("record_ramp: start", bad)
        with pytest.raises(UserError, match=f"ramps.yaml: segments\\[1\\].record_ramp: {said}"):
            scheme_from_text(text, "ramps.yaml")


@pytest.mark.parametrize("axes", [1, 2, 3])
def test_a_recorded_ramp_compiles_on_one_two_and_three_axis_tables(axes):
    """The step turns the scheme's axis (forward kinematics: test_compile.check_plan), keeps the
    ramp in its window at the table's own rate_accel_dps2 and says so; the plan's time counts the
    ramp once in the window and the other outside it."""
    accel = 40.0
    fast = AxisConfig(max_rate_dps=300, max_accel_dps2=300, rate_accel_dps2=accel)
    config = Config(table=TableConfig(axes=axes, limits=(fast,)), run=RunConfig(operator=True, settle_s=5))
    plan = compile_scheme(scheme_from_text(RAMPS, "ramps.yaml"), config)
    assert check_plan(plan, config) == 7
    rot = {s.spec.name: s for s in plan if isinstance(s, Rotate)}
    ramp_s = 100.0 / accel
    for name, kind in (("up_p", "start"), ("up_m", "start"), ("down_p", "end"), ("down_m", "end")):
        step = rot[name]
        assert step.record_ramp == kind and step.accel_dps2 == accel and step.rest_s == RAMP_REST_S
        assert step.capture_s == pytest.approx(3.6 + ramp_s + RAMP_REST_S)
        assert step.estimate_s == pytest.approx(ramp_s + 5 + step.capture_s)      # the other ramp, settling
        assert ("after 0.5 s at rest and the ramp up" if kind == "start" else "then the brake") in step.describe()
    steady = rot["steady_p"]
    assert steady.record_ramp is None and steady.capture_s == pytest.approx(3.6)
    assert steady.estimate_s == pytest.approx(2 * ramp_s + 5 + 3.6)


def _ramp_capture(tmp_path, time_offset_s, seed, rate=100.0):
    """A small dry run: six faces, one steady pair, ramp pairs up (start) and down (end)."""
    from sim_devices.truth import default_truth
    from station.simulate import dryrun

    truth = default_truth(1)
    truth.bench.time_offset_s = time_offset_s
    text = RAMPS.replace("rate_dps: 100", f"rate_dps: {rate:g}").replace(
        "  - {static: s1, up_body: [0, 0, 1]}\n",
        "".join(f"  - {{static: s{i}, up_body: {u}}}\n" for i, u in enumerate(
            [[0, 0, 1], [0, 0, -1], [1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0]]))) + STEADY_XY
    return truth, dryrun.simulate_capture(scheme_from_text(text, "ramps.yaml"), truth, seed)


def test_the_simulated_bench_records_the_ramp_and_the_rates_at_the_window_edges(tmp_path):
    """The window of a ramp up opens at rest and ends at the rate; the gyro shows it; the encoder
    angle is the table's over the window: the rest, the ramp (r^2 / 2a) and the turns."""
    from station.simulate.dryrun import RAMP_ACCEL_DPS2

    _, capture = _ramp_capture(tmp_path, 0.0, 2)
    seg = {s.name: s for s in capture.segments}
    up, down = seg["up_p"], seg["down_m"]
    assert up.extra["record_ramp"] == "start" and up.extra["rate_start_dps"] == 0.0
    assert up.extra["rate_end_dps"] == pytest.approx(100.0)
    assert down.extra["rate_start_dps"] == pytest.approx(-100.0) and down.extra["rate_end_dps"] == 0.0
    ramp_deg = 100.0 ** 2 / (2 * RAMP_ACCEL_DPS2)
    # the encoder's 2 arcsec and the window's rounding to whole samples (half a sample at the rate: 0.5 deg)
    assert up.angle_deg == pytest.approx(360.0 + ramp_deg, abs=0.6)
    g = up.data.gyro @ np.array([1.0, 0, 0])
    assert abs(g[:3].mean()) < 0.5 and g[-3:].mean() == pytest.approx(100.0, rel=0.01)


def _fit(capture):
    from station.estimate import lsq
    from station.estimate.summaries import summarise
    from station.model import EFFECTS

    result = lsq.fit(summarise(capture), [EFFECTS["time_offset"]()])
    names, index, factors, units = lsq._reported_index(result, "m/s^2", "deg/s")
    k = names.index("time_offset")
    value = float(result.x[index[k]]) * factors[k]
    sigma = float(np.sqrt(result.covariance[index[k], index[k]])) * factors[k]
    return result, value, sigma


def test_the_estimate_recovers_a_simulated_time_offset_with_an_honest_sigma(tmp_path):
    """A 5 ms offset of the twin's clock (truth.bench.time_offset_s), estimated from the ramps over
    seeds: the errors over their own 1σ are standard normal.  Over N seeds sum z^2 ~ chi2(N); the
    test takes the 0.1 % and 99.9 % points, so a 1σ 1.9x too large (E sum z^2 = N/3.6) or too
    small (3.6 N) fails: with N = 8 the bounds are 1.65 and 26.1, against 2.2 and 29 expected."""
    from scipy.stats import chi2

    n = 8
    z = []
    for seed in range(n):
        _, capture = _ramp_capture(tmp_path, 0.005, 10 + seed)
        result, value, sigma = _fit(capture)
        # the 1σ from the gyro noise: a ramp pair's integral noise sqrt(2 T / fs) sigma_g over its change
        # of rate (100 deg/s): at the simulated 0.03 deg/h/rtHz, a few microseconds; the fit's 1σ
        # cannot be below 1 us nor above 0.1 ms
        assert 1e-3 < sigma < 0.1, sigma
        z.append((value - 5.0) / sigma)
    s = float(np.sum(np.square(z)))
    assert chi2.ppf(0.001, n) < s < chi2.ppf(0.999, n), z


def test_a_time_offset_is_not_seen_without_a_ramp_and_the_designer_proposes_one(tmp_path, capsys, monkeypatch):
    """On a capture of steady turns a time offset is not revealed and diagnose's words point to the
    ramps; `station design --from CAP --add time_offset --reveal time_offset` proposes turns with
    their ramp up recorded (the fewest: one pair), `run --append` records them into the capture and
    the estimate then finds the simulated 5 ms within 4.5σ."""
    from sim_devices.truth import default_truth
    from station.cli import main
    from station.diagnose import suggest, words
    from station.estimate.summaries import summarise
    from station.io.capture import read_capture

    truth = default_truth(1)
    truth.bench.time_offset_s = 0.005
    (tmp_path / "truth.yaml").write_text(yaml.safe_dump(truth.to_yaml_dict(), sort_keys=False))
    (tmp_path / "s.yaml").write_text(yaml.safe_dump({
        "name": "tiny", "defaults": {"dwell_s": 2.0, "rate_dps": 100.0, "rotation_s": 3.6},
        "segments": [{"static": f"s{i}", "up_body": u} for i, u in enumerate(
            [[0, 0, 1], [0, 0, -1], [1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0]])]
        + [{"rotation": "rz", "axis_body": [0, 0, 1]}, {"rotation": "rx", "axis_body": [1, 0, 0]}]}))
    monkeypatch.chdir(tmp_path)
    assert main(["run", "--scheme", "s.yaml", "--sim", "--sim-truth", "truth.yaml", "--seed", "3", "--out", "cap",
                 "--no-history"]) in (0, 3)
    summaries = summarise(read_capture("cap", load_data=True))
    said = words.aliases(summaries, "time_offset")
    assert said and "record_ramp: start" in said[-1][1], said
    cmd = suggest.separations("cap", [], "time_offset", summaries)
    assert cmd == ["station design --from cap --add time_offset --reveal time_offset -o extension.yaml"]
    capsys.readouterr()
    assert main(["design", "--from", "cap", "--add", "time_offset", "--reveal", "time_offset", "--rates", "100",
                 "--revolutions", "1", "--dwells", "10", "-o", "ext.yaml"]) == 0
    ext = yaml.safe_load((tmp_path / "ext.yaml").read_text())
    assert len(ext["segments"]) == 1 and ext["segments"][0]["record_ramp"] == "start", ext
    assert main(["run", "--sim", "--append", "cap", "--scheme", "ext.yaml", "--no-history"]) in (0, 3)
    capture = read_capture("cap", load_data=True)
    assert sum(1 for s in capture.segments if s.extra.get("record_ramp") == "start") == 2
    result, value, sigma = _fit(capture)
    assert result.chi2 / result.dof < 1.5, (result.chi2, result.dof)      # the fit of all of it holds
    assert sigma < 0.05 and abs(value - 5.0) < 4.5 * sigma, (value, sigma)
    assert words.aliases(summarise(capture), "time_offset") == []


def test_the_benchs_angle_of_a_ramp_from_reads_placed_on_the_imus_clock():
    """station/bench/ramp_angle.py on a table written here: rest at 10 deg until the command at
    IMU time 5.0 s, then 100 deg/s^2 up to 200 deg/s; reads every 0.1 s while it turns, each
    bracketed by the stamp before it and the one after (the read's moment 0-20 ms after the first,
    0-20 ms before the second's end: the host's latency either side); the window ends at 9.005 s.
    The angle is the profile's within the placement: each read is placed at its bracket's middle,
    within 10 ms of its moment (2 deg at 200 deg/s), errors of mean 0 and 1-sigma 4.1 ms: the mean
    of 20 reads within 0.5 deg (2.7 sigma of the mean's 0.18 deg).  A placement at the stamp
    before plus half a period (the old one) is off by the mean latency less 5 ms: ~1 deg, and fails
    (0.84 deg)."""
    from station.bench import ramp_angle

    period, a, w, t_cmd, rest = 0.01, 100.0, 200.0, 5.0, 10.0
    ramp_s = w / a

    def position(t):                # the table's unwrapped angle at table time t
        s = np.clip(t - t_cmd, 0.0, ramp_s)
        return rest + 0.5 * a * s * s + w * max(t - t_cmd - ramp_s, 0.0)

    rng = np.random.default_rng(1)
    marks = []
    for T in np.arange(7.2, 9.2, 0.1):
        before = T - rng.uniform(0, 0.02)                  # the newest stamp received before the query
        after = T + rng.uniform(0, 0.02) - period          # the newest after the answer (its end: + period)
        marks.append(ramp_angle.Mark(position(T) % 360.0, w, before, after))
    edge = 9.005
    turning = ramp_angle.position_at(marks, edge, w, period)
    angle = ramp_angle.window_angle(rest, turning, ramp_angle.expected_angle(w, edge - t_cmd, a, "start"), "start")
    assert abs(angle - (position(edge) - rest)) < 0.5, (angle, position(edge) - rest)
    # a brake: the same reads before the command, the rest position after
    assert ramp_angle.window_angle(100.0, 30.0 + 720.0, 200.0 * 2.0 + 200.0, "end") == pytest.approx(
        100.0 - 30.0 + 360.0 * round((600.0 - 70.0) / 360.0))


def test_a_recorded_ramps_earth_weights_follow_the_harmonics_phase():
    """Issue 28 review item 5: a ramp window's Earth-rate weights (integral of cos, sin of the phase
    over the window) come from the one phase the harmonics use (_ramp_fraction: the gyro with its
    bias taken at rest), computed in rotation_summary.  Noiseless ramp up (1 s rest, 50 deg/s^2 to
    100 deg/s, 6 s) with a 0.1 deg/s gyro bias along the axis: the bias-corrected phase is the
    truth to rounding (the trapezoid of a piecewise-linear rate is exact), so the weights agree to
    1e-9 s; the raw gyro's turn (the bias integrated: 0.6 deg over 6 s) left them ~3e-3 s off."""
    from station.estimate import summaries as S

    hz, rate, accel_dps2, rest = 100.0, 100.0, 50.0, 1.0
    t = np.arange(0.0, 6.0, 1.0 / hz) + 0.5 / hz
    w = np.clip((t - rest) * accel_dps2, 0.0, rate)
    turned = 0.5 * w[0] / hz + np.concatenate([[0.0], np.cumsum(0.5 * (w[1:] + w[:-1]) * np.diff(t))])
    angle = turned[-1] + 0.5 * w[-1] / hz
    gyro = np.zeros((len(t), 3))
    gyro[:, 2] = w + 0.1
    phase = np.radians(turned)
    acc = np.column_stack([9.8 * np.cos(phase), 9.8 * np.sin(phase), np.zeros(len(t))])
    truth = np.array([np.gradient(t) @ np.cos(phase), np.gradient(t) @ np.sin(phase)])
    r = S.rotation_summary("r", (0, 0, 1), 0, angle, t, acc, gyro, None, gyro_sigma_dps=np.full(3, 0.01),
                           steady_rate_dps=rate)
    assert r.earth_weights_s is not None
    assert np.allclose(r.earth_weights_s, truth, atol=1e-9, rtol=0), r.earth_weights_s - truth
    steady = S.rotation_summary("s", (0, 0, 1), 0, 360.0, t, acc, np.tile([0.0, 0.0, 60.0], (len(t), 1)), None)
    assert steady.earth_weights_s is None        # a steady turn keeps the uniform turn's weights


def test_the_dry_run_ramps_at_the_configured_tables_acceleration(tmp_path, monkeypatch):
    """Issue 28 review item 4: `station run --sim` with station.yaml's rate_accel_dps2: 20 records
    its ramps at 20 deg/s^2 (before: the dry run's 50 whatever the table): the manifest says so
    and a ramp up's window holds the turn and the ramp, 360 + 100^2 / (2 * 20) = 610 deg (the
    encoder's 2" and half a sample at the rate: 0.6 deg).  The designer's timeline takes the same
    acceleration (information.Information.clock's third element)."""
    from types import SimpleNamespace

    from station.cli import main
    from station.design import timeline
    from station.io.capture import read_capture

    monkeypatch.chdir(tmp_path)
    (tmp_path / "station.yaml").write_text(
        "version: 1\ntable:\n  axes: 3\n  limits: [{max_rate_dps: 300, max_accel_dps2: 300, rate_accel_dps2: 20}]\n")
    (tmp_path / "s.yaml").write_text(
        "name: r\ndefaults: {dwell_s: 1, rate_dps: 100, rotation_s: 3.6}\nsegments:\n"
        "  - {static: s0, up_body: [0, 0, 1]}\n  - {rotation: up, axis_body: [0, 0, 1], record_ramp: start, pair: false}\n")
    main(["run", "--sim", "--config", "station.yaml", "--scheme", "s.yaml", "--out", "cap", "--no-history"])
    up = read_capture(tmp_path / "cap").segment("up")
    assert up.extra["ramp_accel_dps2"] == 20.0
    assert up.angle_deg == pytest.approx(360.0 + 100.0 ** 2 / (2 * 20.0), abs=0.6)
    c = SimpleNamespace(kind="rotation", key=((0, 0, 1), 0.0, 100.0, 1, "start"))
    assert timeline.segment_seconds(c, 20.0) == pytest.approx([3.6 + 5.0 + RAMP_REST_S] * 2)


def test_a_windows_angle_sigma_is_read_and_checked(tmp_path):
    """Issue 28 review item 1: a ramp window's angle_sigma_deg reaches its summary (and the gyro
    integral's weight: 1 deg along the axis dominates the encoder's 2"); a value that is not a
    finite number >= 0 is refused naming the segment and the key."""
    from station.estimate import lsq
    from station.estimate.summaries import summarise

    _, capture = _ramp_capture(tmp_path, 0.0, 2)
    up = next(s for s in capture.segments if s.name == "up_p")
    up.extra["angle_sigma_deg"] = 1.0
    s = summarise(capture)
    rot = {r.name: r for r in s.rotations}
    assert rot["up_p"].angle_sigma_deg == 1.0 and rot["up_m"].angle_sigma_deg == 0.0
    model = lsq.Model(s, [])
    names = [r.name for r in s.rotations]

    def along_axis_variance(name):      # deg^2: the gyro integral's variance along the turn's axis
        k = names.index(name)
        chol = np.linalg.inv(model.gyro_whiten[k])
        axis = model._rotation_axes_raw[k]
        return float(axis @ chol @ chol.T @ axis)

    # 1 deg^2 added to the encoder's (2")^2 and the white noise's (~1e-6 deg^2 here)
    assert 1.0 <= along_axis_variance("up_p") < 1.001
    assert along_axis_variance("up_m") < 1e-3
    for bad in ("x", -1.0, float("nan"), True):
        up.extra["angle_sigma_deg"] = bad
        with pytest.raises(UserError, match="up_p: angle_sigma_deg"):
            summarise(capture)
