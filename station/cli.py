"""The ``station`` command line: argument parsing and output only."""
from __future__ import annotations

import argparse
import datetime as _dt
import sys
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

import station
from station.errors import UserError
from station.estimate import METHODS

out = Console(highlight=False, width=None if sys.stdout.isatty() else 160)
err = Console(stderr=True, highlight=False)


# --- commands -----------------------------------------------------------------------------------

def cmd_run(args) -> int:
    from station.scheme import load_scheme

    overrides = {k: v for k, v in (("dwell_s", args.dwell_s), ("rate_dps", args.rate_dps),
                                   ("rotation_s", args.rotation_s)) if v is not None}
    scheme = load_scheme(args.scheme, overrides)
    if not args.sim:
        from station import cli_run
        return cli_run.cmd_run(args)
    from station import simrun
    from station.calfile import write_calfile
    from station.estimate import estimate_capture

    truth = simrun.load_truth(args.sim_truth, args.seed)
    stamp = _dt.datetime.now(_dt.timezone.utc).strftime("%Y%m%dT%H%M%SZ")
    out_dir = Path(args.out) if args.out else Path("captures") / f"{scheme.name}-sim-{stamp}"
    out.print(f"dry run: scheme [bold]{scheme.name}[/] ({len(scheme.segments)} segments, "
              f"{scheme.duration_s:.0f} s of data) on the simulated bench, seed {args.seed}")
    with out.status("recording") as status:
        capture = simrun.record_scheme(
            scheme, truth, args.seed, out_dir,
            progress=lambda name, i, n: status.update(f"recording {name} ({i + 1}/{n})"))
    cal, _, provenance = estimate_capture(capture)
    cal_path = write_calfile(capture / "calibration.yaml", cal, provenance)
    _print_errors(cal, simrun.truth_calibration(truth))
    _print_notes(cal)
    out.print(f"capture:          {capture}")
    out.print(f"simulated truth:  {capture / simrun.TRUTH_FILE}")
    out.print(f"calibration file: {cal_path}")
    return 0


def cmd_estimate(args) -> int:
    from station.calfile import write_calfile
    from station.estimate import estimate_capture

    cal, capture, provenance = estimate_capture(args.capture, args.method, args.add)
    for w in capture.warnings:
        err.print(f"warning: {w}")
    target = Path(args.output) if args.output else capture.path / "calibration.yaml"
    write_calfile(target, cal, provenance)
    _print_parameters([(n, v, u, cal.sigma.get(n)) for n, v, u in cal.parameters()],
                      f"calibration of {capture.path} ({provenance['method']})")
    if "reduced_chi2" in cal.fit:
        out.print(f"fit: chi2 {cal.fit['chi2']:.1f} for {cal.fit['dof']} degrees of freedom "
                  f"(reduced {cal.fit['reduced_chi2']:.3f})")
    _print_notes(cal)
    out.print(f"calibration file: {target}")
    return 0


def cmd_apply(args) -> int:
    from station.calfile import read_calfile
    from station.capture import read_segment_csv

    from station.compensate import COMPENSATED_EFFECTS, compensate

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
    from station.calfile import read_calfile

    doc = read_calfile(args.calibration)
    rows = [(n, p["value"], p["unit"], p.get("sigma")) for n, p in doc["parameters"].items()]
    _print_parameters(rows, f"{args.calibration}")
    prov = doc.get("provenance", {})
    out.print(f"effects: {', '.join(doc.get('effects', []))}")
    for key in ("method", "capture", "capture_sha256", "imu_serial", "software", "date_utc"):
        if key in prov:
            out.print(f"{key}: {prov[key]}")
    return 0


