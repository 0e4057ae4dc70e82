"""``station run`` on a bench (hardware or the device twins), and ``station schemes``, ``station
plan`` and ``station init``.  Parsing and output only: the plan comes from station/bench/compile.py,
the devices are driven by station/bench/sequencer.py.
"""
from __future__ import annotations

import datetime as _dt
from pathlib import Path

import yaml

from station.cli import argtypes
from station.cli.calibration import add_accept_poor_fit, report_calibration
from station.cli.output import err, out, rich_console
from station.core.errors import UserError, cannot_write
from station.core import yaml_text
# the pieces shared with several-IMU runs (station/cli/run_multi.py); their names kept here
from station.cli.run_bench import (  # noqa: F401
    CONNECTION, DEVICE_ERRORS, RUN_FILE, RUN_FORMAT, SCHEME_FILE, ConsoleOperator, _estimate, _new_capture,
    _open_devices, _open_imu, _open_table, _out_dir, _overrides, _reopen, _resume_steps, imu_identity,
    read_run_text, sequence, table_geometry)

# ------------------------------------------------------------------------------------ parsers

def add_parsers(sub) -> None:
    run = sub.add_parser("run", help="run a calibration scheme and estimate")
    run.add_argument("--scheme", default=None,
                     help="built-in scheme name or a scheme YAML file (default optimal9; with --append: the extension)")
    run.add_argument("--sim", action="store_true", help="dry run against the simulated bench")
    run.add_argument("--sim-truth", metavar="FILE", help="true sensor errors for --sim (YAML)")
    run.add_argument("--seed", type=argtypes.seed, default=1, help="seed of the simulated truth and noise")
    run.add_argument("--out", metavar="DIR", help="capture directory (default captures/<scheme>-sim-<time>)")
    _add_scheme_overrides(run)
    run.add_argument("--port", metavar="URL", help="IMU port (device path or pyserial URL)")
    run.add_argument("--table-port", metavar="URL", help="rate-table port (device path or pyserial URL)")
    run.add_argument("--imu-protocol", help="vectornav (default), xsens or csv")
    run.add_argument("--table-protocol", help="acutrol (default) or aerosmith")
    run.add_argument("--config", metavar="FILE", help="station.yaml (default: $STATION_CONFIG, ./station.yaml)")
    run.add_argument("--resume", metavar="CAPTURE", help="continue a stopped run from its first missing segment")
    run.add_argument("--append", metavar="CAPTURE",
                     help="record the segments of --scheme (an extension, e.g. station design --from CAPTURE) "
                          "into this capture of station run, after its own, on the same bench; then estimate "
                          "from all of it")
    run.add_argument("--unattended", action="store_true",
                     help="no operator: never ask for a remount (run.operator: false)")
    run.add_argument("--reset-faults", action="store_true", help="clear a fault latched on the table first")
    add_accept_poor_fit(run)
    from station.cli.history import add_history_option

    add_history_option(run, "default: a bench run's is filed, a simulated run's is not")
    run.set_defaults(func=cmd_run)

    schemes = sub.add_parser("schemes", help="list the built-in schemes with their segments and durations")
    schemes.add_argument("--config", metavar="FILE", help="estimate run times for this table configuration")
    schemes.set_defaults(func=cmd_schemes)

    plan = sub.add_parser("plan", help="print the compiled steps of a scheme for the configured table")
    plan.add_argument("--scheme", default="optimal9", help="built-in scheme name or a scheme YAML file")
    plan.add_argument("--config", metavar="FILE", help="station.yaml (default: $STATION_CONFIG, ./station.yaml)")
    _add_scheme_overrides(plan)
    plan.add_argument("--unattended", action="store_true", help="compile without remount steps")
    plan.add_argument("--all", action="store_true", help="also list settle and checkpoint steps")
    plan.add_argument("--reveals", action="store_true",
                      help="say which parameters the scheme reveals on this table (a simulated capture "
                           "fitted with the size effect and any --add; a few seconds)")
    plan.add_argument("--add", action="append", default=[], metavar="EFFECT",
                      help="with --reveals: also this effect (an id; repeatable)")
    plan.add_argument("--sim-truth", metavar="FILE", help="with --reveals: the simulated IMU (default: the simulator's)")
    plan.set_defaults(func=cmd_plan)

    init = sub.add_parser("init", help="write a commented example configuration (station.yaml)")
    init.add_argument("path", nargs="?", default="station.yaml",
                      help="where to write it (default ./station.yaml; an existing file is not overwritten)")
    init.set_defaults(func=cmd_init)


