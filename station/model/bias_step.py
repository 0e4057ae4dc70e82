"""bias_step: biases that jump once during the run, at a time the capture locates."""
from __future__ import annotations

import numpy as np

from station.core import units
from station.model.effect import Effect, Param

MIN_SIDE = 2            # segments on each side of a candidate step time
INTERIOR_EDGE = 0.25    # a step inside a segment next to the statics/rotations boundary: at least this
                        #   share of that segment on the boundary's side (interior_segments)
DENSE = 720             # points per revolution a rotation's phase weights are computed from
FOURIER_ORDER = 4       # their harmonics kept (as table_encoder_scale.turned_time: exact on the 12-point grid)


class BiasStep(Effect):
    id = "bias_step"
    title = "Accelerometer and gyro biases that step once during the run (per axis, time located)"
    physics = ("A bias can jump rather than wander: a knock or a shift of the IMU in its fixture, a "
               "connector or solder joint that settles, a change of the sensor's operating mode or of its "
               "supply; after the jump the new bias stays.  The time of the jump is not a parameter of the "
               "fit: it is located by a profile (the score test's chi2 drop at each candidate time, the best "
               "fitted; its p-value corrected for the candidates tried) over the boundaries between segments "
               "and every split of each segment's samples: a step inside a static moves its mean by the share "
               "of its samples after the step, one inside a rotation the phase points' means by the share of "
               "their revolutions after it.")
    term = ("accel_raw += s_a H(t - t_step) (µg); gyro_raw += s_g H(t - t_step) (°/h); H = 1 from the step on; "
            "t the time in the run (the fit counts it from the first segment's mean time, station apply from "
            "the first sample of the data it is given: apply compensates a recording that starts where the "
            "capture started); the base biases are the ones before the step")
    excited_by = ("segments on both sides of the step in time, the same attitude (or any attitude, for the "
                  "gyro, which sees the step directly) before and after it; a step between the statics and the "
                  "rotations (all statics first, then all rotations) is aliased with an offset every rotation "
                  "shares and is not a candidate: a static after the rotations separates them")
    magnitudes = ("10-1000 µg and 1-100 °/h (MEMS after a knock or a mode change); a navigation-grade IMU "
                  "that steps is faulty")
    signature = ("every segment in time order: residuals that are about constant, jump at one boundary and stay "
                 "at the new level; the same jump on statics and rotations, on both sides of a repeated attitude")
    signature_variable = "time"
    complex_step = True
    bench = True              # ranked after the IMU's significant effects (station.diagnose.core): an
                              #   event of this capture, and the best of many boundaries can stand in for
                              #   a drift (bias_drift) or another effect in time
    bias_like = True          # its term is the biases changing from a time on: its profile's columns are
                              #   the model's bias columns after that time (station.estimate.profile)
    needs = ("time",)
    state_fields = ("step_time_s", "located_by", "origin_s", "start_s", "segment", "step_time_s_sigma")

    def __init__(self):
        self.step_time_s = None        # s, in the fit's clock; None: not located yet
        self.located_by = ""
        self.origin_s = 0.0            # the fit's clock's zero on the capture's clock (its first segment's mean time)
        self.start_s = None            # the capture's first sample on its clock (station apply's zero; None:
                                       #   a file written before issue 25's run 3: apply counts as the fit)
        self.segment = ""              # the segment the step falls inside ("": between two segments)
        self.step_time_s_sigma = None  # s: the time's 1-sigma from the fit with it free (a step inside a
                                       #   segment: station.estimate.lsq frees it, held_values); None else
        self._spans = {}               # segment index -> its span in the fit's clock (setup)
        self._weights_key = None
        self._weights = None

    # --- the step's time: candidates, and a fallback when nothing located it -------------------
    @staticmethod
    def candidate_times(summaries) -> list[tuple[float, str, str]]:
        """(time, segment before, segment after) of every boundary between consecutive segments in
        time order with MIN_SIDE segments on each side, in the fit's clock (from the earliest
        segment's mean time, as station.estimate.lsq counts t): the midpoint of the gap between
        the end of one segment and the start of the next."""
        segs = [x for x in (*summaries.statics, *summaries.rotations) if np.isfinite(x.t_mid_s)]
        if len(segs) < 2 * MIN_SIDE:
            return []
        t0 = min(x.t_mid_s for x in segs)
        segs.sort(key=lambda x: x.t_mid_s)
        statics = {id(st) for st in summaries.statics}
        static = [id(x) in statics for x in segs]
        # static[:k] is all of one kind for k <= first_change, static[k:] for k >= last_change
        # (found once: a set of each side at every k was quadratic, 80 s at 40,000 segments)
        changes = [k for k in range(1, len(segs)) if static[k] != static[k - 1]]
        first_change, last_change = (changes[0], changes[-1]) if changes else (len(segs), 0)
        out = []
        for k in range(MIN_SIDE, len(segs) - MIN_SIDE + 1):
            if k <= first_change and k >= last_change and static[0] != static[-1]:
                # statics before, rotations after (or the reverse): a step there is any offset every
                # rotation shares (a scale asymmetry, g-sensitivity at one rate); not a candidate
                # (the words say so: station.diagnose.words._time_patterns)
                continue
            a, b = segs[k - 1], segs[k]
            end_a = a.t_mid_s + 0.5 * a.duration_s
            start_b = b.t_mid_s - 0.5 * b.duration_s
            out.append((0.5 * (end_a + start_b) - t0, a.name, b.name))
        return out

    def locate(self, time_s: float, how: str) -> None:
        self.step_time_s = float(time_s)
        self.located_by = how
        self.step_time_s_sigma = None

    @staticmethod
    def segment_spans(summaries) -> list[dict]:
        """Every segment of known time, in time order, with its span in the fit's clock (from the
        earliest segment's mean time, as station.estimate.lsq counts t): first and last sample
        (mean time -+ half the span between them, as the summaries keep them), samples, and a
        rotation's encoder angle."""
        segs = [x for x in (*summaries.statics, *summaries.rotations) if np.isfinite(x.t_mid_s)]
        if not segs:
            return []
        t0 = min(x.t_mid_s for x in segs)
        out = []
        for x in sorted(segs, key=lambda q: q.t_mid_s):
            rot = not any(x is st for st in summaries.statics)
            half = 0.5 * max(float(x.duration_s), 0.0)
            out.append({"name": x.name, "index": int(getattr(x, "index", -1)), "rotation": rot,
                        "first": x.t_mid_s - t0 - half, "last": x.t_mid_s - t0 + half,
                        "samples": max(int(x.samples), 1), "angle_deg": float(getattr(x, "angle_deg", 0.0) or 0.0)})
        return out

    @classmethod
    def interior_segments(cls, summaries) -> list[dict]:
        """The segments a step may fall inside (issue 25, run 3): those with a candidate boundary
        on at least one side (MIN_SIDE segments before and after), each with the fraction of its
        samples that may lie after the step (``w_min``..``w_max``).  A step inside the segment on
        either side of the boundary that is not a candidate (all statics, then all rotations) is
        allowed only where it splits that segment by at least INTERIOR_EDGE on the boundary's side:
        a step in the last quarter of the last static (or the first of the first rotation) is,
        within the noise, the step at that boundary, i.e. any offset every rotation shares."""
        segs = cls.segment_spans(summaries)
        if len(segs) < 2 * MIN_SIDE:
            return []
        static = [not x["rotation"] for x in segs]
        n = len(segs)

        def excluded(k):      # the boundary between segs[k-1] and segs[k]
            return (len(set(static[:k])) == 1 and len(set(static[k:])) == 1 and static[0] != static[-1])

        def candidate(k):
            return MIN_SIDE <= k <= n - MIN_SIDE and not excluded(k)

        out = []
        for k, x in enumerate(segs):
            before, after = candidate(k), candidate(k + 1)
            if not (before or after) or x["samples"] < 4:
                continue
            w_min, w_max = 0.0, 1.0
            if 0 < k and excluded(k):           # the boundary before it is the statics/rotations one
                w_max = 1.0 - INTERIOR_EDGE
            if k + 1 < n and excluded(k + 1):
                w_min = INTERIOR_EDGE
            out.append({**x, "w_min": w_min, "w_max": w_max})
        return out

    def setup(self, summaries) -> None:
        mids = [x.t_mid_s for x in (*summaries.statics, *summaries.rotations) if np.isfinite(x.t_mid_s)]
        self.origin_s = float(min(mids)) if mids else 0.0
        spans = self.segment_spans(summaries)
        # the capture's first sample on its clock: station apply counts t from the first sample of
        # the data it is given, the fit from the first segment's mean time (origin_s)
        self.start_s = float(min(x["first"] for x in spans) + self.origin_s) if spans else None
        self._spans = {x["index"]: x for x in spans if x["index"] >= 0}
        self._weights_key = None
        if self.step_time_s is None:
            # not located by a profile (station.estimate.profile does that for estimate and
            # diagnose): the boundary across the longest pause, said in notes()
            cands = self.candidate_times(summaries)
            if cands:
                segs = sorted((x for x in (*summaries.statics, *summaries.rotations) if np.isfinite(x.t_mid_s)),
                              key=lambda x: x.t_mid_s)
                t0 = segs[0].t_mid_s
                gaps = [(b.t_mid_s - 0.5 * b.duration_s) - (a.t_mid_s + 0.5 * a.duration_s)
                        for a, b in zip(segs, segs[1:])][MIN_SIDE - 1:len(segs) - MIN_SIDE]
                k = int(np.argmax(gaps)) if gaps else 0
                self.locate(cands[k][0], f"not located: placed across the longest pause ({cands[k][1]} -> "
                            f"{cands[k][2]}, t = {cands[k][0] + t0:.0f} s)")
            else:
                self.locate(0.0, "not located: too few segments")

    HELD_STEP = 0.02        # the time's central difference: this share of the segment's span (clipped to it)

    def held_values(self) -> list[tuple[str, float]]:
        """(attribute, difference step) of the values the fit holds where the profile located them
        but the data determine (station.estimate.lsq frees them in the covariance): the step's time
        when it falls inside a segment (the share of that segment's samples after it, a static's
        mean or a rotation's phase points, is a continuous number the segment itself fixes; a step
        between two segments fits alike anywhere in the gap: nothing held).  The step is a share
        of the span, so that the difference sees many samples (a static's share moves by whole
        samples) and less than a revolution's harmonics' scale."""
        if not self.segment or self.step_time_s is None:
            return []
        span = next((x for x in self._spans.values() if x["name"] == self.segment), None)
        if span is None or span["last"] <= span["first"]:
            return []
        room = min(self.step_time_s - span["first"], span["last"] - self.step_time_s)
        h = min(self.HELD_STEP * (span["last"] - span["first"]), 0.5 * room)
        return [("step_time_s", h)] if h > 0 else []

    def held_covariance(self):
        """(layout blocks, matrix) added to the covariance of those blocks' parameters
        (station.estimate.lsq): the spread of the step's size and of the calibration over the
        times the capture cannot exclude (station.estimate.profile.location_spread); None when
        the step was not located by fits."""
        return getattr(self, "location_spread", None)

    def notes(self):
        if self.located_by.startswith("not located"):
            return (f"bias_step: the step's time was {self.located_by}; station diagnose --auto locates it",)
        return (f"bias_step: the step's time (t = {self.step_time_s + self.origin_s:.1f} s on the capture's clock, "
                f"{self.step_time_s:.1f} s from its first segment's mean time{self._where()}) {self.located_by}",)

    def _where(self) -> str:
        """Where the step falls, in words: "19.2 s into rotx_m (its samples from 381.0 s); 1σ range
        399.1-400.4 s" (a step inside a segment), or "" (at a boundary)."""
        if not self.segment or self.step_time_s is None:
            return ""
        span = next((x for x in self._spans.values() if x["name"] == self.segment), None)
        into = f"{self.step_time_s - span['first']:.1f} s into {self.segment}" if span else f"inside {self.segment}"
        rng = getattr(self, "time_range", None)
        if rng:
            into += f", 1σ {rng[0] + self.origin_s:.1f}-{rng[1] + self.origin_s:.1f} s"
        sigma = self.step_time_s_sigma
        if sigma is not None and np.isfinite(sigma):
            into += f" (the fit's: ±{sigma:.2g} s)"
        return "; " + into

    @property
    def params(self):
        return (tuple(Param(f"accel_bias_step_{a}", "ug", 1.0, 100.0, 1e5) for a in "xyz")
                + tuple(Param(f"gyro_bias_step_{a}", "deg/h", 1.0, 10.0, 1e4) for a in "xyz"))

    def _after(self, ctx):
        """(N,1): the share of the step each point carries.  In station apply (samples: no
        ``turned_s``) H(t - t_step) on apply's clock, from the first sample of the data it is given:
        the step's time on the capture's clock less the capture's first sample.  In the fit (points
        that stand for segments) the share of each segment's samples after the step: 0 or 1 for a
        segment wholly before or after it, the fraction of its samples after the step for a static
        the step falls in, and for a rotation's phase point the fraction of the revolutions it
        stands for whose visit of that phase comes after the step (phase_weights)."""
        t = ctx.column("t_s")
        step = 0.0 if self.step_time_s is None else self.step_time_s
        if getattr(ctx, "turned_s", None) is None:        # station apply: samples on apply's clock
            if self.start_s is not None:
                step = step + self.origin_s - self.start_s
            return (np.where(np.isfinite(t), t, -np.inf) >= step).astype(float)[:, None]
        out = (np.where(np.isfinite(t), t, -np.inf) >= step).astype(float)
        index = ctx.segment_index
        if index is None or not self._spans:
            return out[:, None]
        index = np.asarray(index, float)
        key = (float(step), index.tobytes())
        if self._weights_key == key:
            return self._weights
        for k, span in self._spans.items():
            if not span["first"] < step <= span["last"]:
                continue
            rows = np.flatnonzero(index == k)
            if not len(rows):
                continue
            if span["rotation"]:
                out[rows] = phase_weights(span, step, len(rows))
            else:
                out[rows] = sample_share(span, step)
        self._weights_key, self._weights = key, out[:, None]
        return self._weights

    # one parameter vector x (6,) or a batch X (B, 6) with a batch context (Effect.accel_batch)
    def accel(self, x, ctx):
        return self._after(ctx) * x[..., None, :3] * units.UG_MPS2

    def gyro(self, x, ctx):
        return self._after(ctx) * x[..., None, 3:] / 3600.0

    accel_batch, gyro_batch = accel, gyro

    def words(self, x, sigma) -> list[str]:
        """The step in words: "gyro z bias steps by +X °/h at t = Y s"."""
        out = []
        for k, (sensor, unit) in enumerate((("accelerometer", "µg"), ("gyro", "°/h"))):
            for i, a in enumerate("xyz"):
                j = 3 * k + i
                if abs(x[j]) > 3 * sigma[j]:
                    out.append(f"{sensor} {a} bias steps by {x[j]:+.3g} ± {sigma[j]:.2g} {unit} at t = "
                               f"{self.step_time_s + self.origin_s:.0f} s on the capture's clock"
                               f"{self._where() or ' (between two segments)'}")
        if out:
            out += self.alias_words()
        return out

    def alias_words(self) -> list[str]:
        """The boundaries the profile found as likely as the chosen one (station.estimate.profile
        sets ``alike``), with the segments between them and what would separate them: a step just
        before those segments and one just after differ only on them, and when their own free
        parameters (a rotation pair's Earth-rate component along its axis, which takes any offset
        the gyro about that axis has in both directions; a static's attitude) absorb an offset,
        the capture cannot say on which side of them the bias jumped."""
        out = []
        for alt in getattr(self, "alike", None) or []:
            between = alt.get("between") or []
            if not between:
                continue
            names = ", ".join(between)
            place = (f"inside {alt['before']}" if alt['before'] == alt['after']
                     else f"at the boundary {alt['before']} -> {alt['after']}")
            out.append(f"the step is as likely {place} (chi2 only "
                       f"+{alt['chi2_more']:.1f}): the two times differ only on {names}, whose own free parameters "
                       f"(a rotation pair's Earth-rate component along its axis takes an offset the gyro about that "
                       f"axis has in both directions; a static's attitude takes part of an accelerometer's) absorb "
                       f"the step; this capture cannot say whether the bias jumped before or after {names}: record "
                       f"{between[0]} again later in the run (or a static with that axis vertical before and after "
                       f"it) to separate them")
        return out


