"""The report page: one self-contained HTML file (figures embedded as data: URIs) that a person
reads to judge a calibration: what was measured (capture, IMU, scheme, date), the parameters
± 1σ, the fit verdict, the residuals before and after each added effect on one y axis, the
before/after tables, the candidate effects, and the noise (Allan deviation).

``write_report`` keeps the figures (SVG) beside the page for people who want them separately.
"""
from __future__ import annotations

import base64
import datetime as _dt
import html
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

import station
from station.core.errors import UserError, cannot_write
from station.diagnose.core import PRIOR_QUANTITIES
from station.diagnose.figures import (CandidateFigure, SegmentPanel, SegmentsFigure, allan_figure, draw,
                                      figure_format)
from station.diagnose.figure_job import ALLAN_FIGURE, SEGMENTS_FIGURE, FigureJob

VARIABLE_LABEL = {
    "rate_squared": "rotation rate squared (deg/s)^2",
    "temperature": "segment temperature (deg C)",
    "gravity_along_axis": "commanded gravity along the residual's axis (g)",
    "signed_rate": "signed rotation rate (deg/s)",
    "rate_change": "rate change across the segment (deg/s)",
    "time": "segment mid-time in the run (s)",
}
SCALE_UNITS = ("1", "raw/(m/s^2)", "raw/(deg/s)")


def _variable(name: str, diagnosis, labels) -> np.ndarray:
    s = diagnosis.result.model.s
    rot = {r.name: r for r in s.rotations}
    stat = {st.name: st for st in s.statics}
    out = np.full(len(labels), np.nan)
    for i, (seg, kind, quantity, axis) in enumerate(labels):
        r, st = rot.get(seg), stat.get(seg)
        if name == "rate_squared":
            out[i] = r.rate_dps ** 2 if r else 0.0
        elif name == "signed_rate" and r:
            out[i] = r.rate_dps
        elif name == "rate_change" and r:
            out[i] = float(np.linalg.norm(r.gyro_end - r.gyro_start))
        elif name == "temperature":
            seg_ = r or st
            out[i] = seg_.temp_c if seg_ is not None and seg_.temp_c is not None else np.nan
        elif name == "time" and (r or st) is not None:
            out[i] = (r or st).t_mid_s
        elif name == "gravity_along_axis" and st is not None and st.up_body is not None and axis in "xyz":
            out[i] = st.up_body["xyz".index(axis)]
    return out


def segments_spec(panels) -> SegmentsFigure:
    """panels: list of (title, diagnosis): the RMS whitened residual per segment of each."""
    return SegmentsFigure([SegmentPanel(title, d.reduced_chi2, [s.name for s in d.segments],
                                        [s.kind for s in d.segments], [s.rms for s in d.segments])
                           for title, d in panels])


def candidate_spec(diagnosis, cand) -> CandidateFigure:
    """The residuals against the change the candidate would make, and against its signature
    variable (data rows only, not the priors)."""
    labels = diagnosis.labels
    r = diagnosis.result.model.residuals(diagnosis.result.x)
    data = np.array([q not in PRIOR_QUANTITIES for _, _, q, _ in labels])
    var = _variable(cand.signature_variable, diagnosis, labels)
    ok = data & np.isfinite(var)
    return CandidateFigure(cand.effect, float(cand.predicted_chi2_drop), -cand.signature_rows[data], r[data],
                           VARIABLE_LABEL.get(cand.signature_variable, cand.signature_variable), var[ok], r[ok])


def candidate_figure_specs(first, most: int = 3, skip=()) -> dict:
    """{file name: what to draw} of the candidates of the model as fitted (known before any effect
    is added) that are significant, at most ``most``, or of the leading one when none is; but
    those named in ``skip``.  (A candidate that is not significant scatters noise, or the share
    of a failing fit's misfit that another effect explains; the page's table has every
    candidate's numbers.)"""
    drawable = [cand for cand in first.candidates if cand.signature_rows is not None]
    chosen = [cand for cand in drawable if cand.significant][:most] or drawable[:1]
    names = [(f"candidate_{cand.effect}.svg", cand) for cand in chosen]
    return {name: candidate_spec(first, cand) for name, cand in names if name not in skip}


