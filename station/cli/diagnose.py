"""``station diagnose``: compare the model with the measurements, find what is missing."""
from __future__ import annotations

import json
import math
from pathlib import Path

from station.cli import plugins
from station.cli.output import err, out
from station.core.errors import UserError, cannot_write


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


def cmd_diagnose(args) -> int:
    if args.report:
        first, steps, final, summary, page = _diagnose_with_page(args)
    else:
        from station import api

        final = api.diagnose(args.capture, add=args.add, **plugins.options(args), calibration=args.calib,
                             force=args.force, auto=args.auto)
        for line in final.warnings:
            err.print(line, markup=False, soft_wrap=True)
        first, steps = final.first, final.steps
        if args.emit_effect:
            _emit(args.emit_effect, final, steps)
        if not args.json:
            _print(out, first, steps, final)
    if args.json:
        from station.diagnose.as_json import to_json

        print(json.dumps(to_json(final, steps), indent=1))
    return _in_a_file(args, final, steps)


def _diagnose_with_page(args) -> tuple:
    """diagnose --report: the diagnosis api.diagnose makes (the same library calls), with the
    page's figures drawn in forked workers meanwhile (station.diagnose.figure_job) and the page
    written: (first, steps, final, summary lines, the page's ReportInput)."""
    from station.diagnose.figure_job import FigureJob

    with FigureJob() as job:      # the figures' processes (started once the capture is about to be read)
        first, steps, final, summary, page = _diagnose(args, job)
        from station.diagnose.report import write_report

        index = write_report(args.report, first, steps, final, summary, page)      # (while they end)
        if not args.json:
            out.print(f"report: {index}")
    return first, steps, final, summary, page


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
    specs = _specs(args, effects)
    plugin = None
    if args.output:
        from station import api

        target = Path(args.output)
        adds = [specs[e] for e in effects]       # a plugin given to --add by its file: by its file again
        if discovered:
            plugin = target.with_name(f"{target.stem}-discovered.py")
            _emit(plugin, final, steps)
            adds.append(f"{plugin}:DiscoveredTerms")
        est = api.estimate(args.capture, method="lsq", add=adds, **plugins.options(args))
        est.save(target)
        ids = [e for e in est.calibration.effects if e not in ("base_triads", "inter_triad")]
        verdict = est.verdict
        err.print(f"calibration file: {target} (effects: {', '.join(ids) or 'none'}; fit {verdict.get('result')}: "
                  f"{verdict.get('reason', '')})", markup=False, soft_wrap=True)
        status = 0 if est.usable else 3
    else:
        status = 0
    for line in commands(args, effects, plugin, discovered, specs):
        err.print(line, markup=False, soft_wrap=True)
    return status


def commands(args, effects, plugin, discovered, specs=None) -> list[str]:
    """The two lines that reproduce and apply the diagnosis's calibration: `station estimate` with
    the effects kept (and the discovered terms' plugin) and `station apply`, each a command the
    shell runs as printed (every argument quoted as the shell needs: a path with a space)."""
    import shlex

    given = [x for p in getattr(args, "plugin", None) or [] for x in ("--plugin", str(p))] + \
            [x for d in getattr(args, "effects_dir", None) or [] for x in ("--effects-dir", str(d))]
    specs = specs if specs is not None else _specs(args, effects)
    adds = [x for e in effects for x in ("--add", specs[e])] + (["--add", f"{plugin}:DiscoveredTerms"] if plugin else [])
    # an effect of a file given to --add (not --plugin): apply needs that file too
    given_apply = given + [x for e in effects if specs[e] != e for x in ("--plugin", specs[e])]
    cal_name = str(args.output or "CAL.yaml")
    estimate = shlex.join(["station", "estimate", str(args.capture), *given, *adds, "-o", cal_name])
    if discovered and not plugin:
        estimate += " --add FOUND.py:DiscoveredTerms (write it with --emit-effect FOUND.py)"
    apply = shlex.join(["station", "apply", cal_name, "RAW.csv", "-o", "COMPENSATED.csv",
                        *(["--plugin", str(plugin)] if plugin else []), *given_apply])
    return [f"to estimate it: {estimate}", f"to apply it: {apply}"]


def _specs(args, effects) -> dict:
    """Each effect id as a new command's --add must name it: its id, or for an effect of a
    plugin file or module its spec (station.diagnose.suggest.added), the effects' sources as this
    command loaded them (the same files: loaded once per process)."""
    from station.api import _registry
    from station.diagnose.suggest import added
    from station.model.registry import effect_ids

    try:
        reg = _registry(plugins=list(getattr(args, "plugin", None) or []),
                        effects_dirs=list(getattr(args, "effects_dir", None) or []), config=getattr(args, "config", None))
        effect_ids(reg, [a for a in getattr(args, "add", None) or [] if a])
    except UserError:               # loaded once already by this command: not reached
        return {e: str(e) for e in effects}
    return {e: added(e, reg) for e in effects}


