"""``station import``: recordings made by other tools into capture bundles (argument parsing and
output only; the work is in station.io.importers)."""
from __future__ import annotations

import argparse

from station.cli import argtypes
from station.cli.choices import (CSV_PRESETS, IMUCAL_DEFAULT_GRAVITY_MPS2, IMUCAL_FORMATS,
                                 RECORDING_MIN_POSES, ROSBAG_STAMPS)
from station.cli.output import out
from station.core.errors import UserError


def _check_estimate_options(args) -> None:
    """--estimate's options, refused before anything is imported (one line, exit status 2)."""
    if args.estimate is None:
        asked = [flag for flag, given in (("--accept-poor-fit", args.accept_poor_fit),
                                          ("--table/--no-table", args.table is not None)) if given]
        if asked:
            raise UserError(f"{' and '.join(asked)}: only with --estimate (they choose how its calibration "
                            "is reported)")
    elif args.estimate is not True and not args.estimate.strip():
        raise UserError("--estimate: an empty file name (give CAL.yaml, or nothing for CAPTURE/calibration.yaml)")


def _then_estimate(args, path) -> int:
    """``--estimate [CAL.yaml]``: the capture just written estimated in this process, as `station
    estimate CAPTURE [-o CAL.yaml]` would (the same file, report and exit status), without a
    second interpreter, numpy and station to start (issue 27: an import and its calibration in
    one command).  0 when not asked."""
    if args.estimate is None:
        return 0
    from station.cli.calibration import estimate_and_report

    return estimate_and_report(path, None if args.estimate is True else args.estimate,
                               accept_poor_fit=args.accept_poor_fit, table=args.table)


def _add_estimate_options(p) -> None:
    p.add_argument("--estimate", nargs="?", const=True, default=None, metavar="CAL.yaml",
                   help="then estimate the calibration from the capture in this process, as station estimate "
                        "CAPTURE would: into CAPTURE/calibration.yaml, or CAL.yaml when given (after the "
                        "input file, or last: a name right after it is taken as CAL.yaml)")
    p.add_argument("--accept-poor-fit", action="store_true",
                   help="with --estimate: exit 0 even when the fit fails (default: exit status 3; the file says so)")
    p.add_argument("--table", action=argparse.BooleanOptionalAction, default=None,
                   help="with --estimate: print the parameters as a table (default: only on a terminal)")


def cmd_import_imucal(args) -> int:
    from station import api

    _check_estimate_options(args)
    path = api.import_imucal(
        args.csv, args.output, rate_hz=args.rate_hz, sections_path=args.sections, fmt=args.format,
        gravity_mps2=args.gravity_mps2, accel_unit=args.accel_unit, gyro_unit=args.gyro_unit,
        model=args.model, serial=args.serial, turn_deg=args.turn_deg, placement_deg=args.placement_deg)
    # the manifest only: the sample counts are the writer's (checked against the files whenever
    # their samples are read); reading the segments back was a sixth of the import's CPU
    capture = api.read_capture(path, samples=False)

    def vec(v):
        return "(" + ", ".join(f"{x:g}" for x in v) + ")"

    for seg in capture.segments:
        what = (f"up_body {vec(seg.up_body)}" if seg.kind == "static"
                else f"axis_body {vec(seg.axis_body)}, rate_dps {seg.rate_dps:+.1f} (direction only)"
                + ("" if seg.angle_deg is None else f", angle_deg {seg.angle_deg:+g} (protocol)"))
        out.print(f"{seg.name:6s} {seg.kind:8s} {seg.extra['samples']:6d} samples  {what}", markup=False)
    out.print(f"capture: {path} ({capture.imu.accel_unit}, {capture.imu.gyro_unit}, "
              f"{capture.imu.sample_rate_hz:g} Hz)", markup=False)
    return _then_estimate(args, path)


def _print_report(report) -> None:
    # one print of all the lines: the same text as a print a line (~1 ms each through rich)
    out.print("\n".join([*report.lines, f"capture: {report.path}"]), markup=False)


def _recording_options(args) -> dict:
    return dict(gravity_mps2=args.gravity_mps2, latitude_deg=args.latitude_deg, sections_path=args.segments,
                window_s=args.window_s, min_static_s=args.min_static_s, rate_threshold_dps=args.rate_threshold_dps,
                init_rest_s=args.init_rest_s, min_poses=args.min_poses, model=args.model, serial=args.serial,
                faces=args.faces, placement_deg=args.placement_deg)


