"""The warm-up of a resumed or extended run (issue 28, nineteenth session).

`station run --resume` and `--append` on a bench, and `run --sim --append`, wait the configured
warm-up again before their first segment, decided by the IMU's temperature then
(station.bench.plan.resumed_warmup: with a slope rule, without the minimum counted from power-on,
so that an IMU still warm passes after one window of readings and one switched off meanwhile
warms up again), and keep its readings as the capture's next warm-up record (warmup-2.csv, ...):
the first run's warmup.csv is never overwritten.  The bench (the sequencer over the twins' real
pseudo-terminals) and the dry run write the same files.

Expected durations are derived from the simulated IMU's exponential warm-up (tau, delta) and the
rule's window, not taken from the code under test; the slopes are checked with numpy's polyfit
(the sequencer's and the dry run's slope code is not used here)."""
from __future__ import annotations

import io
import math

import numpy as np
import pytest
from rich.console import Console

from drivers.base import ImuSettings
from drivers.registry import DEFAULT_IMU_PROTOCOL, open_imu, open_table
from drivers.table import TableSettings
from sim_devices.truth import default_truth
from sim_devices.twins.serve import BenchOptions, BenchServer
from station.bench.compile import compile_scheme
from station.bench.config import Config, RunConfig, TableConfig, WarmupConfig, normal_gravity
from station.bench.live import PlainDisplay
from station.bench.sequencer import Interrupts, RunPaused, Sequencer
from station.io.capture import CaptureWriter, ImuInfo, Site, read_capture
from station.io.scheme import scheme_from_text

SPEED = 200.0
#: the table driver's waits read the table every 10 ms of a real table's time: at the twins' speed
#: (its arrival rule, 5 reads in a row within the tolerances, unchanged in device time)
TWIN_POLL_S = 0.01 / SPEED
RATE_HZ = 25.0
TAU_S, DELTA_C = 30.0, 1.0        # the simulated IMU's warm-up: dT/dt = 120 C/h exp(-t / 30 s)
SLOPE_C_PER_H, WINDOW_S, MIN_S = 6.0, 20.0, 60.0
# from power-on the 20 s straight-line fit crosses 6 C/h at about 100 s (exp(-(t - 10 s)/30 s)
# = 1/20); the minimum of 60 s is below it, so the first warm-up ends on the slope
FIRST_END_S = 10.0 + TAU_S * math.log(120.0 / SLOPE_C_PER_H)
WARMUP = WarmupConfig(duration_s=MIN_S, max_s=2000.0, temp_slope_c_per_h=SLOPE_C_PER_H, window_s=WINDOW_S)
RUN = "name: z\ndefaults: {dwell_s: 2}\nsegments:\n  - {static: zup, up_body: [0, 0, 1]}\n"
WHOLE = RUN + "  - {static: zup2, up_body: [0, 0, 1]}\n"


def _truth():
    truth = default_truth(4)
    truth.temperature.warmup_delta_c = DELTA_C
    truth.temperature.warmup_time_constant_s = TAU_S
    return truth


def _config():
    return Config(table=TableConfig(axes=1), warmup=WARMUP,
                  run=RunConfig(operator=False, settle_s=1, max_missing_fraction=0.5, max_gap_s=100.0))


class PauseAfter(Interrupts):
    """Ctrl-C once the run has looked ``checks`` times whether it was asked to pause (the warm-up
    looks once a reading, a second of device time)."""

    def __init__(self, checks: int):
        super().__init__()
        self.checks = checks

    @property
    def pause_requested(self) -> bool:
        self.checks -= 1
        return self.checks < 0


class NobodyThere:
    """No operator at the bench: a paused run stops (``station run --resume`` continues it)."""

    def resume_after_pause(self, interrupts):
        return False


