"""Sequential design (issue 28 item 3): the fewest extra segments that reveal what a capture
left undetermined, or separate two effects it could not tell apart, on the capture's own table
and with the capture's own fitted noise.

The capture's segments (its manifest: attitudes, rotation axes, rates, lengths, elevations) are
candidates already chosen; the table's candidates (station/design/candidates.py, the table of
the run's own configuration, run.yaml) are the ones that may be added.  The information of
both comes from one computation (station/design/information.py: the estimator's Jacobian of
their noiseless captures, weighted with the capture's noise), so a proposal is scored exactly
as `station design` scores a design:

- ``--reveal P``: every named effect parameter's predicted 1σ at most ``fraction`` (default
  0.5) of its typical size.  The estimator calls a parameter revealed when its 1σ is below its
  typical size (lsq._blind_effect_parameters); the factor 2 of margin covers what this
  prediction leaves out (the capture's own rotations get axis nuisances of their own here, the
  information is taken at the simulator's truth, not the capture's fit);
- ``--separate A,B``: both effects in the model, every parameter of each revealed as above, and
  no correlation between a parameter of A and one of B above ALIAS_COS (0.95, diagnose's alias
  threshold, station/diagnose/terms.py).

The search: the single candidate that meets the goal in the least table time, if there is one;
else greedily the candidate that brings the worst ratio (1σ over its target; a correlation
over ALIAS_COS) down the most per second, until met; then each chosen one is dropped when the
goal holds without it (fewest), and each is exchanged for a shorter one that keeps it (least
time).  Then the estimator's own fit of the capture's segments plus the extension (designer.
predict) checks the proposal: a named parameter it still calls not revealed makes the search
go on (the next best candidate added), so what is written is what `station estimate` will say.

Effects in the time and the temperature (bias_drift, a bias step, temperature_bias, ...; twentieth
session): the capture's segments are informed at their times and recorded temperatures on the
capture's clock, the extension's after the capture's end (CaptureTimeline), and the estimator's
check is the fit at those times and temperatures; a bias step is located in the capture as the
estimator locates it (locate_step), every added segment after it.
"""
from __future__ import annotations

import fnmatch
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from station.core.errors import UserError

ALIAS_COS = 0.95          # diagnose's (station/diagnose/terms.py): this alike are aliases
DEFAULT_FRACTION = 0.5    # target 1σ as a fraction of the parameter's typical size (module doc)
MAX_SEGMENTS = 12         # the most rotation pairs / statics an extension proposes
CHECK_ROUNDS = 4          # the estimator's check sends the search on at most this often
# effects whose parameters the recorded segments decide and that no candidate shares: a placement
# per segment, a step's time.  An offset per axis group (rotation_axis_offsets) is designed: the
# capture's groups keep theirs, a candidate about one of the capture's axes shares its group's (an
# appended rotation is a group of its own for its gravity angle, not for its offset:
# station.model.axis_offsets.offset_groups), a candidate about a new axis has its own, eliminated
# with the group's nuisances (information.py).  The bench's effects of a table axis
# or a rate (table_wobble: one lean per table axis; table_vibration_once_per_rev: one per table axis
# and rate) are designed: a candidate about the same table axis, or at the same rate, shares them
# (information.column_names), one at a new rate brings its own
PER_SEGMENT_EFFECTS = ("remount_per_segment",)
# a bias step's time is located in the capture (locate_step, as the estimator locates it) and every
# segment added after the capture's end is after it (information.information's first_times;
# twentieth session: it was refused with the per-segment effects)
STEP = "bias_step"
# a time offset is seen only where the rate changes within a segment's window (time_offset: the
# gyro integral moves by dt (w_end - w_start)); a steady turn's window has none (the compiler ramps
# before it and brakes after it), so with a time offset in the model the candidates include turns
# whose ramp up is recorded (record_ramp: start, issue 28 item 3; candidates.candidate_set)
TIME_OFFSET = "time_offset"


# an offset per axis group and a vibration once per revolution: turns appended about the capture's
# own axes share its offsets (station.model.axis_offsets.offset_groups).  A level turn at the
# capture's rate about its axis brings the same vibration and offset again; the information credits
# it with what a different start angle of the table would show (the vibration's phase is the table
# angle's), which the estimator's fit of the appended capture did not confirm (predicted 1σ of the
# vibration unchanged, 0.073 mg: docs/design.md, fifteenth session).  Since the vibration is
# modelled about a vertical axis too (sixteenth session) no segment separates the pair and diagnose
# names it without a command (suggest.NOT_SEPARABLE); asked by hand, the designer still searches the
# vertical turns only: measured on the vibration case's capture (benchmarks/alias_separation.py), with
# every candidate in the pool the search proposed turns the estimator's check then did not confirm
# ("does not confirm the proposal", exit 2, 10.6 s of CPU), with the vertical ones only it says no
# segment separates them and what stays furthest (exit 2, 11.6 s): the rule stays for that answer
OFFSETS_VIBRATION = ("rotation_axis_offsets", "table_vibration_once_per_rev")
# a vibration once per revolution's parameters to reveal (--reveal, what diagnose prints for its part
# along the axis: diagnose.core.TILT_ALIKE): no turn about an axis the capture turned
# about already (at its elevation).  The IMU turns with the platter, so the vibration's phase (the
# platter's angle) keeps its relation to the case there whatever the table's start angle; its part
# along the axis is a first harmonic of the accelerometer along it, what a tilt of the turn's axis in
# the accelerometers' frame gives (g x the tilt), which the gyros' misalignments and the inter-triad
# alignment take (docs/design.md, twenty-first session: nine statics and turns about x, y, z at
# 100 deg/s, a 1 mg vibration along the axis is 0.002 +/- 0.0998 mg, the gyro misalignments 300
# arcsec off).  The information credits such a turn with a new start angle, which the estimator
# does not confirm (measured: one more turn about x proposed, "does not confirm the proposal");
# turns about other axes (the diagonals) do: 0.872 +/- 0.012 mg for cos 30 deg of 1 mg.  (--separate
# goals keep every candidate: their extensions were confirmed by the estimator as they are, e.g.
# tests/test_alias_bench.py's, which this rule changed)
VIBRATION_PREFIX = "table_vibration"
SAME_AXES = ("table_vibration_once_per_rev: no turn about an axis this capture turned about already (the IMU turns "
             "with the platter: such a turn shows the vibration along its axis as this capture's turns did, alike "
             "with a tilt of the turn's axis that the gyros' misalignments take)")


