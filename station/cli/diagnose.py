"""``station diagnose``: compare the model with the measurements, find what is missing."""
from __future__ import annotations

import contextlib
import json
import math
from pathlib import Path

from station.cli import plugins
from station.cli.output import err, out
from station.core.errors import UserError


def add_parsers(sub) -> None:
    d = sub.add_parser("diagnose", help="residuals of the fitted model, where it fails, which effect is missing")
    d.add_argument("capture", help="capture directory (rotations need encoder angles)")
    d.add_argument("--calib", metavar="CAL.yaml", help="diagnose the model of this calibration file "
                   "(its effects), refitted to the capture")
    d.add_argument("--force", action="store_true",
                   help="use a --calib made for another IMU serial than the capture's")
    d.add_argument("--add", action="append", default=[], metavar="EFFECT", help="add an effect first")
    d.add_argument("--auto", action="store_true",
                   help="add the most significant candidate, refit, repeat until none is significant")
    d.add_argument("--json", action="store_true", help="print the diagnosis as JSON (docs/diagnose.md)")
    d.add_argument("--report", metavar="DIR", help="write index.html and its figures (SVG) into DIR")
    d.add_argument("--emit-effect", metavar="FILE.py",
                   help="write the terms found outside the library as a ready-to-edit effect plugin")
    d.add_argument("-o", "--output", metavar="CAL.yaml",
                   help="write the calibration of the model the diagnosis ends with (its effects; terms it "
                        "discovered as a plugin beside it, CAL-discovered.py) and print the commands that "
                        "reproduce and apply it; exit 3 when that calibration's fit fails")
    d.add_argument("--config", metavar="FILE", help="station.yaml (its effects section names plugins)")
    plugins.add_arguments(d)
    d.set_defaults(func=cmd_diagnose)

    eff = sub.add_parser("effects", help="list the effects the model can add, or explain one")
    eff.add_argument("name", nargs="?")
    eff.add_argument("--config", metavar="FILE", help="station.yaml (its effects section names plugins)")
    plugins.add_arguments(eff)
    eff.set_defaults(func=cmd_effects)


def _effects(args, capture, reg) -> list[str]:
    from station.cli.calibration import check_serial
    from station.io.calfile import read_calfile

    effects = []
    if args.calib:
        doc = read_calfile(args.calib)
        check_serial(doc, args.calib, capture.imu.serial, args.force, f"capture {capture.path}")
        effects += [e for e in doc.get("effects", []) if e not in ("base_triads", "inter_triad")]
    return plugins.effect_ids(reg, effects + args.add)


def cmd_diagnose(args) -> int:
    with contextlib.ExitStack() as stack:
        job = None
        if args.report:     # the figures' processes (started once the capture is about to be read)
            from station.diagnose.figure_job import FigureJob

            job = stack.enter_context(FigureJob())
        first, steps, final, summary, page = _diagnose(args, job)
        if args.report:       # (while the figures' processes end)
            from station.diagnose.report import write_report

            index = write_report(args.report, first, steps, final, summary, page)
            if not args.json:
                out.print(f"report: {index}")
    if args.json:
        from station.diagnose.as_json import to_json

        print(json.dumps(to_json(final, steps), indent=1))
    elif not args.report:
        _print(out, first, steps, final)
    return _in_a_file(args, final, steps)


def _in_a_file(args, final, steps) -> int:
    """The loop ends in a file: with -o, the calibration of the model the diagnosis ends with
    (the same estimate `station estimate` makes: verdict, noise model, pose check), the
    discovered terms written as a plugin beside it; with or without -o, when the diagnosis
    changed the model, the commands that reproduce and apply it (on stderr)."""
    from station.diagnose.terms import in_model

    effects = [e for e in final.effects if e not in ("base_triads", "inter_triad", "discovered_terms")]
    discovered = in_model(final.result) is not None
    if not args.output and not steps:
        return 0
    plugin = None
    if args.output:
        from station.estimate import estimate_capture
        from station.estimate.verdict import fit_fails
        from station.io.calfile import write_calfile

        target = Path(args.output)
        reg = plugins.registry(args)
        ids = plugins.effect_ids(reg, effects)
        if discovered:
            plugin = target.with_name(f"{target.stem}-discovered.py")
            _emit(plugin, final, steps)
            ids += reg.add(f"{plugin}:DiscoveredTerms")
        cal, _, provenance = estimate_capture(args.capture, "lsq", ids, reg)
        write_calfile(target, cal, provenance)
        verdict = cal.fit.get("verdict", {})
        err.print(f"calibration file: {target} (effects: {', '.join(ids) or 'none'}; fit {verdict.get('result')}: "
                  f"{verdict.get('reason', '')})", markup=False, soft_wrap=True)
        status = 3 if fit_fails(cal) else 0
    else:
        status = 0
    given = " ".join(f"--plugin {p}" for p in getattr(args, "plugin", [])) + "".join(
        f" --effects-dir {d}" for d in getattr(args, "effects_dir", []))
    adds = " ".join([f"--add {e}" for e in effects]
                    + ([f"--add {plugin}:DiscoveredTerms"] if plugin else
                       ["--add FOUND.py:DiscoveredTerms (write it with --emit-effect FOUND.py)"] if discovered else []))
    cal_name = args.output or "CAL.yaml"
    err.print(f"to estimate it: station estimate {args.capture} {given} {adds} -o {cal_name}".replace("  ", " "),
              markup=False, soft_wrap=True)
    apply_plugin = f" --plugin {plugin}" if plugin else ""
    err.print(f"to apply it: station apply {cal_name} RAW.csv -o COMPENSATED.csv{apply_plugin} {given}".rstrip(),
              markup=False, soft_wrap=True)
    return status