def _run(bench, writer, steps, interrupts=None, config=None, imu_protocol=DEFAULT_IMU_PROTOCOL,
         imu_settings=None, table_settings=None):
    """``steps`` run by the sequencer on the twins (a new connection, as a new station run);
    ``config`` _config()'s unless given, the IMU's frames waited for 10 s unless ``imu_settings``."""
    table = open_table(bench.table_path, settings=table_settings or TableSettings(poll_interval_s=TWIN_POLL_S))
    imu = open_imu(bench.imu_path, imu_protocol, settings=imu_settings or ImuSettings(frame_timeout_s=10.0))
    try:
        rate = imu.configure(RATE_HZ)
        Sequencer(table=table, imu=imu, writer=writer, config=config or _config(), operator=NobodyThere(),
                  rate_hz=rate, interrupts=interrupts,
                  display=PlainDisplay(Console(file=io.StringIO(), width=200), 1.0, "test")).run(steps)
    finally:
        table.close()
        imu.close()


def _rows(path):
    rows = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    return rows[:, 0], rows[:, 1]


def _end(t, least=MIN_S):
    """Where a warm-up from power-on whose readings are ``t`` ends: the slope's end, or the
    minimum ``least`` after its first sample (a second before its first reading) when later --
    on a loaded machine the twins' clock runs on before the sequencer reads (seen: 40-80 s)."""
    return max(FIRST_END_S, t[0] - 1.0 + least)


def _slope_c_per_h(t, temp):
    return float(np.polyfit(t, temp, 1)[0] * 3600.0)


def _warmups(directory):
    return sorted(p.name for p in directory.glob("warmup*.csv"))


@pytest.mark.parametrize("power_cycled", [False, True], ids=["warm", "switched-off"])
def test_a_resumed_bench_run_keeps_the_first_warm_up_and_warms_up_by_the_temperature(tmp_path, power_cycled):
    """The run records zup after its warm-up and stops; `--resume` of the run extended by zup2
    (what --append does: station.cli.run_bench._resume_steps of the compiled whole) waits the
    warm-up again: an IMU left on passes after one window (well below the 60 s minimum of the
    first); one switched off meanwhile (the twins restarted: the IMU powered on again, cold)
    warms up until the slope is below the limit again.  warmup.csv is kept byte for byte."""
    from station.cli.run_bench import _resume_steps

    truth, config = _truth(), _config()
    cap = tmp_path / "cap"
    server = BenchServer(truth, BenchOptions(speed=SPEED, seed=4, axes=1, lossless=True))
    with server as bench:
        writer = CaptureWriter(cap, ImuInfo(RATE_HZ, "m/s^2", "deg/s"), Site(normal_gravity(45.0), 45.0), "z")
        _run(bench, writer, compile_scheme(scheme_from_text(RUN, "z.yaml"), config).steps)
        first = (cap / "warmup.csv").read_bytes()
        whole = scheme_from_text(WHOLE, "z.yaml")
        steps = _resume_steps(compile_scheme(whole, config), whole, {"zup"}, config)
        if not power_cycled:
            _run(bench, CaptureWriter.reopen(cap), steps)
    if power_cycled:
        with BenchServer(truth, BenchOptions(speed=SPEED, seed=5, axes=1, lossless=True)) as bench:
            _run(bench, CaptureWriter.reopen(cap), steps)
    assert _warmups(cap) == ["warmup-2.csv", "warmup.csv"]
    assert (cap / "warmup.csv").read_bytes() == first                  # never overwritten
    t1, _ = _rows(cap / "warmup.csv")
    assert t1[-1] == pytest.approx(_end(t1), abs=5.0)
    t2, temp2 = _rows(cap / "warmup-2.csv")
    last = t2 >= t2[-1] - WINDOW_S
    assert abs(_slope_c_per_h(t2[last], temp2[last])) < SLOPE_C_PER_H
    span = t2[-1] - t2[0]
    if power_cycled:
        # cold again: the same end as from power-on (the IMU's clock went back: the slope and
        # the minimum of 60 s from the first sample decide, not one window)
        assert t2[-1] == pytest.approx(_end(t2), abs=5.0)
        if t2[0] < FIRST_END_S - WINDOW_S - 10.0:
            assert span > WINDOW_S + 5.0
    else:
        # warm: after the run (t > 100 s) the slope is < 120 C/h e^-3.3 = 4.4 C/h: one window
        # of readings (20 s, the first reading a second after the resume) and no more
        assert t2[0] > t1[-1] and span == pytest.approx(WINDOW_S, abs=2.0)
    # the dry run's rule (station run --sim --append) on the same IMU begun at the same moment
    # ends at the same reading, to a reading (the bench's readings are means of a second of samples)
    from station.simulate import dryrun

    begun = t2[0] - 1.0         # (switched off: the dry run's rule of a first warm-up, from there)
    assert begun + dryrun.warmup_seconds(WARMUP, truth.temperature, begun, resumed=not power_cycled) == \
        pytest.approx(t2[-1], abs=1.5)
    capture = read_capture(cap, load_data=True)
    assert [s.name for s in capture.complete()] == ["zup", "zup2"]
    assert capture.segment("zup2").data.t[0] > t2[-1]         # the segment after its warm-up