def _direction(axis) -> tuple:
    """A rotation axis as a unit direction up to its sign (rounded: a key)."""
    a = np.asarray(axis, float)
    a = a / np.linalg.norm(a)
    k = int(np.flatnonzero(np.abs(a) > 1e-9)[0])
    return tuple(np.round(a * np.sign(a[k]), 6))
VERTICAL_ONLY = ("rotation_axis_offsets and table_vibration_once_per_rev: only turns about a vertical axis are "
                 "candidates (a level turn about the capture's own axes shares its offsets and brings its vibration "
                 "again)")


@dataclass
class Extension:
    capture: str
    goal: str                       # in words
    names: list                     # the targeted parameters
    before: dict                    # name -> 1σ (reported unit) by the estimator on the capture alone
    after: dict                     # name -> 1σ with the extension
    revealed_before: dict
    revealed_after: dict
    units: dict
    entries: list                   # the scheme file's segments
    text: str                       # the scheme file
    duration_s: float               # the extension's compiled time (moves, settling, ramps included)
    segment_s: list                 # each entry's table time (time model)
    correlation_after: float | None = None   # --separate: the largest |corr| between A's and B's, after
    correlation_before: float | None = None
    noise: object = None
    notes: list = field(default_factory=list)
    searched: dict = field(default_factory=dict)   # name -> 1σ the search's information gives the extension


def capture_scheme(capture):
    """The capture's complete segments as a Scheme (attitudes, axes, rates, lengths,
    elevations from its manifest)."""
    from station.io.scheme import RECORD_RAMPS, RotationSpec, Scheme, StaticSpec

    rate_hz = float(capture.imu.sample_rate_hz)
    specs = []
    for seg in capture.complete():
        samples = float(seg.extra.get("samples") or 0)
        if seg.kind == "static" and seg.up_body is not None:
            specs.append(StaticSpec(seg.name, tuple(float(x) for x in seg.up_body), max(samples / rate_hz, 1.0)))
        elif seg.kind == "rotation" and seg.axis_body is not None and seg.rate_dps and seg.angle_deg:
            angle = abs(seg.angle_deg) if seg.angle_deg else samples / rate_hz * abs(seg.rate_dps)
            ramp = seg.extra.get("record_ramp") if seg.extra.get("record_ramp") in RECORD_RAMPS else None
            if ramp:        # the turn at the rate only (the ramp's angle, rate^2 / 2a, is the spec's own)
                accel = seg.extra.get("ramp_accel_dps2")
                accel = float(accel) if isinstance(accel, (int, float)) and not isinstance(accel, bool) \
                    and accel > 0 else math.inf
                angle = max(angle - seg.rate_dps ** 2 / (2.0 * accel), 1.0)
            specs.append(RotationSpec(seg.name, tuple(float(x) for x in seg.axis_body), float(seg.rate_dps),
                                      angle / abs(seg.rate_dps),
                                      axis_elevation_deg=float(seg.extra.get("axis_elevation_deg", 0.0) or 0.0),
                                      record_ramp=ramp))
    if not any(s.kind == "static" for s in specs):
        raise UserError(f"{capture.path}: no complete static segment with an attitude (up_body): nothing "
                        "to design from")
    centred = isinstance(capture.extra.get("mounting"), dict) and "offset_m" in capture.extra["mounting"]
    return Scheme(capture.scheme or "capture", "the capture's segments", "", {}, tuple(specs), centred=centred)


def capture_sessions(capture) -> dict:
    """{segment name: N} of the capture's complete segments recorded by its N-th ``run --append``
    (the manifest's ``appended: N``); the run's own segments are not listed.  The estimator gives
    an extension's rotations axis groups of their own (summaries: one per body axis and session),
    so the design's model of the capture must too (information.model_of)."""
    out = {}
    for seg in capture.complete():
        n = seg.extra.get("appended", 0)
        if isinstance(n, int) and not isinstance(n, bool) and n > 0:
            out[seg.name] = n
    return out


def capture_groups(base, sessions: dict) -> list:
    """The unit axis of each axis group of the capture, in the estimator's numbering (summaries:
    a new group for each body axis and elevation in each session -- the run, then every ``run
    --append`` -- in the order the rotations come).  The offsets per axis group (rotation_axis_offsets) are
    named by these numbers (axis<g>_offset_*; an appended turn about a line the run turned about
    shares that group's offset and has no name of its own: axis_offsets.offset_groups)."""
    from station.estimate.table_geometry import same_elevation

    axes = []                      # (unit axis, session, elevation)
    for spec in base.segments:
        if spec.kind == "rotation":
            a = np.asarray(spec.axis_body, float) / np.linalg.norm(spec.axis_body)
            n = sessions.get(spec.name, 0)
            e = float(spec.axis_elevation_deg)
            if not any(s == n and same_elevation(e, f) and np.allclose(a, b, atol=1e-6) for b, s, f in axes):
                axes.append((a, n, e))
    return [a for a, _, _ in axes]


def capture_config(path: Path, config_path: str | None):
    """The table the capture was recorded on: --config if given, else the run's own
    configuration (run.yaml), else the configuration station finds ($STATION_CONFIG,
    ./station.yaml) or the built-in simulated bench's (a dry run's capture: extend refuses an
    imported one, suggest.imported)."""
    from station.bench.config import find_config, from_dict, load_config
    from station.core import yaml_text

    if config_path:
        return load_config(config_path), f"the table of {config_path}"
    run_file = path / "run.yaml"
    if run_file.is_file():
        try:
            doc = yaml_text.safe_load(run_file.read_text())
        except (OSError, ValueError) as e:
            raise UserError(f"{run_file}: cannot read it: {e}") from None
        if isinstance(doc, dict) and isinstance(doc.get("config"), dict):
            return from_dict(doc["config"], str(run_file)), f"the run's table ({run_file})"
    found = find_config(None)
    return load_config(None), (f"the table of {found} (a dry run's capture: no run.yaml in it)" if found is not None
                               else "the built-in simulated bench's table (a dry run's capture: no run.yaml in it)")


