"""The fleet page: one self-contained HTML file (the report page's style, the figure embedded as
SVG) of a fleet view (station/diagnose/fleet.py): what was selected, pass/fail counts, every
parameter's spread across units, the units outside the lot's spread, the drift per unit."""
from __future__ import annotations

import datetime as _dt
from pathlib import Path

import station
from station.core.errors import UserError
from station.diagnose.fleet import FLAG_SIGMA, TAIL, Fleet
from station.diagnose.figures import FleetRow, fleet_figure
from station.diagnose.report import CSS, _e, _img, _table

FIGURE = "fleet.svg"


def _g(x, digits: int = 6) -> str:
    return "–" if x is None else f"{x:.{digits}g}"


def _z(x) -> str:
    return "–" if x is None else f"{x:+.2f}"


def figure_rows(f: Fleet) -> list:
    return [FleetRow(p.name, [v.z_lot for v in p.values], [v.outside for v in p.values],
                     None if p.t_limit is None else p.t_limit * (1.0 + 1.0 / (p.units - 1)) ** 0.5)
            for p in f.parameters]


def _selection(f: Fleet) -> str:
    sel = f.selection
    facts = [("store", sel.get("store") or "–"), ("IMU model", sel.get("model") or "any"),
             ("lot", sel.get("lot") or "any"), ("since", sel.get("since") or "any date"),
             ("calibrations", str(f.calibrations)), ("units (serials)", str(f.units))]
    return "".join(f"<dt>{_e(k)}</dt><dd>{_e(v)}</dd>" for k, v in facts)


def render(f: Fleet, figures: dict) -> str:
    made = _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    counts = _table(["verdict", "calibrations", "units (latest calibration)"],
                    [(_e(k), str(f.verdicts.get(k, 0)), str(f.latest_verdicts.get(k, 0)))
                     for k in sorted(set(f.verdicts) | set(f.latest_verdicts))])
    unusable = (f"<p class='flag'>Without a usable calibration (not in the spread): {_e(', '.join(f.unusable_units))}</p>"
                if f.unusable_units else "")
    unusable += "".join(f"<p class='flag'>Not counted: calibration #{r['calibration']} of {_e(r['serial'])}: "
                        f"{_e(r['problem'])}</p>" for r in f.not_counted)
    spread = _table(["parameter", "unit", "units", "mean", "std across units", "median", "min", "max",
                     "median own 1σ", "outside"],
                    [(_e(p.name), _e(p.unit), str(p.units), _g(p.mean, 9), _g(p.std, 4), _g(p.median, 9),
                      _g(p.min, 9), _g(p.max, 9), _g(p.median_sigma, 3),
                      f"<span class='flag'>{len(p.outside)}</span>" if p.outside else "0")
                     for p in f.parameters], left=(0, 1))
    outside = f.outside
    out_rows = [(_e(p.name), _e(v.serial), f"#{v.calibration}", _e(v.date_utc[:10]), _g(v.value, 9), _g(v.sigma, 3),
                 _e(p.unit), _z(v.z_lot), _z(v.z_own)) for p, v in outside]
    out_html = (_table(["parameter", "serial", "calibration", "date", "value", "own 1σ", "unit", "σ of the lot",
                        "own σ"], out_rows, left=(0, 1, 2, 3, 6)) if out_rows else "<p class='yes'>No unit outside "
                "the lot's spread.</p>")
    drift_rows = []
    for d in f.drift:
        flagged = [c for c in d.changes if c["flagged"]]
        drift_rows.append((_e(d.serial), str(d.calibrations), _e(f"{d.first_date[:10]} → {d.last_date[:10]}"),
                           f"<span class='flag'>{len(flagged)}</span>" if flagged else "0",
                           _e(", ".join(f"{c['parameter']} {c['z']:+.1f}σ" for c in flagged)) or "–"))
    drift = (_table(["serial", "calibrations", "first → latest", f"changed > {FLAG_SIGMA:g}σ", "which"],
                     drift_rows, left=(0, 2, 4)) if drift_rows else "<p>No unit calibrated twice with a usable fit.</p>")
    chance = (f"{f.tests} unit × parameter judgements: about {f.expected_by_chance:.1f} outside by chance alone "
              f"(tail {TAIL:.2%} each, the two-sided tail beyond 3σ of a normal)")
    return (f"<!doctype html><html lang='en'><head><meta charset='utf-8'>"
            f"<meta name='viewport' content='width=device-width, initial-scale=1'>"
            f"<title>Fleet</title><style>{CSS}</style></head><body>"
            f"<header><h1>Fleet: {_e(f.selection.get('model') or 'every IMU model')}"
            f"{_e(' · lot ' + f.selection['lot']) if f.selection.get('lot') else ''}</h1>"
            f"<p>station {station.__version__} · page made {made}</p></header><main>"
            f"<section><h2>Selected</h2><dl class='facts'>{_selection(f)}</dl></section>"
            f"<section><h2>Pass / fail</h2>{counts}{unusable}</section>"
            f"<section><h2>Every parameter across units</h2><p class='note'>Each unit by its latest usable calibration "
            f"(passes or noise overestimated). A unit is outside the lot's spread when its distance from the rest of "
            f"the lot exceeds Student's t quantile of the 3σ tail (n − 2 degrees of freedom, the spread of the rest "
            f"widened by √(1 + 1/(n − 1))): the grey bars when one lot is selected. Each unit is judged within its "
            f"own lot. {chance}.</p>"
            + (_img(FIGURE, figures, "every unit's distance from the rest of the lot, per parameter")
               if FIGURE in figures else "") + spread + "</section>"
            f"<section><h2>Units outside the lot's spread</h2>{out_html}</section>"
            f"<section><h2>Drift per unit across recalibrations</h2><p class='note'>First against latest usable "
            f"calibration, in combined σ √(σ₁² + σ₂²); more than {FLAG_SIGMA:g}σ flagged.</p>{drift}</section>"
            "<footer>One self-contained page: the figure is embedded.</footer></main></body></html>\n")


def write_page(path, f: Fleet) -> Path:
    from station.core.user_files import output_path

    path = Path(output_path(path, "the fleet page"))
    figures = {}
    if any(v.t is not None for p in f.parameters for v in p.values):
        figures[FIGURE] = fleet_figure(figure_rows(f), fmt="svg")
    try:
        path.write_text(render(f, figures), encoding="utf-8")
    except OSError as e:
        raise UserError(f"{path}: cannot write the fleet page: {e.strerror}") from None
    return path
