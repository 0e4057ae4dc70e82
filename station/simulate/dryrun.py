"""Dry runs: record a scheme on the simulated bench, into a capture bundle or into memory.

Only this module (and only when the user asks for simulation) imports ``sim_devices``.
"""
from __future__ import annotations

import copy
import math
from pathlib import Path
from typing import Callable, Iterator

import numpy as np
import yaml

from station.core.errors import UserError
from station.io.capture import Capture, DeferredCaptureWriter, ImuInfo, Segment, SegmentData, Site
from station.io.scheme import RAMP_REST_S, RotationSpec, Scheme

BLOCK_SECONDS = 10.0     # samples are written and flushed in blocks of this length
TRUTH_FILE = "sim_truth.yaml"
PLATTER_FILE = "sim_platter.yaml"      # the twin's state carried to an --append session (issue 28)
# a recorded ramp's acceleration on the simulated table without a configured table: station.yaml's
# default rate_accel_dps2 (station.bench.config.AxisConfig); a configured table's own is passed
# in (``ramp_accel_dps2``: table_ramp_accel of station.yaml's table, issue 28 review item 4)
RAMP_ACCEL_DPS2 = 50.0


def table_ramp_accel(table) -> float:
    """The acceleration (deg/s^2) a dry run's recorded ramps take on the configured ``table``
    (station.bench.config.TableConfig): its axes' rate_accel_dps2, the slowest (the simulated bench
    turns a body axis, not a table axis; the slowest's ramp is the longest a window holds)."""
    values = [float(lim.rate_accel_dps2) for lim in getattr(table, "limits", ()) or ()]
    return min(values) if values else RAMP_ACCEL_DPS2
# the keys a simulated rotation reports as the bench does (written when it closes)
SEGMENT_KEYS = ("angle_deg", "table_axis", "record_ramp", "ramp_accel_dps2", "rate_start_dps", "rate_end_dps")


def load_truth(truth_path: str | None, seed: int):
    from sim_devices.truth import Truth, default_truth

    return Truth.from_yaml(truth_path) if truth_path else default_truth(seed)


MAX_SIMULATED_SAMPLES = 5_000_000   # per segment: the simulator holds a segment whole (~1 GB at this)


WARMUP_READ_S = 1.0       # the station reads the IMU's temperature this often during a warm-up (sequencer)
MAX_SIMULATED_WARMUP_S = 7 * 86400.0     # a longer configured warm-up is refused by the dry run (one line)