def _add_scheme_overrides(p) -> None:
    p.add_argument("--dwell-s", type=argtypes.positive, help="override the scheme's dwell per attitude, s")
    # up to what a capture may record (station.io.capture.MAX_RATE_DPS; not imported here: --help)
    p.add_argument("--rate-dps", type=argtypes.between(1e-3, 1e5), help="override the scheme's rotation rate, deg/s")
    p.add_argument("--rotation-s", type=argtypes.positive,
                   help="override the scheme's rotation time per direction, s")


# ------------------------------------------------------------------------------------ commands

def cmd_init(args) -> int:
    from station.bench.config import EXAMPLE

    from station.core.user_files import output_path

    path = Path(output_path(args.path, "the configuration"))
    if path.exists():
        raise UserError(f"{path}: already exists; will not overwrite it")
    try:
        path.write_text(EXAMPLE)
    except OSError as e:
        raise cannot_write(path, e) from None
    out.print(f"wrote {path}: edit the ports, the table geometry and limits, and the site")
    return 0


def cmd_schemes(args) -> int:
    from rich.table import Table

    from station import api
    from station.bench.config import load_config

    config = load_config(args.config)
    table = Table(title=f"built-in schemes (run s: estimated for the {config.table.axes}-axis table of "
                        f"the configuration: {config.source})")
    for col in ("scheme", "statics", "rotations", "recording s", "run s", "operator steps", "title"):
        table.add_column(col, justify="left" if col in ("scheme", "title") else "right")
    # each scheme compiled (or read from the cache): ~0.17 s CPU for all seven (issue 26)
    for row in api.schemes(config=args.config):
        if row["note"]:
            err.print(f"note: {row['note']}", markup=False, soft_wrap=True)
        table.add_row(row["name"], str(row["statics"]), str(row["rotations"]), f"{row['recording_s']:.0f}",
                      "-" if row["run_s"] is None else f"{row['run_s']:.0f}",
                      "-" if row["operator_steps"] is None else str(row["operator_steps"]), row["title"])
    out.print(table)
    return 0


def cmd_plan(args) -> int:
    from station import api
    from station.bench.plan import Checkpoint, Settle

    c = api.plan(args.scheme, config=args.config, unattended=args.unattended, dwell_s=args.dwell_s,
                 rate_dps=args.rate_dps, rotation_s=args.rotation_s)
    scheme, config, plan = c.scheme, c.config, c.plan
    t = config.table
    where = "by hand (no table)" if plan.manual else (
        f"{t.axes}-axis table, axes at zero (east-north-up) {t.axis_list()}, IMU mounted "
        f"{list(t.mounting)}, {'with' if config.run.operator else 'without'} an operator")
    out.print(f"scheme {scheme.name}: {len(scheme.segments)} segments, {scheme.duration_s:.0f} s of "
              f"recording; {where} ({config.source})", markup=False)
    elapsed = 0.0
    for i, step in enumerate(plan.steps, 1):
        elapsed += step.estimate_s
        if args.all or not isinstance(step, (Settle, Checkpoint)):
            out.print(f"{i:4d} {elapsed:8.0f} s  {step.describe()}", markup=False)
    for note in plan.notes:
        err.print(f"note: {note}", markup=False, soft_wrap=True)
    out.print(f"total: {plan.duration_s:.0f} s ({plan.duration_s / 3600:.2f} h) of device time, "
              f"{len(plan.steps)} steps, {sum(type(s).__name__ == 'Operator' for s in plan)} operator steps"
              + (f", {chambers} chamber step(s) (an operator sets the chamber)"
                 if (chambers := sum(type(s).__name__ == 'Chamber' for s in plan)) else ""),
              markup=False)
    if getattr(args, "reveals", False):
        _print_reveals(scheme, config, plan, args)
    return 0


