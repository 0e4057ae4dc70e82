"""``station estimate``, ``station show`` and ``station apply``: calibration files from captures,
read and used (argument parsing and output only)."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from station.cli import plugins
from station.cli.choices import ESTIMATE_METHODS
from station.cli.output import EXIT_POOR_FIT, err, out, print_notes, print_parameters, print_verdict


def add_parsers(sub) -> None:
    est = sub.add_parser("estimate", help="estimate a calibration from a capture (no hardware)")
    est.add_argument("capture", help="capture directory (with manifest.yaml)")
    est.add_argument("-o", "--output", metavar="CAL.yaml", help="default: CAPTURE/calibration.yaml")
    est.add_argument("--method", choices=ESTIMATE_METHODS, default="auto",
                     help="auto (default): lsq when rotations have encoder angles, fourier otherwise")
    est.add_argument("--add", action="append", default=[], metavar="EFFECT",
                     help="add an effect to the model: an id (station effects lists them) or a plugin "
                          "FILE.py:CLASS (repeatable)")
    est.add_argument("--config", metavar="FILE", help="station.yaml (its effects section names plugins)")
    plugins.add_arguments(est)
    est.add_argument("--max-missing-fraction", type=float, default=0.01, metavar="F",
                     help="leave out a segment that lost more than this share of its frames (default 0.01)")
    est.add_argument("--max-gap-s", type=float, default=1.0, metavar="S",
                     help="leave out a segment with a longer stretch without a frame, s (default 1)")
    est.add_argument("--turn-sigma-deg", type=float, default=None, metavar="DEG",
                     help="hand turns: their 1-sigma per turn, degrees (default: estimated from their "
                          "scatter when it exceeds their white noise; stated, the turns are tested)")
    add_accept_poor_fit(est)
    est.add_argument("--table", action=argparse.BooleanOptionalAction, default=None,
                     help="print the parameters as a table (default: only when the output is a terminal; "
                          "the file holds them all, station show prints them)")
    from station.cli.history import add_history_option

    add_history_option(est, "default: not filed")
    est.set_defaults(func=cmd_estimate)

    app = sub.add_parser("apply", help="compensate raw samples with a calibration file (every effect)")
    app.add_argument("calibration", metavar="CAL.yaml")
    app.add_argument("input", metavar="IN.csv", help="columns t,ax,ay,az,gx,gy,gz[,temp] in the raw units")
    app.add_argument("-o", "--output", metavar="OUT.csv", required=True)
    app.add_argument("--config", metavar="FILE", help="station.yaml (its effects section names plugins)")
    plugins.add_arguments(app)
    app.add_argument("--force", action="store_true",
                     help="apply a calibration made for another IMU serial (the input's serial is "
                          "given with --serial)")
    app.add_argument("--serial", metavar="SERIAL",
                     help="serial of the IMU that recorded IN.csv; refused when the calibration "
                          "names another one (unless --force)")
    app.set_defaults(func=cmd_apply)

    show = sub.add_parser("show", help="print a calibration file")
    show.add_argument("calibration", metavar="CAL.yaml",
                      help="a calibration file (station-calibration/1): its parameters ± 1σ, verdict and notes")
    show.set_defaults(func=cmd_show)


def add_accept_poor_fit(parser) -> None:
    parser.add_argument("--accept-poor-fit", action="store_true",
                        help=f"exit 0 even when the fit fails (default: exit status {EXIT_POOR_FIT}; "
                             "the file says so either way)")


def report_calibration(cal, title: str, target, accept_poor_fit: bool, truth=None, table: bool = True) -> int:
    """Print a written calibration (parameters, chi-square, verdict, notes, file) and return the
    exit status: 0, or EXIT_POOR_FIT when the fit fails and the user did not accept it.  Without
    ``table`` the parameters are counted in one line instead of a table (a pipe or a log: the
    file holds them, and rich's table machinery is not imported)."""
    from station.cli.output import print_errors
    from station.estimate.verdict import fit_fails

    dropped = set(cal.fit.get("not_determined", []))
    if truth is not None:
        print_errors(cal, truth)
    elif not table:
        written = [n for n, _, _ in cal.parameters() if n not in dropped]
        out.print(f"{title}: {len(written)} parameters written (station show {target} prints them)",
                  markup=False, soft_wrap=True)
    else:
        print_parameters([(n, v, u, cal.sigma.get(n)) for n, v, u in cal.parameters() if n not in dropped],
                         title)
    if "reduced_chi2" in cal.fit:
        out.print(f"fit: chi2 {cal.fit['chi2']:.1f} for {cal.fit['dof']} degrees of freedom "
                  f"(reduced {cal.fit['reduced_chi2']:.3f})", markup=False)
    print_notes(cal)
    print_verdict(cal.fit.get("verdict", {}))
    out.print(f"calibration file: {target}", markup=False)
    if fit_fails(cal):
        what = "fails" if cal.fit["verdict"]["result"] == "fails" else "did not converge"
        if accept_poor_fit:
            err.print(f"note: the fit {what}; accepted (--accept-poor-fit): exit status 0", markup=False)
            return 0
        err.print(f"station: the fit {what} (exit status {EXIT_POOR_FIT}); the file says so; "
                  "station diagnose shows where, --accept-poor-fit accepts it", markup=False, soft_wrap=True)
        return EXIT_POOR_FIT
    return 0


def cmd_estimate(args) -> int:
    return estimate_and_report(args.capture, args.output, method=args.method, add=args.add,
                               plugin_options=plugins.options(args), turn_sigma_deg=args.turn_sigma_deg,
                               max_missing_fraction=args.max_missing_fraction, max_gap_s=args.max_gap_s,
                               history=bool(args.history), accept_poor_fit=args.accept_poor_fit, table=args.table)


def estimate_and_report(capture, output=None, *, method: str = "auto", add=(), plugin_options=None,
                        turn_sigma_deg=None, max_missing_fraction: float = 0.01, max_gap_s: float = 1.0,
                        history: bool = False, accept_poor_fit: bool = False, table: bool | None = None) -> int:
    """What `station estimate CAPTURE` does after parsing its options: the estimate, its warnings,
    the calibration file (``output``, default CAPTURE/calibration.yaml), the history when asked,
    the report; the exit status (0, or EXIT_POOR_FIT).  `station import ... --estimate` calls it
    on the capture it has just written, in the same process."""
    from station import api

    est = api.estimate(capture, method=method, add=list(add), **(plugin_options or {}),
                       turn_sigma_deg=turn_sigma_deg, max_missing_fraction=max_missing_fraction,
                       max_gap_s=max_gap_s)
    for w in est.capture.warnings:
        err.print(f"warning: {w}", markup=False, soft_wrap=True)
    target = est.save(Path(output) if output else est.capture.path / "calibration.yaml")
    from station.cli.history import file_quietly

    file_quietly(target, asked=history)
    table = sys.stdout.isatty() if table is None else table
    return report_calibration(est.calibration, f"calibration of {est.capture.path} ({est.provenance['method']})",
                              target, accept_poor_fit, table=table)


def print_messages(lines) -> None:
    """The API's lines for stderr (warnings, notes, what was compensated), one each."""
    for line in lines:
        err.print(line, markup=False, soft_wrap=True)


def cmd_apply(args) -> int:
    from station import api

    done = api.apply_file(args.calibration, args.input, args.output, serial=args.serial, force=args.force,
                          **plugins.options(args))
    print_messages(done.messages)
    out.print(f"{done.samples} samples compensated into {args.output} (m/s^2, deg/s, frame p)")
    return 0


def cmd_show(args) -> int:
    from station import api

    doc = api.load_calibration(args.calibration)
    rows = [(n, p["value"], p["unit"], p.get("sigma")) for n, p in doc["parameters"].items()]
    print_parameters(rows, f"{args.calibration}")
    prov = doc.get("provenance") or {}
    out.print(f"effects: {', '.join(doc.get('effects', []))}", markup=False)
    held = (doc.get("fit") or {}).get("not_determined")
    if isinstance(held, list) and held:
        out.print(f"not determined by the capture (not written): {', '.join(map(str, held))}", markup=False,
                  soft_wrap=True)
    from station.io.calfile import not_compensated

    for eid, names, whole in not_compensated(doc):
        out.print(f"{eid}: not compensated" + ("" if whole else f" for {', '.join(names)}")
                  + " (not determined by the capture: its nominal 0 is used)", markup=False, soft_wrap=True)
    if doc.get("gyro_pass_through"):
        out.print("gyro: not calibrated (accelerometer-only calibration; apply passes the gyro through)")
    for key in ("method", "capture", "capture_sha256", "imu_model", "imu_serial", "imu_firmware", "imu_lot",
                "software", "date_utc"):
        if prov.get(key) is not None:
            out.print(f"{key}: {prov[key]}", markup=False)
    if doc.get("verdict"):
        print_verdict(doc["verdict"])
    return 0