def segments_figure_specs(first, steps) -> dict:
    """{file name: what to draw}: the residuals per segment, before and after each step."""
    panels = [("as fitted", first)] + [(f"after adding {s.added}", s.after) for s in steps]
    return {SEGMENTS_FIGURE: segments_spec(panels)}


def diagnosis_figure_specs(first, steps) -> dict:
    """{file name: what to draw}: the residuals per segment (before and after each step) and the
    significant candidates (candidate_figure_specs)."""
    return {**segments_figure_specs(first, steps), **candidate_figure_specs(first)}


class DiagnosisFigures:
    """Gives a FigureJob the diagnosis' figures as soon as each is known: the candidates' when
    the model as fitted is diagnosed (``first_known``, station.diagnose.auto.run's on_first), if
    the loop then refits (a significant candidate: drawn meanwhile); the residuals per segment,
    and the candidates' if not given yet, once every step is known (``known``)."""

    def __init__(self, job: FigureJob):
        self.job, self.given = job, set()

    def first_known(self, first) -> None:
        if any(c.significant for c in first.candidates):
            specs = candidate_figure_specs(first)
            self.job.draw(specs)
            self.given.update(specs)

    def known(self, first, steps) -> None:
        self.job.draw({**segments_figure_specs(first, steps), **candidate_figure_specs(first, skip=self.given)})
        self.job.all_cores()          # what is left here (printing, the page) is little


def diagnosis_figures(first, steps) -> dict:
    """{file name: SVG}, drawn here (a FigureJob draws them in its worker)."""
    return draw(diagnosis_figure_specs(first, steps))


# ----------------------------------------------------------------------------------- the page

@dataclass
class ReportInput:
    """Everything the page shows; any part may be missing (the page says so)."""
    title: str
    facts: list = field(default_factory=list)       # (label, value) about the capture and the IMU
    calibration: dict | None = None                 # a calibration document (read_calfile)
    calibration_path: str | None = None
    verdict: str | None = None                      # the calibration file's fit verdict
    first: object = None                            # Diagnosis of the model as fitted
    steps: list = field(default_factory=list)       # auto.Step
    final: object = None
    diagnosis_note: str | None = None               # why there is no diagnosis
    noise: object = None                            # estimate.noise.NoiseResult
    noise_note: str | None = None
    figures: dict = field(default_factory=dict)     # {file name: bytes} already drawn (by a FigureJob)


CSS = """
body{font-family:-apple-system,"Segoe UI",Roboto,"Helvetica Neue",Arial,sans-serif;margin:0;
background:#f4f5f7;color:#1d2330;line-height:1.45}
main{max-width:1100px;margin:0 auto;padding:24px 28px 48px}
header{background:#1d2a44;color:#fff;padding:22px 28px}
header h1{margin:0;font-size:1.5em;font-weight:600}
header p{margin:4px 0 0;color:#c8d0e0;font-size:.95em}
section{background:#fff;border-radius:8px;box-shadow:0 1px 3px rgba(0,0,0,.08);
padding:18px 22px;margin:18px 0}
h2{font-size:1.15em;margin:0 0 12px;color:#1d2a44;border-bottom:2px solid #e3e7ef;padding-bottom:6px}
h3{font-size:1em;margin:16px 0 8px}
table{border-collapse:collapse;width:100%;font-size:.9em}
th,td{padding:4px 10px;border-bottom:1px solid #e8ebf1;text-align:right;white-space:nowrap}
th{background:#f0f2f6;font-weight:600}
td.l,th.l{text-align:left}
tr:nth-child(even) td{background:#fafbfc}
dl.facts{display:grid;grid-template-columns:max-content 1fr;gap:4px 18px;margin:0}
dl.facts dt{font-weight:600;color:#4a5468}
dl.facts dd{margin:0;word-break:break-all}
.verdict{display:inline-block;padding:6px 14px;border-radius:6px;font-weight:600;margin:4px 0 10px}
.pass{background:#e3f5e8;color:#17692f;border:1px solid #9fd9b0}
.fail{background:#fde8e8;color:#9b1c1c;border:1px solid #f2a7a7}
.unknown{background:#eef0f4;color:#3b4456;border:1px solid #cfd5e0}
img{max-width:100%;height:auto;display:block;margin:8px 0}
.note{color:#5b6478;font-size:.9em}
.yes{color:#17692f;font-weight:600}
.flag{color:#9b1c1c;font-weight:600}
footer{color:#6b7385;font-size:.8em;margin-top:24px}
ul.design li{margin:4px 0}
ul.design code{white-space:pre-wrap;word-break:break-all;background:#f0f2f6;padding:1px 4px}
"""


