"""``station design``: the scheme that calibrates a model best on a table within a time budget
(station/design/, docs/design.md)."""
from __future__ import annotations

import contextlib

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


def _temperatures(text: str) -> tuple:
    """A comma-separated list of temperatures, °C (finite; -273.15 °C or above)."""
    import argparse
    import math

    try:
        values = tuple(float(x) for x in text.split(",") if x.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a comma-separated list of temperatures: {text!r}") from None
    if not values or any(not math.isfinite(v) or v < -273.15 for v in values):
        raise argparse.ArgumentTypeError(f"not temperatures in °C: {text!r}")
    return values


def add_parsers(sub) -> None:
    d = sub.add_parser("design", help="design the scheme that calibrates your model best on your table "
                                      "within a time budget (docs/design.md)")
    d.add_argument("--duration", type=argtypes.between(60, 1e6), metavar="S",
                   help="time budget in seconds of table time (the compiled plan's: moves, settling, ramps, "
                        "operator steps included); required unless --from")
    d.add_argument("--from", dest="from_capture", metavar="CAPTURE",
                   help="sequential design: the fewest extra segments for this capture (its table, its fitted "
                        "noise) that --reveal or --separate; written as a scheme extension to record with "
                        "station run --append CAPTURE --scheme EXT.yaml")
    d.add_argument("--reveal", metavar="PARAM,...",
                   help="with --from: effect parameters (fnmatch patterns) the capture left not revealed")
    d.add_argument("--separate", metavar="A,B",
                   help="with --from: two effects the capture cannot tell apart (ids, or plugins FILE.py:CLASS "
                        "as --add takes them); both are added to the model")
    d.add_argument("--fraction", type=argtypes.between(0.01, 1.0), default=0.5,
                   help="with --from: the target 1σ as a fraction of each parameter's typical size (default 0.5; "
                        "the estimator reveals a parameter below 1)")
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
                   help="candidate static dwells, s (default 10,20,50,100,200,500,1000)")
    d.add_argument("--setpoints", type=_temperatures, default=None, metavar="C,C,...",
                   help="with a temperature chamber (station.yaml chamber:): the setpoints the candidates are "
                        "offered at, °C, besides the room (default the end of the chamber's range farther from "
                        "the room, and with a term in the temperature's square the middle of that span too); "
                        "the search chooses which it uses, each paid for by its ramp and soak")
    d.add_argument("--passes", type=argtypes.whole(0), default=20,
                   help="at most this many exchange passes (default 20)")
    d.add_argument("--compare", default=",".join(("optimal9", "chatfield18", "traditional24", "sizeeffect")),
                   metavar="NAME,...", help="built-in schemes to compare at the same duration ('' for none)")
    d.add_argument("--centred", action="store_true",
                   help="the IMU mounted with its reference point on the table's axes (the scheme says "
                        "centred: true, as sizeeffect does: no mounting offset to estimate)")
    d.add_argument("--statics", choices=("any", "unknown", "table"), default="any",
                   help="the kinds of design searched: nine or more statics of unknown attitude, six to eight of "
                        "the table's attitude (known to its angle error, one mounting), or both, the better kept "
                        "by the estimator's fit (default any)")
    d.add_argument("--verify-runs", type=argtypes.whole(0), default=4, metavar="N",
                   help="noisy dry runs of the design estimated as station montecarlo does, each criterion "
                        "parameter's error checked against its predicted 1σ (default 4; 0: none). A design the "
                        "estimator does not deliver is not written (exit 3)")
    d.add_argument("--scheduler", metavar="tcp://HOST:8786",
                   help="compute the predictions (the design's and the built-in schemes') and the verification's "
                        "dry runs on this Dask scheduler's workers (default: forked processes on this machine's cores)")
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
    if args.from_capture or args.reveal or args.separate:
        return _cmd_from(args)
    if args.duration is None:
        raise UserError("--duration S is required (or --from CAPTURE with --reveal or --separate)")
    return _cmd_design(args)


