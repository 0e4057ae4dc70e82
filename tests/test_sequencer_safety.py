"""The sequencer in process against the device twins (real pseudo-terminals): limits are never
exceeded, axes with angle limits stay inside them, the table is unpowered while the operator
remounts the IMU, the warm-up waits for the temperature, and a hand scheme (manual6) is found
in one continuous recording (the twin table plays the operator's hands)."""
import dataclasses
import io
import math
import time

import numpy as np
import pytest
from rich.console import Console

from drivers.base import ImuSettings, TableSettings
from drivers.registry import open_imu, open_table
from sim_devices.truth import default_truth
from sim_devices.twins.serve import BenchOptions, BenchServer
from station.io.capture import CaptureWriter, ImuInfo, Site, read_capture
from station.bench.compile import compile_scheme
from station.bench.config import AxisConfig, Config, RunConfig, TableConfig, WarmupConfig, normal_gravity
from station.estimate import estimate_with
from station.bench.gimbal import Gimbal
from station.bench.live import PlainDisplay
from station.bench.plan import HandStatic, MoveTo, Operator, Rotate
from station.io.scheme import RotationSpec, load_scheme, scheme_from_text
from station.bench.sequencer import Sequencer, SequencerError

SPEED = 100.0
# At --speed 100 a reader descheduled for 10 ms of wall time misses 1 s of device time: on a
# shared, loaded machine the twins drop frames that a real bench would never drop.  These
# tests are about motion and safety, so they allow that loss; the data-loss limits themselves
# are tested at a lower speed with injected drops (test_run_faults.py).
LOSS_AT_SPEED = dict(max_missing_fraction=0.5, max_gap_s=100.0, rerecord_attempts=3)


class Hands:
    """A test operator: confirms at once, remembers what the table looked like then; for hand
    steps the 3-axis table twin puts the IMU on a face or turns it one whole turn."""

    def __init__(self, bench=None, table=None, speed=SPEED):
        self.bench, self.table, self.speed = bench, table, speed
        self.seen = []
        self.gimbal = Gimbal(((0, 0, 1), (1, 0, 0), (0, 1, 0)), np.eye(3))

    def confirm(self, step, interrupts):
        self.seen.append((step, [ax.interlock_closed for ax in self.bench.table.axes]))

    def resume_after_pause(self, interrupts):
        return False

    def act(self, step):
        now = self.table.read_positions_deg()
        if isinstance(step, HandStatic):
            self.table.move_to(self.gimbal.solve_static(step.spec.up_body, now))
            return
        up = self.gimbal.solve_static(step.spec.axis_body, now)       # the turn's axis up ...
        self.table.move_to(up)
        # ... still a moment: 3 s of device time (segment_detect needs 2 s of stillness between
        # the move and the turn).  Not a wall-clock sleep: the twins' clock waits for a reader
        # that falls behind, so on a loaded machine 3 / speed wall seconds were less than 2 s of
        # device time, the move and the turn became one motion of the wrong angle and the run
        # waited for ever for the turn to be done again
        t0 = self.bench.clock.now()
        while self.bench.clock.now() < t0 + 3.0:
            time.sleep(0.002)
        turned, last = 0.0, float(up[0])
        for quarter, rate in enumerate((20.0, 60.0, 30.0, 50.0)):     # ... one whole turn, unevenly
            self.table.set_rate(1, math.copysign(rate, step.spec.rate_dps), wait=False)
            while turned < min(90.0 * (quarter + 1), 300.0):
                p = float(self.table.read_positions_deg()[0])
                turned += abs((p - last + 180.0) % 360.0 - 180.0)
                last = p
                time.sleep(0.002)
        self.table.move_to(up)


def twin_table(bench):
    """The table driver on the twins, its waits reading the table every 10 ms of a real table's
    time at the twins' speed (the arrival rule, 5 reads in a row, unchanged in device time)."""
    return open_table(bench.table_path, settings=TableSettings(poll_interval_s=0.01 / bench.clock.speed))


