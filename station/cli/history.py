"""``station history`` and ``station diff``: calibrations filed per IMU serial, listed, compared
and plotted over time (argument parsing and output only)."""
from __future__ import annotations

import argparse

from station.cli.output import err, out


STORE_HELP = ("the calibration store: a folder (SQLite index) or postgresql://USER@HOST/DB (default: "
              "$STATION_STORE, else the folder $STATION_HISTORY_DIR or the user's data directory)")


def add_parsers(sub) -> None:
    h = sub.add_parser("history", help="calibrations filed per IMU serial: list, file, plot drift")
    h.add_argument("serial", nargs="?", help="the IMU serial (none: list the serials in the store)")
    h.add_argument("--add", action="append", default=[], metavar="CAL.yaml",
                   help="file a calibration into the history (repeatable); estimate and run file theirs")
    h.add_argument("--drift", metavar="PNG", help="plot every parameter of SERIAL against the date, ± 1σ")
    h.add_argument("--lot", metavar="LOT", help="with --add: the IMUs' production lot, where the file does "
                   "not state it (provenance imu_lot); also set on a calibration filed before")
    h.add_argument("--imu-model", metavar="MODEL", help="with --add: the IMU model, where the file does not "
                   "state it (provenance imu_model)")
    h.add_argument("--rebuild", action="store_true", help="build a new index from the calibration files in "
                   "the store's folder (after the index was lost or damaged; the old one is kept aside)")
    h.add_argument("--store", metavar="DIR|URL", help=STORE_HELP)
    h.set_defaults(func=cmd_history)

    d = sub.add_parser("diff", help="compare two calibrations parameter by parameter, in units and in σ")
    d.add_argument("a", metavar="A", help="a calibration file or an id of the history (#N)")
    d.add_argument("b", metavar="B", help="a calibration file or an id of the history (#N)")
    d.add_argument("--all", action="store_true", help="list unchanged parameters too")
    d.add_argument("--store", metavar="DIR|URL", help="the history store for ids (" + STORE_HELP + ")")
    d.add_argument("--drift", metavar="PNG", help="also plot the drift over time of A's IMU serial "
                   "(every calibration of it in the history)")
    d.set_defaults(func=cmd_diff)


def add_history_option(parser, default: str) -> None:
    parser.add_argument("--history", action=argparse.BooleanOptionalAction, default=None,
                        help=f"file the calibration in the IMU's history ({default}; a simulated run "
                             "only in the simulations' own store; only an IMU with a serial)")


def file_quietly(cal_path, store=None, *, asked: bool, simulated: bool = False) -> None:
    """File a calibration just written, by the history's policy (docs/calibration-file.md,
    "History"), when ``asked`` (the callers' defaults: a bench run files unless
    ``--no-history``; ``estimate`` and a simulated run only with ``--history``): a calibration of
    a real IMU (its serial known) into the store; a simulated run or a simulated IMU's (serial
    SIM-...) into the simulations' own store; one without a serial not at all.  A calibration of
    the same capture and model already filed is not filed again.  A store that cannot be written
    is a warning, never a failure (the calibration file itself is already safe)."""
    if not asked:
        return      # before the imports: the store's modules (sqlite3, its schema) only when filing
    from station.core.errors import UserError
    from station.io.calfile import read_calfile
    from station.io.history import SIMULATED_PREFIX, Store, real_serial, simulation_store

    try:
        doc = read_calfile(cal_path)
        serial = ((doc.get("provenance") or {}).get("imu_serial") or "")
        if simulated or (isinstance(serial, str) and serial.startswith(SIMULATED_PREFIX)):
            root = simulation_store(store)
        elif real_serial(doc) is None:
            out.print("history: not filed: the calibration names no IMU serial (station history --add "
                      "files it anyway, under 'unknown')", markup=False)
            return
        else:
            root = store
        with Store(root) as store:
            entry, new = store.file(cal_path)
    except UserError as e:
        err.print(f"warning: not filed in the calibration history: {e}", markup=False, soft_wrap=True)
        return
    if new:
        out.print(f"history: filed as #{entry.id} for IMU {entry.serial} ({entry.path})", markup=False)
    else:
        out.print(f"history: already filed as #{entry.id} (this file, or the same capture and model)", markup=False)


