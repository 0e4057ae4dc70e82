"""``station export``: a calibration file in another tool's format (argument parsing and output)."""
from __future__ import annotations

from pathlib import Path

from station.cli.choices import EXPORT_FORMATS
from station.cli.output import err, out


def add_parsers(sub) -> None:
    ex = sub.add_parser("export", help="write a calibration file in another tool's format")
    ex.add_argument("calibration", metavar="CAL.yaml")
    ex.add_argument("--to", required=True, choices=sorted(EXPORT_FORMATS), metavar="FORMAT",
                    help="; ".join(f"{name}: {title}" for name, title in EXPORT_FORMATS.items()))
    ex.add_argument("-o", "--output", metavar="PATH",
                    help="default: next to CAL, named CAL-FORMAT with the format's ending; a "
                    "directory: that name inside it")
    ex.add_argument("--noise", metavar="NOISE.yaml",
                    help="noise figures from `station noise` when CAL has none (Kalibr needs them)")
    ex.add_argument("--force", action="store_true", help="use --noise of another IMU serial")
    ex.set_defaults(func=cmd_export)


def cmd_export(args) -> int:
    from station.io.calfile import read_calfile
    from station.io.exporters import FORMATS, source_from_document
    from station.core.errors import UserError
    from station.io.noise_file import noise_serial, read_noise_block

    fmt = FORMATS[args.to]
    cal = Path(args.calibration)
    source = source_from_document(read_calfile(cal), cal)
    if args.noise:
        source.noise = read_noise_block(args.noise)
        other = noise_serial(args.noise)
        if other and source.imu_serial and other != source.imu_serial and not args.force:
            raise UserError(f"{args.noise}: noise of IMU {other!r}, calibration of IMU {source.imu_serial!r} "
                            "(--force to combine them anyway)")
    name = f"{cal.stem}-{args.to}{fmt.SUFFIX}"
    target = Path(args.output) if args.output else cal.with_name(name)
    if args.output and (target.is_dir() or args.output.endswith(("/", "\\"))):
        target = target / name            # a directory: the default name inside it
    written = fmt.write(source, target)
    for line in source.header_lines()[1:]:
        err.print(f"note: {line}", markup=False, soft_wrap=True)
    out.print(f"convention: {fmt.CONVENTION}", markup=False, soft_wrap=True)
    for path in written:
        out.print(f"{args.to}: {path}", markup=False)
    return 0