def sequencer(bench, config, writer, operator, rate_hz=100.0, table=True, paced=False):
    """``paced``: the table driver's waits at the twins' speed (``twin_table``); otherwise a real
    table's 10 ms of wall time (tests/test_ramp_hold.py and its kin)."""
    console = Console(file=io.StringIO(), width=200)
    display = PlainDisplay(console, 1.0, "test")
    tab = (twin_table(bench) if paced else open_table(bench.table_path)) if table else None
    imu = open_imu(bench.imu_path, settings=ImuSettings(frame_timeout_s=2.0))
    rate = imu.configure(rate_hz)
    seq = Sequencer(table=tab, imu=imu, writer=writer, config=config, display=display, operator=operator,
                    rate_hz=rate)
    seq.console = console
    return seq, tab, imu


def new_writer(path, scheme="test", gravity=normal_gravity(45.0), extra=None):
    return CaptureWriter(path, ImuInfo(100.0, "m/s^2", "deg/s"), Site(gravity, 45.0), scheme, extra=extra)


@pytest.fixture()
def bench3():
    with BenchServer(default_truth(3), BenchOptions(speed=SPEED, seed=3, axes=3, lossless=True)) as b:
        yield b


def test_rates_and_angles_beyond_the_limits_are_never_commanded(bench3, tmp_path):
    limits = (AxisConfig(max_rate_dps=50, angle_min_deg=-170, angle_max_deg=170), AxisConfig(max_rate_dps=50),
              AxisConfig(max_rate_dps=50))
    config = Config(table=TableConfig(axes=3, limits=limits), run=RunConfig(**LOSS_AT_SPEED, operator=False, settle_s=1))
    seq, table, imu = sequencer(bench3, config, new_writer(tmp_path / "cap"), Hands(bench3), paced=True)
    spec = RotationSpec("fast", (0.0, 1.0, 0.0), 60.0, 6.0)
    with pytest.raises(SequencerError, match="outside its limits"):
        seq.run([Rotate("too fast", "fast", 1.0, spec=spec, axis=3, table_rate_dps=60.0, revolutions=1)])
    with pytest.raises(SequencerError, match="outside its limits"):     # the limited axis cannot turn
        seq.run([Rotate("limited", "fast", 1.0, spec=dataclasses.replace(spec, rate_dps=10.0), axis=1,
                        table_rate_dps=10.0, revolutions=1)])
    with pytest.raises(SequencerError, match=r"outside its limits \[-170, 170\]"):
        seq.run([MoveTo("too far", None, 1.0, positions_deg=(175.0, None, None))])
    assert [bench3.table.read_rate(a) for a in (1, 2, 3)] == [0.0, 0.0, 0.0]
    assert [ax.mode for ax in bench3.table.axes] == ["position"] * 3    # stopped and held, never turned
    assert bench3.table.read_position(1) == 0.0

    # from +160 to -160 deg the short way (40 deg) would leave [-170, 170]: waypoints go through 0
    t0 = bench3.clock.now()
    seq.run([MoveTo("a", None, 1.0, positions_deg=(160.0, None, None)),
             MoveTo("b", None, 1.0, positions_deg=(-160.0, None, None))])
    path = bench3.table.axis_states(np.linspace(t0, bench3.clock.now(), 4000))[0][:, 0]
    assert path.max() == pytest.approx(160.0, abs=0.05) and path.min() == pytest.approx(-160.0, abs=0.05)
    assert np.all(np.abs(path) <= 170.0)
    table.close()
    imu.close()