def _diagnose(args, job) -> tuple:
    """(first, steps, final, summary lines, the page's ReportInput or None); with a FigureJob
    (--report), its figures drawn and the diagnosis printed meanwhile."""
    from station.diagnose import DIAGNOSIS_MODULES, segment_check
    from station.estimate import summarise_while_importing
    from station.io.capture import read_capture

    capture = read_capture(args.capture, load_data=False)      # the manifest: samples below
    cal_doc = cal_path = None
    if args.report:     # the page shows the calibration it describes: --calib, else the capture's own
        from station.io.calfile import read_calfile

        cal_path = args.calib or (capture.path / "calibration.yaml" if (capture.path / "calibration.yaml").is_file()
                                  else None)
        cal_doc = read_calfile(cal_path) if cal_path else None
    check = segment_check(capture)
    # each segment read, checked and summarised (in a child, while the fit is imported here);
    # with --report, the noise where the capture is read
    if job is not None:
        from station.diagnose.figure_job import read_for_report

        noise, noise_note = read_for_report(capture, cal_doc, job, check)
        from station.diagnose.report import DiagnosisFigures       # (imported while reading)

        figures = DiagnosisFigures(job)
    else:
        summarise_while_importing(capture, check, modules=DIAGNOSIS_MODULES)
    from station.diagnose import auto
    from station.diagnose.core import diagnose
    from station.estimate import lsq

    s = lsq.summarise(capture)
    reg = plugins.registry(args)
    effects = _effects(args, capture, reg)
    if args.auto:
        steps, final = auto.run(s, effects, progress=None, registry=reg,
                                on_first=figures.first_known if job is not None else None)
        first = steps[0].before if steps else final
    else:
        steps, first = [], diagnose(lsq.fit(s, [reg.create(e) for e in effects]), registry=reg)
        auto.conclude(first, s)
        final = first
    if args.emit_effect:
        _emit(args.emit_effect, final, steps)
    summary = _summary_lines(final)
    page = None
    if job is not None:
        from station.diagnose.report import ReportInput, capture_facts
        from station.io.history import verdict_of

        figures.known(first, steps)
        if not args.json:
            _print(out, first, steps, final)        # while the figures are drawn
        page = ReportInput(title=f"Diagnosis: {Path(str(capture.path)).name}",
                           facts=capture_facts(capture, cal_doc) + [("summary", line) for line in summary],
                           calibration=cal_doc, calibration_path=None if cal_path is None else str(cal_path),
                           verdict=verdict_of(cal_doc) if cal_doc is not None else None,
                           noise=noise, noise_note=noise_note, figures=job.result())
    return first, steps, final, summary, page


def _emit(path, d, steps=()) -> None:
    """Write the discovered terms (in the final model, or proposed) as a working plugin; when
    there are none, one line says so and nothing is written (exit 0)."""
    from station.diagnose.terms import in_model, plugin_source

    got = in_model(d.result)
    aliases = [a for st in steps if st.discovered and st.proposal is not None for a in st.proposal.alias_lines()]
    how = "station diagnose --auto (added: it passed the out-of-sample stop rule)"
    if got is None and d.proposal is not None:
        got = (d.proposal.effect, d.proposal.values, d.proposal.sigmas)
        aliases = d.proposal.alias_lines()
        how = ("station diagnose (proposed" + ("" if d.proposal.kept else f"; NOT kept: {d.proposal.reason}") + ")")
    if got is None:
        err.print(f"--emit-effect {path}: nothing to emit: no term outside the library was found "
                  "(the model explains the data, or a library effect accounts for it); no file written",
                  markup=False, soft_wrap=True)
        return
    try:
        Path(path).write_text(plugin_source(*got, aliases=aliases, discovered_by=how))
    except OSError as e:
        raise UserError(f"{path}: cannot write: {e.strerror}") from None
    err.print(f"effect plugin written: {path} (add it with --add {path}:DiscoveredTerms; check it with "
              f"python {path})", markup=False, soft_wrap=True)