def _blind_names(result) -> set:
    from station.estimate import lsq

    names, index, _, _ = lsq._reported_index(result, "m/s^2", "deg/s")
    rank = set(int(c) for c in result.rank_deficient)
    return set(result.model.unobservable) | {n for n, c in zip(names, index) if int(c) in rank}


def extend(capture_path, effects: list, *, reveal=(), separate=(), config_path=None,
           fraction: float = DEFAULT_FRACTION, rates_dps=None, revolutions=None, dwells_s=None,
           name: str = "extension", command: str = "", progress=None) -> Extension:
    """The extension (module doc).  ``effects``: the model (Effect instances), with the two to
    separate among them; ``reveal``: fnmatch patterns of effect parameters; ``separate``: two
    effect ids."""
    from dataclasses import replace

    from station.bench.compile import compile_scheme
    from station.design import candidates as cand_mod
    from station.design import noise as noise_mod
    from station.design.designer import _segments_of, geometry_of, predict, scheme_text
    from station.design.information import UNIT_DWELL_S, information
    from station.design.search import Candidate, Criterion, Scorer, State
    from station.io.capture import read_capture
    from station.io.scheme import Scheme

    say = progress or (lambda text: None)
    path = Path(capture_path)
    capture = read_capture(path, load_data=False)
    if bool(reveal) == bool(separate):
        raise UserError("--from: give --reveal PARAMS or --separate A,B (one of them)")
    per_segment = [e.id for e in effects if e.id in PER_SEGMENT_EFFECTS]
    if per_segment:
        raise UserError(f"--from: {', '.join(per_segment)} has parameters of its own per segment (set from the "
                        "segments recorded) that no added segment shares, so segments to add cannot be weighed for "
                        "it; what separates it is said beside it in station diagnose")
    from station.diagnose.suggest import hand_turns, imported       # the rules diagnose's commands follow

    hand = hand_turns(capture)
    if hand:
        raise UserError(f"{path}: {', '.join(hand)} turned without a table's angle and rate (by hand): station "
                        "design --from weighs a table's segments against the capture's own, and a hand turn has "
                        "none to weigh; design a table scheme with station design, or record more attitudes and "
                        "turns by hand")
    table_doc = capture.extra.get("table") if isinstance(capture.extra.get("table"), dict) else {}
    if "axes" not in table_doc and "no table" in str(table_doc.get("note", "")):
        raise UserError(f"{path}: recorded by hand, without a rate table: station design --from designs segments "
                        "for a table (record the extra attitudes by hand with a hand scheme)")
    source = imported(capture)
    if source:
        raise UserError(f"{path}: imported ({source}), not a capture of station run: station design --from designs "
                        "segments that station run --append records into a run's capture; design a scheme for "
                        "your table with station design --config station.yaml (--add, --criterion "
                        "'worst:PARAMS', --duration) and record it with station run, or record more attitudes "
                        "and turns by hand")
    config, table_source = capture_config(path, config_path)
    base = capture_scheme(capture)
    sessions = capture_sessions(capture)          # a capture extended before: its extensions' segments
    # effects in the time (bias_drift): the capture's own segments informed at their times on the
    # capture's clock, the extension's after its end (CaptureTimeline; twentieth session)
    timed = any(hasattr(e, "time_shear") for e in effects)
    stepped = any(e.id == STEP for e in effects)
    # effects in the temperature's difference from a reference: the capture's segments at their
    # recorded temperatures, the extension's at the simulated IMU's after the capture's end
    # (CaptureTimeline; not with a chamber: its levels are the candidates' own)
    tempered = _temperature_referenced(effects) and getattr(config, "chamber", None) is None
    summaries = None
    if timed or stepped or tempered:
        from station.estimate.summaries import summarise

        summaries = summarise(capture)
        _one_clock(path, summaries)
    noise = noise_mod.from_capture(path, summaries)
    if stepped:
        say("locating the bias step in the capture (as station estimate does)")
        locate_step(capture, effects)
    # --- the candidates: the capture's own segments first (chosen), then the table's
    table = cand_mod.Table(config)
    cands, chunks, notes, masks = cand_mod.candidate_set(
        table, rates_dps or cand_mod.DEFAULT_RATES_DPS, revolutions or cand_mod.DEFAULT_REVOLUTIONS,
        dwells_s or cand_mod.DEFAULT_DWELLS_S, ramps=any(e.id == TIME_OFFSET for e in effects))
    own_chunk, own, own_segments = [], [], []
    for spec in base.segments:
        own_segments.append(spec.name)
        if spec.kind == "static":
            own_chunk.append((("capture", spec.name), replace(spec, dwell_s=UNIT_DWELL_S)))
            own.append(Candidate(("capture", spec.name, spec.dwell_s), "static", 0.0, dwell_s=spec.dwell_s,
                                 slot=("capture", spec.name)))
        else:
            # its own axis group (conservative: the estimator may merge it with a new rotation's)
            key = (("capture",) + tuple(spec.axis_body), spec.axis_elevation_deg, spec.name)
            own_chunk.append((key, (spec,)))
            own.append(Candidate(key, "rotation", 0.0, axis=key[:2]))
    if stepped:           # where the step was located, which the design takes as known
        notes += [f"{n}; every added segment comes after it; the design takes the step's time as known there (the "
                  f"estimate counts its uncertainty too: a step of a few σ gets a larger 1σ than predicted here)"
                  for e in effects if e.id == STEP for n in e.notes()]
    say(f"the information of the capture's {len(own)} segments and of {len(cands)} candidates on "
        f"{table_source}")
    first_times = None
    if stepped:                 # the capture's own segments at their times: which are after the step
        # (and their spans: a static is informed at another dwell, UNIT_DWELL_S, than its own,
        # and the step may fall inside it: bias_step.sample_share)
        first_times = {x.name: (float(x.t_mid_s), float(x.duration_s))
                       for x in (*summaries.statics, *summaries.rotations) if np.isfinite(x.t_mid_s)}
    info = information([own_chunk] + chunks, effects, noise, config, geometry_of(config), base.centred,
                       appended=sessions, times=timed, first_times=first_times, timeline=tempered)
    all_cands = own + cands
    masks_all = [0] * len(own) + list(masks)
    names = info.parameters.names
    units = info.parameters.units
    typical = info.parameters.typical
    # the parameters the capture's own model has (a bench effect's table axes and rates: those it
    # turned at); a candidate at a new rate brings parameters of its own, nuisances here
    own_names = set(info.chunk_parameters[0])
    # --- the goal
    if reveal:
        targets = sorted({i for p in reveal for i, n in enumerate(names)
                          if n in own_names and fnmatch.fnmatchcase(n, p)})
        missing = [p for p in reveal if not any(fnmatch.fnmatchcase(n, p) for n in names if n in own_names)]
        if missing:
            raise UserError(f"--reveal: no parameter of this model matches {', '.join(missing)} (its effect "
                            f"parameters: {', '.join(names[21:]) or 'none: add the effect with --add'})")
        base_named = [names[i] for i in targets if not math.isfinite(typical[i])]
        if base_named:
            raise UserError(f"--reveal: {', '.join(base_named)} belong to the base model, which every capture "
                            "with rotations determines: name effect parameters (e.g. accel_position_*)")
        group_a = group_b = np.zeros(0, int)
        goal = f"reveal {', '.join(names[i] for i in targets)} (1σ at most {fraction:g} x their typical size)"
    else:
        ids = [e.id for e in effects]
        a, b = separate
        of = info.parameters.effects
        for x in (a, b):
            if x not in ids:
                raise UserError(f"--separate: {x} is not in the model ({', '.join(ids)})")
        # each effect's parameters as the capture's segments set them up (a bench effect's table
        # axes and rates: those the capture turned at)
        group_a, group_b = (np.array([i for i, n in enumerate(names) if of[i] == x and n in own_names], int)
                            for x in (a, b))
        for x, g in ((a, group_a), (b, group_b)):
            if not len(g):
                raise UserError(f"--separate: {x} has no parameter this capture's segments can show (e.g. a "
                                "table effect of rotations about a vertical axis only)")
        targets = sorted(set(group_a.tolist()) | set(group_b.tolist()))
        goal = (f"separate {a} from {b} (every parameter of each with 1σ at most {fraction:g} x its typical "
                f"size, no correlation between them above {ALIAS_COS})")
    targets = np.array(targets, int)
    scorer = Scorer(info, all_cands, Criterion("worst"), targets)
    n_own = len(own)
    placed = (CaptureTimeline(scorer, all_cands, own_segments, summaries, masks_all, config, noise,
                              _unsummarised_end(capture, summaries))
              if (timed and scorer.shear) or stepped or scorer.temperature_timed else None)

    def place(added) -> None:
        """Every candidate at its time (CaptureTimeline.place): nothing without effects in the time."""
        if placed is not None:
            placed.place(added)
    # the goal as rows over the reported parameters: each target itself, but an offset per axis
    # group (rotation_axis_offsets) by its component across both its axis and the first group's --
    # the part along its axis is seen by no segment (w x (w x d) and dw/dt x d are across w), the
    # part along the first group's trades with the common offset's, which no turn sees; both are
    # held by the estimator's prior, so they are neither targets nor "not revealed" (_goal_rows)
    T, row_limit, side, prior, along = _goal_rows(names, targets, typical, fraction, info,
                                                  capture_groups(base, sessions), group_a, group_b)

    def badness(F) -> float:
        """Above 1 while the goal is not met: the worst 1σ over its target, or a correlation
        between the two effects over ALIAS_COS (as a ratio)."""
        cov = T @ scorer.covariance_of(F + prior) @ T.T
        sig = np.sqrt(np.clip(np.diag(cov), 0.0, None))
        worst = float(np.max(sig / row_limit))
        if len(group_a):
            corr = _cross_correlation(cov, np.flatnonzero(side == 1), np.flatnonzero(side == 2))
            worst = max(worst, corr / ALIAS_COS)
        return worst

    def worst_of(F) -> str:
        """What stays furthest from the goal, in words (the refusal's)."""
        cov = T @ scorer.covariance_of(F + prior) @ T.T
        ratio = np.sqrt(np.clip(np.diag(cov), 0.0, None)) / row_limit
        k = int(np.argmax(ratio))
        what = " + ".join(names[j] for j in np.flatnonzero(T[k]))
        text = f"{what}'s 1σ {ratio[k]:.2g} x its target"
        if len(group_a):
            corr = _cross_correlation(cov, np.flatnonzero(side == 1), np.flatnonzero(side == 2))
            text += f", the largest correlation between the two {corr:.2f}"
        return text

    secs = np.array([c.seconds for c in all_cands])

    def allowed(chosen, j) -> bool:
        c = all_cands[j]
        for i in chosen:
            o = all_cands[i]
            if c.slot and o.slot == c.slot:
                return False
            if c.kind == "rotation" and o.kind == "rotation" and o.axis[0] == c.axis[0] and o.axis != c.axis:
                return False
        return j not in chosen

    pool = range(n_own, len(all_cands))
    if reveal and any(names[i].startswith(VIBRATION_PREFIX) for i in targets):
        own_axes = {(_direction(o.axis[0][1:]), o.axis[1]) for o in own if o.kind == "rotation"}
        kept = [j for j in pool if not (all_cands[j].kind == "rotation"
                                        and (_direction(all_cands[j].axis[0]), all_cands[j].axis[1]) in own_axes)]
        if len(kept) < len(pool):
            pool = kept
            notes.append(SAME_AXES)
    if set(separate) == set(OFFSETS_VIBRATION):
        pool = [j for j in pool if all_cands[j].kind == "rotation" and all_cands[j].axis[1] == 90.0]
        notes.append(VERTICAL_ONLY)
    say(f"searching for the fewest segments ({goal})")

    def state(added) -> State:
        """The capture's segments and ``added``, every candidate placed on the capture's timeline
        for them (place: the next one after them)."""
        place(added)
        return State(scorer, list(range(n_own)) + list(added))

    def kept(candidate, added):
        """On the timeline: ``candidate`` placed and judged so; (its state, it, True) where it keeps
        the goal, else (``added`` placed again, ``added``, False)."""
        trial = state(candidate)
        if badness(trial.information()) <= 1.0:
            return trial, candidate, True
        return state(added), added, False

    def search(forced=()) -> list:
        st = state(forced)
        added = list(forced)
        if not forced:          # one candidate alone, the shortest that does it
            ok = [j for j in pool if allowed(st.chosen, j) and badness(st.information(add=(j,))) <= 1.0]
            if ok:
                best = min(ok, key=lambda j: secs[j])
                state([best])
                return [best]
        current = badness(st.information())
        while current > 1.0 and len(added) < MAX_SEGMENTS:
            best, best_gain, best_v = None, 0.0, current
            for j in pool:
                if not allowed(st.chosen, j):
                    continue
                v = badness(st.information(add=(j,)))
                gain = (math.log(current) - math.log(max(v, 1e-300))) / secs[j]
                if v < current and gain > best_gain:
                    best, best_gain, best_v = j, gain, v
            if best is None:
                break
            added.append(best)
            if placed is None:
                st.add(best)
                current = best_v
            else:               # the others after it now
                st = state(added)
                current = badness(st.information())
        if current > 1.0:
            state(added)
            return added
        for i in list(reversed(added)):          # fewest: drop what is not needed
            if len(added) > 1 and badness(st.information(remove=(i,))) <= 1.0:
                rest = [j for j in added if j != i]
                if placed is None:
                    st.remove(i)
                    added = rest
                    continue
                # (on the timeline: the others move up without it, so judged again placed so)
                st, added, _ = kept(rest, added)
        for k, i in enumerate(list(added)):      # least time: a shorter one that keeps the goal
            rest = st.chosen - {i}
            better = [j for j in pool if secs[j] < secs[i] and allowed(rest, j)
                      and badness(st.information(remove=(i,), add=(j,))) <= 1.0]
            for j in sorted(better, key=lambda j: secs[j]):
                changed = added[:k] + [j] + added[k + 1:]
                if placed is None:
                    st.remove(i)
                    st.add(j)
                    added = changed
                    break
                st, added, ok = kept(changed, added)
                if ok:
                    break
        state(added)
        return added

    times = placed.own_times if placed is not None else None
    temps = placed.own_temps if placed is not None and scorer.temperature_timed else None
    before = _aligned(predict(base, effects, noise, config, appended=sessions, times=times, temperatures=temps),
                      names)
    if (badness(state(()).information()) <= 1.0
            and all(before.revealed[i] or i in along for i in targets)):
        # the capture's own segments meet the goal already (by the information and by the
        # estimator's own fit of them): the fewest segments are none, and none is proposed
        corr = _cross_correlation(before.covariance, group_a, group_b) if len(group_a) else None
        tnames = [names[i] for i in targets]
        said = (f"the capture's own segments already {goal.split(' (')[0]}: no extra segment is needed "
                "(the predicted 1-sigma below; station diagnose --auto on the capture decides between them)")
        return Extension(str(path), goal, tnames, {n: float(before.sigma[i]) for n, i in zip(tnames, targets)},
                         {n: float(before.sigma[i]) for n, i in zip(tnames, targets)},
                         {n: True for n in tnames}, {n: True for n in tnames},
                         {names[i]: units[i] for i in targets}, [], "", 0.0, [], corr, corr, noise,
                         notes + [said])
    added = search()
    for _ in range(CHECK_ROUNDS):
        if not added:
            raise UserError(f"{path}: no candidate segment on this table can {goal.split(' (')[0]}")
        reached = badness(state(added).information())
        entries, specs = _segments_of(added, all_cands, [0] * n_own + list(masks))
        ext = Scheme(name, "extension designed by station design --from", "docs/design.md", {}, tuple(specs),
                     centred=base.centred)
        more = _renamed(ext.segments, base)
        whole = Scheme(base.name, "", "", {}, base.segments + more, centred=base.centred)
        # (the extension's segments as run --append records them: its rotations axis groups of
        # their own for the estimator, an offset per axis group the capture's about the same axis)
        # (a capture extended before: this is its next extension, the manifest's appended: N + 1)
        following = max(sessions.values(), default=0) + 1
        if placed is not None:          # the capture's segments at their times, the extension's after its end
            times = {**placed.own_times, **placed.segment_times(added, [x.name for x in more])}
            if scorer.temperature_timed:
                temps = {**placed.own_temps, **placed.segment_temperatures(added, [x.name for x in more])}
        after = _aligned(predict(whole, effects, noise, config,
                                 appended={**sessions, **{s.name: following for s in more}}, times=times,
                                 temperatures=temps), names)
        searched = scorer.sigma(list(range(n_own)) + added)
        blind = [names[i] for i in targets if not after.revealed[i] and i not in along]
        if reached <= 1.0 and not blind:
            break
        if reached > 1.0:
            raise UserError(f"{path}: no {MAX_SEGMENTS} segments this table can do {goal.split(' (')[0]} "
                            f"(the closest: {worst_of(state(added).information())})")
        notes.append(f"the estimator still called {', '.join(blind)} not revealed with {len(added)} "
                     "segment(s): one more added")
        extra = [j for j in pool if allowed(set(range(n_own)) | set(added), j)]
        st = state(added)
        best = min(extra, key=lambda j: badness(st.information(add=(j,))))
        added = search(forced=added + [best])
    else:
        raise UserError(f"{path}: the estimator does not confirm the proposal for {goal.split(' (')[0]}")
    plan = compile_scheme(ext, config)
    cov_after = after.covariance
    corr_after = corr_before = None
    if len(group_a):
        corr_after = _cross_correlation(cov_after, group_a, group_b)
        corr_before = _cross_correlation(before.covariance, group_a, group_b)
    tnames = [names[i] for i in targets]
    ext_entries = _renamed_entries(entries, base)
    header = [f"{name}: extra segments for the capture {path} designed by `station design --from`",
              f"goal: {goal}",
              f"compiled time of the extension: {plan.duration_s:.0f} s on {table_source}",
              f"noise: the capture's fitted noise: accel {noise.accel_noise_ug:.4g} ug/rtHz, gyro "
              f"{noise.gyro_noise_dph:.4g} deg/h/rtHz, table angle {noise.table_angle_arcsec:.3g} arcsec",
              f"record into the same capture: station run --append {path} --scheme THIS_FILE",
              "predicted 1-sigma (the estimator's fit of the capture's segments, then with these):"]
    for i in targets:
        header.append(f"  {names[i]}: {before.sigma[i]:.4g} -> {after.sigma[i]:.4g} {units[i]}"
                      + ("" if before.revealed[i] else " (not revealed before)"))
    if corr_after is not None:
        header.append(f"  largest |correlation| between {separate[0]} and {separate[1]}: "
                      f"{corr_before:.3f} -> {corr_after:.3f}")
    if command:
        header.append(f"made by: {command}")
    text = scheme_text(name, ext_entries, header, base.centred)
    return Extension(str(path), goal, tnames,
                     {names[i]: float(before.sigma[i]) for i in targets},
                     {names[i]: float(after.sigma[i]) for i in targets},
                     {names[i]: bool(before.revealed[i]) for i in targets},
                     {names[i]: bool(after.revealed[i]) for i in targets},
                     {names[i]: units[i] for i in targets}, ext_entries, text, plan.duration_s,
                     [_entry_s(table, e) for e in ext_entries], corr_after, corr_before, noise,
                     notes + list(plan.notes), {names[i]: float(searched[i]) for i in targets})


