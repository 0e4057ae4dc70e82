"""What diagnose says beside an alias or a parameter not revealed: the exact `station design
--from` command that proposes the fewest extra segments revealing it (station/design/
sequential.py, docs/design.md "Sequential design")."""
from __future__ import annotations

import shlex
from pathlib import Path

BASE = ("base_triads", "inter_triad")
ALIAS_COS = 0.95      # two candidates whose one-step signatures are this alike: aliases (terms.py's threshold)
# effects a scheme extension cannot be designed for: parameters per segment that no added segment
# shares (a table axis' wobble, a vibration per table axis and rate and an offset per axis group are
# designed: station/design/information.py) (station.design.sequential.PER_SEGMENT_EFFECTS, copied:
# diagnose is below design).  A bias step is designed since the twentieth session (station design
# --from --add bias_step locates it as station estimate does and weighs segments after the capture,
# all after the step); diagnose prints its commands since the twenty-first.
# effects of the time and the temperature: the candidates' temperatures are on their own timeline,
# not the capture's clock going on (the drift's time is, since the twentieth session:
# sequential.CaptureTimeline), and the table has no chamber: two of them are not separated by
# segments the designer can weigh (docs/design.md, Limits).  A step against a drift: every added
# segment comes after the step, where a drift goes on and the step stays, but the designer finds no
# 12 segments that separate them on a capture whose every attitude was visited once (measured: the
# drift's 1sigma 2.9 x its target, correlation 0.91; tests/test_suggest_bias_step.py)
TIMELINE = ("bias_drift", "temperature_bias", "temperature_bias_quadratic", "scale_temperature", "bias_step")
NOT_DESIGNED = ("remount_per_segment",)
# why, in words (measured, twenty-first session: station design --from refuses bias_step against
# temperature_bias on the step capture with its extension recorded: the closest 12 segments leave
# accel_bias_tempco_z's 1-sigma 3.1 x its target, correlation 0.96; against bias_drift likewise)
TIMELINE_WHY = ("each follows the capture's clock or its temperature, and every segment added after the capture "
                "comes later and warmer alike (the table has no chamber to set the temperature apart from the "
                "time), so station design --from finds no segments that separate them")
# pairs no segments separate (measured: station design --from refuses them with what stays
# furthest; words.aliases says why): no command is printed for them.  An offset per axis group and
# a vibration once per revolution: separated in the fifteenth session by turns about the capture's
# axes with the table axis vertical, where no vibration was modelled; since the sixteenth the
# vibration is modelled there too, and a vibration's part turning with the platter is an offset's
# constant at every rate and elevation (station/model/table_vibration.py; the designer refuses:
# docs/design.md, sixteenth session)
NOT_SEPARABLE: tuple = ({"rotation_axis_offsets", "table_vibration_once_per_rev"},)
TIME_OFFSET = "time_offset"     # revealed by turns whose ramp is recorded (separations)


def added(effect_id: str, registry=None) -> str:
    """What ``--add`` needs to find ``effect_id`` in a new command: its id for the library's and
    an installed package's effects, the plugin's own spec (``/abs/path/file.py:Class``,
    ``module:Class``) for one loaded from a file or module, which a new command would not know."""
    from station.model.unlisted import UNLISTED

    if effect_id in UNLISTED and (registry is None or effect_id not in registry):
        # kept outside the library's ranking (diagnose --auto may add one): its importable spec
        return f"station.model.unlisted:{UNLISTED[effect_id].__name__}"
    if registry is None:
        return effect_id
    try:
        source = registry.source(effect_id)
    except KeyError:
        return effect_id
    if source == "library" or source.startswith("entry point"):
        return effect_id
    where, _, cls = source.rpartition(":")
    path = Path(where)
    if path.suffix == ".py" and path.is_file():
        return f"{path.resolve()}:{cls}"
    return source


def imported(capture) -> str | None:
    """What ``capture`` (a Capture, as read) was imported from, when it is not a capture of
    ``station run`` (no run.yaml beside it) nor a dry run's: ``station design --from`` designs
    segments that ``station run --append`` records into the capture, which it does only into a
    run's (its configuration, scheme and table are the run's), so it refuses such a capture
    (sequential.extend, the same rule) and diagnose prints no command for it.  Before, the
    designer took the built-in simulated bench's table for it and proposed segments on a table
    the user may not have, into a capture nothing could append to (issue 28, eighteenth session:
    imucal's session)."""
    if (Path(capture.path) / "run.yaml").is_file() or isinstance(capture.extra.get("simulation"), dict):
        return None
    source = capture.extra.get("import")
    source = source.get("from") if isinstance(source, dict) else None
    return str(source) if isinstance(source, str) and source else "outside station run"