def _summary_lines(d) -> list[str]:
    lines = [d.verdict, f"effects in the model: {', '.join(d.effects)}",
             f"chi2 {d.chi2:.1f} for {d.dof} degrees of freedom (reduced {d.reduced_chi2:.3f}, p = {d.p_value:.3g})"]
    lines += [f"where it fails: {f}" for f in d.failures]
    lines += [f"not kept: {r.effect}: {r.reason}" for r in d.rejected]
    return lines + [f"note: {n}" for n in d.notes]


def _candidates_table(d) -> Table:
    from rich.table import Table

    t = Table(title="candidate effects (score test at the current fit)")
    for col in ("effect", "significant", "pred. Δχ²", "p (Holm)", "largest one-step estimate", "note"):
        t.add_column(col, justify="right" if col in ("pred. Δχ²", "p (Holm)") else "left")
    for c in d.candidates:
        est, note = c.largest_estimate(), c.note()
        if not note:
            smallest = {}
            for v, u in zip(c.detectable, c.units):
                if math.isfinite(v):
                    smallest[u] = min(v, smallest.get(u, math.inf))
            note = "detects ≥ " + ", ".join(f"{v:.2g} {u}" for u, v in smallest.items())
        t.add_row(c.effect, "yes" if c.significant else "no", f"{c.predicted_chi2_drop:.4g}",
                  f"{c.p_value_corrected:.2g}", est, note)
    return t


def _print(out, first, steps, final) -> None:
    from rich.table import Table

    from station.diagnose.auto import comparison_rows

    for line in _summary_lines(first):
        out.print(line)
    worst = sorted(first.segments, key=lambda s: -s.rms)[:5]
    out.print("worst segments: " + ", ".join(f"{s.name} ({s.kind}) {s.rms:.2g}σ" for s in worst))
    out.print(_candidates_table(first))
    for k, st in enumerate(steps, 1):
        t = Table(title=f"step {k}: added {st.added}" + (" (discovered outside the library)" if st.discovered else ""))
        for col in ("", "before", "after"):
            t.add_column(col, justify="left" if not col else "right")
        for what, b, a in comparison_rows(st.before, st.after):
            t.add_row(what, f"{b:.4g}", f"{a:.4g}")
        t.add_row("predicted χ² drop", f"{st.predicted_drop:.4g}", "")
        t.add_row("actual χ² drop", f"{st.actual_drop:.4g}", "")
        t.add_row("leave-one-segment-out score", f"{st.holdout_before:.4g}", f"{st.holdout_after:.4g}")
        if st.share is not None:
            t.add_row("share of the excess χ² explained", f"{100 * st.share:.0f} %", "")
        out.print(t)
        out.print("added: " + "; ".join(f"{n} = {v:.4g} ± {s:.2g} {u}" for n, v, s, u in st.estimate))
        for c in st.caveats:
            out.print(f"caveat: {c}")
        for _, why in st.removed:
            out.print(f"removed: {why}", markup=False)
    if steps:
        for line in _summary_lines(final):
            out.print(line)
        if final.candidates:
            out.print(_candidates_table(final))


def cmd_effects(args) -> int:
    from rich.table import Table

    reg = plugins.registry(args)
    if args.name is None:
        table = Table(title="effects the model can add (station estimate --add ID; plugins: docs/effects.md)")
        table.add_column("id")
        table.add_column("what")
        table.add_column("source")
        plugins_seen = []
        for eid in reg.ids():
            source = reg.source(eid)
            if source != "library":
                plugins_seen.append((eid, source))
                source = "plugin (below)"
            table.add_row(eid, reg.classes[eid].title, source)
        out.print(table)
        # a plugin's path is printed whole, never cut to the table's width
        for eid, source in plugins_seen:
            out.print(f"plugin {eid}: {source}", markup=False, highlight=False, soft_wrap=True)
        return 0
    e = reg.create(args.name)
    out.print(f"[bold]{e.id}[/]: {e.title}  ({reg.source(e.id)})\n")
    for label, text in (("physics", e.physics), ("term", e.term), ("excited by", e.excited_by),
                        ("typical size", e.magnitudes), ("when missing", e.signature)):
        out.print(f"[bold]{label}:[/] {text}")
    params = getattr(e, "all_params", None) or e.params
    if params:
        out.print("[bold]parameters:[/] " + ", ".join(f"{p.name} ({p.unit})" for p in params))
    if e.needs:
        out.print(f"[bold]compensation needs:[/] {', '.join(e.needs)}")
    return 0