def _e(text) -> str:
    return html.escape(str(text), quote=True)


def _img(name: str, figures: dict, alt: str) -> str:
    kind = "svg+xml" if figure_format(name) == "svg" else "png"
    return f"<img alt='{_e(alt)}' src='data:image/{kind};base64,{base64.b64encode(figures[name]).decode()}'>"


def _table(header, rows, left=(0,)) -> str:
    th = "".join(f"<th class='l'>{_e(h)}</th>" if i in left else f"<th>{_e(h)}</th>" for i, h in enumerate(header))
    body = "".join("<tr>" + "".join(f"<td class='l'>{c}</td>" if i in left else f"<td>{c}</td>"
                                    for i, c in enumerate(row)) + "</tr>" for row in rows)
    return f"<table><thead><tr>{th}</tr></thead><tbody>{body}</tbody></table>"


def _verdict_class(text: str) -> str:
    t = text.lower()
    if t.startswith(("passes", "pass", "the model explains")):
        return "pass"
    if t.startswith(("fails", "fail", "the model does not", "not converged")):
        return "fail"
    return "unknown"


def _parameters_section(inp: ReportInput) -> str:
    doc = inp.calibration
    if doc is None:
        return "<section><h2>Parameters</h2><p class='note'>No calibration file.</p></section>"
    rows = []
    for name, p in doc.get("parameters", {}).items():
        value, unit, sigma = p["value"], p["unit"], p.get("sigma")
        if unit in SCALE_UNITS:
            v = f"{value:.9f}"
            s = "" if sigma is None or not math.isfinite(sigma) else f"{sigma:.3g} ({sigma / value * 1e6:.3g} ppm)"
        else:
            v = f"{value:.4f}"
            s = "" if sigma is None or not math.isfinite(sigma) else f"{sigma:.3g}"
        rows.append([_e(name), v, _e(s), _e(unit)])
    effects = ", ".join(doc.get("effects", []))
    verdict = inp.verdict or "not stated"
    fit = doc.get("fit") or {}
    chi = ""
    if isinstance(fit.get("reduced_chi2"), (int, float)):
        chi = (f"<p>χ² {fit.get('chi2', float('nan')):.1f} for {fit.get('dof', '?')} degrees of freedom "
               f"(reduced {fit['reduced_chi2']:.3f}), method {_e(fit.get('method', ''))}</p>")
    notes = "".join(f"<li>{_e(n)}</li>" for n in fit.get("notes", []) if isinstance(n, str))
    held = [str(n) for n in fit.get("not_determined") or []] if isinstance(fit.get("not_determined"), list) else []
    if held:
        chi += f"<p>Not determined by the capture (not written): {_e(', '.join(held))}.</p>"
    return (f"<section><h2>Parameters ± 1σ</h2>"
            f"<p>Calibration file <code>{_e(inp.calibration_path)}</code>; effects: {_e(effects)}.</p>"
            f"<div class='verdict {_verdict_class(verdict)}'>fit verdict: {_e(verdict)}</div>{chi}"
            + _table(["parameter", "value", "± 1σ", "unit"], rows)
            + (f"<h3>Notes</h3><ul>{notes}</ul>" if notes else "") + "</section>")