def test_the_table_is_unpowered_while_the_operator_remounts_the_imu(tmp_path):
    scheme = scheme_from_text("name: up\ndefaults: {dwell_s: 2}\nsegments:\n  - {static: xup, up_body: [1, 0, 0]}\n",
                              "up.yaml")
    config = Config(table=TableConfig(axes=2), run=RunConfig(**LOSS_AT_SPEED, operator=True, settle_s=1))
    plan = compile_scheme(scheme, config)              # x up: the inner (east) axis is body x at zero
    ops = [s for s in plan if isinstance(s, Operator)]
    assert len(ops) == 1 and ops[0].remount and ops[0].instruction.startswith("mount the IMU with its ")
    assert ops[0].mounting != config.table.mounting
    with BenchServer(default_truth(2), BenchOptions(speed=SPEED, seed=2, axes=2, lossless=True)) as bench:
        hands = Hands(bench)
        seq, table, imu = sequencer(bench, config, new_writer(tmp_path / "cap"), hands, paced=True)
        seq.run(plan.steps)
        assert [closed for _, closed in hands.seen] == [[False, False]]        # open while asked
        assert all(ax.interlock_closed for ax in bench.table.axes)              # closed again
        assert seq.mounting == ops[0].mounting
        table.close()
        imu.close()
    assert read_capture(tmp_path / "cap").segment("xup").extra["mounting"] == list(ops[0].mounting)


def test_warm_up_lasts_until_the_temperature_slope_is_below_the_threshold(tmp_path):
    truth = default_truth(4)
    # dT/dt = 120 C/h exp(-t / 30 s) (2 C over 60 s before: the same starting slope, the
    # threshold crossed 90 s of device time sooner).  The slope changes by slope / 30 s there,
    # 0.2 C/h per s (0.1 before): a given error of the fitted slope is half the time error it was
    truth.temperature.warmup_delta_c = 1.0
    truth.temperature.warmup_time_constant_s = 30.0
    config = Config(table=TableConfig(axes=1),
                    warmup=WarmupConfig(duration_s=30.0, max_s=2000.0, temp_slope_c_per_h=6.0, window_s=20.0),
                    run=RunConfig(**LOSS_AT_SPEED, operator=False, settle_s=1))
    scheme = scheme_from_text("name: z\ndefaults: {dwell_s: 2}\nsegments:\n  - {static: zup, up_body: [0, 0, 1]}\n",
                              "z.yaml")
    with BenchServer(truth, BenchOptions(speed=SPEED, seed=4, axes=1, lossless=True)) as bench:
        seq, table, imu = sequencer(bench, config, new_writer(tmp_path / "cap"), Hands(bench), paced=True)
        seq.run(compile_scheme(scheme, config).steps)
        table.close()
        imu.close()
    rows = np.loadtxt(tmp_path / "cap" / "warmup.csv", delimiter=",", skiprows=1)
    t, temp = rows[:, 0], rows[:, 1]
    # device time t since the twins started: the slope fitted over the last 20 s is below 6 C/h
    # once exp(-(t - 10 s)/30 s) < 1/20, at t = 100 s (the 20 s straight-line fit of this
    # exponential crosses 6 C/h at 100.2 s, computed noise-free); the warm-up lasts at least 30 s
    expected = max(10.0 + 30.0 * math.log(20.0), t[0] + 30.0)
    assert t[-1] == pytest.approx(expected, abs=5.0)
    last = t >= t[-1] - 20.0
    assert abs(np.polyfit(t[last], temp[last], 1)[0] * 3600.0) < 6.0
    if t[0] < 60.0:                        # it did wait for the temperature, not only 30 s
        early = t <= t[0] + 20.0
        assert abs(np.polyfit(t[early], temp[early], 1)[0] * 3600.0) > 6.0