def hand_turns(capture) -> list[str]:
    """The complete rotations of ``capture`` (a Capture, as read) without a table's angle and rate
    (turned by hand, or an encoder that did not report): ``station design --from`` weighs table
    segments against the capture's own and refuses such a capture (sequential.extend, the same
    rule), so no command is printed for it."""
    return [seg.name for seg in capture.complete() if seg.kind == "rotation" and not (seg.rate_dps and seg.angle_deg)]


def suggest_all(first, final, steps, capture, summaries, registry=None) -> None:
    """What diagnose says beside its findings, set on the diagnoses it shows (the first and the
    final, each once) and on --auto's steps; ``capture`` the Capture the diagnosis read (its
    manifest is not read again)."""
    hand = hand_turns(capture)
    source = None if hand else imported(capture)
    for d in {id(first): first, id(final): final}.values():
        suggest(d, capture.path, registry, summaries=summaries, hand=hand, source=source)
    no_command = bool(hand or source)
    if not no_command:
        suggest_steps(steps, capture.path, summaries, registry)
    # the effects outside the library a warm-up scheme is blind to, when this capture is (unrevealed.py)
    from station.diagnose import unrevealed

    final.not_revealed = [u.text + ("" if no_command else unrevealed.after(u, capture.path, command))
                          for u in unrevealed.find(final, summaries)]


def command(capture, effects, reveal, registry=None) -> str:
    """station design --from CAPTURE --add E ... --reveal P1,P2,... -o extension.yaml"""
    adds = "".join(f" --add {shlex.quote(added(e, registry))}" for e in effects)
    return (f"station design --from {shlex.quote(str(capture))}{adds} --reveal {','.join(reveal)} "
            "-o extension.yaml")


def separate_command(capture, effects, a: str, b: str, registry=None) -> str:
    """station design --from CAPTURE --add E ... --separate A,B -o extension.yaml: A and B named
    as --add names them (a plugin by its file), so that the command works as printed."""
    adds = "".join(f" --add {shlex.quote(added(e, registry))}" for e in effects)
    pair = shlex.quote(f"{added(a, registry)},{added(b, registry)}")
    return f"station design --from {shlex.quote(str(capture))}{adds} --separate {pair} -o extension.yaml"


def separations(capture, model_effects, effect_id: str, summaries, registry=None) -> list[str]:
    """For each library effect this capture cannot tell ``effect_id`` from (words.aliases), the
    command that designs the segments that would: ``effect_id`` in the model (with the model's
    own effects), the rival added by the designer."""
    from station.diagnose.words import aliases

    effects = [e for e in model_effects if e not in BASE and e != "discovered_terms" and e not in NOT_DESIGNED]
    if effect_id not in effects:
        effects.append(effect_id)
    if effect_id in NOT_DESIGNED:
        return []
    if effect_id == TIME_OFFSET and summaries.rotations and not any(
            getattr(r, "record_ramp", None) for r in summaries.rotations):
        # its aliases have no effect for a rival (the gyro scale, the mounting offset): the turns
        # with their ramp recorded that reveal it (station design --from: candidates with
        # record_ramp: start, issue 28 item 3)
        return [command(capture, effects, [TIME_OFFSET], registry)]
    return [separate_command(capture, effects, effect_id, rival, registry)
            for rival, _ in aliases(summaries, effect_id)
            if rival is not None and rival != effect_id and rival not in NOT_DESIGNED
            and {effect_id, rival} not in NOT_SEPARABLE]