def _verdict_box(text: str, inp: ReportInput, prefix: str = "") -> str:
    """The diagnosis' verdict; never greener than the calibration file's own: when the file says
    its fit fails (or did not converge, or was not tested) and this page's refit says the model
    explains the data, the box takes the file's colour and says why they differ (the file's
    test: its noise model, the groups it tested, the pose check)."""
    cls = _verdict_class(text)
    file_cls = _verdict_class(inp.verdict) if inp.verdict else None
    if file_cls in ("fail", "unknown") and cls == "pass" and inp.calibration is not None:
        return (f"<div class='verdict {file_cls}'>{_e(prefix + text)}; but the calibration file's own fit "
                f"verdict is: {_e(inp.verdict)} (its test, with its noise model and pose check, is what "
                "the file stands for)</div>")
    return f"<div class='verdict {cls}'>{_e(prefix + text)}</div>"


def _candidates_table(d) -> str:
    rows = []
    for c in d.candidates:
        est, note = c.largest_estimate(), c.note()
        sig = "<span class='yes'>yes</span>" if c.significant else "no"
        rows.append([_e(c.effect), sig, f"{c.predicted_chi2_drop:.4g}", f"{c.p_value_corrected:.2g}",
                     _e(est), _e(note)])
    return _table(["effect", "significant", "predicted Δχ²", "p (Holm)", "largest one-step estimate", "note"],
                  rows, left=(0, 1, 4, 5))


def _unrevealed_section(first, steps, final) -> str:
    """What the capture cannot reveal or separate, each line as diagnose prints it on screen and
    in JSON (``design_suggestions``, ``not_revealed``, the candidates' and the steps' commands:
    station.diagnose.suggest.all_lines), the `station design` command that ends it (--from, or a
    new run's --config) in code so that it is copied whole."""
    from station.diagnose.suggest import all_lines

    lines = all_lines(first, steps, final)
    if not lines:
        return ""
    items = []
    for line in lines:
        words, sep, cmd = line.partition("station design --")
        items.append(f"<li>{_e(words)}<code>{_e(sep + cmd)}</code></li>" if sep else f"<li>{_e(line)}</li>")
    return ("<h3>What this capture cannot reveal, and the segments that would</h3><ul class='design'>"
            + "".join(items) + "</ul>")


def _diagnosis_section(inp: ReportInput, figures: dict) -> str:
    from station.diagnose.auto import comparison_rows

    if inp.first is None:
        return (f"<section><h2>Model against measurements</h2><p class='note'>"
                f"{_e(inp.diagnosis_note or 'No diagnosis.')}</p></section>")
    first, final = inp.first, inp.final or inp.first
    parts = [f"<section><h2>Model against measurements</h2>", _verdict_box(first.verdict, inp),
             f"<p>χ² {first.chi2:.1f} for {first.dof} degrees of freedom (reduced {first.reduced_chi2:.3f}, "
             f"p = {first.p_value:.3g}); effects in the model: {_e(', '.join(first.effects))}.</p>"]
    if first.failures:
        parts.append("<h3>Where it fails</h3><ul>" + "".join(f"<li>{_e(f)}</li>" for f in first.failures) + "</ul>")
    notes = list(dict.fromkeys([*first.notes, *final.notes]))
    if notes:
        parts.append("<h3>Notes on the diagnosis</h3><ul>" + "".join(f"<li>{_e(n)}</li>" for n in notes) + "</ul>")
    parts.append("<h3>Residual per segment, before and after each added effect (same y axis)</h3>")
    parts.append(_img(SEGMENTS_FIGURE, figures, "RMS whitened residual per segment"))
    for k, st in enumerate(inp.steps, 1):
        rows = [[_e(what), f"{b:.4g}", f"{a:.4g}"] for what, b, a in comparison_rows(st.before, st.after)]
        rows += [["predicted χ² drop", f"{st.predicted_drop:.4g}", ""], ["actual χ² drop", f"{st.actual_drop:.4g}", ""]]
        parts.append(f"<h3>Step {k}: added {_e(st.added)}</h3>" + _table(["", "before", "after"], rows))
        words = getattr(st, "held_words", None) or (lambda n: "")
        parts.append("<p>" + "; ".join(_e(f"{n} = {v:.4g} ± {s:.2g} {u}" + words(n))
                                       for n, v, s, u in st.estimate) + "</p>")
        # what the capture cannot tell the added effect from (the screen's and the JSON's caveats;
        # the commands that separate them are in the section of what the capture cannot reveal)
        alike = [c for c in st.caveats if "cannot tell" in c]
        if alike:
            parts.append("<ul>" + "".join(f"<li>caveat: {_e(c)}</li>" for c in alike) + "</ul>")
    if inp.steps:
        parts.append(_verdict_box(final.verdict, inp, "after the added effects: "))
    account = getattr(final, "account", None) or []
    if account:
        parts.append("<h3>Why it still fails: what was tried, what each explained, what the residuals follow</h3>"
                     "<ul>" + "".join(f"<li>{_e(line)}</li>" for line in account) + "</ul>")
    parts.append(_unrevealed_section(first, inp.steps, final))
    parts.append("<h3>Candidate effects (score test at the fit as it was first made)</h3>")
    parts.append(_candidates_table(first))
    for name in figures:
        if name.startswith("candidate_"):
            effect = name[len("candidate_"):-len(".svg")]
            parts.append(f"<h3>{_e(effect)}: residuals against the change it would make, and against "
                         f"its signature variable</h3>" + _img(name, figures, effect))
    return "".join(parts) + "</section>"


