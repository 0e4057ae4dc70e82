"""``station report``: one self-contained HTML page about a capture and its calibration."""
from __future__ import annotations

from station.cli.output import out


def add_parsers(sub) -> None:
    r = sub.add_parser("report", help="one self-contained HTML page: capture, IMU, parameters ± 1σ, "
                       "verdict, residuals before/after each added effect, candidates, noise")
    r.add_argument("capture", help="capture directory")
    r.add_argument("--cal", metavar="CAL.yaml", help="default: CAPTURE/calibration.yaml if it exists")
    r.add_argument("-o", "--output", metavar="REPORT.html", help="default: CAPTURE/report.html")
    r.add_argument("--force", action="store_true",
                   help="use a --cal made for another IMU serial than the capture's")
    r.add_argument("--no-auto", action="store_true",
                   help="diagnose the model as fitted only (no add-and-refit loop)")
    r.set_defaults(func=cmd_report)


def cmd_report(args) -> int:
    from station import api
    from station.cli.calibration import print_messages

    page = api.report(args.capture, calibration=args.cal, output=args.output, force=args.force, auto=not args.no_auto)
    print_messages(page.warnings)
    out.print(f"report: {page.path}", markup=False)
    return 0
