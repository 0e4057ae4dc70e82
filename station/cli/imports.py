"""``station import``: recordings made by other tools into capture bundles (argument parsing and
output only; the work is in station.io.importers)."""
from __future__ import annotations

import argparse

from station.cli.output import out
from station.core.errors import UserError


def cmd_import_imucal(args) -> int:
    from station.io.importers import imucal

    path = imucal.import_imucal(
        args.csv, args.output, rate_hz=args.rate_hz, sections_path=args.sections, fmt=args.format,
        gravity_mps2=args.gravity_mps2, accel_unit=args.accel_unit, gyro_unit=args.gyro_unit,
        model=args.model, serial=args.serial, turn_deg=args.turn_deg, placement_deg=args.placement_deg)
    from station.io.capture import read_capture

    capture = read_capture(path)
    def vec(v):
        return "(" + ", ".join(f"{x:g}" for x in v) + ")"

    for seg in capture.segments:
        what = (f"up_body {vec(seg.up_body)}" if seg.kind == "static"
                else f"axis_body {vec(seg.axis_body)}, rate_dps {seg.rate_dps:+.1f} (direction only)"
                + ("" if seg.angle_deg is None else f", angle_deg {seg.angle_deg:+g} (protocol)"))
        out.print(f"{seg.name:6s} {seg.kind:8s} {len(seg.data.t):6d} samples  {what}", markup=False)
    out.print(f"capture: {path} ({capture.imu.accel_unit}, {capture.imu.gyro_unit}, "
              f"{capture.imu.sample_rate_hz:g} Hz)", markup=False)
    return 0


def _positive(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not value > 0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"must be a positive number, got {text!r}")
    return value


def add_parsers(sub) -> None:
    """Add the ``import`` command (sub-command ``imucal``) to station's subparsers."""
    from station.io.importers import imucal
    from station.core.units import ACCEL_UNITS, GYRO_UNITS

    imp = sub.add_parser("import", help="turn another tool's recording into a capture bundle")
    kinds = imp.add_subparsers(dest="source", required=True, metavar="SOURCE", parser_class=type(imp))
    p = kinds.add_parser("imucal", help="an imucal Ferraris session (CSV, with a JSON section list or a 'part' column)")
    p.add_argument("csv", metavar="CSV", help="imucal session CSV")
    p.add_argument("--sections", metavar="JSON", help="imucal section list {label: {start, end}} (session layout)")
    p.add_argument("--rate-hz", type=_positive, required=True, metavar="HZ",
                   help="sample rate: imucal files carry none (the example session: 102.4)")
    p.add_argument("-o", "--output", required=True, metavar="CAPTURE", help="new capture directory")
    p.add_argument("--format", choices=imucal.FORMATS, default="auto",
                   help="session (JSON sections, m/s^2 and deg/s) or annotated ('part' column, raw counts); "
                        "auto: annotated when the header has 'part'")
    p.add_argument("--gravity-mps2", type=_positive, default=imucal.DEFAULT_GRAVITY_MPS2,
                   help=f"local gravity, m/s^2 (default {imucal.DEFAULT_GRAVITY_MPS2}, imucal's)")
    p.add_argument("--accel-unit", choices=ACCEL_UNITS, help="override the layout's accelerometer unit")
    p.add_argument("--gyro-unit", choices=GYRO_UNITS, help="override the layout's gyro unit")
    p.add_argument("--model", help="IMU model, recorded in the manifest")
    p.add_argument("--serial", help="IMU serial number, recorded in the manifest")
    p.add_argument("--turn-deg", type=_positive, metavar="DEG",
                   help="record each rotation section as a turn of DEG (imucal's protocol: 360) so "
                        "that the least-squares model can use it; no encoder measured it")
    p.add_argument("--placement-deg", type=_positive, default=1.0, metavar="DEG",
                   help="1-sigma accuracy of the hand placement and turns (default 1 deg)")
    p.set_defaults(func=cmd_import_imucal)


__all__ = ["add_parsers", "UserError"]