SIX = ("name: six\ndefaults: {dwell_s: 4}\nsegments:\n" + "".join(
    f"  - {{static: {n}, up_body: {u}}}\n" for n, u in (("zu", [0, 0, 1]), ("zd", [0, 0, -1]), ("xu", [1, 0, 0]),
                                                      ("xd", [-1, 0, 0]), ("yu", [0, 1, 0]), ("yd", [0, -1, 0]))))


def test_a_dry_runs_append_keeps_the_first_warm_up_and_writes_what_the_bench_writes(tmp_path, monkeypatch, capsys):
    """`run --sim --append` with the configured warm-up (station.yaml, as the run had it): the
    extension's warm-up is waited for on the simulated IMU as warm as the run left it (one window,
    as the bench's), kept as warmup-2.csv after the run's warmup.csv (untouched), stamped on the
    capture's clock between the run's last segment and the extension's first."""
    import yaml

    from station.cli import main

    (tmp_path / "truth.yaml").write_text(yaml.safe_dump(_truth().to_yaml_dict(), sort_keys=False))
    (tmp_path / "station.yaml").write_text(f"version: 1\nwarmup: {{duration_s: {MIN_S:g}, max_s: {WARMUP.max_s:g}, "
                                           f"temp_slope_c_per_h: {SLOPE_C_PER_H:g}, window_s: {WINDOW_S:g}}}\n")
    (tmp_path / "six.yaml").write_text(SIX)
    (tmp_path / "ext.yaml").write_text("name: ext\ndefaults: {dwell_s: 4}\nsegments:\n"
                                       "  - {static: x1_zu, up_body: [0, 0, 1]}\n")
    monkeypatch.chdir(tmp_path)
    common = ["--config", "station.yaml", "--no-history"]
    assert main(["run", "--scheme", "six.yaml", "--sim", "--seed", "4", "--sim-truth", "truth.yaml", "--out", "cap",
                 *common]) == 0
    cap = tmp_path / "cap"
    first = (cap / "warmup.csv").read_bytes()
    assert main(["run", "--sim", "--append", "cap", "--scheme", "ext.yaml", *common]) == 0
    capsys.readouterr()
    assert _warmups(cap) == ["warmup-2.csv", "warmup.csv"]            # the files the bench writes
    assert (cap / "warmup.csv").read_bytes() == first
    t1, _ = _rows(cap / "warmup.csv")
    t2, temp2 = _rows(cap / "warmup-2.csv")
    assert t1[-1] == pytest.approx(_end(t1), abs=5.0)
    capture = read_capture(cap, load_data=True)
    run_end, ext = capture.segment("yd").data.t[-1], capture.segment("x1_zu").data.t
    assert run_end < t2[0] and t2[-1] < ext[0]
    assert t2[-1] - t2[0] == pytest.approx(WINDOW_S, abs=2.0)
    last = t2 >= t2[-1] - WINDOW_S
    assert abs(_slope_c_per_h(t2[last], temp2[last])) < SLOPE_C_PER_H