def cmd_history(args) -> int:
    from rich.table import Table

    from station import api
    from station.core.errors import UserError

    if args.rebuild:
        if args.add or args.serial or args.drift:
            raise UserError("--rebuild goes alone (with --store): it re-reads the store's own files")
        r = api.rebuild_history(store=args.store)
        for path, why in r.skipped:
            err.print(f"not filed: {path}: {why}", markup=False, soft_wrap=True)
        if r.kept_aside:
            out.print(f"the old index kept as {r.kept_aside}", markup=False)
        out.print(f"history rebuilt: {len(r.filed)} calibration(s) of {len({e.serial for e in r.filed})} IMU(s) "
                  f"filed from the files of the store into {r.where}; {len(r.skipped)} file(s) not filed", markup=False)
        return 0
    if args.drift and args.serial is None:      # (it was ignored: exit 0 and no plot)
        raise UserError(f"--drift {args.drift}: give the SERIAL whose drift to plot: station history SERIAL "
                        "--drift PNG (station history lists the serials)")
    h = api.history(args.serial, store=args.store, add=args.add, lot=args.lot, imu_model=args.imu_model)
    for entry, new in h.filed:
        out.print(f"{'filed' if new else 'already filed'}: #{entry.id} {entry.serial} {entry.date_utc} "
                  f"({entry.path})", markup=False)
    if args.serial is None:
        if not args.add:
            t = Table(title=f"IMU serials in {h.store}")
            t.add_column("serial")
            t.add_column("calibrations", justify="right")
            for serial, n in h.serials:
                t.add_row(serial, str(n))
            out.print(t)
        return 0
    if not h.entries:
        raise UserError(f"no calibration of IMU {args.serial!r} in {h.store} (station history lists the serials)")
    t = Table(title=f"calibrations of IMU {args.serial}")
    for col in ("id", "date (UTC)", "scheme", "method", "verdict", "file"):
        t.add_column(col)
    for e in h.entries:
        t.add_row(f"#{e.id}", e.date_utc, e.scheme or "", e.method or "", e.verdict,
                  str(e.path) if not e.problem else f"NOT THE FILE FILED: {e.problem}")
    out.print(t)
    for e in h.entries:
        if e.problem:
            err.print(f"warning: calibration #{e.id}: {e.problem} (the index is not the record of it; "
                      "station history --rebuild re-reads the store's files)", markup=False, soft_wrap=True)
    if args.drift:
        _drift(args.serial, args.drift, args.store)
    return 0


def _drift(serial: str, png, store) -> None:
    from station import api

    path, marked = api.drift(serial, png, store=store)
    if marked:
        err.print(f"note: drawn apart in the drift plot (not passing): {', '.join(marked)}", markup=False,
                  soft_wrap=True)
    out.print(f"drift plot: {path}", markup=False)


def cmd_diff(args) -> int:
    from rich.table import Table

    from station import api
    from station.io.calcompare import FLAG_SIGMA

    d = api.diff(args.a, args.b, store=args.store)
    rows = d.changes
    t = Table(title=f"{d.a} → {d.b}")
    for col in ("parameter", "A", "B", "change", "unit", "change / σ", ""):
        t.add_column(col, justify="left" if col in ("parameter", "unit", "") else "right")
    flagged = 0
    for c in rows:
        if not args.all and not c.flagged and c.z is not None and abs(c.z) < 1:
            continue
        flagged += c.flagged
        value = (lambda v: f"{v:.9f}") if c.change_ppm is not None else (lambda v: f"{v:.4f}")
        change = f"{c.change_ppm:+.2f} ppm" if c.change_ppm is not None else f"{c.change:+.4f}"
        t.add_row(c.name, value(c.before), value(c.after), change, c.unit,
                  "" if c.z is None else f"{c.z:+.2f}", f"> {FLAG_SIGMA:g}σ" if c.flagged else "")
    out.print(t)
    da_date = (d.doc_a.get("provenance") or {}).get("date_utc")
    db_date = (d.doc_b.get("provenance") or {}).get("date_utc")
    compared = [c for c in rows if c.z is not None]
    out.print(f"A: {da_date}, B: {db_date}; σ combined as sqrt(σA² + σB²); "
              f"{flagged} of {len(compared)} parameters with a 1σ on both sides changed by more than "
              f"{FLAG_SIGMA:g}σ"
              + ("" if args.all else " (changes under 1σ not listed; --all lists them)"), markup=False)
    if len(compared) < len(rows):
        out.print(f"{len(rows) - len(compared)} of {len(rows)} parameters have no 1σ in A or B: their change is "
                  "not judged (" + ", ".join(c.name for c in rows if c.z is None) + ")", markup=False, soft_wrap=True)
    for line in d.warnings:
        err.print(line, markup=False, soft_wrap=True)
    for label, names, other, side in (("only in A", d.only_a, d.doc_b, "B"), ("only in B", d.only_b, d.doc_a, "A")):
        held = (other.get("fit") or {}).get("not_determined")
        held = held if isinstance(held, list) else []
        if names:
            out.print(f"{label}: " + ", ".join(f"{n} (not determined by {side}'s capture)" if n in held else n
                                               for n in names), markup=False, soft_wrap=True)
    if args.drift:
        from station.core.errors import UserError

        serial = (d.doc_a.get("provenance") or {}).get("imu_serial")
        h = api.history(serial if isinstance(serial, str) else None, store=args.store)
        if not h.entries:
            raise UserError(f"{d.a}: its IMU serial {serial!r} has no calibration in the history {h.store}")
        _drift(serial, args.drift, args.store)
    return 0