def _filed_noise(inp: ReportInput) -> str:
    """The calibration file's own noise block (e.g. from a long noise recording), as a table."""
    block = (inp.calibration or {}).get("noise")
    if not isinstance(block, dict):
        return ""
    rows = []
    for sensor, key, unit in (("accel", "white_noise_ug_rthz", "µg/√Hz"), ("gyro", "white_noise_dph_rthz", "°/h/√Hz")):
        for axis, r in (block.get(sensor) or {}).items():
            if isinstance(r, dict) and isinstance(r.get(key), (int, float)):
                rows.append([_e(f"{sensor} {axis}"), _e(f"{r[key]:.4g} {unit}")])
    kal = block.get("kalibr") or {}
    kal_rows = [[_e(k), _e(f"{v:.4g}")] for k, v in kal.items() if isinstance(v, float)]
    return (f"<h3>In the calibration file (from {_e(block.get('source', 'station noise'))})</h3>"
            + _table(["axis", "white noise"], rows) + "<h3>Kalibr</h3>" + _table(["key", "value"], kal_rows))


def _noise_section(inp: ReportInput, figures: dict) -> str:
    if inp.noise is None:
        return (f"<section><h2>Noise</h2><p class='note'>{_e(inp.noise_note or 'Not characterised.')}"
                f"</p>{_filed_noise(inp)}</section>")
    res = inp.noise
    rows = []
    for a in res.axes:
        r = a.report()
        if a.sensor == "accel":
            white = f"{r['white_noise_ug_rthz']:.4g} ± {r['white_noise_sigma_ug_rthz']:.2g} µg/√Hz"
            bi, bu, rw, ru = "bias_instability_ug", "µg", "random_walk_ug_rth", "µg/√h"
        else:
            white = f"{r['white_noise_dph_rthz']:.4g} ± {r['white_noise_sigma_dph_rthz']:.2g} °/h/√Hz"
            bi, bu, rw, ru = "bias_instability_dph", "°/h", "random_walk_dph_rth", "°/h/√h"
        b = f"{r[bi]:.3g} {bu}" if r[bi] is not None else f"&lt; {r[bi.replace('instability', 'instability_upper')]:.3g} {bu}"
        w = f"{r[rw]:.3g} {ru}" if r[rw] is not None else f"&lt; {r[rw.replace('random_walk', 'random_walk_upper')]:.3g} {ru}"
        rows.append([_e(f"{a.sensor} {a.axis}"), _e(white), b, w])
    return ("<section><h2>Noise (overlapping Allan deviation)</h2>"
            f"<p>{_e(res.source)}: {res.duration_s:.0f} s at {res.sample_rate_hz:g} Hz. "
            "Bias instability and random walk are upper bounds (&lt;) when the record is too short "
            "to show them.</p>"
            + _table(["axis", "white noise ± 1σ", "bias instability", "bias random walk"], rows)
            + _img(ALLAN_FIGURE, figures, "Allan deviation") + _filed_noise(inp) + "</section>")