def cmd_import_csv(args) -> int:
    from station import api
    from station.io.importers.delimited import parse_columns     # the --columns text, parsed

    _check_estimate_options(args)
    columns = parse_columns(args.columns) if args.columns else None
    report = api.import_csv(
        args.file, args.output, preset=args.preset, columns=columns, delimiter=args.delimiter, header=args.header,
        accel_unit=args.accel_unit, gyro_unit=args.gyro_unit, accel_nominal=args.accel_nominal,
        gyro_nominal=args.gyro_nominal, time_unit=args.time_unit, rate_hz=args.rate_hz, gyro_path=args.gyro_file,
        **_recording_options(args))
    _print_report(report)
    return _then_estimate(args, report.path)


def cmd_import_rosbag(args) -> int:
    from station import api

    _check_estimate_options(args)
    report = api.import_rosbag(args.bag, args.output, topic=args.topic, stamps=args.stamps, rate_hz=args.rate_hz,
                               **_recording_options(args))
    _print_report(report)
    return _then_estimate(args, report.path)


def _add_recording_options(p) -> None:
    """Options shared by the importers of continuous recordings (sections, site, output)."""
    p.add_argument("-o", "--output", required=True, metavar="CAPTURE", help="new capture directory")
    p.add_argument("--segments", metavar="FILE",
                   help="give the sections by hand instead of finding them: YAML/JSON list of {name, kind "
                        "(static|rotation), start, end (rows from 0, end exclusive) or start_s, end_s, "
                        "up_body, axis_body}, or imucal's {label: {start, end}}")
    p.add_argument("--gravity-mps2", type=argtypes.positive, default=9.80665,
                   help="local gravity, m/s^2 (default 9.80665: give your site's)")
    p.add_argument("--latitude-deg", type=argtypes.finite, help="site latitude: the Earth rate is then modelled")
    p.add_argument("--window-s", type=argtypes.positive, default=0.5, help="stillness window, s (default 0.5)")
    p.add_argument("--min-static-s", type=argtypes.positive, default=2.0,
                   help="shortest still interval taken as a pose, s (default 2)")
    p.add_argument("--rate-threshold-dps", type=argtypes.positive, default=1.0,
                   help="largest mean rate (less the bias) of a still interval, deg/s (default 1)")
    p.add_argument("--init-rest-s", type=argtypes.positive, default=2.0,
                   help="length of the still rest the recording starts with, s: scales raw outputs of "
                        "unknown scale (default 2)")
    p.add_argument("--min-poses", type=argtypes.whole(2), default=RECORDING_MIN_POSES,
                   help=f"fewest static poses accepted (default {RECORDING_MIN_POSES}: the accelerometer's 9 "
                        "unknowns with unknown attitudes)")
    p.add_argument("--faces", action="store_true",
                   help="the IMU was laid on its faces: each pose's up_body is the nearest case axis")
    p.add_argument("--placement-deg", type=argtypes.positive, default=1.0,
                   help="1-sigma of a hand placement on a face, deg (with --faces or up_body; default 1)")
    p.add_argument("--model", help="IMU model, recorded in the manifest")
    p.add_argument("--serial", help="IMU serial number, recorded in the manifest")