def _print_reveals(scheme, config, plan, args) -> None:
    """What the scheme reveals on this table: station/simulate/reveal.py."""
    from station.model import EFFECTS
    from station.simulate.reveal import reveals

    ids = ["accel_lever_arm"] + [e for e in args.add if e != "accel_lever_arm"]
    for e in ids:
        if e not in EFFECTS:
            raise UserError(f"--add {e}: not an effect of the library ({', '.join(EFFECTS)})")
    rows, notes = reveals(scheme, config, plan, ids, truth_path=getattr(args, "sim_truth", None))
    out.print(f"reveals (a simulated capture of {scheme.name} on this table, fitted with {', '.join(ids)}):",
              markup=False)
    for status in ("revealed", "not revealed", "convention"):
        chosen = [r for r in rows if r.status == status]
        if not chosen:
            continue
        words = {"revealed": "revealed (1 sigma)", "not revealed": "not revealed",
                 "convention": "0 by convention (not estimated)"}[status]
        items = [r.name if r.sigma is None or status != "revealed" else f"{r.name} +/- {r.sigma:.3g} {r.unit}"
                 for r in chosen]
        out.print(f"  {words}: {', '.join(items)}", markup=False, soft_wrap=True)
    for note in notes:
        out.print(f"  note: {note}", markup=False, soft_wrap=True)


def cmd_run(args) -> int:
    from station.io.scheme import load_scheme

    overrides = {k: v for k, v in (("dwell_s", args.dwell_s), ("rate_dps", args.rate_dps),
                                   ("rotation_s", args.rotation_s)) if v is not None}
    if args.append:
        if args.resume:
            raise UserError("give --append CAPTURE or --resume CAPTURE, not both (an interrupted append is "
                            "continued with --resume)")
        if args.scheme is None:
            raise UserError("--append: give the extension with --scheme EXT.yaml (station design --from writes one)")
        if args.sim:
            return _append_dry_run(args, overrides)
    if args.scheme is None:
        args.scheme = "optimal9"
    if args.resume and args.sim:
        raise UserError(f"--resume {args.resume} continues a run on a bench; a --sim dry run is recorded "
                        "in one go and cannot be resumed: leave out --sim (with --port/--table-port) "
                        "or run --sim afresh")
    if not args.sim:
        return _run_on_bench(args)
    scheme = load_scheme(args.scheme, overrides)
    from station.simulate import dryrun

    config = _config(args)
    if config.imus:                    # several IMUs: each its own simulated sensor
        from station.cli.run_multi import run_multi_sim

        return run_multi_sim(args, config, scheme)
    truth = dryrun.load_truth(args.sim_truth, args.seed)
    # the table's geometry as station.yaml states it, recorded as station run records it
    geometry = table_geometry(config.table) if scheme.table else None
    stamp = _dt.datetime.now(_dt.timezone.utc).strftime("%Y%m%dT%H%M%SZ")
    out_dir = Path(args.out) if args.out else Path("captures") / f"{scheme.name}-sim-{stamp}"
    out.print(f"dry run: scheme [bold]{scheme.name}[/] ({len(scheme.segments)} segments, "
              f"{scheme.duration_s:.0f} s of data) on the simulated bench, seed {args.seed}")
    with out.status("recording") as status:
        capture = dryrun.record_scheme(
            scheme, truth, args.seed, out_dir,
            progress=lambda name, i, n: status.update(f"recording {name} ({i + 1}/{n})"), geometry=geometry,
            chamber=config.chamber, ramp_accel_dps2=dryrun.table_ramp_accel(config.table), warmup=config.warmup)
    from station.cli.history import file_quietly
    from station.cli.noise import characterise_run, is_noise_recording

    if is_noise_recording(scheme.segments):
        return characterise_run(capture)
    from station import api

    est = api.estimate(capture)
    cal_path = est.save(capture / "calibration.yaml")
    file_quietly(cal_path, asked=bool(args.history), simulated=True)
    out.print(f"capture:          {capture}", markup=False)
    out.print(f"simulated truth:  {capture / dryrun.TRUTH_FILE}", markup=False)
    return report_calibration(est.calibration, "", cal_path, args.accept_poor_fit,
                              truth=dryrun.truth_calibration(truth))