def warmup_seconds(warmup, temperature, start_s: float = 0.0, resumed: bool = False) -> float:
    """How long the configured ``warmup`` (station.yaml ``warmup:``, station.bench.config.WarmupConfig:
    duration_s, max_s, temp_slope_c_per_h, window_s; None: none) lasts on the simulated IMU powered
    on at bench time 0, whose temperature is ``temperature.at(t)`` (sim_devices/truth.py
    TemperatureTruth; or a function of t), begun at bench time ``start_s``: the sequencer's rule
    (station/bench/sequencer.py ``_warmup``) on readings a second apart -- at least ``duration_s``,
    then until the least-squares slope over the last ``window_s`` is below ``temp_slope_c_per_h``
    or ``max_s`` is reached; without a slope rule ``duration_s`` exactly.  ``resumed``: the warm-up
    of a resumed or extended run (station.bench.plan.resumed_warmup): with a slope rule, without
    the minimum ``duration_s`` (a warm IMU passes after one window).  0 without a warm-up."""
    if warmup is None:
        return 0.0
    at = temperature.at if hasattr(temperature, "at") else temperature
    least = max(0.0, float(warmup.duration_s))
    if least > MAX_SIMULATED_WARMUP_S:
        raise UserError(f"warmup.duration_s: {least:g} s is longer than a dry run simulates a warm-up "
                        f"({MAX_SIMULATED_WARMUP_S:g} s, a week)")
    if warmup.temp_slope_c_per_h is None:
        return least
    if resumed:
        least = 0.0
    limit = float(warmup.temp_slope_c_per_h) / 60.0     # C/min, compared as SlopeSettle compares
    window = float(warmup.window_s)
    most = max(least, float(warmup.max_s)) if warmup.max_s is not None else math.inf
    # SlopeSettle's rule (station.core.chamber: the least-squares slope of the readings x_j >= x - window_s,
    # x from the first reading, once x >= window_s and three readings are in it), for an hour of
    # readings a second at once: the readings are evenly spaced, so every full window holds the same
    # count and the slope is one linear filter of the temperatures (numpy.convolve; it was
    # SlopeSettle.feed a reading at a time: 3.7 s of CPU for a week's readings, eighteenth session)
    n = int(np.count_nonzero(WARMUP_READ_S * np.arange(int(window / WARMUP_READ_S) + 2) <= window))
    k = np.arange(n) - 0.5 * (n - 1)
    weights = k / (WARMUP_READ_S * float(k @ k)) if n >= 3 else None      # C/s per reading, newest last
    done = 0                                      # readings before this hour
    before = np.empty(0)                          # the last n - 1 of them (the first window's start)
    while done * WARMUP_READ_S < MAX_SIMULATED_WARMUP_S:         # (an hour of readings at a time)
        t = WARMUP_READ_S * (done + 1 + np.arange(3600))
        t = t[t <= MAX_SIMULATED_WARMUP_S]
        temps = _warmup_readings(float(start_s) + t, at)
        x = t - WARMUP_READ_S                     # from the first reading
        settled = np.zeros(t.size, bool)
        if weights is not None:
            both = np.concatenate([before, temps])
            if both.size >= n:                    # (a window longer than the readings so far: none full)
                slope = np.convolve(both - both[-1], weights[::-1], mode="valid")     # ending at each reading
                slope = np.concatenate([np.full(t.size - slope.size, np.nan), slope])
                settled = (x >= window) & (np.abs(slope * 60.0) < limit)
            before = both[-(n - 1):]
        stop = (t >= least) & (settled | (t >= most))
        if stop.any():
            return float(t[np.argmax(stop)])
        done += t.size
    raise UserError(f"warmup: the simulated IMU's temperature slope is still above temp_slope_c_per_h "
                    f"({warmup.temp_slope_c_per_h:g} C/h) after {MAX_SIMULATED_WARMUP_S:g} s (a week), and max_s "
                    f"({most:g} s) is longer: a dry run simulates a warm-up of at most a week")


def _warmup_readings(t, at) -> np.ndarray:
    """The warm-up's temperature readings stamped at ``t`` as the sequencer takes them (``at``: the
    IMU's temperature at a time): each the mean of the second of samples it ends (on the simulated
    warm-up's exponential, its temperature half a second before, to 1e-7 degC), rounded to the
    0.1 mK warmup.csv keeps, on which the sequencer decides.  (The exact temperature at the stamp
    ended a 3 s window's warm-up 56 s later than the sequencer: 0.1 mK steps are 0.12 C/h there.)"""
    return np.round(at(np.asarray(t, dtype=float) - 0.5 * WARMUP_READ_S), 4)