def _cmd_from(args) -> int:
    """station design --from CAPTURE --reveal P | --separate A,B: station/design/sequential.py."""
    import json
    import shlex
    import sys
    from pathlib import Path

    from station.design.sequential import extend
    from station.io.calfile import write_new_file

    if not args.from_capture:
        raise UserError("--reveal and --separate design extra segments for a capture: give --from CAPTURE")
    if bool(args.reveal) == bool(args.separate):
        raise UserError("--from: give --reveal PARAMS or --separate A,B (one of them)")
    if args.duration is not None:
        raise UserError("--from proposes the fewest segments whatever their time: leave out --duration")
    if getattr(args, "setpoints", None) is not None:
        raise UserError("--setpoints chooses a new scheme's chamber levels; --from adds segments at the capture's "
                        "temperatures: leave out --setpoints")
    if not Path(args.from_capture).is_dir():
        raise UserError(f"--from {args.from_capture}: not a capture directory")
    separate = ()
    adds = list(args.add)
    if args.separate:
        separate = tuple(x.strip() for x in args.separate.split(",") if x.strip())
        if len(separate) != 2 or separate[0] == separate[1]:
            raise UserError(f"--separate: name two different effects, A,B; got {args.separate!r}")
        adds += [x for x in separate if x not in adds]
    reg = plugins.registry(args)
    effects = [reg.create(e) for e in plugins.effect_ids(reg, adds)]
    if separate:
        # each of A and B an effect id or a plugin spec (FILE.py:CLASS, module:CLASS), as --add
        # takes them: the ids they name (a spec naming several effects is refused)
        named = [plugins.effect_ids(reg, [x]) for x in separate]
        for x, ids in zip(separate, named):
            if len(ids) != 1:
                raise UserError(f"--separate: {x} names {len(ids)} effects ({', '.join(ids)}): name one "
                                "(FILE.py:CLASS)")
        separate = (named[0][0], named[1][0])
        if separate[0] == separate[1]:
            raise UserError(f"--separate: {args.separate!r} names one effect twice ({separate[0]})")
    reveal = tuple(x.strip() for x in (args.reveal or "").split(",") if x.strip())
    out_path = Path(args.out if args.out != "designed.yaml" else "extension.yaml")
    if out_path.suffix not in (".yaml", ".yml"):
        raise UserError(f"-o {out_path}: a scheme file ends in .yaml")
    revolutions = tuple(int(round(r)) for r in args.revolutions) if args.revolutions else None
    command = "station " + " ".join(shlex.quote(a) for a in sys.argv[1:]) if sys.argv[1:2] == ["design"] else ""
    e = extend(args.from_capture, effects, reveal=reveal, separate=separate, config_path=args.config,
               fraction=args.fraction, rates_dps=args.rates, revolutions=revolutions, dwells_s=args.dwells,
               name=args.name if args.name != "designed" else "extension", command=command,
               progress=lambda text: err.print(f"design: {text}", markup=False, soft_wrap=True))
    if not e.entries:        # the capture's own segments meet the goal: nothing to record, nothing written
        if args.json:
            print(json.dumps({"scheme_file": None, "capture": e.capture, "goal": e.goal, "duration_s": 0.0,
                              "segments": [], "segment_s": [],
                              "parameters": [{"name": n, "unit": e.units[n], "sigma_before": e.before[n],
                                              "sigma_after": e.after[n], "revealed_before": True,
                                              "revealed_after": True} for n in e.names],
                              "correlation_before": e.correlation_before, "correlation_after": e.correlation_after,
                              "noise": vars(e.noise), "record": None, "notes": e.notes}, indent=1))
            return 0
        out.print(f"goal: {e.goal}", markup=False, soft_wrap=True)
        out.print(e.notes[-1], markup=False, soft_wrap=True)
        for n in e.names:
            out.print(f"  {n}: 1σ {e.before[n]:.4g} {e.units[n]}", markup=False, soft_wrap=True)
        if e.correlation_before is not None:
            out.print(f"  largest |correlation| between the two effects: {e.correlation_before:.3f}", markup=False)
        out.print(f"nothing written ({out_path} not made)", markup=False)
        return 0
    try:
        write_new_file(out_path, e.text.encode("utf-8"), what="scheme file")
    except OSError as x:
        raise UserError(f"{out_path}: cannot write the scheme file: {x.strerror}") from None
    record = f"station run --append {args.from_capture} --scheme {out_path}"
    if args.json:
        print(json.dumps({"scheme_file": str(out_path), "capture": e.capture, "goal": e.goal,
                          "duration_s": e.duration_s, "segments": e.entries, "segment_s": e.segment_s,
                          "parameters": [{"name": n, "unit": e.units[n], "sigma_before": e.before[n],
                                          "sigma_after": e.after[n], "revealed_before": e.revealed_before[n],
                                          "revealed_after": e.revealed_after[n],
                                          "sigma_searched": e.searched.get(n)} for n in e.names],
                          "correlation_before": e.correlation_before, "correlation_after": e.correlation_after,
                          "noise": vars(e.noise), "record": record, "notes": e.notes}, indent=1))
        return 0
    out.print(f"goal: {e.goal}", markup=False, soft_wrap=True)
    for entry, secs in zip(e.entries, e.segment_s):
        what = (f"static {entry['static']}: up {entry['up_body']} for {entry['dwell_s']:g} s" if "static" in entry else
                f"rotation {entry['rotation']}: about {entry['axis_body']} at +/-{entry['rate_dps']:g} deg/s, "
                f"{entry['rotation_s']:g} s each way, axis elevation {entry.get('axis_elevation_deg', 0):g} deg")
        out.print(f"  {what} ({secs:.0f} s with moves, settling and ramps)", markup=False, soft_wrap=True)
    out.print(f"{len(e.entries)} extra segment(s), {e.duration_s:.0f} s of table time as compiled", markup=False)
    for n in e.names:
        out.print(f"  {n}: 1σ {e.before[n]:.4g} -> {e.after[n]:.4g} {e.units[n]}"
                  f"{'' if e.revealed_before[n] else ' (not revealed by the capture)'}"
                  f"{'' if e.revealed_after[n] else ' (still not revealed)'}", markup=False, soft_wrap=True)
    if e.correlation_after is not None:
        out.print(f"  largest |correlation| between the two effects: {e.correlation_before:.3f} -> "
                  f"{e.correlation_after:.3f}", markup=False)
    for note in e.notes:
        err.print(f"note: {note}", markup=False, soft_wrap=True)
    out.print(f"wrote {out_path}: record it into the same capture with: {record}", markup=False, soft_wrap=True)
    return 0


