"""``station run`` with several IMUs (station.yaml ``imus:``): on a bench (the table moves once,
every IMU into its own bundle: station/bench/multi.py, station/bench/sequencer.py), its
``--resume``, and ``--sim`` (each IMU its own simulated sensor).  Parsing and output only."""
from __future__ import annotations

import datetime as _dt
import shutil
from pathlib import Path

import yaml

from station.cli.output import err, out, rich_console
from station.core import yaml_text
from station.core.errors import UserError

#: exit status of a run in which an IMU was lost: the others' calibrations are written; resume
EXIT_IMU_LOST = 4


def read_run_text(path: Path) -> str:
    from station.cli.run_bench import read_run_text as read

    return read(path)


def is_multi_run(directory: Path) -> bool:
    """Whether ``directory`` is the folder of a several-IMU run (its run.yaml lists ``imus``)."""
    from station.cli.run_bench import RUN_FILE

    try:
        doc = yaml_text.safe_load(read_run_text(directory / RUN_FILE))
    except (OSError, yaml.YAMLError, ValueError):
        return False
    return isinstance(doc, dict) and isinstance(doc.get("imus"), list)


def run_multi(args, config) -> int:
    from station.bench.compile import compile_scheme
    from station.bench.multi import done_segments, imu_config
    from station.cli.run_bench import DEVICE_ERRORS, _out_dir, _overrides, _resume_steps
    from station.io.scheme import load_scheme, scheme_text

    if args.resume:
        directory = Path(args.resume)
        scheme, config, folders, done = _resumed(directory, config, args)
        text = None
    else:
        text, _ = scheme_text(args.scheme)
        scheme = load_scheme(args.scheme, _overrides(args))
        directory = _out_dir(args, config, scheme)
        folders, done = None, [set() for _ in config.imus]
    if not scheme.table:
        raise UserError(f"scheme {scheme.name} is done by hand: several IMUs (imus:) are recorded through a "
                        "table scheme; record hand schemes one IMU at a time (imu:)")
    for k, imu in enumerate(config.imus):
        if not imu.port:
            raise UserError(f"{config.source}: field 'imus[{k}].port': no port for this IMU")
    if not config.table.port:
        raise UserError(f"scheme {scheme.name} needs a rate table: give --table-port or set table.port")
    reference = imu_config(config, 0)           # the scheme is compiled for the first IMU's mounting
    plan = compile_scheme(scheme, reference)
    steps = plan.steps
    if args.resume:
        steps = _resume_steps(plan, scheme, done_segments(done), reference)
        if not any(s.segment for s in steps):
            out.print(f"{directory}: every segment of every IMU is recorded; estimating", markup=False)
            return _estimate_all(directory, folders, config, scheme, args, lost={})
    try:
        return _record(args, config, reference, scheme, plan, steps, directory, text, folders, done)
    except DEVICE_ERRORS as e:
        where = (f"; what was recorded is kept: continue with station run --resume {directory}"
                 if (directory / "run.yaml").is_file() else "")
        raise UserError(f"a device failed or disconnected ({type(e).__name__}: {str(e)[:100]}){where}") from None