class CaptureTimeline:
    """Where every candidate of station design --from is recorded in time, for the effects in the
    time (bias_drift; information.Information.time_shear; twentieth session): the capture's own
    segments at their mean sample times on the capture's clock (its summaries' t_mid_s, as the
    estimator reads them), the extension's after the capture's end -- from its last sample (half a
    sample after it), the configured warm-up of a resumed run (station.yaml ``warmup:``, as
    ``run --append`` waits it: dryrun.warmup_seconds(resumed=True) on the simulated IMU), then its
    segments in the written order on the simulated bench's clock (timeline.seconds_timeline: the
    gap before each segment, its samples), as ``station run --sim --append`` records them; a
    candidate not chosen where it would be recorded next, after the chosen ones.  The reference
    is the estimator's, the mean time of every static (the capture's and the extension's).
    Before, each candidate was informed at its time in the candidates' own simulated capture (and
    the capture's segments in theirs), with a reference of its own chunk."""

    def __init__(self, scorer, cands, own_names, summaries, masks, config, noise, last_sample_s=None):
        from station.design import timeline
        from station.design.information import quiet_truth, ramp_accel_of
        from station.simulate import dryrun

        self.scorer, self.cands, self.masks = scorer, cands, masks
        self.n_own = len(own_names)
        truth = quiet_truth(noise, config)          # (information.Information.clock's)
        self.clock = (float(truth.bench.move_s + truth.bench.settle_s), float(truth.sample_rate_hz),
                      ramp_accel_of(config))
        mids = {x.name: float(x.t_mid_s) for x in (*summaries.statics, *summaries.rotations)
                if np.isfinite(x.t_mid_s)}
        ends = [float(x.t_mid_s) + 0.5 * float(x.duration_s) for x in (*summaries.statics, *summaries.rotations)
                if np.isfinite(x.t_mid_s) and np.isfinite(x.duration_s)]
        fs = float(summaries.sample_rate_hz)
        self.own_times = {n: mids[n] for n in own_names if n in mids}
        self.own = [mids.get(n) for n in own_names]
        # the recorded temperatures (each segment's mean), and the simulated IMU's warm-up going on
        # from the newest of them (its temperature model, shifted to meet it: IMUShifted)
        recorded = {x.name: float(x.temp_c) for x in (*summaries.statics, *summaries.rotations)
                    if x.temp_c is not None and np.isfinite(x.temp_c)}
        self.own_temps = {n: recorded[n] for n in own_names if n in recorded}
        self.own_t = [recorded.get(n) for n in own_names]
        self.temperature = None
        if recorded and scorer.temperature_timed:
            newest = max(recorded, key=lambda n: mids.get(n, -math.inf))
            model = scorer.info.temperature
            self.temperature = _Shifted(model, recorded[newest] - float(model.at(np.array([mids[newest]]))[0]))
        if last_sample_s is not None:       # (a segment the summaries leave out: an aborted one's samples)
            ends.append(float(last_sample_s))
        end = (max(ends) if ends else 0.0) + 0.5 / fs
        warmup = config.warmup if config is not None else None
        self.start_s = end + (dryrun.warmup_seconds(warmup, truth.temperature, end, resumed=True)
                              if warmup is not None else 0.0)
        gap, rate = self.clock[:2]
        accel = self.clock[2] if len(self.clock) > 2 else None
        self.lengths = [timeline.segment_seconds(c, accel) if i >= self.n_own else []
                        for i, c in enumerate(cands)]
        # each candidate's mean time recorded first from 0, and the time it takes with its gaps
        self.first = {}
        self.span = {}
        for i in range(self.n_own, len(cands)):
            self.first[i] = float(timeline.seconds_timeline([self.lengths[i]], None, self.clock)[1][0])
            self.span[i] = sum(gap + max(1, int(round(x * rate))) / rate for x in self.lengths[i])

    def sequence(self, added) -> list:
        """The added candidates in the order the extension is written (designer._segments_of's)."""
        from station.design import timeline

        return timeline.written_order(list(added), self.cands, self.masks)

    def times(self, added) -> dict:
        """{candidate index: its time on the capture's clock, s} (class doc)."""
        from station.design import timeline

        seq = self.sequence(added)
        out = {i: t for i, t in enumerate(self.own) if t is not None}
        if seq:
            mids = timeline.seconds_timeline([self.lengths[i] for i in seq], None, self.clock,
                                             start_s=self.start_s)[1]
            out.update({i: float(t) for i, t in zip(seq, mids)})
        end = self.start_s + sum(self.span[i] for i in seq)
        chosen = set(seq)
        for i in self.first:
            if i not in chosen:
                out[i] = end + self.first[i]
        return out

    def temperatures(self, added) -> dict:
        """{candidate index: its mean temperature, degC} (class doc): the capture's recorded, the
        extension's on the simulated IMU's warm-up after the capture (self.temperature)."""
        from station.design import timeline

        seq = self.sequence(added)
        out = {i: v for i, v in enumerate(self.own_t) if v is not None}
        if self.temperature is None:
            return out
        if seq:
            temps = timeline.seconds_timeline([self.lengths[i] for i in seq], self.temperature, self.clock,
                                              start_s=self.start_s)[0]
            out.update({i: float(v) for i, v in zip(seq, temps)})
        end = self.start_s + sum(self.span[i] for i in seq)
        chosen = set(seq)
        rest = [i for i in self.first if i not in chosen]
        for i in rest:        # (each as if recorded next)
            out[i] = float(timeline.seconds_timeline([self.lengths[i]], self.temperature, self.clock, start_s=end)[0][0])
        return out

    def place(self, added) -> None:
        """Every candidate's information at its time and temperature less the references
        (Scorer.set_temperatures; nothing without an effect in the time or the temperature: a
        bias step's candidates are all after it)."""
        sc = self.scorer
        if not (sc.shear or sc.temperature_timed):
            return
        chosen = set(range(self.n_own)) | set(added)
        dt_s = dt_c = None
        if sc.shear:
            t = self.times(added)
            statics = [t[i] for i in chosen if i in t and self.cands[i].kind == "static"]
            reference = float(np.mean(statics)) if statics else 0.0
            dt_s = {i: v - reference for i, v in t.items()}
        if sc.temperature_timed:
            T = self.temperatures(added)
            statics = [T[i] for i in chosen if i in T and self.cands[i].kind == "static"]
            reference = float(np.mean(statics)) if statics else 0.0
            dt_c = {i: v - reference for i, v in T.items()}
        sc.set_temperatures(dt_c or {}, dt_s)

    def segment_temperatures(self, added, names) -> dict:
        """{segment name: mean temperature} of the extension's segments (segment_times')."""
        from station.design import timeline

        seq = self.sequence(added)
        lengths = [[x] for i in seq for x in self.lengths[i]]
        temps = timeline.seconds_timeline(lengths, self.temperature, self.clock, start_s=self.start_s)[0]
        return {n: float(t) for n, t in zip(names, temps)}

    def segment_times(self, added, names) -> dict:
        """{segment name: mean sample time} of the extension's segments (``names``: in the order
        written, a rotation pair's two), as the estimator's summaries would have them."""
        from station.design import timeline

        seq = self.sequence(added)
        lengths = [[x] for i in seq for x in self.lengths[i]]
        mids = timeline.seconds_timeline(lengths, None, self.clock, start_s=self.start_s)[1]
        if len(mids) != len(names):
            raise ValueError("the extension's segments and their times do not match")
        return {n: float(t) for n, t in zip(names, mids)}