def test_manual6_is_found_in_one_continuous_recording(tmp_path):
    truth = default_truth(5)
    scheme = load_scheme("manual6")
    config = Config(run=RunConfig(**LOSS_AT_SPEED, operator=True))
    plan = compile_scheme(scheme, config)
    speed = 50.0
    with BenchServer(truth, BenchOptions(speed=speed, seed=5, axes=3, lossless=True)) as bench:
        hands_table = twin_table(bench)
        hands_table.close_interlocks()
        writer = new_writer(tmp_path / "cap", "manual6", extra={"table": {"angle_error_arcsec": 3600.0}})
        seq, _, imu = sequencer(bench, config, writer, Hands(bench, hands_table, speed), table=False)
        seq.run(plan.steps)
        hands_table.stop()
        hands_table.close()
        imu.close()
    capture = read_capture(tmp_path / "cap")
    assert [s.name for s in capture.complete()] == ["session"] + [s.name for s in scheme.segments]
    session = capture.segment("session")
    for seg in capture.complete("static"):
        assert len(seg.data.t) >= 10 * 100
        assert np.abs(seg.data.gyro).max() < 0.05                     # still: Earth rate and noise
        up = seg.data.accel.mean(axis=0)
        assert np.degrees(np.arccos(up @ seg.up_body / np.linalg.norm(up))) < 1.0   # tilt errors only
        i = np.searchsorted(session.data.t, seg.data.t[0])
        np.testing.assert_array_equal(session.data.accel[i:i + len(seg.data.t)], seg.data.accel)
    for seg in capture.complete("rotation"):
        assert seg.angle_deg == 360.0 and seg.rate_dps > 0
        turned = np.sum(seg.data.gyro, axis=0) / 100.0
        assert np.linalg.norm(turned) == pytest.approx(360.0, rel=0.01)
        assert np.degrees(np.arccos(turned @ seg.axis_body / np.linalg.norm(turned))) < 1.0
        rest = np.linalg.norm(seg.data.gyro, axis=1)
        assert rest[:10].max() < 0.05 and rest[-10:].max() < 0.05        # from rest to rest
        assert seg.extra["motion"] == "hand"
    # the estimator takes the hand turns (angle_deg by protocol); its accuracy on such captures is
    # the estimator's business (docs/sequencer.md)
    assert estimate_with(capture)[1] == "lsq"


def test_after_a_pause_the_operator_can_continue_in_place(bench3, tmp_path):
    """Ctrl-C during a dwell, then 'continue': the table was at rest, the segment starts again
    (the interrupted attempt kept aside as .incomplete) and the run completes."""
    import threading

    from station.bench.sequencer import Interrupts

    scheme = scheme_from_text("name: two\ndefaults: {dwell_s: 30}\nsegments:\n  - {static: zup, up_body: [0, 0, 1]}\n"
                              "  - {static: xup, up_body: [1, 0, 0]}\n", "two.yaml")
    config = Config(table=TableConfig(axes=3), run=RunConfig(**LOSS_AT_SPEED, operator=False, settle_s=1))
    interrupts = Interrupts()

    class Continue(Hands):
        def resume_after_pause(self, interrupts):
            self.seen.append(("paused", [bench3.table.read_rate(a) for a in (1, 2, 3)]))
            return True

    operator = Continue(bench3)
    seq, table, imu = sequencer(bench3, config, new_writer(tmp_path / "cap"), operator, paced=True)
    seq.interrupts = interrupts

    def ctrl_c():                    # once xup is being recorded
        while not (tmp_path / "cap" / "xup.csv").exists() or (tmp_path / "cap" / "xup.csv").stat().st_size < 3000:
            time.sleep(0.005)
        interrupts.count = 1

    threading.Thread(target=ctrl_c, daemon=True).start()
    seq.run(compile_scheme(scheme, config).steps)
    table.close()
    imu.close()
    assert operator.seen == [("paused", [0.0, 0.0, 0.0])]
    capture = read_capture(tmp_path / "cap")
    assert [(s.name, s.status) for s in capture.segments] == [("zup", "complete"), ("xup", "complete")]
    assert len(capture.segment("xup").data.t) == 3000
    assert (tmp_path / "cap" / "xup.csv.incomplete").stat().st_size > 0