def _cmd_design(args) -> int:
    import json
    from pathlib import Path

    from rich.table import Table

    from station.bench.config import load_config
    from station.design import candidates as cand_mod
    from station.design.designer import criterion_of, design, efficiency
    from station.io.calfile import write_new_file
    from station.io.scheme import StaticSpec, builtin_names

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
    with contextlib.ExitStack() as stack:
        executor = None
        if args.scheduler:
            from station.batch.cluster import open_client

            executor = stack.enter_context(open_client(args.scheduler)).get_executor(pure=False)
            err.print(f"design: on the Dask scheduler {args.scheduler}", markup=False, soft_wrap=True)
        d = design(config, effects, noise, args.duration, args.criterion,
                   rates_dps=args.rates or cand_mod.DEFAULT_RATES_DPS, revolutions=revolutions,
                   dwells_s=args.dwells or cand_mod.DEFAULT_DWELLS_S, max_passes=args.passes, name=args.name,
                   compare=compare, centred=args.centred, verify_runs=args.verify_runs, executor=executor,
                   statics=args.statics, setpoints=args.setpoints,
                   progress=lambda text: err.print(f"design: {text}", markup=False, soft_wrap=True))
    v = d.verification
    if v is not None and not v.ok:
        for line in v.problems:
            err.print(f"design: not delivered: {line}", markup=False, soft_wrap=True)
        err.print(f"station design: the estimator does not deliver this design's predicted 1σ in {v.runs} noisy dry "
                  f"runs ({len(v.problems)} problem(s) above); no scheme file written (try other --rates, "
                  "--revolutions or a longer --duration)", markup=False, soft_wrap=True)
        return 3
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
            "static_attitudes": d.attitudes,
            "verification": None if v is None else {"runs": v.runs, "worst_z": v.worst_z, "worst": v.worst},
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
    out.print("statics: nine or more, each attitude unknown (fitted)" if d.attitudes == "unknown" else
              f"statics: {sum(isinstance(s, StaticSpec) for s in d.scheme.segments)} of the table's attitudes, known "
              "to its angle error (one mounting; the estimator's choice below nine statics)", markup=False, soft_wrap=True)
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
              f"({d.evaluations} evaluations, {d.passes} passes), predictions {sec['predictions']:.1f} s"
              + (f", verification {sec['verification']:.1f} s" if "verification" in sec else ""),
              markup=False, soft_wrap=True)
    if v is not None:
        out.print(f"verified: {v.runs} noisy dry runs estimated as station montecarlo does: the largest error "
                  f"{v.worst_z:.2f} x the predicted 1σ ({v.worst})", markup=False, soft_wrap=True)
    out.print(f"wrote {out_path} ({len(d.scheme.segments)} segments, {d.scheme.duration_s:.0f} s of recording, "
              f"{d.duration_s:.0f} s compiled): station plan --scheme {out_path}"
              f"{' --config ' + args.config if args.config else ''}; station run --scheme {out_path} --sim"
              # (the configuration's warm-up and chamber are in the prediction: the dry run takes them too)
              f"{' --config ' + args.config if args.config else ''}",
              markup=False, soft_wrap=True)
    return 0


def _cell(sigma, revealed) -> str:
    return f"{sigma:.4g}" if revealed else "-"