def _bench(scheme: Scheme, truth, seed: int, start_s: float = 0.0, chamber=None, ramp_accel_dps2=None,
           warmup=None):
    """The simulated bench for ``scheme`` (its clock from ``start_s``; ``warmup``: the configured
    warm-up, station.yaml's, waited for first -- the IMU powered on at ``start_s``, warming as its
    physics says, the first segment recorded after it: warmup_seconds); UserError naming the segment
    when one gives fewer than 2 samples, or more than the simulator holds at once, or sets a
    temperature chamber that ``chamber`` (station.core.chamber.ChamberConfig) does not provide,
    before anything is simulated or written."""
    from sim_devices.bench import SimulatedBench

    check_chamber(scheme, chamber)
    bench = SimulatedBench(_mounted(truth, scheme), seed, start_s=start_s)
    bench.station_warmup_s = warmup_seconds(warmup, bench.truth.temperature)
    bench.station_warmup_from_s = float(start_s)
    bench.wait(bench.station_warmup_s)
    bench.station_chamber = chamber
    bench.station_ramp_accel_dps2 = ramp_accel_dps2        # None: RAMP_ACCEL_DPS2
    rate_hz = bench.sample_rate_hz
    for spec in scheme.segments:
        n = spec.duration_s * rate_hz
        what = "--dwell-s or the scheme's dwell_s" if spec.kind == "static" else "--rotation-s or the scheme's rotation_s"
        if n < 2:
            raise UserError(f"scheme {scheme.name}: segment {spec.name!r}: {spec.duration_s:g} s gives fewer "
                            f"than 2 samples at {rate_hz:g} Hz ({what})")
        if n > MAX_SIMULATED_SAMPLES:
            raise UserError(f"scheme {scheme.name}: segment {spec.name!r}: {spec.duration_s:g} s is {n:.3g} samples "
                            f"at {rate_hz:g} Hz, more than the simulator holds at once ({MAX_SIMULATED_SAMPLES:,}; "
                            f"{what})")
    return bench


def check_chamber(scheme: Scheme, chamber) -> None:
    """UserError (one line) when ``scheme`` sets a chamber that is not configured or outside its range."""
    steps = scheme.chamber_steps
    if not steps:
        return
    spec, setpoint = steps[0]
    if chamber is None:
        raise UserError(f"scheme {scheme.name}: segment {spec.name!r} sets the chamber (chamber_c: {setpoint:g}) "
                        "but no chamber is configured (station.yaml chamber:, given with --config)")
    for spec, setpoint in steps:
        if not chamber.in_range(setpoint):
            raise UserError(f"scheme {scheme.name}: segment {spec.name!r}: chamber_c {setpoint:g} C is outside the "
                            f"chamber's range {chamber.range_c[0]:g}..{chamber.range_c[1]:g} C (chamber.range_c)")


def chamber_air(room_c: float):
    """A simulated chamber's air at the room's temperature (sim_devices/chamber.py ChamberAir:
    ``set(t, setpoint_c, ramp_c_per_min)``), for a timeline's temperatures
    (``TemperatureTruth.at(t, air)``) outside a dry run (station/design/timeline.py)."""
    from sim_devices.chamber import ChamberAir

    return ChamberAir(room_c)


CHAMBER_READ_S = 1.0      # the station reads the IMU's temperature this often while it waits


def chamber_step(bench, spec, previous_c: float, chamber) -> dict:
    """Set the simulated chamber to ``spec.chamber_c`` and wait as the station waits
    (station.core.chamber: the ramp, then the fixed soak or until the IMU's temperature -- read
    from the simulated IMU every second -- settles); the manifest's ``chamber`` entry: setpoint,
    the wait, the IMU's temperature then, and the cross-check's finding, if any."""
    from station.core.chamber import SlopeSettle, finding

    to = float(spec.chamber_c)
    bench.set_chamber(to, chamber.ramp_c_per_min)
    start = bench.time_s          # the bench's clock when the chamber was set
    ramp = chamber.ramp_s(previous_c, to)
    if chamber.soak_s is not None:
        bench.wait(ramp + chamber.soak_s)
        settled = True
    else:
        bench.wait(ramp)
        rule = SlopeSettle(chamber.settle_slope_c_per_min, chamber.settle_window_s)
        limit = bench.time_s + chamber.settle_max_s
        settled = False
        while bench.time_s < limit:
            step = min(60.0, limit - bench.time_s)
            t = bench.time_s + np.arange(CHAMBER_READ_S, step + 1e-9, CHAMBER_READ_S)
            for ti, Ti in zip(t, bench.imu_temperature(t)):
                rule.feed(ti, Ti)
                if rule.settled:
                    bench.wait(ti - bench.time_s)
                    settled = True
                    break
            if settled:
                break
            bench.wait(step)
    imu_c = float(bench.imu_temperature(bench.time_s))
    entry = {"setpoint_c": to, "from_c": float(previous_c), "waited_s": round(bench.time_s - start, 3),
             "imu_c": round(imu_c, 4), "settled": settled,
             # the simulated chamber's history, so that a --sim --append continues it (replay_chamber)
             "set_at_s": round(float(start), 6), "ramp_c_per_min": float(chamber.ramp_c_per_min)}
    problem = finding(to, imu_c, chamber.agree_c)
    if problem is not None:
        entry["finding"] = problem
    if not settled:
        entry["finding"] = ((entry.get("finding", "") + "; ") if "finding" in entry else "") + (
            f"the IMU's temperature had not settled after {chamber.settle_max_s:g} s (chamber.settle_max_s)")
    return entry