def render(inp: ReportInput, figures: dict) -> str:
    facts = "".join(f"<dt>{_e(k)}</dt><dd>{_e(v)}</dd>" for k, v in inp.facts)
    made = _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    convention = (inp.calibration or {}).get("convention") or {}
    conv = "".join(f"<li><b>{_e(k)}</b>: {_e(v)}</li>" for k, v in convention.items() if isinstance(v, str))
    return (f"<!doctype html><html lang='en'><head><meta charset='utf-8'>"
            f"<meta name='viewport' content='width=device-width, initial-scale=1'>"
            f"<title>{_e(inp.title)}</title><style>{CSS}</style></head><body>"
            f"<header><h1>{_e(inp.title)}</h1><p>station {station.__version__} · report made {made}</p></header>"
            f"<main><section><h2>What was measured</h2><dl class='facts'>{facts}</dl></section>"
            + _parameters_section(inp) + _diagnosis_section(inp, figures) + _noise_section(inp, figures)
            + (f"<section><h2>Convention</h2><ul>{conv}</ul></section>" if conv else "")
            + "<footer>One self-contained page: every figure is embedded.</footer></main></body></html>\n")


def figures_of(inp: ReportInput) -> dict:
    """Every figure of the page: those already drawn (inp.figures, by a FigureJob), the others
    drawn now."""
    figures = {}
    if inp.first is not None:
        drawn = {name: data for name, data in inp.figures.items() if name != ALLAN_FIGURE}
        figures.update(drawn or diagnosis_figures(inp.first, inp.steps))
    if inp.noise is not None:
        figures[ALLAN_FIGURE] = inp.figures.get(ALLAN_FIGURE) or allan_figure(inp.noise, fmt="svg")
    return figures


def write_page(path, inp: ReportInput, figure_dir=None) -> Path:
    """Write the page (and, with ``figure_dir``, its figures as files there)."""
    from station.core.user_files import output_path

    path = Path(output_path(path, "the report"))
    figures = figures_of(inp)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(render(inp, figures), encoding="utf-8")
        if figure_dir is not None:
            for name, data in figures.items():
                (Path(figure_dir) / name).write_bytes(data)
    except OSError as e:
        raise cannot_write(path, e, "the report") from None
    return path


def write_report(directory, first, steps, final, summary_lines, inp: ReportInput | None = None) -> Path:
    """``diagnose --report DIR``: DIR/index.html (self-contained) and the figures beside it."""
    from station.core.user_files import output_path

    directory = Path(output_path(directory, "the report directory"))
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise UserError(f"{directory}: cannot create the report directory: {e.strerror}") from None
    inp = inp or ReportInput(title="station diagnosis")
    inp.first, inp.steps, inp.final = first, steps, final
    if not inp.facts:
        inp.facts = [("summary", line) for line in summary_lines]
    return write_page(directory / "index.html", inp, figure_dir=directory)


# ------------------------------------------------------------------- from a capture to the page

