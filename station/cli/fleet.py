"""``station fleet``: the calibrations of many units side by side, from the calibration store
(argument parsing and output only; the numbers: station/diagnose/fleet.py, the page:
station/diagnose/fleet_page.py)."""
from __future__ import annotations

from station.cli.output import err, out


def add_parsers(sub) -> None:
    from station.cli.history import STORE_HELP

    f = sub.add_parser("fleet", help="units side by side: each parameter's spread across units, units outside "
                       "their lot's spread, drift per unit, pass/fail counts")
    f.add_argument("--model", metavar="M", help="only this IMU model (provenance imu_model)")
    f.add_argument("--lot", metavar="L", help="only this production lot (provenance imu_lot, history --add --lot)")
    f.add_argument("--since", metavar="DATE", help="only calibrations dated on or after DATE (YYYY-MM-DD, UTC)")
    f.add_argument("--json", action="store_true", help="the fleet view as JSON on stdout (docs/fleet.md)")
    f.add_argument("-o", "--output", metavar="PAGE.html", help="write the fleet page (self-contained HTML)")
    f.add_argument("--store", metavar="DIR|URL", help=STORE_HELP)
    f.set_defaults(func=cmd_fleet)


def _since(text: str | None) -> str | None:
    import datetime as dt

    from station.core.errors import UserError

    if text is None:
        return None
    try:
        day = dt.date.fromisoformat(text)
    except ValueError:
        raise UserError(f"--since {text!r}: not a date (YYYY-MM-DD)") from None
    return day.isoformat()


def cmd_fleet(args) -> int:
    import json
    import sys

    from station.core.errors import UserError
    from station.diagnose.fleet import FLAG_SIGMA, fleet, to_json
    from station.io.history import Store

    since = _since(args.since)
    with Store(args.store) as store:
        filed = store.filed(imu_model=args.model, lot=args.lot, since=since)
        where = store.where
    selection = {"store": where, "model": args.model, "lot": args.lot, "since": since}
    if not filed:
        said = ", ".join(f"{k} {v}" for k, v in selection.items() if v and k != "store") or "any"
        raise UserError(f"no calibration in {where} matches ({said}); station history lists the serials")
    view = fleet(filed, selection)
    for row in view.not_counted:
        err.print(f"not counted: calibration #{row['calibration']} of {row['serial']}: {row['problem']} (the index "
                  "is not the record of it; station history --rebuild re-reads the store's files)", markup=False,
                  soft_wrap=True)
    if not view.calibrations:
        raise UserError(f"no calibration in {where} whose file is the one filed ({len(view.not_counted)} not counted)")
    if args.output:
        from station.diagnose.fleet_page import write_page

        write_page(args.output, view)
    if args.json:
        sys.stdout.write(json.dumps(to_json(view), indent=1, allow_nan=False) + "\n")
        if args.output:
            err.print(f"fleet page: {args.output}", markup=False)
        return 0
    _print(view, FLAG_SIGMA)
    if args.output:
        out.print(f"fleet page: {args.output}", markup=False)
    return 0


def _print(view, flag_sigma: float) -> None:
    from rich.table import Table

    def g(x, d=6):
        return "–" if x is None else f"{x:.{d}g}"

    counts = ", ".join(f"{k} {n}" for k, n in sorted(view.verdicts.items()))
    out.print(f"{view.calibrations} calibrations of {view.units} units: {counts}", markup=False)
    latest = ", ".join(f"{k} {n}" for k, n in sorted(view.latest_verdicts.items()))
    out.print(f"units by their latest calibration: {latest}", markup=False)
    if view.unusable_units:
        out.print(f"without a usable calibration (not in the spread): {', '.join(view.unusable_units)}", markup=False,
                  soft_wrap=True)
    t = Table(title="every parameter across units (each unit's latest usable calibration)")
    for col in ("parameter", "unit", "units", "mean", "std", "min", "max", "median own 1σ", "outside"):
        t.add_column(col, justify="left" if col in ("parameter", "unit") else "right")
    for p in view.parameters:
        t.add_row(p.name, p.unit, str(p.units), g(p.mean, 9), g(p.std, 4), g(p.min, 9), g(p.max, 9),
                  g(p.median_sigma, 3), str(len(p.outside)))
    out.print(t)
    if view.outside:
        t = Table(title="units outside the lot's spread")
        for col in ("parameter", "serial", "calibration", "value", "own 1σ", "unit", "σ of the lot", "own σ"):
            t.add_column(col, justify="left" if col in ("parameter", "serial", "unit") else "right")
        for p, v in view.outside:
            t.add_row(p.name, v.serial, f"#{v.calibration}", g(v.value, 9), g(v.sigma, 3), p.unit,
                      f"{v.z_lot:+.2f}", "–" if v.z_own is None else f"{v.z_own:+.2f}")
        out.print(t)
    out.print(f"outside: {len(view.outside)} of {view.tests} unit × parameter judgements (about "
              f"{view.expected_by_chance:.1f} expected by chance at the 3σ tail)", markup=False)
    for d in view.drift:
        flagged = [c for c in d.changes if c["flagged"]]
        if flagged:
            out.print(f"drift {d.serial} ({d.calibrations} calibrations, {d.first_date[:10]} → {d.last_date[:10]}): "
                      + ", ".join(f"{c['parameter']} {c['z']:+.1f}σ" for c in flagged)
                      + f" (> {flag_sigma:g}σ)", markup=False, soft_wrap=True)
    drifted = sum(1 for d in view.drift if any(c["flagged"] for c in d.changes))
    out.print(f"drift: {len(view.drift)} units recalibrated, {drifted} with a parameter changed by more than "
              f"{flag_sigma:g}σ", markup=False)