def _simulate(scheme: Scheme, bench, setpoint: float | None = None) -> Iterator[tuple[object, object, dict]]:
    """(spec, simulated segment, commanded manifest keys) for every segment, in order; a segment
    that sets the chamber first sets the simulated one and waits (chamber_step), and while a
    chamber is set every segment says its setpoint (``chamber_c``; ``setpoint``: the one in force
    when the scheme starts, a dry run's capture extended by --append)."""
    chamber = getattr(bench, "station_chamber", None)
    for spec in scheme.segments:
        keys = {}
        if spec.chamber_c is not None:
            keys["chamber"] = chamber_step(bench, spec, chamber.ambient_c if setpoint is None else setpoint, chamber)
            setpoint = float(spec.chamber_c)
        if setpoint is not None:
            keys["chamber_c"] = setpoint
        for spec_, seg, meta in _simulate_one(spec, bench):
            yield spec_, seg, {**meta, **keys}


def _simulate_one(spec, bench):
    """(spec, simulated segment, commanded manifest keys) of one scheme segment."""
    if isinstance(spec, RotationSpec):
        # a turn without an encoder: a screwdriver's (its rate drifts, its angle is unknown) or
        # a hand's by protocol (turn_deg: back to the same edge; the hand's placement is the
        # bench's angle error), written as the bench writes it (station/bench/manual.py)
        protocol = not spec.encoder and spec.turn_deg is not None
        drift = 0.0 if spec.encoder or protocol else bench.truth.bench.rate_drift_fraction
        ramp = {}
        if spec.record_ramp:        # the ramp recorded (issue 28 item 3): at the configured table's rate_accel
            ramp = dict(record_ramp=spec.record_ramp, ramp_rest_s=RAMP_REST_S,
                        ramp_accel_dps2=getattr(bench, "station_ramp_accel_dps2", None) or RAMP_ACCEL_DPS2)
        seg = bench.rotation(spec.axis_body, spec.rate_dps, spec.duration_s,
                             axis_elevation_deg=spec.axis_elevation_deg,
                             drift_fraction=drift, encoder=spec.encoder, **ramp)
        meta = {"axis_body": list(spec.axis_body), "rate_dps": spec.rate_dps}
        if spec.encoder:        # on the table: the elevation it turned axis_body at (as station run records)
            meta["axis_elevation_deg"] = float(spec.axis_elevation_deg)
        if protocol:
            meta.update(angle_deg=float(np.sign(spec.rate_dps)) * spec.turn_deg, motion="hand",
                        note=f"angle_deg is the protocol's turn ({spec.turn_deg:g} deg by hand), not an "
                             "encoder reading")
        elif not spec.encoder:
            meta["note"] = "no encoder: rate_dps is the nominal rate and gives the direction only"
        yield spec, seg, meta
    else:
        yield spec, bench.static(spec.up_body, spec.dwell_s), {"up_body": list(spec.up_body)}