def suggest_steps(steps, capture, summaries, registry=None) -> None:
    """Set ``separations`` on every step of --auto whose added effect this capture cannot tell
    from a library effect (its caveats): the station design --from ... --separate commands."""
    for st in steps:
        if st.discovered:
            continue
        st.separations = separations(capture, st.after.effects, st.added, summaries, registry)
        # the library effects --auto found to explain the step's misfit as well (auto.Step.rivals)
        named = {_pair_of(x)[1] for x in st.separations}
        effects = [e for e in st.after.effects if e not in BASE and e != "discovered_terms" and e not in NOT_DESIGNED]
        for rival in getattr(st, "rivals", None) or []:
            if added(rival, registry) in named:
                continue
            if (rival in NOT_DESIGNED or st.added in NOT_DESIGNED or {st.added, rival} in NOT_SEPARABLE
                    or (st.added in TIMELINE and rival in TIMELINE)):
                st.caveats.append(f"no segments of this table are designed to separate {st.added} from {rival}: "
                                  + (TIMELINE_WHY if st.added in TIMELINE and rival in TIMELINE else
                                     "no added segment shares their parameters (docs/design.md, Limits)"))
                continue
            st.separations.append(separate_command(capture, effects, st.added, rival, registry))


def suggest(diagnosis, capture, registry=None, summaries=None, hand=(), source=None) -> None:
    """Set ``suggestion`` on every candidate the capture cannot reveal (no parameter it can
    size, or parameters aliased with the model's) and ``design_suggestions`` on the diagnosis
    for the model's own parameters it left not revealed (held by their priors); ``registry``:
    where the effects came from, so that a plugin's is named by its file (added()).  ``hand``:
    the rotations turned by hand (hand_turns), ``source``: what the capture was imported from
    (imported): no command, but why."""
    model_effects = [e for e in diagnosis.effects if e not in BASE and e != "discovered_terms"]
    if source and not hand:
        hidden = list(getattr(diagnosis.result.model, "unobservable", None) or [])
        diagnosis.design_suggestions = ([f"not revealed by this capture: {', '.join(hidden)}"] if hidden else []) + [
            f"no `station design --from` command: this capture was imported ({source}), and `station run "
            "--append` records extra segments only into a capture of `station run`; design a scheme for your "
            "table (`station design --config station.yaml --add EFFECT --criterion 'worst:PARAMS' --duration S`) "
            "and record it with `station run`, or record more attitudes and turns by hand"]
        return
    if hand:        # turned by hand (hand_turns): no command, but why
        hidden = list(getattr(diagnosis.result.model, "unobservable", None) or [])
        diagnosis.design_suggestions = ([f"not revealed by this capture: {', '.join(hidden)}"] if hidden else []) + [
            f"no `station design --from` command: {', '.join(hand)} turned without a table's angle and rate "
            "(by hand), and the designer weighs a table's segments against the capture's own; design a "
            "table scheme with `station design`, or record more attitudes and turns by hand"]
        return
    alike = alike_candidates(diagnosis.candidates)
    for c in diagnosis.candidates:
        blind = list(c.aliased) if c.dof else list(c.names)
        if blind and c.names and not c.advice.startswith("cannot be tested"):
            c.suggestion = command(capture, model_effects + [c.effect], blind, registry)
        if c.significant:
            said = separations(capture, model_effects, c.effect, summaries, registry) if summaries is not None else []
            named = {_pair_of(x)[1] for x in said}
            effects = [e for e in model_effects if e not in NOT_DESIGNED]
            effects += [] if c.effect in effects else [c.effect]
            said += [separate_command(capture, effects, c.effect, other, registry)
                     for other in alike.get(c.effect, []) if other not in named
                     and not (c.effect in TIMELINE and other in TIMELINE)
                     and {c.effect, other} not in NOT_SEPARABLE]
            c.separations = said
            c.alike = [o for o in alike.get(c.effect, []) if c.effect in TIMELINE and o in TIMELINE]
    lines = []
    hidden = list(getattr(diagnosis.result.model, "unobservable", None) or [])
    if hidden:
        lines.append(f"not revealed by this capture: {', '.join(hidden)}; the fewest segments that reveal them: "
                     f"{command(capture, model_effects, hidden, registry)}")
    diagnosis.design_suggestions = lines


def _pair_of(cmd: str) -> tuple:
    """(A, B) of a --separate command; ("", "") for a --reveal one (the time offset's)."""
    words = shlex.split(cmd)
    if "--separate" not in words:
        return "", ""
    a, _, b = words[words.index("--separate") + 1].rpartition(",")
    return a, b