def _record(args, config, reference, scheme, plan, steps, directory, text, folders, done) -> int:
    from station.bench.channels import ImuChannel, relative_mounting
    from station.bench.guardian import start_guardian
    from station.bench.imu_stream import ImuStream
    from station.bench.live import make_display
    from station.bench.multi import folder_names, imu_config
    from station.cli.run_bench import (SCHEME_FILE, _new_capture, _open_table, _overrides, _reopen, imu_identity,
                                       sequence)

    table = _open_table(config)
    imus, guardian = [], None
    resuming = folders is not None
    try:
        # an IMU that fails to start (its port missing, no reply to its start-up) is lost at the
        # start: said, its bundle marked, the others go on (exit status 4); none left: the run stops
        imus, rates, failed = _start_imus(config)
        if table.found_moving:      # left turning by an earlier run: stopped
            err.print(f"warning: {table.describe_leftover()}", markup=False, soft_wrap=True)
        guardian = start_guardian(table.url, table.protocol, table.settings, directory)
        for note in plan.notes:
            err.print(f"note: {note}", markup=False, soft_wrap=True)
        serials = [imu_identity(getattr(imu, "identity", None)).get("serial") for imu in imus]
        if folders is None:
            folders = folder_names(serials, [cfg.name for cfg in config.imus])
            _write_run(directory, scheme, text, _overrides(args), config, folders)
            writers = [_new_capture(directory / f, scheme, text, _overrides(args), imu_config(config, k), imu, rate,
                                    lost_at_start=failed.get(k))
                       for k, (f, imu, rate) in enumerate(zip(folders, imus, rates))]
        else:
            writers = []
            for k, (f, imu, rate, serial) in enumerate(zip(folders, imus, rates, serials)):
                if k in failed:                   # lost again: its bundle as it is
                    writers.append(None)
                elif _lost_at_start(directory / f):   # lost at the start before: its bundle begun now
                    shutil.rmtree(directory / f)
                    writers.append(_new_capture(directory / f, scheme, read_run_text(directory / SCHEME_FILE),
                                                _overrides_of(directory), imu_config(config, k), imu, rate))
                else:
                    writers.append(_reopen(directory / f, rate, serial))
        for k, why in failed.items():
            err.print(f"IMU {folders[k]} (imus[{k}], {config.imus[k].port}) lost at the start ({why}): the other "
                      f"IMUs go on; station run --resume {directory} records it", markup=False, soft_wrap=True)
        names = {seg.name for seg in scheme.segments}
        idle = resuming and bool(failed) and all(k in failed or names <= set(d) for k, d in enumerate(done))
        if idle:      # only IMUs lost again lack segments: nobody would record, the table stays put
            err.print(f"nothing to record: every IMU that lacks segments is lost again at the start "
                      f"({', '.join(folders[k] for k in failed)}); the table is not moved", markup=False,
                      soft_wrap=True)
        m0 = config.imus[0].mounting_matrix(config.table)
        channels = [ImuChannel(label=serial or folder, stream=None if imu is None else ImuStream(imu, rate),
                               writer=writer, rate_hz=rate,
                               to_case=relative_mounting(m0, cfg.mounting_matrix(config.table)), done=frozenset(d),
                               lost=None if k not in failed else f"at the start: {failed[k]}")
                    for k, (serial, folder, imu, rate, writer, cfg, d)
                    in enumerate(zip(serials, folders, imus, rates, writers, config.imus, done))]
        out.print(f"run: {directory} ({len(channels)} IMUs: " +
                  ", ".join(f"{ch.label} -> {directory / f}" for ch, f in zip(channels, folders)) + ")",
                  markup=False, soft_wrap=True)
        display = make_display(rich_console(out), sum(s.estimate_s for s in steps),
                               f"{scheme.name} on {config.table.axes}-axis table, {len(channels)} IMUs")
        status = None if idle else sequence(steps, display, directory, table=table, config=reference,
                                            reset_faults=args.reset_faults, channels=channels)
        if status is not None:
            return status
    finally:
        for device in (table, *(imu for imu in imus if imu is not None)):
            try:
                device.close()
            except Exception:         # noqa: BLE001 - a lost IMU's port may be gone already
                pass
        if guardian is not None:
            guardian.release()
    lost = {f: ch.lost for f, ch in zip(folders, channels) if ch.lost}
    return _estimate_all(directory, folders, config, scheme, args, lost)