def test_a_warm_up_cut_short_by_a_pause_is_kept_and_the_resume_warms_up_in_full(tmp_path):
    """Ctrl-C 10 readings into the first warm-up: the run stops with those readings kept in
    warmup.csv (they were lost before); `--resume` (no segment recorded yet: the warm-up from
    power-on never ended) waits the whole rule again, the 60 s minimum too, into warmup-2.csv."""
    from station.cli.run_bench import _resume_steps

    truth, config = _truth(), _config()
    cap = tmp_path / "cap"
    scheme = scheme_from_text(RUN, "z.yaml")
    with BenchServer(truth, BenchOptions(speed=SPEED, seed=4, axes=1, lossless=True)) as bench:
        writer = CaptureWriter(cap, ImuInfo(RATE_HZ, "m/s^2", "deg/s"), Site(normal_gravity(45.0), 45.0), "z")
        with pytest.raises(RunPaused):
            _run(bench, writer, compile_scheme(scheme, config).steps, interrupts=PauseAfter(10))
        first = (cap / "warmup.csv").read_bytes()
        t1, _ = _rows(cap / "warmup.csv")
        assert len(t1) == 10 and not read_capture(cap, load_data=False).segments
        _run(bench, CaptureWriter.reopen(cap), _resume_steps(compile_scheme(scheme, config), scheme, set(), config))
    assert _warmups(cap) == ["warmup-2.csv", "warmup.csv"] and (cap / "warmup.csv").read_bytes() == first
    t2, temp2 = _rows(cap / "warmup-2.csv")
    # the minimum applied (the resumed rule's one window, 20 s, or the slope's end near 100 s
    # would have ended it sooner), and the slope below the limit at its end
    assert t2[-1] - t2[0] >= MIN_S - 1.0
    last = t2 >= t2[-1] - WINDOW_S
    assert abs(_slope_c_per_h(t2[last], temp2[last])) < SLOPE_C_PER_H


def test_a_resume_after_a_power_cycle_waits_the_configured_minimum_from_the_imus_power_on(tmp_path):
    """The minimum duration_s counts from the IMU's power-on (what resumed_warmup drops it for):
    an IMU switched off while the run was stopped (the twins restarted: their clock, the IMU's
    time since startup, from 0 again, the IMU cold) has been on for less than it at the resume,
    and its clock says so (its stamps went back below the capture's).  With a minimum longer than
    the slope's end (240 s against ~100 s from power-on) the resumed warm-up must not end before
    the IMU has been on for the minimum -- the slope alone cannot tell an IMU that has not
    started warming yet (a sensor lagging the heat source, a coarse temperature LSB) from a warm
    one.  (Before the fix: ended at the slope's end, ~100 s after power-on.)"""
    from station.cli.run_bench import _resume_steps

    least = 240.0
    truth = _truth()
    config = Config(table=TableConfig(axes=1), warmup=WarmupConfig(duration_s=least, max_s=2000.0,
                                                                     temp_slope_c_per_h=SLOPE_C_PER_H,
                                                                     window_s=WINDOW_S),
                    run=RunConfig(operator=False, settle_s=1, max_missing_fraction=0.5, max_gap_s=100.0))

    def run(bench, writer, steps):
        _run(bench, writer, steps, config=config)

    cap = tmp_path / "cap"
    scheme = scheme_from_text(RUN, "z.yaml")
    with BenchServer(truth, BenchOptions(speed=SPEED, seed=4, axes=1, lossless=True)) as bench:
        writer = CaptureWriter(cap, ImuInfo(RATE_HZ, "m/s^2", "deg/s"), Site(normal_gravity(45.0), 45.0), "z")
        run(bench, writer, compile_scheme(scheme, config).steps)
    whole = scheme_from_text(WHOLE, "z.yaml")
    steps = _resume_steps(compile_scheme(whole, config), whole, {"zup"}, config)
    with BenchServer(truth, BenchOptions(speed=SPEED, seed=5, axes=1, lossless=True)) as bench:   # switched on again
        run(bench, CaptureWriter.reopen(cap), steps)
    t2, _ = _rows(cap / "warmup-2.csv")
    # the twins' device time is the IMU's time since power-on; its first sample a second before
    # the first reading
    assert t2[-1] >= least - 1.0, f"the resumed warm-up ended {t2[-1]:.1f} s after the IMU's power-on"
    assert read_capture(cap, load_data=True).segment("zup2").data.t[0] > t2[-1]