def _bench_keys(truth, scheme: Scheme, geometry: dict | None = None) -> dict:
    """What the bench's datasheet says (manifest keys beyond the spec, kept by every reader);
    ``geometry``: the table's geometry as the station's configuration states it (``station run``
    records it: manifest ``table.geometry``), None: not stated."""
    keys = {"table": {"angle_error_arcsec": float(truth.bench.table_angle_error_arcsec)}}
    if geometry is not None:
        keys["table"]["geometry"] = dict(geometry)
    if scheme.centred:
        keys["mounting"] = {"offset_m": [0.0, 0.0, 0.0]}
    return keys


def _mounted(truth, scheme: Scheme):
    """The truth as mounted for this scheme: centred schemes put the IMU on the table's axes."""
    if not scheme.centred:
        return truth
    placed = copy.deepcopy(truth)
    placed.bench.lever_arm_m = np.zeros(3)
    return placed


def _headers(bench, seed: int) -> tuple[ImuInfo, Site]:
    imu = ImuInfo(sample_rate_hz=bench.sample_rate_hz, accel_unit="m/s^2", gyro_unit="deg/s",
                  model="station simulated IMU", serial=f"SIM-{seed}")
    return imu, Site(gravity_mps2=bench.gravity_mps2, latitude_deg=bench.latitude_deg)


def record_scheme(scheme: Scheme, truth, seed: int, out_dir: Path,
                  progress: Callable[[str, int, int], None] | None = None, geometry: dict | None = None,
                  chamber=None, ramp_accel_dps2: float | None = None, warmup=None) -> Path:
    """Simulate every segment of ``scheme`` and write the capture bundle to ``out_dir``
    (``geometry``: the table's as stated, _bench_keys; ``chamber``: the configured temperature
    chamber, station.core.chamber.ChamberConfig, needed by a scheme that sets one; ``ramp_accel_dps2``:
    the recorded ramps' acceleration, table_ramp_accel of the configured table; ``warmup``: the
    configured warm-up, station.bench.config.WarmupConfig, waited for before the first segment and
    its temperatures written to ``warmup.csv`` as the sequencer writes them)."""
    bench = _bench(scheme, truth, seed, chamber=chamber, ramp_accel_dps2=ramp_accel_dps2, warmup=warmup)
    imu, site = _headers(bench, seed)
    # the manifest written at the start and the end (a dry run is redone, never resumed: a run's
    # writer rewrites it at every segment's start and end, quadratic in the segments), and in the
    # finally on an error or Ctrl-C: what was written is listed, the segment cut short incomplete
    writer = DeferredCaptureWriter(out_dir, imu, site, scheme.name,
                                   extra={**_bench_keys(truth, scheme, geometry),
                                          "simulation": {"seed": seed, "truth_file": TRUTH_FILE}})
    try:
        writer.write_file(TRUTH_FILE, yaml.safe_dump(truth.to_yaml_dict(), sort_keys=False))
        if bench.station_warmup_s > 0:
            writer.write_file("warmup.csv", _warmup_csv(bench))
        try:
            _write_segments(writer, scheme, bench, progress)
        finally:            # also after Ctrl-C: the complete segments stay, --append goes on from them
            _write_platter(writer, bench)
    finally:
        writer.finish()
    return writer.path


def _warmup_csv(bench) -> str:
    """The warm-up's temperatures as the sequencer writes them (``warmup.csv``: a reading a second,
    ms and 0.1 mK, stamped on the bench's clock) for the dry run's bench, which waited
    ``bench.station_warmup_s`` from its clock's ``bench.station_warmup_from_s`` (0: power-on; an
    extension's: the capture's end)."""
    start = getattr(bench, "station_warmup_from_s", 0.0)
    t = start + np.arange(WARMUP_READ_S, bench.station_warmup_s + 0.5 * WARMUP_READ_S, WARMUP_READ_S)
    rows = ["t_s,temp_c"] + [f"{a:.3f},{b:.4f}" for a, b in zip(t, _warmup_readings(t, bench.imu_temperature))]
    return "\n".join(rows) + "\n"