def _start_imus(config) -> tuple:
    """(drivers, rates, {k: why}) of the IMUs of ``config.imus``, each opened and configured;
    one that fails to (its port missing or refusing, no reply to its start-up, its line hung
    up) is None with the reason, at its configured rate.  Every one failing: the run stops as a
    one-IMU run does (the first one's error, naming each).  A bad configuration (csv_units) is
    not a device failure: it stops the run (exit status 2) whatever the others do."""
    from drivers.errors import DeviceError
    from station.bench.multi import imu_config
    from station.cli.run_bench import DEVICE_ERRORS, _open_imu

    imus, rates, failed = [], [], {}
    for k, cfg in enumerate(config.imus):
        imu = None
        try:
            imu = _open_imu(imu_config(config, k), field=f"imus[{k}]")
            rates.append(imu.configure(cfg.rate_hz))
        except (DeviceError, *DEVICE_ERRORS) as e:
            failed[k] = f"{type(e).__name__}: {' '.join(str(e).split())[:200]}"
            if imu is not None:
                try:
                    imu.close()
                except Exception:       # noqa: BLE001 - its port may be gone
                    pass
            imu = None
            rates.append(float(cfg.rate_hz))
        except BaseException:
            for opened in imus:
                if opened is not None:
                    opened.close()
            raise
        imus.append(imu)
    if len(failed) == len(config.imus):
        raise UserError("no IMU started: " + "; ".join(f"imus[{k}] ({config.imus[k].port}): {why}"
                                                        for k, why in failed.items()))
    return imus, rates, failed


#: the manifest key of the bundle of an IMU lost at the start of a run (no segment recorded)
LOST_AT_START = "lost_at_start"


def _lost_at_start(bundle: Path) -> bool:
    """Whether ``bundle`` is the mark of an IMU lost at the start: no segment, the key set."""
    try:
        doc = yaml_text.safe_load(read_run_text(bundle / "manifest.yaml"))
    except (OSError, yaml.YAMLError, ValueError):
        return False
    return isinstance(doc, dict) and LOST_AT_START in doc and not doc.get("segments")


def _overrides_of(directory: Path) -> dict:
    from station.cli.run_bench import RUN_FILE

    doc = yaml_text.safe_load(read_run_text(directory / RUN_FILE))
    return dict(doc.get("overrides") or {})


def _estimate_all(directory, folders, config, scheme, args, lost: dict) -> int:
    """Estimate every IMU whose bundle has every segment; say which do not, and why."""
    from station.bench.multi import imu_config
    from station.cli.calibration import report_calibration
    from station.cli.history import file_quietly
    from station.core import forked
    from station.io.capture import read_capture

    from station.cli.noise import characterise_run, is_noise_recording

    noise = is_noise_recording(scheme.segments)        # characterised, not calibrated

    names = [seg.name for seg in scheme.segments]
    statuses, results, ready = [], [], []
    for k, folder in enumerate(folders):
        bundle = directory / folder
        complete = {s.name for s in read_capture(bundle, load_data=False).complete()}
        missing = [n for n in names if n not in complete]
        if missing:
            why = f"lost: {lost[folder]}" if folder in lost else "incomplete"
            err.print(f"IMU {folder}: {why}; {len(missing)} of {len(names)} segments not recorded (first: "
                      f"{missing[0]}): station run --resume {directory} records them", markup=False, soft_wrap=True)
            results.append((folder, f"{len(names) - len(missing)}/{len(names)} segments ({why})", None))
            statuses.append(EXIT_IMU_LOST)
        else:
            ready.append((k, folder))
    # the fits on every core (a forked child each), printed here in the IMUs' order
    if noise:
        for k, folder in ready:
            out.print(f"--- IMU {folder} ---", markup=False)
            statuses.append(characterise_run(directory / folder))
            results.append((folder, "noise characterised", statuses[-1]))
        ready = []
    fitted = forked.map_in_children(lambda item: _fit(directory / item[1], imu_config(config, item[0])), ready)
    for (k, folder), (cal, warnings, path, method) in zip(ready, fitted):
        out.print(f"--- IMU {folder} ---", markup=False)
        for w in warnings:
            err.print(f"warning: {w}", markup=False, soft_wrap=True)
        file_quietly(path, asked=True if args.history is None else args.history)
        code = report_calibration(cal, f"calibration of {directory / folder} ({method})", path, args.accept_poor_fit)
        statuses.append(code)
        results.append((folder, "estimated", code))
    out.print("IMUs of the run:", markup=False)
    for folder, what, code in results:
        verdict = "" if code is None else ("  (fit passes)" if code == 0 else f"  (exit status {code})")
        out.print(f"  {folder}: {what}{verdict}  {directory / folder}", markup=False)
    if EXIT_IMU_LOST in statuses:
        err.print(f"station run: {statuses.count(EXIT_IMU_LOST)} IMU(s) not complete (exit status "
                  f"{EXIT_IMU_LOST}); the others' calibrations are written", markup=False, soft_wrap=True)
        return EXIT_IMU_LOST
    return max(statuses, default=0)