def test_the_next_warm_up_record_never_takes_the_name_of_a_link_left_in_the_capture(tmp_path):
    """A symbolic link named warmup-2.csv (a user's, to a disk not mounted now; or to a file
    moved away) is a name taken: the resume's record goes to the next free name, and writing it
    neither fails after the whole warm-up (a link outside the capture is refused by write_file:
    ValueError, a traceback, the record lost) nor replaces the link."""
    from station.io.capture import warmup_file

    cap = tmp_path / "cap"
    writer = CaptureWriter(cap, ImuInfo(RATE_HZ, "m/s^2", "deg/s"), Site(normal_gravity(45.0), 45.0), "z")
    writer.write_file(warmup_file(cap), "t_s,temp_c\n1.000,25.0000\n")
    (cap / "warmup-2.csv").symlink_to(tmp_path / "unmounted" / "warmup-2.csv")
    (cap / "warmup-3.csv").symlink_to("warmup-3.csv.moved")
    name = warmup_file(cap)
    writer.write_file(name, "t_s,temp_c\n900.000,26.0000\n")
    assert name == "warmup-4.csv"
    assert (cap / "warmup-2.csv").is_symlink() and (cap / "warmup-3.csv").is_symlink()


@pytest.mark.parametrize("power_cycled", [False, True], ids=["warm", "switched-off"])
def test_a_host_stamped_imu_switched_off_waits_the_minimum_and_a_warm_one_does_not(tmp_path, power_cycled):
    """An IMU whose lines are stamped by the host's clock (a logger stamping each line as it
    arrives: the csv twin with ``csv_clock_start_s``) never has its clock go back, so
    _clock_restarted cannot see it switched off.  What the capture then holds is the temperature:
    switched off while the run was stopped (the twins started again, cold, their stamps going on
    from after the run's last: a pause of 50 s), its first reading is below the capture's last
    (by what it has not warmed again yet of its 5 C) far beyond the readings' noise, and the
    resume must wait the minimum (240 s from its first reading, not the slope's end near 183 s
    from power-on); left on, it is as warm as the run left it and passes after one window
    (20 s).  (Before the change: the switched-off IMU's resumed warm-up ended on the slope.)"""
    from drivers.protocols.csvlines import CsvFormat
    from drivers.transport import SerialSettings
    from station.cli.run_bench import _resume_steps

    least = 240.0
    truth = _truth()
    truth.sample_rate_hz = RATE_HZ
    # a warm-up of 5 C over tau 40 s: its slope falls below 6 C/h about 183 s after power-on (before
    # the minimum), and an IMU switched on again is still measurably cold (5 exp(-t/40) C below)
    # however long the twins' clock ran before the first reading on a loaded machine (0.3-0.5 C of
    # warming seen with 1 C over 30 s at a load of 23 on 2 cores)
    truth.temperature.warmup_delta_c, truth.temperature.warmup_time_constant_s = 5.0, 40.0
    config = Config(table=TableConfig(axes=1), warmup=WarmupConfig(duration_s=least, max_s=2000.0,
                                                                     temp_slope_c_per_h=SLOPE_C_PER_H,
                                                                     window_s=WINDOW_S),
                    run=RunConfig(operator=False, settle_s=1, max_missing_fraction=0.5, max_gap_s=100.0))
    host_s = 5000.0                  # the host's clock at the IMU's first power-on

    def options(seed, start_s):
        return BenchOptions(speed=SPEED, seed=seed, axes=1, lossless=True, imu_protocol="csv",
                            csv_format=CsvFormat(), csv_clock_start_s=start_s)

    def run(bench, writer, steps):
        # (replies within 10 s: on a loaded machine the table's first reply once took over 1 s)
        _run(bench, writer, steps, config=config, imu_protocol="csv",
             imu_settings=ImuSettings(frame_timeout_s=10.0, csv_format=CsvFormat()),
             table_settings=TableSettings(serial=SerialSettings(timeout_s=10.0), poll_interval_s=TWIN_POLL_S))

    cap = tmp_path / "cap"
    whole = scheme_from_text(WHOLE, "z.yaml")
    with BenchServer(truth, options(4, host_s)) as bench:
        writer = CaptureWriter(cap, ImuInfo(RATE_HZ, "m/s^2", "deg/s"), Site(normal_gravity(45.0), 45.0), "z")
        run(bench, writer, compile_scheme(scheme_from_text(RUN, "z.yaml"), config).steps)
        steps = _resume_steps(compile_scheme(whole, config), whole, {"zup"}, config)
        if not power_cycled:
            run(bench, CaptureWriter.reopen(cap), steps)
    t1, temp1 = _rows(cap / "warmup.csv")
    assert t1[0] > host_s
    if power_cycled:
        ended = float(read_capture(cap, load_data=True).segment("zup").data.t[-1])
        with BenchServer(truth, options(5, ended + 50.0)) as bench:       # switched on again, 50 s later
            run(bench, CaptureWriter.reopen(cap), steps)
    t2, temp2 = _rows(cap / "warmup-2.csv")
    assert t2[0] > t1[-1]                                      # the host's clock went on
    if power_cycled:
        assert temp1[-1] - temp2[0] > 0.01                     # colder again (the twin: from the room)
        # its power-on a second before its first reading at the most
        assert t2[-1] - t2[0] >= least - 1.0, f"the resumed warm-up ended {t2[-1] - t2[0]:.1f} s after its start"
    else:
        assert temp2[0] >= temp1[-1] - 1e-3
        assert t2[-1] - t2[0] == pytest.approx(WINDOW_S, abs=2.0)      # one window, not the minimum
    assert read_capture(cap, load_data=True).segment("zup2").data.t[0] > t2[-1]