def _append_dry_run(args, overrides) -> int:
    """``station run --sim --append CAPTURE --scheme EXT.yaml``: the extension recorded into a dry
    run's capture on the same simulated bench and IMU (station.simulate.dryrun.append_scheme), then
    the estimate from all of it, as the bench's --append does."""
    from station.io.scheme import load_scheme, scheme_text
    from station.simulate import dryrun

    directory = Path(args.append)
    if not (directory / "manifest.yaml").is_file():
        raise UserError(f"--append {directory}: no capture there (no manifest.yaml)")
    from station.cli.run_multi import is_multi_run

    if is_multi_run(directory):
        raise UserError(f"--append {directory}: appending to a run of several IMUs is not supported; "
                        "record the extension as a run of its own")
    if args.out and Path(args.out) != directory:
        raise UserError(f"--out {args.out}: --append records into {directory} itself; leave out --out")
    text, source = scheme_text(args.scheme)
    ext = load_scheme(args.scheme, overrides)
    out.print(f"dry run: appending {len(ext.segments)} segment(s) of {source} ({ext.duration_s:.0f} s of data) "
              f"to {directory}, on its simulated bench and IMU", markup=False, soft_wrap=True)
    config = _config(args)
    with out.status("recording") as status:
        # the configured warm-up waited for again before the extension, as on a bench's --append
        dryrun.append_scheme(ext, text, directory,
                             progress=lambda name, i, n: status.update(f"recording {name} ({i + 1}/{n})"),
                             chamber=config.chamber, ramp_accel_dps2=dryrun.table_ramp_accel(config.table),
                             warmup=config.warmup)
    from station import api
    from station.cli.history import file_quietly

    est = api.estimate(directory)
    cal_path = est.save(directory / "calibration.yaml")
    file_quietly(cal_path, asked=bool(args.history), simulated=True)
    truth = dryrun.load_truth(str(directory / dryrun.TRUTH_FILE), 0)
    out.print(f"capture:          {directory} (estimated from all {len(est.capture.complete())} segments)", markup=False)
    out.print(f"simulated truth:  {directory / dryrun.TRUTH_FILE}", markup=False)
    return report_calibration(est.calibration, "", cal_path, args.accept_poor_fit,
                              truth=dryrun.truth_calibration(truth))


def _run_on_bench(args) -> int:
    """``station run`` without --sim: a run on the bench named by the flags and the configuration."""
    from station.bench.compile import compile_scheme
    from station.io.scheme import load_scheme, scheme_text

    config = _config(args)
    from station.cli.run_multi import is_multi_run, run_multi

    if args.append and (is_multi_run(Path(args.append)) or config.imus):
        raise UserError(f"--append {args.append}: appending to a run of several IMUs is not supported; "
                        "record the extension as a run of its own")
    if (args.resume and is_multi_run(Path(args.resume))) or (not args.resume and config.imus):
        return run_multi(args, config)
    done: set = set()
    if args.append:
        directory = Path(args.append)
        scheme, config, done = _resumed(directory, config, args)
        scheme, args.keep_extension, extension_of = _appended(directory, scheme, args.scheme)
        args.appended_of = {**getattr(args, "appended_of", {}), **extension_of}
        args.resume = str(directory)          # from here on: a resume of the extended run
    elif args.resume:
        directory = Path(args.resume)
        scheme, config, done = _resumed(directory, config, args)
    else:
        text, _ = scheme_text(args.scheme)
        scheme = load_scheme(args.scheme, _overrides(args))
        directory = _out_dir(args, config, scheme)
    if not config.imu.port:
        raise UserError("no IMU port: give --port (and --table-port), set imu.port in station.yaml "
                        "(station init writes an example), or add --sim for a dry run against the "
                        "simulated bench")
    if scheme.table and not config.table.port:
        raise UserError(f"scheme {scheme.name} needs a rate table: give --table-port or set table.port")
    plan = compile_scheme(scheme, config)
    steps = _resume_steps(plan, scheme, done, config) if args.resume else plan.steps
    if args.resume and not any(s.segment for s in steps):
        out.print(f"{directory}: every segment is recorded; estimating", markup=False)
        return _estimate(directory, args.accept_poor_fit, config, history=args.history)
    try:
        return _record_and_estimate(args, config, scheme, plan, steps, directory, text if not args.resume else None)
    except DEVICE_ERRORS as e:
        where = (f"; what was recorded is kept: continue with station run --resume {directory}"
                 if (Path(directory) / "manifest.yaml").is_file() else "")
        raise UserError(f"{config.table.port if scheme.table else config.imu.port}: a device failed or "
                        f"disconnected ({type(e).__name__}: {str(e)[:100]}){where}") from None


