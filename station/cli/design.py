"""``station design``: the scheme that calibrates a model best on a table within a time budget
(station/design/, docs/design.md)."""
from __future__ import annotations

from station.cli import argtypes, choices, plugins
from station.cli.output import err, out
from station.core.errors import UserError


def _numbers(text: str) -> tuple:
    """A comma-separated list of positive numbers."""
    import argparse

    try:
        values = tuple(float(x) for x in text.split(",") if x.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a comma-separated list of numbers: {text!r}") from None
    if not values or any(not (v > 0 and v < 1e6) for v in values):
        raise argparse.ArgumentTypeError(f"must be positive numbers below 1e6, got {text!r}")
    return values


def add_parsers(sub) -> None:
    d = sub.add_parser("design", help="design the scheme that calibrates your model best on your table "
                                      "within a time budget (docs/design.md)")
    d.add_argument("--duration", type=argtypes.between(60, 1e6), required=True, metavar="S",
                   help="time budget in seconds of table time (the compiled plan's: moves, settling, ramps, "
                        "operator steps included)")
    d.add_argument("--config", metavar="FILE",
                   help="station.yaml: the table (axes, limits, operator, geometry) (default: $STATION_CONFIG, "
                        "./station.yaml, else the built-in simulated bench's 3-axis table)")
    d.add_argument("--add", action="append", default=[], metavar="EFFECT",
                   help="design for the base model plus this effect (an id, or FILE.py:CLASS); repeatable")
    plugins.add_arguments(d)
    d.add_argument("--criterion", default="D", metavar="|".join(choices.DESIGN_CRITERIA) + ":PARAM,...",
                   help="D (the parameters' covariance determinant), A (sum of their variances in reported "
                        "units) or worst:PARAM,... (the largest 1σ of the named parameters, fnmatch patterns; "
                        "default D)")
    d.add_argument("--accel-noise-ug", type=argtypes.between(1e-3, 1e5), default=None,
                   help="accelerometer white noise, µg/√Hz (default 100, the Monte Carlo's)")
    d.add_argument("--gyro-noise-dph", type=argtypes.between(1e-6, 1e5), default=None,
                   help="gyro white noise, °/h/√Hz (default 0.03)")
    d.add_argument("--table-angle-arcsec", type=argtypes.between(0, 3600), default=None,
                   help="1σ of the table's angles, arc-seconds (default 2, or the capture's)")
    d.add_argument("--accel-disturbance-ug", type=argtypes.between(0, 1e5), default=None,
                   help="1σ white acceleration disturbance per sample, µg (default 50 with datasheet numbers, "
                        "0 with --noise or --noise-from)")
    d.add_argument("--noise", metavar="FILE", help="the noise of `station noise` (noise.yaml or a calibration "
                                                     "file with a noise block): its white noise densities")
    d.add_argument("--noise-from", metavar="CAPTURE", help="the white noise a capture's statics show")
    d.add_argument("--rates", type=_numbers, default=None, metavar="R,R,...",
                   help="candidate rotation rates, deg/s (default 10,30,100,200; those above the table's "
                        "max_rate_dps left out)")
    d.add_argument("--revolutions", type=_numbers, default=None, metavar="N,N,...",
                   help="candidate whole revolutions per rotation direction (default 1,2,5)")
    d.add_argument("--dwells", type=_numbers, default=None, metavar="S,S,...",
                   help="candidate static dwells, s (default 10,20,50,100,200)")
    d.add_argument("--passes", type=argtypes.whole(0), default=20,
                   help="at most this many exchange passes (default 20)")
    d.add_argument("--compare", default=",".join(("optimal9", "chatfield18", "traditional24", "sizeeffect")),
                   metavar="NAME,...", help="built-in schemes to compare at the same duration ('' for none)")
    d.add_argument("--centred", action="store_true",
                   help="the IMU mounted with its reference point on the table's axes (the scheme says "
                        "centred: true, as sizeeffect does: no mounting offset to estimate)")
    d.add_argument("--name", default="designed", help="the scheme's name (default designed)")
    d.add_argument("-o", "--out", default="designed.yaml", metavar="FILE",
                   help="the scheme file to write (default designed.yaml)")
    d.add_argument("--json", action="store_true", help="the comparison as JSON on stdout")
    d.set_defaults(func=cmd_design)


def _noise(args):
    from station.design.information import Noise
    from station.design import noise as noise_mod

    if args.noise and args.noise_from:
        raise UserError("give --noise or --noise-from, not both")
    if args.noise:
        n = noise_mod.from_noise_file(args.noise, args.table_angle_arcsec if args.table_angle_arcsec is not None else 2.0)
    elif args.noise_from:
        n = noise_mod.from_capture(args.noise_from)
        if args.table_angle_arcsec is not None:
            n.table_angle_arcsec = args.table_angle_arcsec
    else:
        n = Noise()
        stated = []
        for flag, attr in (("accel_noise_ug", "accel_noise_ug"), ("gyro_noise_dph", "gyro_noise_dph"),
                           ("table_angle_arcsec", "table_angle_arcsec")):
            if getattr(args, flag) is not None:
                setattr(n, attr, getattr(args, flag))
                stated.append(flag)
        n.source = "datasheet numbers given" if stated else n.source
    if args.accel_disturbance_ug is not None:
        n.accel_disturbance_ug = args.accel_disturbance_ug
    return n


def cmd_design(args) -> int:
    import json
    from pathlib import Path

    from rich.table import Table

    from station.bench.config import load_config
    from station.design import candidates as cand_mod
    from station.design.designer import criterion_of, design, efficiency
    from station.io.calfile import write_new_file
    from station.io.scheme import builtin_names

    config = load_config(args.config)
    reg = plugins.registry(args)
    effects = [reg.create(e) for e in plugins.effect_ids(reg, args.add)]
    noise = _noise(args)
    compare = tuple(x.strip() for x in args.compare.split(",") if x.strip())
    unknown = [c for c in compare if c not in builtin_names()]
    if unknown:
        raise UserError(f"--compare: not built-in schemes: {', '.join(unknown)} (built-in: {', '.join(builtin_names())})")
    out_path = Path(args.out)
    if out_path.suffix not in (".yaml", ".yml"):
        raise UserError(f"-o {args.out}: a scheme file ends in .yaml")
    revolutions = tuple(int(round(r)) for r in args.revolutions) if args.revolutions else cand_mod.DEFAULT_REVOLUTIONS
    d = design(config, effects, noise, args.duration, args.criterion,
               rates_dps=args.rates or cand_mod.DEFAULT_RATES_DPS, revolutions=revolutions,
               dwells_s=args.dwells or cand_mod.DEFAULT_DWELLS_S, max_passes=args.passes, name=args.name,
               compare=compare, centred=args.centred, progress=lambda text: err.print(f"design: {text}", markup=False, soft_wrap=True))
    try:
        write_new_file(out_path, d.text.encode("utf-8"), what="scheme file")
    except OSError as e:
        raise UserError(f"{out_path}: cannot write the scheme file: {e.strerror}") from None
    p = d.prediction
    usable = [b for b in d.builtins if len(b.sigma)]
    crit_vals = {b.scheme: criterion_of(b, d.criterion) for b in usable}
    own = criterion_of(p, d.criterion)
    kind = d.criterion.split(":")[0]
    from station.design.search import parse_criterion

    _, which = parse_criterion(d.criterion, p.names)
    reveals = {b.scheme: [n for n, mine, theirs in zip(p.names, p.revealed, b.revealed) if mine and not theirs]
               for b in usable}
    if args.json:
        print(json.dumps({
            "scheme_file": str(out_path), "criterion": d.criterion, "duration_s": d.duration_s, "budget_s": d.budget_s,
            "noise": vars(noise), "effects": [e.id for e in effects],
            "designed": {"criterion": own, "parameters": [
                {"name": n, "unit": u, "sigma": float(s), "revealed": bool(r)}
                for n, u, s, r in zip(p.names, p.units, p.sigma, p.revealed)]},
            "builtins": [{"scheme": b.scheme, "duration_s": b.duration_s if b.duration_s == b.duration_s else None,
                          "note": b.note,
                          "criterion": crit_vals.get(b.scheme),
                          "efficiency": (efficiency(own, crit_vals[b.scheme], kind, len(which))
                                         if b.scheme in crit_vals else None),
                          "sigma": [float(x) for x in b.sigma], "revealed": [bool(x) for x in b.revealed],
                          "design_reveals_beyond": reveals.get(b.scheme, [])} for b in d.builtins],
            "seconds": d.seconds, "candidates": d.candidates, "evaluations": d.evaluations}, indent=1))
        return 0
    table = Table(title=f"predicted 1σ at {d.duration_s:.0f} s of table time (the estimator's fit of each "
                        "scheme's noiseless capture; - : not revealed)")
    table.add_column("parameter", justify="left")
    table.add_column(p.scheme, justify="right")
    for b in usable:
        table.add_column(f"{b.scheme}\n{b.duration_s:.0f} s", justify="right")
    table.add_column("unit", justify="left")
    for k, (n, u) in enumerate(zip(p.names, p.units)):
        cells = [_cell(p.sigma[k], p.revealed[k])] + [_cell(b.sigma[k], b.revealed[k]) for b in usable]
        table.add_row(n, *cells, u)
    out.print(table)
    for b in d.builtins:
        if not len(b.sigma):
            err.print(f"note: {b.scheme} not compared: {b.note}", markup=False, soft_wrap=True)
    out.print(f"criterion {d.criterion}: designed {own:.6g}" + "".join(
        f"; {b}: {v:.6g} (x{efficiency(own, v, kind, len(which)):.3f})" for b, v in crit_vals.items()) +
        ("  (x: the design's D-efficiency against it, (det C_it / det C_design)^(1/p))" if kind == "D" else
         "  (x: its criterion / the design's)"), markup=False, soft_wrap=True)
    for b, names in reveals.items():
        if names:
            out.print(f"the design reveals what {b} does not: {', '.join(names)}", markup=False, soft_wrap=True)
    not_revealed = [n for n, r in zip(p.names, p.revealed) if not r]
    if not_revealed:
        out.print(f"not revealed by the design either: {', '.join(not_revealed)}", markup=False, soft_wrap=True)
    for note in d.notes:
        err.print(f"note: {note}", markup=False, soft_wrap=True)
    sec = d.seconds
    err.print(f"designed in {sum(sec.values()):.1f} s: candidates {sec['candidates']:.1f} s, information of "
              f"{d.candidates} candidates {sec['information']:.1f} s, search {sec['search']:.1f} s "
              f"({d.evaluations} evaluations, {d.passes} passes), predictions {sec['predictions']:.1f} s",
              markup=False, soft_wrap=True)
    out.print(f"wrote {out_path} ({len(d.scheme.segments)} segments, {d.scheme.duration_s:.0f} s of recording, "
              f"{d.duration_s:.0f} s compiled): station plan --scheme {out_path}"
              f"{' --config ' + args.config if args.config else ''}; station run --scheme {out_path} --sim",
              markup=False, soft_wrap=True)
    return 0


def _cell(sigma, revealed) -> str:
    return f"{sigma:.4g}" if revealed else "-"