def _fit(bundle: Path, config) -> tuple:
    """(calibration, capture warnings, calibration file, method) of one IMU's bundle, with the
    data-loss limits of the run (as station run estimates one IMU: station/cli/run.py _estimate)."""
    from station.estimate import estimate_capture
    from station.io.calfile import write_calfile

    cal, capture, provenance = estimate_capture(bundle, max_missing_fraction=config.run.max_missing_fraction,
                                                max_gap_s=config.run.max_gap_s)
    path = write_calfile(bundle / "calibration.yaml", cal, provenance)
    return cal, list(capture.warnings), path, provenance["method"]


def _write_run(directory: Path, scheme, text, overrides, config, folders) -> None:
    """The run's own run.yaml and scheme.yaml (the bundles are written by CaptureWriter)."""
    from station.cli.run_bench import RUN_FILE, RUN_FORMAT, SCHEME_FILE

    from station.core.user_files import output_path

    output_path(directory, "the capture directory")
    if directory.exists() and any(directory.iterdir()):
        raise UserError(f"{directory}: exists and is not empty: choose another --out")
    try:
        directory.mkdir(parents=True, exist_ok=True)
        (directory / SCHEME_FILE).write_text(text)
        doc = {"format": RUN_FORMAT, "scheme": scheme.name, "overrides": overrides,
               "started_utc": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
               "imus": [{"index": k, "folder": f, "port": imu.port} for k, (f, imu) in enumerate(zip(folders, config.imus))],
               "config": config.to_dict()}
        tmp = directory / (RUN_FILE + ".tmp")
        tmp.write_text(yaml.safe_dump(doc, sort_keys=False))
        tmp.replace(directory / RUN_FILE)
    except OSError as e:
        raise UserError(f"{directory}: cannot write: {e.strerror}") from None