def _write_segments(writer, scheme: Scheme, bench, progress, setpoint: float | None = None, **extra) -> None:
    """Simulate ``scheme``'s segments on ``bench`` into ``writer``, in blocks (``extra``: manifest
    keys every segment gets; ``setpoint``: the chamber's in force at the start, _simulate)."""
    block = max(1, int(round(BLOCK_SECONDS * bench.sample_rate_hz)))
    for i, (spec, seg, meta) in enumerate(_simulate(scheme, bench, setpoint)):
        if progress:
            progress(spec.name, i, len(scheme.segments))
        with writer.begin_segment(spec.name, spec.kind, **meta, **extra) as out:
            for k in range(0, len(seg.t), block):
                sl = slice(k, k + block)
                out.write(seg.t[sl], seg.accel[sl], seg.gyro[sl], seg.temp[sl])
            out.close("complete", **{k: v for k, v in seg.meta.items() if k in SEGMENT_KEYS})


def replay_chamber(bench, capture, chamber=None) -> float | None:
    """Give ``bench``'s simulated chamber the history the dry run's ``capture`` recorded (each
    chamber step's setpoint, when it was set and the ramp: the segments' ``chamber`` entries), so
    that the world goes on as it was: the air where it was, the IMU's case still lagging it.
    Returns the setpoint in force at the capture's end (None: the chamber was never set).  An
    entry without its time is set at the end of the segment before (where the dry run sets it),
    one without its ramp takes the configured chamber's (``chamber``), else it is refused."""
    setpoint, end = None, None
    for seg in capture.segments:
        entry = seg.extra.get("chamber") if isinstance(seg.extra, dict) else None
        if isinstance(entry, dict) and seg.status == "complete":
            where = f"{capture.path}/manifest.yaml: segment {seg.name!r}: field 'chamber'"
            try:
                to = float(entry["setpoint_c"])
                at = float(entry["set_at_s"]) if "set_at_s" in entry else end
                ramp = entry.get("ramp_c_per_min", None if chamber is None else chamber.ramp_c_per_min)
                ramp = float(ramp) if ramp is not None else None
            except (KeyError, TypeError, ValueError):
                raise UserError(f"{where}: needs a number setpoint_c (and set_at_s, ramp_c_per_min)") from None
            if at is None or ramp is None or not (np.isfinite(to) and np.isfinite(at) and ramp > 0):
                raise UserError(f"{where}: the simulated chamber's history is not known (no set_at_s or "
                                "ramp_c_per_min, a capture written before they were recorded): give the run's "
                                "configuration with --config (its chamber: ramp_c_per_min)")
            bench.chamber.set(at, to, ramp)
            setpoint = to
        if seg.data is not None and len(seg.data.t):
            end = float(seg.data.t[-1]) + 0.5 / capture.imu.sample_rate_hz
        if seg.status == "complete" and seg.extra.get("chamber_c") is not None:
            setpoint = float(seg.extra["chamber_c"])
    return setpoint