def cmd_montecarlo(args) -> int:
    import json

    from station import montecarlo
    from station.scheme import load_scheme

    if args.runs < 2:
        raise UserError("--runs must be at least 2")
    scheme = load_scheme(args.scheme)
    settings = montecarlo.Settings(accel_noise_ug=args.accel_noise_ug, gyro_noise_dph=args.gyro_noise_dph,
                                   table_angle_arcsec=args.table_angle_arcsec,
                                   accel_disturbance_ug=args.accel_disturbance_ug, method=args.method)
    names, errors, sigmas = montecarlo.run(scheme, settings, args.runs, first_seed=args.seed)
    crlb = montecarlo.cramer_rao(scheme, settings)
    std = errors.std(axis=0, ddof=1)
    with np.errstate(all="ignore"):
        mean_sigma = np.nanmean(sigmas, axis=0) if np.isfinite(sigmas).any() else np.full(len(std), np.nan)
    rows = [{"name": n, "unit": u, "std": float(sd), "crlb": float(c),
             "mean_sigma": None if not np.isfinite(ms) else float(ms), "mean_error": float(me)}
            for (n, u), sd, c, ms, me in zip(names, std, crlb, mean_sigma, errors.mean(axis=0))]
    if args.json:
        print(json.dumps({"scheme": scheme.name, "runs": args.runs, "method": args.method,
                          "settings": {"accel_noise_ug_rthz": args.accel_noise_ug,
                                       "gyro_noise_dph_rthz": args.gyro_noise_dph,
                                       "table_angle_arcsec": args.table_angle_arcsec,
                                       "accel_disturbance_ug": args.accel_disturbance_ug},
                          "parameters": rows}, indent=1))
        return 0
    table = Table(title=f"{scheme.name}: {args.runs} dry runs, {args.method}; errors against the "
                        "simulated truth (scale factors relative)")
    for col in ("parameter", "std", "CRLB", "std/CRLB", "mean 1σ", "1σ/std", "mean error", "unit"):
        table.add_column(col, justify="left" if col in ("parameter", "unit") else "right")
    for r in rows:
        ms = r["mean_sigma"]
        table.add_row(r["name"], f"{r['std']:.4g}", f"{r['crlb']:.4g}", f"{r['std'] / r['crlb']:.2f}",
                      "" if ms is None else f"{ms:.4g}", "" if ms is None else f"{ms / r['std']:.2f}",
                      f"{r['mean_error']:+.3g}", r["unit"])
    out.print(table)
    return 0


def cmd_effects(args) -> int:
    from station.model import EFFECTS

    if args.name is None:
        table = Table(title="effects the model can add (station estimate --add ID)")
        table.add_column("id")
        table.add_column("what")
        for eid, cls in sorted(EFFECTS.items()):
            table.add_row(eid, cls.title)
        out.print(table)
        return 0
    if args.name not in EFFECTS:
        raise UserError(f"unknown effect {args.name!r}: the library has {', '.join(sorted(EFFECTS))}")
    e = EFFECTS[args.name]()
    out.print(f"[bold]{e.id}[/]: {e.title}\n")
    for label, text in (("physics", e.physics), ("term", e.term), ("excited by", e.excited_by),
                        ("typical size", e.magnitudes), ("when missing", e.signature)):
        out.print(f"[bold]{label}:[/] {text}")
    params = getattr(e, "all_params", None) or e.params
    if params:
        out.print("[bold]parameters:[/] " + ", ".join(f"{p.name} ({p.unit})" for p in params))
    return 0


# --- output helpers -----------------------------------------------------------------------------

def _print_parameters(rows, title: str) -> None:
    """rows: (name, value, unit, 1-sigma or None); scale factors get their 1σ in ppm."""
    table = Table(title=title)
    table.add_column("parameter")
    table.add_column("value", justify="right")
    table.add_column("± 1σ", justify="right")
    table.add_column("unit")
    for name, value, unit, sigma in rows:
        is_scale = unit in ("1", "raw/(m/s^2)", "raw/(deg/s)")
        if sigma is None or not np.isfinite(sigma):
            spread = ""
        elif is_scale:
            spread = f"{sigma / value * 1e6:.3g} ppm"
        else:
            spread = f"{sigma:.3g}"
        table.add_row(name, f"{value:.9g}" if is_scale else f"{value:.4f}", spread, unit)
    out.print(table)