def _record_and_estimate(args, config, scheme, plan, steps, directory, text) -> int:

    from station.bench.guardian import start_guardian

    imu, table = _open_devices(config, scheme)
    guardian = None
    try:
        if table is not None and table.found_moving:      # left turning by an earlier run: stopped
            err.print(f"warning: {table.describe_leftover()}", markup=False, soft_wrap=True)
        if table is not None:         # stops the table should this process die (SIGKILL, a crash)
            guardian = start_guardian(table.url, table.protocol, table.settings, directory)
        for note in plan.notes:
            err.print(f"note: {note}", markup=False, soft_wrap=True)
        rate_hz = imu.configure(config.imu.rate_hz)
        if not args.resume:
            writer = _new_capture(directory, scheme, text, _overrides(args), config, imu, rate_hz)
        else:
            writer = _reopen(directory, rate_hz, imu_identity(getattr(imu, "identity", None)).get("serial"))
            if getattr(args, "keep_extension", None) is not None:     # --append: the same IMU is connected
                args.keep_extension()
            writer.segment_extra = {name: {"appended": k} for name, k in getattr(args, "appended_of", {}).items()}
        out.print(f"capture: {directory}", markup=False)
        from station.bench.live import make_display

        display = make_display(rich_console(out), sum(s.estimate_s for s in steps),
                               f"{scheme.name} on {config.table.axes if scheme.table else 'no'}-axis table")
        status = sequence(steps, display, directory, table=table, imu=imu, writer=writer, config=config,
                          rate_hz=rate_hz, reset_faults=args.reset_faults)
        if status is not None:
            return status
    finally:
        for device in (table, imu):
            if device is not None:
                device.close()
        if guardian is not None:
            guardian.release()
    return _estimate(directory, args.accept_poor_fit, config, history=args.history)


def _config(args):
    from station.bench.config import load_config

    config = load_config(getattr(args, "config", None))
    if config.imus and (getattr(args, "port", None) or getattr(args, "imu_protocol", None)):
        raise UserError(f"{config.source}: field 'imus': the configuration lists {len(config.imus)} IMU(s), "
                        "each with its port and protocol: leave out --port and --imu-protocol (or use imu: "
                        "for one IMU)")
    config = config.with_overrides("imu", port=getattr(args, "port", None),
                                   protocol=getattr(args, "imu_protocol", None))
    config = config.with_overrides("table", port=getattr(args, "table_port", None),
                                   protocol=getattr(args, "table_protocol", None))
    if getattr(args, "unattended", False):
        config = config.with_overrides("run", operator=False)
    return config