def append_scheme(extension: Scheme, text: str, directory: Path,
                  progress: Callable[[str, int, int], None] | None = None, chamber=None,
                  ramp_accel_dps2: float | None = None, warmup=None) -> Path:
    """Record ``extension``'s segments into the dry run's capture ``directory``, after its own, on
    the same simulated bench: the IMU of the capture's ``sim_truth.yaml``, still mounted as it was,
    the bench's clock going on from the end of the capture's last segment (a warm-up, a drift or a
    step continues), new noise (the capture's seed and its count of segments make the extension's
    seed: an extension never repeats the noise of the run), the temperature chamber as the run left
    it (replay_chamber: the extension's segments at the setpoint in force, and say so; a segment of
    the extension that sets the chamber needs ``chamber``, the configured one).  The capture's
    complete segments are left untouched; the extension's scheme file (``text``) is kept in it
    (``scheme-append-N.yaml``).  ``warmup``: the configured warm-up (station.yaml ``warmup:``),
    waited for again before the extension as the sequencer waits on a bench's ``--append``
    (station.bench.plan.resumed_warmup: the IMU as warm as the run left it passes after one window
    of a slope rule), on the simulated IMU's temperature in the chamber as the run left it, and
    its readings kept as the capture's next warm-up record (station.io.capture.warmup_file:
    ``warmup-2.csv``, ...; the run's own ``warmup.csv`` is not touched)."""
    from station.io.capture import CaptureWriter, read_capture, warmup_file
    from station.io.scheme import load_scheme

    directory = Path(directory)
    capture = read_capture(directory, load_data=True)
    sim = capture.extra.get("simulation")
    if not isinstance(sim, dict) or sim.get("truth_file") != TRUTH_FILE or not isinstance(sim.get("seed"), int):
        raise UserError(f"{directory}: not the capture of a dry run (its manifest has no 'simulation' block "
                        f"naming {TRUTH_FILE} and a seed): with --sim, --append extends a capture that "
                        "station run --sim wrote; a bench run's capture is extended on the bench")
    truth = load_truth(str(directory / TRUTH_FILE), 0)
    names = {s.name for s in capture.segments}
    taken = sorted(names & {s.name for s in extension.segments})
    if taken:
        raise UserError(f"scheme {extension.name}: segment names already in {directory}: {', '.join(taken)} "
                        "(rename them; station design --from prefixes its segments x1_, x2_, ...)")
    centred = capture.extra.get("mounting", {}).get("offset_m") == [0.0, 0.0, 0.0]
    if extension.centred != centred:
        raise UserError(f"scheme {extension.name}: field 'centred': {extension.centred}, the capture's IMU "
                        f"{'is' if centred else 'is not'} on the table's axes: the extension must be mounted as "
                        "the run was")
    try:
        run_table = load_scheme(capture.scheme).table if capture.scheme else extension.table
    except UserError:                   # a scheme file of the user's, not at hand: not checked
        run_table = extension.table
    if extension.table != run_table:
        raise UserError(f"scheme {extension.name}: {'a hand scheme' if not extension.table else 'a table scheme'} "
                        f"cannot extend {'a table run' if run_table else 'a run by hand'}")
    ends = [float(s.data.t[-1]) for s in capture.segments if s.data is not None and len(s.data.t)]
    # the bench's clock at the end of the last segment's window: half a sample after its last
    # sample (SimulatedBench._times), as in one uninterrupted run
    start_s = max(ends, default=-0.5 / capture.imu.sample_rate_hz) + 0.5 / capture.imu.sample_rate_hz
    seed = int(np.random.SeedSequence([int(sim["seed"]), len(capture.segments)]).generate_state(1)[0])
    bench = _bench(extension, truth, seed, start_s=start_s, chamber=chamber, ramp_accel_dps2=ramp_accel_dps2)
    # the IMU still mounted as it was on the platter (the platter starts each axis where this session
    # starts it; the imbalance stays where it is against the IMU): the twin's state, issue 28
    try:
        bench.restore_platter(_read_platter(directory))
    except (KeyError, TypeError, ValueError, AttributeError) as e:
        raise UserError(f"{directory / PLATTER_FILE}: not the simulated table's state ({type(e).__name__}: {e}); "
                        "delete it to start every axis anew") from None
    # the chamber as the run left it: its air, the IMU's case lagging it, the setpoint in force
    setpoint = replay_chamber(bench, capture, chamber)
    # the warm-up again, on the IMU's temperature there (a run's segments came after its first)
    bench.station_warmup_s = warmup_seconds(warmup, bench.imu_temperature, start_s,
                                            resumed=bool(capture.complete()))
    bench.wait(bench.station_warmup_s)
    listed = sorted(directory.glob("scheme-append-*.yaml"))
    number = len(listed) + 1
    kept = directory / f"scheme-append-{number}.yaml"
    from station.core.user_files import output_path

    output_path(kept, "the appended scheme")
    try:
        kept.write_text(text)
    except OSError as e:
        raise UserError(f"{kept}: cannot write: {e.strerror}") from None
    writer = CaptureWriter.reopen(directory)
    if bench.station_warmup_s > 0:
        writer.write_file(warmup_file(directory), _warmup_csv(bench))
    try:
        _write_segments(writer, extension, bench, progress, setpoint, appended=number)
    finally:                # also after Ctrl-C: where the table was left, for the next --append
        _write_platter(writer, bench)
    return directory