class _ScriptedHands:
    """A hand scheme's IMU without devices: still (noise only) except for the turns the operator
    makes when asked (about z at 45 deg/s), the first ``first_delay_s`` of device time after
    being asked, the others 5 s after."""

    def __init__(self, angles, first_delay_s):
        self.angles, self.first_delay_s = list(angles), first_delay_s
        self.asked = 0
        self.k = 0                          # samples made so far (100 Hz)
        self.turns = []                     # (first sample, last sample + 1)
        self.rng = np.random.default_rng(7)

    def act(self, step):
        angle = self.angles[min(self.asked, len(self.angles) - 1)]
        first = self.k + int(round(100 * (self.first_delay_s if self.asked == 0 else 5.0)))
        self.asked += 1
        self.turns.append((first, first + int(round(angle / 45.0 * 100))))

    def take(self, n):
        from drivers.samples import ImuSamples

        k = np.arange(self.k, self.k + n)
        self.k += n
        gyro = self.rng.normal(0.0, 0.01, (n, 3))
        for a, b in self.turns:
            gyro[(k >= a) & (k < b), 2] += 45.0
        accel = np.array([0.0, 0.0, 9.81]) + self.rng.normal(0.0, 0.01, (n, 3))
        return ImuSamples(k / 100.0, accel, gyro, np.full(n, 25.0))


def test_a_hand_turn_is_waited_for_at_a_bounded_cost_and_asked_again_when_wrong(monkeypatch):
    """The operator waits 3 minutes before turning, then turns 180 deg instead of 360: every
    look of the sequencer covers a bounded stretch of data (before, all the data since the step
    began: the cost of a look grew with the wait), the angle is said and the operator asked
    again (before, the sequencer waited for ever for a turn nobody was asked to make again)."""
    from station.bench import manual
    from station.bench.plan import HandRotation

    class Segment:
        def write(self, *a):
            pass

    class Writer:
        def begin_segment(self, *a, **k):
            return Segment()

    class Display:
        def __init__(self):
            self.notes, self.prompts = [], []

        def prompt(self, text):
            self.prompts.append(text)

        def note(self, text):
            self.notes.append(text)

        def values_update(self, values):
            pass

    # 3 minutes (10 before: the scripted samples and the looks at them were the test's time);
    # a look covering all the data since the step began would see 18 000 samples, 9 x the bound
    hands = _ScriptedHands([180.0, 360.0], first_delay_s=180.0)
    looked = []
    real_detect = manual.detect

    def detect(t, accel, gyro, **kw):
        looked.append(len(t))
        return real_detect(t, accel, gyro, **kw)

    monkeypatch.setattr(manual, "detect", detect)
    monkeypatch.setattr(manual, "_segment_names", lambda writer: [])
    seq = type("Seq", (), {})()
    seq.rate_hz, seq.display, seq.operator = 100.0, Display(), hands
    seq.stream = type("Stream", (), {"live": lambda self: {}, "counters": None})()
    seq._take, seq._progress, seq._check_pause = hands.take, lambda n: None, lambda: None
    seq._session = manual.Session(Writer(), 100.0)
    manual._feed(seq, seq._session, 10.0)                       # still before the step
    step = HandRotation("turn", "rotz", 10.0, spec=RotationSpec("rotz", (0.0, 0.0, 1.0), 45.0, 8.0,
                                                                 encoder=False, turn_deg=360.0),
                        instruction="turn the IMU one whole turn about z")
    manual.hand_step(seq, step)
    assert hands.asked == 2                                      # asked again after the 180 deg
    assert any("turned 180 deg, not 360" in n for n in seq.display.notes)
    assert seq.display.notes[-1] == "rotz: turned 360 deg"
    assert seq.display.prompts == [step.instruction] * 2
    assert seq._session.n > 18_000 and max(looked) < 2_000       # at most 20 s of 3 minutes
