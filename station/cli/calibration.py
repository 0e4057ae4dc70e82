"""``station estimate``, ``station show`` and ``station apply``: calibration files from captures,
read and used (argument parsing and output only)."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from station.cli import plugins
from station.cli.choices import ESTIMATE_METHODS
from station.cli.output import EXIT_POOR_FIT, err, out, print_notes, print_parameters, print_verdict
from station.core.errors import UserError


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
    from station.estimate import estimate_capture   # scipy and the file writer: while the capture is read

    reg = plugins.registry(args)
    if not (0 <= args.max_missing_fraction < 1 and args.max_gap_s > 0):
        raise UserError("--max-missing-fraction must be within [0, 1) and --max-gap-s > 0")
    if args.turn_sigma_deg is not None and not (0 <= args.turn_sigma_deg < 90):
        raise UserError(f"--turn-sigma-deg {args.turn_sigma_deg}: must be within [0, 90) degrees")
    cal, capture, provenance = estimate_capture(args.capture, args.method, plugins.effect_ids(reg, args.add), reg,
                                                max_missing_fraction=args.max_missing_fraction,
                                                max_gap_s=args.max_gap_s, turn_sigma_deg=args.turn_sigma_deg)
    for w in capture.warnings:
        err.print(f"warning: {w}", markup=False, soft_wrap=True)
    target = Path(args.output) if args.output else capture.path / "calibration.yaml"
    from station.io.calfile import write_calfile

    write_calfile(target, cal, provenance)
    from station.cli.history import file_quietly

    file_quietly(target, asked=bool(args.history))
    table = sys.stdout.isatty() if args.table is None else args.table
    return report_calibration(cal, f"calibration of {capture.path} ({provenance['method']})", target,
                              args.accept_poor_fit, table=table)


def check_serial(doc: dict, calibration, serial, force: bool, what: str) -> None:
    """Refuse (UserError) a calibration made for another IMU than ``serial`` unless ``force``."""
    made_for = (doc.get("provenance") or {}).get("imu_serial") or (doc.get("imu") or {}).get("serial")
    if serial is None or made_for is None or str(made_for) == str(serial):
        return
    if force:
        err.print(f"warning: {calibration} was made for IMU serial {made_for}, {what} comes from serial "
                  f"{serial}: used anyway (--force)", markup=False, soft_wrap=True)
        return
    raise UserError(f"{calibration}: field 'provenance.imu_serial': made for IMU serial {made_for}, "
                    f"but {what} comes from serial {serial}: refused (--force uses it anyway)")


def _input_serial(args):
    """The serial of the IMU that recorded the input: --serial, or the manifest of the capture
    the input file lies in (if it lies in one)."""
    from station.io.capture import MANIFEST, read_capture

    if args.serial is not None:
        return args.serial
    folder = Path(args.input).parent
    if (folder / MANIFEST).is_file():
        return read_capture(folder, load_data=False).imu.serial
    return None


def cmd_apply(args) -> int:
    from station.io.calfile import compensation_effects, read_calfile
    from station.io.capture import read_segment_csv
    from station.model.compensate import LEGACY_EFFECTS, compensate, compensate_with_effects

    doc = read_calfile(args.calibration)
    check_serial(doc, args.calibration, _input_serial(args), args.force, args.input)
    if doc.get("gyro_pass_through") and (doc.get("imu") or {}).get("gyro_unit") == "raw":
        raise UserError(f"{args.calibration}: calibrates the accelerometers only, and the gyro output is in "
                        "raw counts: apply has no scale to write the gyros in deg/s (calibrate the gyros: "
                        "rotations with encoder angles, or hand turns between statics)")
    data = read_segment_csv(Path(args.input))
    comp = doc["compensation"]
    if "effects" in comp:
        effects = compensation_effects(doc, plugins.registry(args), args.calibration)
        needs = {need: [e.id for e, _ in effects if need in e.needs] for need in ("temperature", "time")}
        if needs["temperature"] and data.temp is None:
            raise UserError(f"{args.input}: no temp column, which the compensation of "
                            f"{', '.join(needs['temperature'])} needs (deg C)")
        if needs["time"] and len(data.t) < 3:
            raise UserError(f"{args.input}: {len(data.t)} samples; the compensation of "
                            f"{', '.join(needs['time'])} needs rates of change (at least 3 samples)")
        t, f, w = compensate_with_effects(comp, effects, data.t, data.accel, data.gyro, data.temp)
        for e, _ in effects:
            inputs = ", ".join(e.needs)
            err.print(f"compensated: {e.id} ({getattr(e, '_station_source', 'library')})"
                      + (f", using {inputs}" if inputs else ""), markup=False)
    else:                               # a file written before compensation.effects
        t = data.t
        f, w = compensate(comp, data.t, data.accel, data.gyro, data.temp)
        skipped = [e for e in doc.get("effects", []) if e not in LEGACY_EFFECTS]
        if skipped:
            err.print(f"note: this calibration file predates compensation.effects: not compensated: "
                      f"{', '.join(skipped)} (estimate again to compensate them)", markup=False)
    if doc.get("gyro_pass_through"):
        err.print(f"note: {args.calibration} calibrates the accelerometers only: the gyro columns are "
                  "passed through untouched (converted to deg/s only)", markup=False, soft_wrap=True)
    verdict = doc.get("verdict") or {}
    if verdict.get("result") in ("fails", "not converged"):
        err.print(f"warning: {args.calibration}: its fit {verdict['result'].replace('not converged', 'did not converge')} "
                  f"({verdict.get('reason', '')})",
                  markup=False, soft_wrap=True)
    import numpy as np

    table = np.column_stack([t, f, w])
    try:
        with open(args.output, "w") as fh:
            fh.write("t,ax,ay,az,gx,gy,gz\n")
            np.savetxt(fh, table, delimiter=",", fmt=["%.9f"] + ["%.12g"] * 6)
    except OSError as e:
        raise UserError(f"{args.output}: cannot write: {e.strerror}") from None
    out.print(f"{len(table)} samples compensated into {args.output} (m/s^2, deg/s, frame p)")
    return 0


def cmd_show(args) -> int:
    from station.io.calfile import read_calfile

    doc = read_calfile(args.calibration)
    rows = [(n, p["value"], p["unit"], p.get("sigma")) for n, p in doc["parameters"].items()]
    print_parameters(rows, f"{args.calibration}")
    prov = doc.get("provenance") or {}
    out.print(f"effects: {', '.join(doc.get('effects', []))}", markup=False)
    if doc.get("gyro_pass_through"):
        out.print("gyro: not calibrated (accelerometer-only calibration; apply passes the gyro through)")
    for key in ("method", "capture", "capture_sha256", "imu_model", "imu_serial", "imu_firmware",
                "software", "date_utc"):
        if prov.get(key) is not None:
            out.print(f"{key}: {prov[key]}", markup=False)
    if doc.get("verdict"):
        print_verdict(doc["verdict"])
    return 0
