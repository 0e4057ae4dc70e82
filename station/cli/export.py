"""``station export``: a calibration file in another tool's format (argument parsing and output)."""
from __future__ import annotations

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
    from station import api

    written = api.export(args.calibration, args.to, args.output, noise=args.noise, force=args.force)
    for line in written.notes:
        err.print(f"note: {line}", markup=False, soft_wrap=True)
    out.print(f"convention: {written.convention}", markup=False, soft_wrap=True)
    for path in written:
        out.print(f"{args.to}: {path}", markup=False)
    return 0