def _resumed(directory: Path, current, args):
    """(scheme, config, complete segment names) of a run to continue: what is recorded comes
    from the capture; the connection (ports, protocols, serial) from the flags and the file."""
    from dataclasses import replace

    from station.io.capture import read_capture
    from station.bench.config import from_dict
    from station.io.scheme import scheme_from_text

    run_file = directory / RUN_FILE
    try:
        doc = yaml_text.safe_load(read_run_text(run_file))
        text = read_run_text(directory / SCHEME_FILE)
    except OSError as e:
        raise UserError(f"{directory}: not a capture of station run (no {e.filename}): cannot resume") from None
    except (yaml.YAMLError, ValueError) as e:
        raise UserError(f"{run_file}: not valid YAML: {yaml_text.error_line(e)}") from None
    if not isinstance(doc, dict) or doc.get("format") != RUN_FORMAT:
        raise UserError(f"{run_file}: field 'format': must be {RUN_FORMAT}")
    if _overrides(args):
        raise UserError("--resume continues with the run's own timings: leave out --dwell-s, --rate-dps "
                        "and --rotation-s")
    scheme = scheme_from_text(text, str(directory / SCHEME_FILE), doc.get("overrides") or {})
    config = from_dict(doc.get("config") or {}, str(run_file))
    for section, keys in CONNECTION.items():
        fresh = getattr(current, section)
        config = replace(config, **{section: replace(getattr(config, section),
                                                     **{k: getattr(fresh, k) for k in keys})})
    if getattr(args, "unattended", False) and config.run.operator:
        raise UserError(f"{directory} was recorded with an operator (remounts may have happened): "
                        "resume it with one (leave out --unattended)")
    for k, name in enumerate(doc.get("appended") or [], 1):        # extensions recorded by --append
        if not isinstance(name, str) or "/" in name or not name.startswith("scheme-append-"):
            raise UserError(f"{run_file}: field 'appended[{k}]': must name a scheme-append-N.yaml of the capture")
        try:
            more = scheme_from_text(read_run_text(directory / name), str(directory / name))
        except OSError as e:
            raise UserError(f"{directory / name}: cannot read the appended scheme: {e.strerror}") from None
        scheme = replace(scheme, segments=scheme.segments + more.segments)
        # its segments say so in the manifest (``appended: k``): the estimator does not take a
        # rotation of an extension for the run's rotation about the same axis (summaries' groups)
        args.appended_of = {**getattr(args, "appended_of", {}), **{s.name: k for s in more.segments}}
    capture = read_capture(directory, load_data=False)
    done = {s.name for s in capture.complete()}
    return scheme, config, done


def _atomic_text(path: Path, text: str) -> None:
    import os

    tmp = path.with_name(f".{path.name}.append.tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


def _appended(directory: Path, scheme, extension: str):
    """The run's scheme with the extension's segments after its own; the extension kept in the
    capture (scheme-append-N.yaml, listed in run.yaml's ``appended``) so that an interrupted
    append is continued by --resume and the capture says what was recorded after the run."""
    from dataclasses import replace

    from station.io.scheme import load_scheme, scheme_text

    text, source = scheme_text(extension)
    ext = load_scheme(extension)
    if ext.table != scheme.table:
        raise UserError(f"{source}: {'a hand scheme' if not ext.table else 'a table scheme'} cannot extend "
                        f"{'a table run' if scheme.table else 'a run by hand'}")
    if ext.centred != scheme.centred:
        raise UserError(f"{source}: field 'centred': {ext.centred}, the run's scheme says {scheme.centred}: the "
                        "extension must be mounted as the run was")
    taken = {s.name for s in scheme.segments} & {s.name for s in ext.segments}
    if taken:
        raise UserError(f"{source}: segment names already in {directory}: {', '.join(sorted(taken))} (rename them; "
                        "station design --from prefixes its segments x1_, x2_, ...)")
    run_file = directory / RUN_FILE
    try:
        number = len(yaml_text.safe_load(read_run_text(run_file)).get("appended") or []) + 1
    except (OSError, AttributeError, yaml.YAMLError, ValueError):
        number = 1                      # _resumed read the file just before: not reached
    appended_of = {s.name: number for s in ext.segments}

    def keep() -> None:
        """Write the extension into the capture (once the same IMU is found connected)."""
        doc = yaml_text.safe_load(read_run_text(run_file))
        listed = list(doc.get("appended") or [])
        name = f"scheme-append-{len(listed) + 1}.yaml"
        try:
            _atomic_text(directory / name, text)
            doc["appended"] = listed + [name]
            _atomic_text(run_file, yaml.safe_dump(doc, sort_keys=False))
        except OSError as e:
            raise cannot_write(e.filename or directory, e) from None
        out.print(f"appending {len(ext.segments)} segment(s) of {source} to {directory} (kept as {name}; "
                  f"an interrupted append continues with station run --resume {directory})", markup=False,
                  soft_wrap=True)

    return replace(scheme, segments=scheme.segments + ext.segments), keep, appended_of