def test_a_temperature_drop_within_the_readings_noise_is_not_a_restart(tmp_path):
    """The drop is judged against the noise of the capture's own readings (the newest warm-up
    record's scatter about a line over the slope rule's window): a noisy sensor (1-s readings of
    sd 0.05 C) left on, whose first reading at the resume is 2.5 sd of one reading below the
    last one recorded, is not held back (5000 pairs of such readings: the rule's false alarms at
    most 1 %, counted here); one switched off, 1 C colder, is."""
    from station.bench.sequencer import _temperature_fell

    rng = np.random.default_rng(7)
    sd = 0.05
    t = np.arange(0.0, 120.0, 1.0)
    temp = np.round(26.0 + sd * rng.standard_normal(t.size), 4)
    cap = tmp_path / "cap"
    cap.mkdir()
    (cap / "warmup.csv").write_text("t_s,temp_c\n" + "".join(f"{a:.3f},{b:.4f}\n" for a, b in zip(t, temp)))
    last = temp[-1]
    assert _temperature_fell(cap, last - 2.5 * sd, WINDOW_S) is None
    assert _temperature_fell(cap, last - 1.0, WINDOW_S) is not None
    # the false alarms of a warm IMU: both readings noisy about the same temperature
    _, threshold = _temperature_fell(cap, last - 1.0, WINDOW_S)
    pairs = sd * rng.standard_normal((5000, 2))
    assert np.mean(pairs[:, 0] - pairs[:, 1] > threshold) <= 0.01
    assert threshold < 0.5                     # a switched-off IMU's drop of a fraction of a degree is seen


def _record(path, t, temp):
    path.write_text("t_s,temp_c\n" + "".join(f"{a:.3f},{b:.4f}\n" for a, b in zip(t, temp)))


@pytest.mark.parametrize("kept", [1, 2])
def test_a_warm_up_cut_short_does_not_make_a_noisy_warm_imu_wait(tmp_path, kept):
    """A resume stopped (Ctrl-C) after its first reading or two keeps them as the newest warm-up
    record (Sequencer._warmup keeps what was read).  The noise of the readings is the sensor's all
    the same (sd 0.05 C, seen over 120 readings of warmup.csv): the next resume of the warm IMU,
    its first reading 1 sd below the last, is not a restart, and one 1 C colder is.  (Review of the
    twentieth session: with the newest record's 1-2 readings taken for the noise, the threshold
    fell to 0.00016 C and half of a warm IMU's resumes waited the minimum.)"""
    from station.bench.sequencer import _temperature_fell

    rng = np.random.default_rng(11)
    sd = 0.05
    cap = tmp_path / "cap"
    cap.mkdir()
    t = np.arange(0.0, 120.0, 1.0)
    _record(cap / "warmup.csv", t, np.round(26.0 + sd * rng.standard_normal(t.size), 4))
    t2 = 500.0 + np.arange(kept)
    temp2 = np.round(26.0 + sd * rng.standard_normal(kept), 4)
    _record(cap / "warmup-2.csv", t2, temp2)
    last = temp2[-1]
    assert _temperature_fell(cap, last - sd, WINDOW_S) is None
    assert _temperature_fell(cap, last - 1.0, WINDOW_S) is not None