def _diagnose(args, job) -> tuple:
    """(first, steps, final, summary lines, the page's ReportInput): api.diagnose's diagnosis
    (the same station.diagnose.pipeline.run), with
    the capture read where the figures' noise is taken, the candidates' figures drawn as soon as
    the first diagnosis is known, and the diagnosis printed while the figures are drawn."""
    from station.api import _model_effects, _registry
    from station.diagnose import segment_check
    from station.diagnose.figure_job import read_for_report
    from station.io.calfile import read_calfile
    from station.io.capture import read_capture

    capture = read_capture(args.capture, load_data=False)      # the manifest: samples below
    # the page shows the calibration it describes: --calib, else the capture's own
    cal_path = args.calib or (capture.path / "calibration.yaml" if (capture.path / "calibration.yaml").is_file()
                              else None)
    cal_doc = read_calfile(cal_path) if cal_path else None
    # each segment read, checked and summarised (in a child, while the fit is imported here),
    # and the noise where the capture is read
    noise, noise_note = read_for_report(capture, cal_doc, job, segment_check(capture))
    from station.diagnose.report import DiagnosisFigures       # (imported while reading)

    figures = DiagnosisFigures(job)
    from station.diagnose import pipeline

    reg = _registry(**plugins.options(args))
    effects, warnings = _model_effects(capture, reg, args.add, args.calib, args.force)
    for line in warnings:
        err.print(line, markup=False, soft_wrap=True)
    first, steps, final, _ = pipeline.run(capture, effects, registry=reg, auto=args.auto,
                                          on_first=figures.first_known)
    if args.emit_effect:
        _emit(args.emit_effect, final, steps)
    summary = _summary_lines(final, design=False)       # the page lists the design lines in their own place
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
    from station.core.user_files import output_path

    output_path(path, "the effect plugin")
    try:
        Path(path).write_text(plugin_source(*got, aliases=aliases, discovered_by=how))
    except OSError as e:
        raise cannot_write(path, e) from None
    err.print(f"effect plugin written: {path} (add it with --add {path}:DiscoveredTerms; check it with "
              f"python {path})", markup=False, soft_wrap=True)


def _summary_lines(d, design: bool = True) -> list[str]:
    lines = [d.verdict, f"effects in the model: {', '.join(d.effects)}",
             f"chi2 {d.chi2:.1f} for {d.dof} degrees of freedom (reduced {d.reduced_chi2:.3f}, p = {d.p_value:.3g})"]
    t = getattr(d, "test", None)
    if t is not None and abs(t["dof"] - d.dof) > 0.005:
        # the verdict's test, the calibration file's (station.diagnose.core.fit_test)
        lines.append(f"verdict: {t['result']}: the data's chi2 {t['chi2']:.1f} on their redundancy {t['dof']:.1f} "
                     f"(reduced {t['reduced_chi2']:.3f}, p = {t['p_value']:.3g}; the rest of the degrees of "
                     "freedom are the priors'), as station estimate judges it")
    lines += [f"where it fails: {f}" for f in d.failures]
    lines += [f"not kept: {r.effect}: {r.reason}" for r in d.rejected]
    lines += [f"why it still fails: {line}" for line in getattr(d, "account", None) or []]
    if design:
        from station.diagnose.suggest import design_lines

        lines += design_lines(d)
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


def _print_suggestions(out, d) -> None:
    """Beside each candidate the capture cannot reveal, the command that designs the segments
    that would (station design --from: docs/design.md); the words are station.diagnose.suggest's,
    which the report page lists too."""
    from station.diagnose.suggest import candidate_lines

    for line in candidate_lines(d):
        out.print(line, markup=False, soft_wrap=True, highlight=False)


def _print(out, first, steps, final) -> None:
    from rich.table import Table

    from station.diagnose.auto import comparison_rows
    from station.diagnose.suggest import step_lines

    for line in _summary_lines(first):
        # a command is printed whole (soft_wrap): it is copied into a shell
        out.print(line, **({"soft_wrap": True, "markup": False, "highlight": False} if line.startswith("design:") else {}))
    worst = sorted(first.segments, key=lambda s: -s.rms)[:5]
    out.print("worst segments: " + ", ".join(f"{s.name} ({s.kind}) {s.rms:.2g}σ" for s in worst))
    out.print(_candidates_table(first))
    _print_suggestions(out, first)
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
        out.print("added: " + "; ".join(f"{n} = {v:.4g} ± {s:.2g} {u}" + st.held_words(n)
                                        for n, v, s, u in st.estimate))
        for c in st.caveats:
            out.print(f"caveat: {c}")
        for line in step_lines(st):
            out.print(line, markup=False, soft_wrap=True, highlight=False)
        for _, why in st.removed:
            out.print(f"removed: {why}", markup=False)
    if steps:
        for line in _summary_lines(final):
            out.print(line)
        if final.candidates:
            out.print(_candidates_table(final))


def cmd_effects(args) -> int:
    from station import api

    if args.name is None:
        from rich.table import Table

        table = Table(title="effects the model can add (station estimate --add ID; plugins: docs/effects.md)")
        table.add_column("id")
        table.add_column("what")
        table.add_column("source")
        plugins_seen = []
        for e in api.effects(**plugins.options(args)):
            source = e.source
            if source != "library":
                plugins_seen.append((e.id, source))
                source = "plugin (below)"
            table.add_row(e.id, e.title, source)
        out.print(table)
        # a plugin's path is printed whole, never cut to the table's width
        for eid, source in plugins_seen:
            out.print(f"plugin {eid}: {source}", markup=False, highlight=False, soft_wrap=True)
        return 0
    e = api.effect(args.name, **plugins.options(args))
    out.print(f"[bold]{e.id}[/]: {e.title}  ({e.source})\n")
    for label, text in (("physics", e.physics), ("term", e.term), ("excited by", e.excited_by),
                        ("typical size", e.magnitudes), ("when missing", e.signature)):
        out.print(f"[bold]{label}:[/] {text}")
    if e.parameters:
        out.print("[bold]parameters:[/] " + ", ".join(f"{name} ({unit})" for name, unit in e.parameters))
    if e.needs:
        out.print(f"[bold]compensation needs:[/] {', '.join(e.needs)}")
    return 0
