"""``station report``: one self-contained HTML page about a capture and its calibration."""
from __future__ import annotations

from pathlib import Path

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
    from station.diagnose.report import report_input, write_page
    from station.io.calfile import read_calfile
    from station.io.capture import read_capture

    capture = read_capture(args.capture, load_data=False)     # the manifest: samples as needed
    cal_path = Path(args.cal) if args.cal else capture.path / "calibration.yaml"
    cal_doc = read_calfile(cal_path) if (args.cal or cal_path.exists()) else None
    if cal_doc is not None:
        from station.cli.calibration import check_serial

        check_serial(cal_doc, cal_path, capture.imu.serial, args.force, f"capture {capture.path}")
    effects = [e for e in (cal_doc or {}).get("effects", []) if e not in ("base_triads", "inter_triad")]
    inp = report_input(capture, cal_doc, cal_path if cal_doc else None, effects=effects, auto=not args.no_auto)
    target = Path(args.output) if args.output else capture.path / "report.html"
    write_page(target, inp)
    out.print(f"report: {target}", markup=False)
    return 0