def capture_facts(capture, cal_doc=None) -> list:
    """(label, value) rows: capture, IMU, scheme, dates, site, calibration provenance."""
    started = [s.extra.get("started_utc") for s in capture.segments if isinstance(s.extra.get("started_utc"), str)]
    prov = (cal_doc or {}).get("provenance") or {}
    rows = [("capture", str(capture.path)),
            ("IMU", f"{capture.imu.model or 'unknown model'}, serial {capture.imu.serial or 'unknown'}"),
            ("output", f"{capture.imu.sample_rate_hz:g} Hz; accelerometers in {capture.imu.accel_unit}, "
                       f"gyros in {capture.imu.gyro_unit}"),
            ("scheme", capture.scheme or "not named"),
            ("segments", f"{len(capture.complete('static'))} static, {len(capture.complete('rotation'))} "
                         f"rotation complete of {len(capture.segments)}"),
            ("recorded (UTC)", f"{min(started)} to {max(started)}" if started else "not stated"),
            ("site", f"gravity {capture.site.gravity_mps2:.6f} m/s²"
                     + (f", latitude {capture.site.latitude_deg:g}°" if capture.site.latitude_deg is not None else ""))]
    if prov:
        rows.append(("calibrated (UTC)", f"{prov.get('date_utc', 'not stated')} by {prov.get('software', '?')}, "
                                         f"method {prov.get('method', '?')}"))
    return rows


def report_input(capture, cal_doc=None, cal_path=None, *, effects=(), auto=True, registry=None) -> ReportInput:
    """Everything for the page from a capture (read with or without its samples) and its
    calibration; the diagnosis (with ``auto``, the add-and-refit loop) needs encoder angles on
    every rotation.  As ``diagnose --report``: the capture is read and summarised in a child
    while the fit is imported, which also computes the noise's Allan curves, and the figures
    are drawn by a FigureJob.  ``registry``: where the effects come from (station.api._registry,
    as diagnose builds it; default the library's)."""
    from station.diagnose import RotationWithoutAngle, segment_check
    from station.diagnose.figure_job import read_for_report
    from station.io.history import verdict_of

    inp = ReportInput(title=f"Calibration report: {Path(str(capture.path)).name}",
                      calibration=cal_doc, calibration_path=None if cal_path is None else str(cal_path),
                      verdict=verdict_of(cal_doc) if cal_doc is not None else None)
    without_angle = ("The diagnosis fits the least-squares model, which needs the encoder angle of every "
                     "rotation that is not a hand turn between statics; this capture has rotations without one.")
    check = None
    if not capture.complete("rotation"):
        inp.diagnosis_note = "No rotation segments: nothing to diagnose (a noise recording)."
    else:
        try:
            check = segment_check(capture)       # hand turns between statics are diagnosed
        except RotationWithoutAngle:
            inp.diagnosis_note = without_angle
    with FigureJob() as job:          # started where the capture is read: matplotlib imported meanwhile
        if inp.diagnosis_note is None:
            try:
                inp.noise, inp.noise_note = read_for_report(capture, cal_doc, job, check)
            except RotationWithoutAngle:                # a rotation without angle, not a hand's
                inp.diagnosis_note = without_angle
        if inp.diagnosis_note is None:
            figures = DiagnosisFigures(job)
            inp.first, inp.steps, inp.final = _diagnosis(capture, effects, auto, on_first=figures.first_known,
                                                          registry=registry)
            figures.known(inp.first, inp.steps)
        else:
            inp.noise, inp.noise_note = noise_of(capture, cal_doc)
            if inp.noise is not None:
                job.draw({ALLAN_FIGURE: inp.noise})
        inp.figures.update(job.result())
    inp.facts = capture_facts(capture, cal_doc)       # the segments as read (their status)
    return inp


def _diagnosis(capture, effects, auto: bool, on_first=None, registry=None) -> tuple:
    """(first, steps, final) of the capture's (summarised) least-squares fit: the diagnosis
    ``station diagnose`` makes (station.diagnose.pipeline.run), with or without --auto's loop;
    ``on_first`` as in station.diagnose.auto.run."""
    from station.diagnose import pipeline

    first, steps, final, _ = pipeline.run(capture, effects, registry=registry, auto=auto, on_first=on_first)
    return first, steps, final


# ----------------------------------------------------------------------------------- the noise

def noise_of(capture, cal_doc=None) -> tuple:
    """(NoiseResult or None, note) of the capture's longest static segment."""
    from station.estimate import noise

    try:
        return noise.from_capture(capture, None, cal_doc), None     # reads what is not loaded
    except UserError as e:
        return None, f"Not characterised: {e}"