def _unsummarised_end(capture, summaries):
    """The last stamp of the segments the summaries leave out (an incomplete one: a segment aborted
    by a pause or a failure; the bench's clock went on through its samples, and an extension
    recorded next comes after them, as dryrun.append_scheme and the sequencer record it), or None
    (review of the twentieth session)."""
    summarised = {x.name for x in (*summaries.statics, *summaries.rotations)}
    last = []
    for seg in capture.segments:
        if seg.name in summarised:
            continue
        try:
            data = capture.read_samples(seg, warnings=[])
        except Exception:           # (what is wrong with it is said where it is read for the estimate)
            continue
        if data is not None and len(data.t) and np.isfinite(data.t[-1]):
            last.append(float(data.t[-1]))
    return max(last) if last else None


def _one_clock(path, summaries) -> None:
    """UserError when two segments of the capture overlap in time on its clock (one clock never
    records two at once): an IMU's own clock restarted between two sessions (switched off and
    on), the sessions interleaved on it -- an extension recorded next goes on from the newest
    session's clock, not after the largest stamp, and a drift or a step has no timeline to be
    placed on (review of the twentieth session).  (Segments listed out of time order without
    overlapping, as an import may list them, are not refused.)"""
    segs = sorted((x for x in (*summaries.statics, *summaries.rotations)
                   if np.isfinite(x.t_mid_s) and np.isfinite(x.duration_s)), key=lambda x: x.t_mid_s)
    half = 0.5 / float(summaries.sample_rate_hz)
    for a, b in zip(segs, segs[1:]):
        if b.t_mid_s - 0.5 * b.duration_s < a.t_mid_s + 0.5 * a.duration_s - half:
            first, later = (a, b) if a.index < b.index else (b, a)
            raise UserError(f"{path}: the capture's clock went back: {later.name} (recorded after {first.name}) "
                            f"overlaps it in time ({b.t_mid_s - 0.5 * b.duration_s:.1f} s, before "
                            f"{a.t_mid_s + 0.5 * a.duration_s:.1f} s: the IMU restarted between sessions?): the "
                            "effects in the time cannot be placed on it")


