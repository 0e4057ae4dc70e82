"""Dry runs: record a scheme on the simulated bench, into a capture bundle or into memory.

Only this module (and only when the user asks for simulation) imports ``sim_devices``.
"""
from __future__ import annotations

import copy
from pathlib import Path
from typing import Callable, Iterator

import numpy as np
import yaml

from station.core.errors import UserError
from station.io.capture import Capture, DeferredCaptureWriter, ImuInfo, Segment, SegmentData, Site
from station.io.scheme import RotationSpec, Scheme

BLOCK_SECONDS = 10.0     # samples are written and flushed in blocks of this length
TRUTH_FILE = "sim_truth.yaml"


def load_truth(truth_path: str | None, seed: int):
    from sim_devices.truth import Truth, default_truth

    return Truth.from_yaml(truth_path) if truth_path else default_truth(seed)


MAX_SIMULATED_SAMPLES = 5_000_000   # per segment: the simulator holds a segment whole (~1 GB at this)


def _bench(scheme: Scheme, truth, seed: int, start_s: float = 0.0):
    """The simulated bench for ``scheme`` (its clock from ``start_s``); UserError naming the segment
    when one gives fewer than 2 samples, or more than the simulator holds at once, before anything
    is simulated or written."""
    from sim_devices.bench import SimulatedBench

    bench = SimulatedBench(_mounted(truth, scheme), seed, start_s=start_s)
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


def _simulate(scheme: Scheme, bench) -> Iterator[tuple[object, object, dict]]:
    """(spec, simulated segment, commanded manifest keys) for every segment, in order."""
    for spec in scheme.segments:
        if isinstance(spec, RotationSpec):
            # a turn without an encoder: a screwdriver's (its rate drifts, its angle is unknown) or
            # a hand's by protocol (turn_deg: back to the same edge; the hand's placement is the
            # bench's angle error), written as the bench writes it (station/bench/manual.py)
            protocol = not spec.encoder and spec.turn_deg is not None
            drift = 0.0 if spec.encoder or protocol else bench.truth.bench.rate_drift_fraction
            seg = bench.rotation(spec.axis_body, spec.rate_dps, spec.duration_s,
                                 axis_elevation_deg=spec.axis_elevation_deg,
                                 drift_fraction=drift, encoder=spec.encoder)
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
                  progress: Callable[[str, int, int], None] | None = None, geometry: dict | None = None) -> Path:
    """Simulate every segment of ``scheme`` and write the capture bundle to ``out_dir``
    (``geometry``: the table's as stated, _bench_keys)."""
    bench = _bench(scheme, truth, seed)
    imu, site = _headers(bench, seed)
    # the manifest written at the start and the end (a dry run is redone, never resumed: a run's
    # writer rewrites it at every segment's start and end, quadratic in the segments), and in the
    # finally on an error or Ctrl-C: what was written is listed, the segment cut short incomplete
    writer = DeferredCaptureWriter(out_dir, imu, site, scheme.name,
                                   extra={**_bench_keys(truth, scheme, geometry),
                                          "simulation": {"seed": seed, "truth_file": TRUTH_FILE}})
    try:
        writer.write_file(TRUTH_FILE, yaml.safe_dump(truth.to_yaml_dict(), sort_keys=False))
        _write_segments(writer, scheme, bench, progress)
    finally:
        writer.finish()
    return writer.path


def _write_segments(writer, scheme: Scheme, bench, progress, **extra) -> None:
    """Simulate ``scheme``'s segments on ``bench`` into ``writer``, in blocks (``extra``: manifest
    keys every segment gets)."""
    block = max(1, int(round(BLOCK_SECONDS * bench.sample_rate_hz)))
    for i, (spec, seg, meta) in enumerate(_simulate(scheme, bench)):
        if progress:
            progress(spec.name, i, len(scheme.segments))
        with writer.begin_segment(spec.name, spec.kind, **meta, **extra) as out:
            for k in range(0, len(seg.t), block):
                sl = slice(k, k + block)
                out.write(seg.t[sl], seg.accel[sl], seg.gyro[sl], seg.temp[sl])
            out.close("complete", **{k: v for k, v in seg.meta.items() if k in ("angle_deg", "table_axis")})


def append_scheme(extension: Scheme, text: str, directory: Path,
                  progress: Callable[[str, int, int], None] | None = None) -> Path:
    """Record ``extension``'s segments into the dry run's capture ``directory``, after its own, on
    the same simulated bench: the IMU of the capture's ``sim_truth.yaml``, still mounted as it was,
    the bench's clock going on from the end of the capture's last segment (a warm-up, a drift or a
    step continues), new noise (the capture's seed and its count of segments make the extension's
    seed: an extension never repeats the noise of the run).  The capture's complete segments are
    left untouched; the extension's scheme file (``text``) is kept in it (``scheme-append-N.yaml``)."""
    from station.io.capture import CaptureWriter, read_capture
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
    start_s = max(ends, default=0.0)
    seed = int(np.random.SeedSequence([int(sim["seed"]), len(capture.segments)]).generate_state(1)[0])
    bench = _bench(extension, truth, seed, start_s=start_s)
    listed = sorted(directory.glob("scheme-append-*.yaml"))
    number = len(listed) + 1
    kept = directory / f"scheme-append-{number}.yaml"
    from station.core.user_files import output_path

    output_path(kept, "the appended scheme")
    try:
        kept.write_text(text)
    except OSError as e:
        raise UserError(f"{kept}: cannot write: {e.strerror}") from None
    _write_segments(CaptureWriter.reopen(directory), extension, bench, progress, appended=number)
    return directory


def simulate_capture(scheme: Scheme, truth, seed: int, geometry: dict | None = None) -> Capture:
    """The capture a dry run would write, kept in memory (for Monte Carlo runs)."""
    bench = _bench(scheme, truth, seed)
    imu, site = _headers(bench, seed)
    segments = []
    for spec, seg, meta in _simulate(scheme, bench):
        segments.append(Segment(
            name=spec.name, kind=spec.kind, file=f"{spec.name}.csv", status="complete",
            up_body=np.array(meta["up_body"]) if "up_body" in meta else None,
            axis_body=np.array(meta["axis_body"]) if "axis_body" in meta else None,
            rate_dps=meta.get("rate_dps"), angle_deg=seg.meta.get("angle_deg", meta.get("angle_deg")),
            note=meta.get("note"), extra={**{k: meta[k] for k in ("motion", "axis_elevation_deg") if k in meta},
                                          **{k: v for k, v in seg.meta.items() if k == "table_axis"}},
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