def _resumed(directory: Path, current, args):
    """(scheme, config, folders, complete segments per IMU) of a several-IMU run to continue:
    what is recorded comes from the run; the connection (ports, protocols, serial) from the
    configuration given now (the same number of IMUs, in the same order)."""
    from dataclasses import replace

    from station.bench.config import from_dict
    from station.cli.run_bench import CONNECTION, RUN_FILE, SCHEME_FILE, _overrides
    from station.io.capture import read_capture
    from station.io.scheme import scheme_from_text

    run_file = directory / RUN_FILE
    doc = yaml_text.safe_load(read_run_text(run_file))
    try:
        text = read_run_text(directory / SCHEME_FILE)
    except OSError as e:
        raise UserError(f"{directory}: not a capture of station run (no {e.filename}): cannot resume") from None
    if _overrides(args):
        raise UserError("--resume continues with the run's own timings: leave out --dwell-s, --rate-dps "
                        "and --rotation-s")
    scheme = scheme_from_text(text, str(directory / SCHEME_FILE), doc.get("overrides") or {})
    config = from_dict(doc.get("config") or {}, str(run_file))
    entries = doc["imus"]
    folders = []
    for k, entry in enumerate(entries):
        folder = entry.get("folder") if isinstance(entry, dict) else None
        if not isinstance(folder, str) or not folder or "/" in folder or folder in (".", ".."):
            raise UserError(f"{run_file}: field 'imus[{k}].folder': must be a folder name, got {folder!r}")
        folders.append(folder)
    if len(folders) != len(config.imus):
        raise UserError(f"{run_file}: field 'imus': {len(folders)} folders for {len(config.imus)} IMUs")
    if current.imus:
        if len(current.imus) != len(config.imus):
            raise UserError(f"{current.source}: field 'imus': {len(current.imus)} IMUs, the run {directory} has "
                            f"{len(config.imus)}: list the same IMUs in the same order to resume it")
        imus = tuple(replace(rec, **{k: getattr(now, k) for k in CONNECTION["imu"]})
                     for rec, now in zip(config.imus, current.imus))
        config = replace(config, imus=imus, imu=imus[0])
    config = replace(config, table=replace(config.table, **{k: getattr(current.table, k)
                                                            for k in CONNECTION["table"]
                                                            if getattr(current.table, k) is not None}))
    if getattr(args, "unattended", False) and config.run.operator:
        raise UserError(f"{directory} was recorded with an operator (remounts may have happened): "
                        "resume it with one (leave out --unattended)")
    done = []
    for folder in folders:
        bundle = directory / folder
        if not (bundle / "manifest.yaml").is_file():
            raise UserError(f"{bundle}: no manifest.yaml: not a bundle of this run; cannot resume")
        done.append({s.name for s in read_capture(bundle, load_data=False).complete()})
    return scheme, config, folders, done


def run_multi_sim(args, config, scheme) -> int:
    """``station run --sim`` with ``imus:``: each IMU its own simulated sensor (truth seed
    ``--seed + k``), the scheme recorded for each into its own bundle, each estimated."""
    from station.cli.calibration import report_calibration
    from station.cli.history import file_quietly
    from station.cli.run_bench import table_geometry
    from station.estimate import estimate_capture
    from station.io.calfile import write_calfile
    from station.bench.multi import folder_names, imu_config
    from station.simulate import dryrun

    stamp = _dt.datetime.now(_dt.timezone.utc).strftime("%Y%m%dT%H%M%SZ")
    directory = Path(args.out) if args.out else Path("captures") / f"{scheme.name}-sim-{stamp}"
    seeds = [args.seed + k for k in range(len(config.imus))]
    folders = folder_names([None] * len(seeds), [imu.name or f"sim-{s}" for imu, s in zip(config.imus, seeds)])
    codes = []
    for k, (seed, folder) in enumerate(zip(seeds, folders)):
        cfg = imu_config(config, k)
        truth = dryrun.load_truth(args.sim_truth, seed)
        geometry = table_geometry(cfg.table) if scheme.table else None
        out.print(f"dry run: IMU {folder} (seed {seed}), scheme {scheme.name}", markup=False)
        with out.status("recording") as status:
            capture = dryrun.record_scheme(
                scheme, truth, seed, directory / folder,
                progress=lambda name, i, n: status.update(f"IMU {folder}: recording {name} ({i + 1}/{n})"),
                geometry=geometry, chamber=cfg.chamber, ramp_accel_dps2=dryrun.table_ramp_accel(cfg.table),
                warmup=cfg.warmup)
        cal, _, provenance = estimate_capture(capture)
        cal_path = write_calfile(capture / "calibration.yaml", cal, provenance)
        file_quietly(cal_path, asked=bool(args.history), simulated=True)
        out.print(f"capture:          {capture}", markup=False)
        codes.append(report_calibration(cal, "", cal_path, args.accept_poor_fit,
                                        truth=dryrun.truth_calibration(truth)))
    return max(codes)