def _print_errors(cal, truth) -> None:
    from station.calibration import parameter_errors

    table = Table(title="estimate against the simulated truth")
    for col in ("parameter", "estimate", "truth", "error", "± 1σ", "unit"):
        table.add_column(col, justify="left" if col in ("parameter", "unit") else "right")
    for name, value, true, error, unit in parameter_errors(cal, truth):
        fmt = "{:.9f}" if "_scale_" in name else "{:.4f}"
        sigma = cal.sigma.get(name)
        if sigma is not None and "_scale_" in name:
            sigma = sigma / value * 1e6
        table.add_row(name, fmt.format(value), fmt.format(true), f"{error:+.4f}",
                      "" if sigma is None else f"{sigma:.4f}", unit)
    out.print(table)


def _print_notes(cal) -> None:
    for note in cal.fit.get("notes", []):
        err.print(f"note: {note}")


# --- parser -------------------------------------------------------------------------------------

class _Parser(argparse.ArgumentParser):
    """argparse with usage errors on one line (exit status 2, as for every user error)."""

    def error(self, message):
        self.exit(2, f"{self.prog}: {message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    from station import cli_devices, cli_diagnose
    from station import cli_import
    from station import cli_run

    p = _Parser(prog="station", description="IMU calibration with a rate table.")
    p.add_argument("--version", action="version", version=f"station {station.__version__}")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND", parser_class=_Parser)

    run = sub.add_parser("run", help="run a calibration scheme and estimate")
    run.add_argument("--scheme", default="optimal9", help="built-in scheme name or a scheme YAML file")
    run.add_argument("--sim", action="store_true", help="dry run against the simulated bench")
    run.add_argument("--sim-truth", metavar="FILE", help="true sensor errors for --sim (YAML)")
    run.add_argument("--seed", type=int, default=1, help="seed of the simulated truth and noise")
    run.add_argument("--out", metavar="DIR", help="capture directory (default captures/<scheme>-sim-<time>)")
    run.add_argument("--dwell-s", type=float, help="override the scheme's dwell per attitude, s")
    run.add_argument("--rate-dps", type=float, help="override the scheme's rotation rate, deg/s")
    run.add_argument("--rotation-s", type=float, help="override the scheme's rotation time per direction, s")
    cli_run.add_run_arguments(run)
    run.set_defaults(func=cmd_run)

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

    mc = sub.add_parser("montecarlo", help="repeat simulate -> estimate; compare with the Cramér-Rao bound")
    mc.add_argument("--scheme", default="optimal9")
    mc.add_argument("--runs", type=int, default=100)
    mc.add_argument("--accel-noise-ug", type=float, default=100.0, help="µg/√Hz (default 100)")
    mc.add_argument("--gyro-noise-dph", type=float, default=0.03, help="°/h/√Hz (default 0.03)")
    mc.add_argument("--table-angle-arcsec", type=float, default=2.0, help="1σ table angle error (default 2)")
    mc.add_argument("--accel-disturbance-ug", type=float, default=50.0,
                    help="1σ white acceleration disturbance (default 50, the 2010 paper's)")
    mc.add_argument("--method", choices=("lsq", "zhang2010"), default="lsq")
    mc.add_argument("--seed", type=int, default=1000, help="first seed (runs use seed, seed+1, ...)")
    mc.add_argument("--json", action="store_true")
    mc.set_defaults(func=cmd_montecarlo)

    eff = sub.add_parser("effects", help="list the effects the model can add, or explain one")
    eff.add_argument("name", nargs="?")
    eff.set_defaults(func=cmd_effects)

    # Commands defined in other modules register here (one line each).
    cli_run.add_parsers(sub)
    cli_diagnose.add_parsers(sub, out, err)
    cli_import.add_parsers(sub)
    cli_devices.add_parsers(sub)
    return p


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except UserError as e:
        err.print(f"station {args.command}: {e}", markup=False, soft_wrap=True)
        return 2
    except KeyboardInterrupt:
        err.print("interrupted")
        return 130


if __name__ == "__main__":
    sys.exit(main())