def _write_platter(writer, bench) -> None:
    """The twin's hidden state that a later session (--append) continues from: where the table left
    each axis with the IMU mounted on its platter (SimulatedBench.platter_state), beside the truth."""
    writer.write_file(PLATTER_FILE, yaml.safe_dump({"platter": bench.platter_state()}, sort_keys=False))


def _read_platter(directory: Path) -> list:
    """PLATTER_FILE's state ([] when absent: a capture written before it, the mounting unknown)."""
    path = Path(directory) / PLATTER_FILE
    if not path.is_file():
        return []
    try:
        data = yaml.safe_load(path.read_text())
        return list(data.get("platter") or [])
    except (OSError, yaml.YAMLError, AttributeError, TypeError) as e:
        first = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        raise UserError(f"{path}: unreadable ({first}): the simulated table's state; delete it to start every "
                        "axis anew") from None


def simulate_capture(scheme: Scheme, truth, seed: int, geometry: dict | None = None, chamber=None,
                     ramp_accel_dps2: float | None = None, warmup=None) -> Capture:
    """The capture a dry run would write, kept in memory (for Monte Carlo runs; ``warmup``: the
    configured warm-up, waited for before the first segment, as record_scheme)."""
    bench = _bench(scheme, truth, seed, chamber=chamber, ramp_accel_dps2=ramp_accel_dps2, warmup=warmup)
    imu, site = _headers(bench, seed)
    segments = []
    for spec, seg, meta in _simulate(scheme, bench):
        segments.append(Segment(
            name=spec.name, kind=spec.kind, file=f"{spec.name}.csv", status="complete",
            up_body=np.array(meta["up_body"]) if "up_body" in meta else None,
            axis_body=np.array(meta["axis_body"]) if "axis_body" in meta else None,
            rate_dps=meta.get("rate_dps"), angle_deg=seg.meta.get("angle_deg", meta.get("angle_deg")),
            note=meta.get("note"), extra={**{k: meta[k] for k in ("motion", "axis_elevation_deg", "chamber_c",
                                                                  "chamber") if k in meta},
                                          **{k: v for k, v in seg.meta.items()
                                             if k in SEGMENT_KEYS and k != "angle_deg"}},
            data=SegmentData(t=seg.t, accel=seg.accel, gyro=seg.gyro, temp=seg.temp, gaps=0)))
    return Capture(path=Path(f"<simulated seed {seed}>"), imu=imu, site=site, scheme=scheme.name,
                   segments=segments, extra=_bench_keys(truth, scheme, geometry), warnings=[])


def truth_calibration(truth):
    """The simulated truth expressed as a Calibration, to compare estimates with."""
    from station.model.calibration import Calibration

    p = truth.paper_parameters()
    return Calibration(accel_unit="m/s^2", gyro_unit="deg/s",
                       accel_scale=p["accel_scale"], accel_T=p["accel_T"], accel_bias=p["accel_bias"],
                       gyro_scale=p["gyro_scale"], gyro_T=p["gyro_T"], gyro_bias=p["gyro_bias"],
                       R_po=p["R_po"])