def add_parsers(sub) -> None:
    """Add the ``import`` command (sub-commands ``imucal``, ``csv``, ``rosbag``) to station's subparsers."""
    from station.core.units import ACCEL_UNITS, GYRO_UNITS

    imp = sub.add_parser("import", help="turn another tool's recording into a capture bundle")
    kinds = imp.add_subparsers(dest="source", required=True, metavar="SOURCE", parser_class=type(imp))
    p = kinds.add_parser("imucal", help="an imucal Ferraris session (CSV, with a JSON section list or a 'part' column)")
    p.add_argument("csv", metavar="CSV", help="imucal session CSV")
    p.add_argument("--sections", metavar="JSON", help="imucal section list {label: {start, end}} (session layout)")
    p.add_argument("--rate-hz", type=argtypes.positive, required=True, metavar="HZ",
                   help="sample rate: imucal files carry none (the example session: 102.4)")
    p.add_argument("-o", "--output", required=True, metavar="CAPTURE", help="new capture directory")
    p.add_argument("--format", choices=IMUCAL_FORMATS, default="auto",
                   help="session (JSON sections, m/s^2 and deg/s) or annotated ('part' column, raw counts); "
                        "auto: annotated when the header has 'part'")
    p.add_argument("--gravity-mps2", type=argtypes.positive, default=IMUCAL_DEFAULT_GRAVITY_MPS2,
                   help=f"local gravity, m/s^2 (default {IMUCAL_DEFAULT_GRAVITY_MPS2}, imucal's)")
    p.add_argument("--accel-unit", choices=ACCEL_UNITS, help="override the layout's accelerometer unit")
    p.add_argument("--gyro-unit", choices=GYRO_UNITS, help="override the layout's gyro unit")
    p.add_argument("--model", help="IMU model, recorded in the manifest")
    p.add_argument("--serial", help="IMU serial number, recorded in the manifest")
    p.add_argument("--turn-deg", type=argtypes.positive, metavar="DEG",
                   help="record each rotation section as a turn of DEG (imucal's protocol: 360) so "
                        "that the least-squares model can use it; no encoder measured it")
    p.add_argument("--placement-deg", type=argtypes.positive, default=1.0, metavar="DEG",
                   help="1-sigma accuracy of the hand placement and turns (default 1 deg)")
    _add_estimate_options(p)
    p.set_defaults(func=cmd_import_imucal)

    c = kinds.add_parser("csv", help="a continuous recording in delimited text: statics and hand turns found in it")
    c.add_argument("file", metavar="FILE", help="the log (CSV, ';'-, tab- or blank-separated)")
    c.add_argument("--preset", choices=CSV_PRESETS,
                   help="a known layout: station/t-a-g (t,ax,ay,az,gx,gy,gz; s, m/s^2, deg/s), imu_tk (two "
                        "files 't x y z', accel and --gyro-file; s, m/s^2, rad/s), imucal (its session CSV)")
    c.add_argument("--columns", metavar="MAP",
                   help="ROLE=COLUMN,... by header name or index from 0; roles t (time) or index (sample "
                        "counter), ax ay az gx gy gz (default t-a-g: t=0,ax=1,...,gz=6)")
    c.add_argument("--delimiter", choices=[",", ";", "tab", "space"], help="default: from the first data line")
    c.add_argument("--header", choices=["auto", "yes", "no"], help="default auto: a non-numeric first line")
    c.add_argument("--accel-unit", choices=ACCEL_UNITS, help="default m/s^2 (or the preset's)")
    c.add_argument("--gyro-unit", choices=GYRO_UNITS, help="default deg/s (or the preset's)")
    c.add_argument("--accel-nominal", type=argtypes.positive, metavar="MPS2_PER_COUNT",
                   help="raw accelerometer: nominal m/s^2 per count (thresholds, unit check)")
    c.add_argument("--gyro-nominal", type=argtypes.positive, metavar="DPS_PER_COUNT",
                   help="raw gyro: nominal deg/s per count (thresholds, unit check, the fit's start)")
    c.add_argument("--time-unit", choices=["s", "ms", "us", "ns"], help="unit of the time column (default s)")
    c.add_argument("--rate-hz", type=argtypes.positive, metavar="HZ",
                   help="sample rate: time = index column (or row number) / rate, when there is no time column")
    c.add_argument("--gyro-file", metavar="FILE", help="imu_tk layout: the gyro's file")
    _add_recording_options(c)
    _add_estimate_options(c)
    c.set_defaults(func=cmd_import_csv)

    b = kinds.add_parser("rosbag", help="sensor_msgs/Imu from a ROS 1 bag or a ROS 2 bag (db3 or MCAP)")
    b.add_argument("bag", metavar="BAG", help="a .bag file, a ROS 2 bag directory, or an .mcap file")
    b.add_argument("--topic", help="the Imu topic (default: the bag's only one)")
    b.add_argument("--stamps", choices=ROSBAG_STAMPS, default="header",
                   help="time from each message's header.stamp (default) or the recorder's receive time")
    b.add_argument("--rate-hz", type=argtypes.positive, metavar="HZ",
                   help="re-time the messages evenly at HZ (stamps that jitter: a driver stamped at receive "
                        "time); refused when the stamps' span disagrees with the count at HZ by more than 1 %%")
    _add_recording_options(b)
    _add_estimate_options(b)
    b.set_defaults(func=cmd_import_rosbag)


__all__ = ["add_parsers", "UserError"]