def alike_candidates(candidates) -> dict:
    """{effect: [other effects]} of the significant candidates that this capture cannot tell
    apart, whoever wrote them (a plugin as the library): their one-step signatures (the change
    each would make to the whitened residuals, outside the model: core.Candidate.signature_rows)
    alike to ALIAS_COS, and their difference, the chi2 by which the data would prefer one, not
    significant (below the 1 % point of chi2 with the smaller one's degrees of freedom, after the
    over-dispersion the statistics are divided by).  Alike alone is not enough: with two rates a
    scale asymmetry and a |w|^3 term are alike to 0.97 on a misfit of chi2 10^4, yet the 600 by
    which one explains it better tells them apart."""
    import numpy as np
    from scipy.special import chdtri     # chi2.isf, without scipy.stats' import (~0.5 s)

    sig = [c for c in candidates if c.significant and c.signature_rows is not None and c.dof
           and c.effect not in NOT_DESIGNED]
    out: dict = {}
    for i, a in enumerate(sig):
        for b in sig[i + 1:]:
            u, v = np.ravel(a.signature_rows), np.ravel(b.signature_rows)
            if u.shape != v.shape:
                continue
            den = float(np.linalg.norm(u) * np.linalg.norm(v))
            if not den > 0 or abs(float(u @ v)) / den < ALIAS_COS:
                continue
            apart = float(np.sum((u - v) ** 2)) / max(a.overdispersion, b.overdispersion, 1.0)
            if apart < chdtri(min(a.dof, b.dof), 0.01):
                out.setdefault(a.effect, []).append(b.effect)
                out.setdefault(b.effect, []).append(a.effect)
    return out


# ------------------------------------------------------------------ the words, screen and page alike

def design_lines(diagnosis) -> list[str]:
    """The ``design:`` lines of a diagnosis: the model's own parameters not revealed and the
    effects outside the library the capture is blind to (unrevealed.py), each with its command."""
    return ([f"design: {line}" for line in getattr(diagnosis, "design_suggestions", None) or []]
            + [f"design: {line}" for line in getattr(diagnosis, "not_revealed", None) or []])


def rival_of(cmd: str) -> str:
    """B of a ``--separate A,B`` command ("" for a --reveal one: the time offset's)."""
    return _pair_of(cmd)[1]


def candidate_lines(diagnosis) -> list[str]:
    """Beside each candidate the capture cannot reveal or tell from another, the command that
    designs the segments that would (or why there is none)."""
    lines = []
    for c in diagnosis.candidates:
        if getattr(c, "suggestion", ""):
            lines.append(f"{c.effect}: the fewest segments that reveal it: {c.suggestion}")
        for cmd in getattr(c, "separations", None) or []:
            lines.append(separation_line(c.effect, cmd))
        others = list(getattr(c, "alike", None) or [])
        if others:
            lines.append(f"{c.effect}: this capture cannot tell it from {', '.join(others)} (they explain the misfit "
                         f"alike); no segments of this table are designed to separate them: {TIMELINE_WHY}")
    return lines


def step_lines(step) -> list[str]:
    """Under a step of --auto: the commands that separate its added effect from a rival."""
    return [f"caveat: the fewest segments that separate {step.added} from {rival_of(cmd)}: {cmd}" if rival_of(cmd)
            else f"caveat: {separation_line(step.added, cmd)}" for cmd in getattr(step, "separations", None) or []]


def separation_line(effect: str, cmd: str) -> str:
    """What diagnose prints beside an alias and its command: a pair's --separate, or the time
    offset's --reveal (its rivals are no effect: the gyro scale, the mounting offset)."""
    rival = rival_of(cmd)
    if rival:
        return f"{effect}: this capture cannot tell it from {rival}; the fewest segments that separate them: {cmd}"
    return (f"{effect}: this capture's turns keep one steady rate in their windows, so a time offset shows only "
            f"through their rate ripple, alike with the gyro scale and the mounting offset's tangential term; the "
            f"fewest turns with their ramp recorded that reveal it: {cmd}")


def all_lines(first, steps, final) -> list[str]:
    """Every line diagnose prints about what the capture cannot reveal or separate, in the order
    the screen shows them (the first diagnosis, its candidates, the steps, the final), each once:
    what the report page lists (issue 28)."""
    lines = design_lines(first) + candidate_lines(first)
    for st in steps:
        lines += step_lines(st)
    if final is not None and final is not first:
        lines += design_lines(final)
    return list(dict.fromkeys(lines))