class _Shifted:
    """A temperature model T(t) moved by ``offset`` degC (CaptureTimeline.temperature)."""

    def __init__(self, model, offset: float):
        self.model, self.offset = model, float(offset)
        self.start_c = getattr(model, "start_c", 0.0)

    def at(self, t, air=None):
        return self.model.at(t) + self.offset


def _temperature_referenced(effects) -> bool:
    """Effects in the temperature's difference from a reference, and no other that needs the
    temperature (information.temperature_powers' condition)."""
    from station.model.temperature import TemperatureReferenced

    needs = [e for e in effects if "temperature" in getattr(e, "needs", ())]
    return bool(needs) and all(isinstance(e, TemperatureReferenced) for e in needs)


def locate_step(capture, effects) -> None:
    """A bias step's time (bias_step in ``effects`` not located yet) located in ``capture`` as
    station estimate locates it (station.estimate: the profile of the score test at the fit
    without it, station/estimate/profile.py), on the capture's fit clock."""
    import copy

    from station.estimate import lsq, profile

    pending = [e for e in effects if e.id == STEP and getattr(e, "step_time_s", 0.0) is None]
    if not pending:
        return
    summaries = lsq.summarise(capture)
    base = lsq.fit(summaries, [copy.deepcopy(e) for e in effects if e not in pending])
    for e in pending:
        profile.locate(base, e)
        e.setup(summaries)          # (its clock's origin and the spans, for its notes; the time kept)


