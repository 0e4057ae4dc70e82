"""``station estimate``, ``station show`` and ``station apply``: calibration files from captures,
read and used (argument parsing and output only)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from station.cli.output import err, out, print_notes, print_parameters
from station.core.errors import UserError
from station.estimate import METHODS


def add_parsers(sub) -> None:
    est = sub.add_parser("estimate", help="estimate a calibration from a capture (no hardware)")
    est.add_argument("capture", help="capture directory (with manifest.yaml)")
    est.add_argument("-o", "--output", metavar="CAL.yaml", help="default: CAPTURE/calibration.yaml")
    est.add_argument("--method", choices=METHODS, default="auto",
                     help="auto (default): lsq when rotations have encoder angles, fourier otherwise")
    est.add_argument("--add", action="append", default=[], metavar="EFFECT",
                     help="add an effect of the library to the model (repeatable; station effects lists them)")
    est.set_defaults(func=cmd_estimate)

    app = sub.add_parser("apply", help="compensate raw samples with a calibration file")
    app.add_argument("calibration", metavar="CAL.yaml")
    app.add_argument("input", metavar="IN.csv", help="columns t,ax,ay,az,gx,gy,gz[,temp] in the raw units")
    app.add_argument("-o", "--output", metavar="OUT.csv", required=True)
    app.set_defaults(func=cmd_apply)

    show = sub.add_parser("show", help="print a calibration file")
    show.add_argument("calibration", metavar="CAL.yaml")
    show.set_defaults(func=cmd_show)


def cmd_estimate(args) -> int:
    from station.io.calfile import write_calfile
    from station.estimate import estimate_capture

    cal, capture, provenance = estimate_capture(args.capture, args.method, args.add)
    for w in capture.warnings:
        err.print(f"warning: {w}")
    target = Path(args.output) if args.output else capture.path / "calibration.yaml"
    write_calfile(target, cal, provenance)
    from station.cli.history import file_quietly

    file_quietly(target)
    print_parameters([(n, v, u, cal.sigma.get(n)) for n, v, u in cal.parameters()],
                      f"calibration of {capture.path} ({provenance['method']})")
    if "reduced_chi2" in cal.fit:
        out.print(f"fit: chi2 {cal.fit['chi2']:.1f} for {cal.fit['dof']} degrees of freedom "
                  f"(reduced {cal.fit['reduced_chi2']:.3f})")
    print_notes(cal)
    out.print(f"calibration file: {target}")
    return 0


def cmd_apply(args) -> int:
    from station.io.calfile import read_calfile
    from station.io.capture import read_segment_csv

    from station.model.compensate import COMPENSATED_EFFECTS, compensate

    doc = read_calfile(args.calibration)
    data = read_segment_csv(Path(args.input))
    f, w = compensate(doc["compensation"], data.t, data.accel, data.gyro, data.temp)
    skipped = [e for e in doc.get("effects", []) if e not in COMPENSATED_EFFECTS]
    if skipped:
        err.print(f"note: estimated but not compensated by apply: {', '.join(skipped)}")
    table = np.column_stack([data.t, f, w])
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
    prov = doc.get("provenance", {})
    out.print(f"effects: {', '.join(doc.get('effects', []))}")
    for key in ("method", "capture", "capture_sha256", "imu_serial", "software", "date_utc"):
        if key in prov:
            out.print(f"{key}: {prov[key]}")
    return 0