def test_a_quantised_sensor_one_step_lower_is_not_a_restart(tmp_path):
    """An IMU whose temperature comes in 0.5 C steps: warm and steady, its last resume's record (one
    window) read one value throughout, and at the next resume it reads one step lower (the
    temperature a hair across a step's edge).  Its resolution was seen in warmup.csv (the steps of
    the first warm-up), so a drop of one step is within it and not a restart; a switched-off IMU,
    2 C colder, is.  (Review of the twentieth session: the resolution was taken from the newest
    record alone, constant, so the threshold was 0.00016 C and the warm IMU waited the minimum.)"""
    from station.bench.sequencer import _temperature_fell

    cap = tmp_path / "cap"
    cap.mkdir()
    t = np.arange(0.0, 300.0, 1.0)
    _record(cap / "warmup.csv", t, np.round((26.0 - 3.0 * np.exp(-t / 60.0)) / 0.5) * 0.5)
    t2 = 900.0 + np.arange(21.0)
    _record(cap / "warmup-2.csv", t2, np.full(t2.size, 26.0))
    assert _temperature_fell(cap, 25.5, WINDOW_S) is None
    assert _temperature_fell(cap, 24.0, WINDOW_S) is not None


@pytest.mark.parametrize("power_cycled", [False, True], ids=["warm", "switched-off"])
def test_a_restarted_warm_up_cut_short_is_still_a_restart_at_the_next_resume(tmp_path, power_cycled):
    """A host-stamped IMU switched off during a pause: the resume sees it cold and warms it up
    again, and is stopped (Ctrl-C) 10 s into that warm-up, which keeps its cold readings as the
    newest warm-up record.  Resumed again at once, the IMU (on for 15 s, still 3.8 C below where
    the run recorded its segments) is still cold: the minimum counted from power-on must apply
    again, as it does for an IMU whose clock went back (its stamps below the first warm-up's).  A
    warm IMU whose resume was stopped likewise is not held back.  (Review of the twentieth
    session: the drop was judged from the cut warm-up's last reading, 21.9 C, and the cold IMU
    passed on the slope.)"""
    from station.bench.sequencer import _temperature_fell

    cap = tmp_path / "cap"
    writer = CaptureWriter(cap, ImuInfo(RATE_HZ, "m/s^2", "deg/s"), Site(normal_gravity(45.0), 45.0), "z")
    t = 5000.0 + np.arange(0.0, 200.0, 1.0)
    _record(cap / "warmup.csv", t, np.round(26.0 - 5.0 * np.exp(-(t - 5000.0) / 40.0), 4))
    ts = 5300.0 + np.arange(250) / RATE_HZ
    with writer.begin_segment("zup", "static", up_body=[0, 0, 1]) as out:
        out.write(ts, np.tile([0.0, 0.0, 9.8], (ts.size, 1)), np.zeros((ts.size, 3)), np.full(ts.size, 26.0))
        out.close("complete", temperature_c=26.0)
    t2 = 5400.0 + np.arange(10.0)
    temp2 = np.round(26.0 - 5.0 * np.exp(-(t2 - 5399.0) / 40.0), 4) if power_cycled else np.full(t2.size, 26.0)
    _record(cap / "warmup-2.csv", t2, temp2)
    first = round(26.0 - 5.0 * np.exp(-15.0 / 40.0), 4) if power_cycled else 26.0
    fell = _temperature_fell(cap, first, WINDOW_S)
    assert (fell is not None) == power_cycled, fell