def _entry_s(table, entry) -> float:
    """An entry's table time by the time model (candidates.Table): dwell or both directions with
    their ramps, settling and moves."""
    if "static" in entry:
        return float(table.static_s(entry["dwell_s"]))
    rate = float(entry["rate_dps"])
    return float(table.rotation_pair_s(rate, max(1, round(rate * entry["rotation_s"] / 360.0)),
                                       entry.get("record_ramp")))


def _goal_rows(names, targets, typical, fraction, info, axes, group_a, group_b):
    """(T, limits, side, prior, along): the goal's quantities as rows of T over the reported
    parameters (reported units), each row's largest 1σ, its side (1: effect A, 2: B, 0: --reveal),
    the prior information over G that holds each capture axis group's offset along its own axis
    (its typical size, as the estimator's prior holds it: without it that direction has no
    information and every other number is lost in it), and the targets that are such offsets
    with a part along their axis (the estimator calls them not revealed, rightly).  ``axes``: the
    capture's axis groups' unit axes as the estimator numbers them (capture_groups: per body axis
    and session, a capture already extended counted right; before, the groups were taken as one
    session's, and on a capture extended once the offsets' rows were of the wrong axes or the
    estimator's names refused: issue 28)."""
    import re

    in_a, in_b = set(np.asarray(group_a).tolist()), set(np.asarray(group_b).tolist())
    G = info.shared
    prior = np.zeros((G, G))
    rows, limits, side, along = [], [], [], set()
    offsets: dict = {}
    for i in targets:
        m = re.fullmatch(r"axis(\d+)_offset_([xyz])", names[i])
        if m and (info.parameters.effects or [None] * len(names))[i] == "rotation_axis_offsets" \
                and int(m.group(1)) < len(axes):
            offsets.setdefault(int(m.group(1)), {})["xyz".index(m.group(2))] = i
            continue
        r = np.zeros(len(names))
        r[i] = 1.0
        rows.append(r)
        limits.append(fraction * typical[i])
        side.append(1 if i in in_a else 2 if i in in_b else 0)
    l0 = axes[0] if axes else None
    for g, where in sorted(offsets.items()):
        if len(where) != 3:
            named = ", ".join(names[i] for i in where.values())
            raise UserError(f"--reveal {named}: name the three components of table axis group {g}'s offset "
                            f"(axis{g}_offset_*): a turn sees an offset only across its axis, so the "
                            "components are revealed together or not at all")
        l = axes[g]
        idx = [where[k] for k in range(3)]
        along |= set(idx)
        # seen: d_g + c l0 across l (c the common offset's part along the first group's axis l0,
        # which no turn sees): of d_g itself, only the direction across both l and l0
        n = np.cross(l, l0)
        if np.linalg.norm(n) > 1e-6:
            r = np.zeros(len(names))
            r[idx] = n / np.linalg.norm(n)
            rows.append(r)
            limits.append(fraction * typical[idx[0]])
            side.append(1 if idx[0] in in_a else 2 if idx[0] in in_b else 0)
        v = np.zeros(G)
        cols = info.parameters.columns[idx]
        v[cols] = l
        sigma_internal = typical[idx[0]] / info.parameters.factors[idx[0]]
        prior += np.outer(v, v) / sigma_internal ** 2
    cols = [k for k, n in enumerate(info.column_names) if n.startswith("mounting_offset[")]
    if offsets and l0 is not None and len(cols) == 3:
        # c, the common offset's part along l0, held by a prior of the offsets' typical size (the
        # directions no turn sees get the estimator's kind of prior, so that the rest is numbers)
        i = next(iter(offsets[min(offsets)].values()))
        v = np.zeros(G)
        v[cols] = l0
        prior += np.outer(v, v) / (typical[i] / info.parameters.factors[i]) ** 2
    if not rows:
        raise UserError(f"--reveal {', '.join(names[i] for i in targets)}: nothing a turn can see: the first "
                        "axis group's offset along and across its own axis is the common offset, which no "
                        "segment of this table reveals (the estimator holds it by a prior)")
    return np.array(rows), np.array(limits), np.array(side), prior, along