def sample_share(span: dict, step_s: float) -> float:
    """The fraction of a segment's samples (evenly spaced from span["first"] to span["last"]) at or
    after ``step_s``."""
    n = span["samples"]
    if n < 2 or span["last"] <= span["first"]:
        return float(step_s <= span["first"])
    h = (span["last"] - span["first"]) / (n - 1)
    before = int(np.clip(np.ceil((step_s - span["first"]) / h - 1e-9), 0, n))
    return (n - before) / n


def phase_weights(span: dict, step_s: float, phases: int) -> np.ndarray:
    """(phases,): at each point of a rotation's phase grid (phase 2 pi j / phases of the encoder's
    angle from the start), the fraction of the visits of that phase within the segment's arc that
    come at or after ``step_s`` (the table at its mean rate), as its Fourier series to
    FOURIER_ORDER, so that the grid's projection on the fit's harmonics (orders 0-2) and its mean
    (the gyro integral) are those of the dense function; each phase's fraction is weighted by its
    visits over their mean (part of a revolution: the phases visited once more count more, one the
    arc never reaches counts 0), so that the mean is the share of the samples after the step."""
    A = np.radians(span["angle_deg"])
    share = sample_share(span, step_s)
    if A == 0 or span["last"] <= span["first"]:
        return np.full(phases, share)
    turns = abs(A)
    p = 2 * np.pi * np.arange(DENSE) / DENSE
    first = p if A > 0 else np.where(p == 0, 0.0, 2 * np.pi - p)     # the first visit's |angle| turned
    n = np.floor((turns - first) / (2 * np.pi)) + 1                    # visits within the arc
    # the time of visit k at |angle| first + 2 pi k: span["first"] + duration |angle| / |A|
    dur = span["last"] - span["first"]
    k_step = (step_s - span["first"]) / dur * turns                    # |angle| turned at the step
    before = np.clip(np.ceil((k_step - first) / (2 * np.pi) - 1e-12), 0, None)
    # the visits after the step over the mean number of visits per phase: the fraction of each
    # phase's visits after it, weighted by how often the arc visits that phase, so that the mean
    # over the phases is the fraction of the samples after the step (the gyro integral's share;
    # part of a revolution more visits some phases once more than others)
    frac = np.clip(n - before, 0, None) * (n >= 1) / max(float(np.mean(np.maximum(n, 0))), 1e-12)
    grid = 2 * np.pi * np.arange(phases) / phases
    out = np.full(phases, frac.mean())
    for k in range(1, FOURIER_ORDER + 1):
        c, s = 2 * np.mean(frac * np.cos(k * p)), 2 * np.mean(frac * np.sin(k * p))
        out += c * np.cos(k * grid) + s * np.sin(k * grid)
    return out