def _aligned(pred, names):
    """The estimator's prediction (designer.predict: its own parameters' order) in the order of
    ``names`` (the information's): a parameter that scheme has not (a rate it does not turn at)
    NaN and not revealed."""
    from types import SimpleNamespace

    at = {n: k for k, n in enumerate(pred.names)}
    k = np.array([at.get(n, -1) for n in names])
    ok = k >= 0
    sigma = np.full(len(names), np.nan)
    sigma[ok] = np.asarray(pred.sigma)[k[ok]]
    revealed = np.zeros(len(names), bool)
    revealed[ok] = np.asarray(pred.revealed)[k[ok]]
    cov = np.full((len(names), len(names)), np.nan)
    cov[np.ix_(ok, ok)] = np.asarray(pred.covariance)[np.ix_(k[ok], k[ok])]
    return SimpleNamespace(sigma=sigma, revealed=revealed, covariance=cov)


def _cross_correlation(cov, a, b) -> float:
    if not (len(a) and len(b)):
        return 0.0
    d = np.sqrt(np.clip(np.diag(cov), 1e-300, None))
    # (only the block between the two: a parameter the design leaves ~1e5 x its target overflowed
    # the whole matrix's division, a RuntimeWarning on screen; twentieth session)
    with np.errstate(over="ignore", invalid="ignore"):
        corr = cov[np.ix_(a, b)] / np.outer(d[a], d[b])
    return float(np.nanmax(np.abs(corr)))


PREFIX = "x"


def _prefix(base) -> str:
    """A prefix no segment name of the capture starts with (x1_, x2_, ...): appended segments
    never take a recorded one's name."""
    names = {s.name for s in base.segments}
    k = 1
    while any(n.startswith(f"{PREFIX}{k}_") for n in names):
        k += 1
    return f"{PREFIX}{k}_"


def _renamed(specs, base) -> tuple:
    from dataclasses import replace

    p = _prefix(base)
    return tuple(replace(s, name=p + s.name) for s in specs)


def _renamed_entries(entries, base) -> list:
    p = _prefix(base)
    out = []
    for e in entries:
        e = dict(e)
        key = "static" if "static" in e else "rotation"
        e[key] = p + e[key]
        out.append(e)
    return out
