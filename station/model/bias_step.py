"""bias_step: biases that jump once during the run, at a time the capture locates."""
from __future__ import annotations

import numpy as np

from station.core import units
from station.model.effect import Effect, Param

MIN_SIDE = 2            # segments on each side of a candidate step time


class BiasStep(Effect):
    id = "bias_step"
    title = "Accelerometer and gyro biases that step once during the run (per axis, time located)"
    physics = ("A bias can jump rather than wander: a knock or a shift of the IMU in its fixture, a "
               "connector or solder joint that settles, a change of the sensor's operating mode or of its "
               "supply; after the jump the new bias stays.  The time of the jump is not a parameter of the "
               "fit: it is located by a profile over the boundaries between segments (the score test's chi2 "
               "drop at each candidate time, the largest kept; its p-value corrected for the candidates "
               "tried), because a step inside a segment cannot be told from one at its edges by segment "
               "means.")
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
    state_fields = ("step_time_s", "located_by", "origin_s")

    def __init__(self):
        self.step_time_s = None        # s, in the fit's clock; None: not located yet
        self.located_by = ""
        self.origin_s = 0.0            # the fit's clock's zero on the capture's clock (its first segment's mean time)

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

    def setup(self, summaries) -> None:
        mids = [x.t_mid_s for x in (*summaries.statics, *summaries.rotations) if np.isfinite(x.t_mid_s)]
        self.origin_s = float(min(mids)) if mids else 0.0
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

    def notes(self):
        if self.located_by.startswith("not located"):
            return (f"bias_step: the step's time was {self.located_by}; station diagnose --auto locates it",)
        return (f"bias_step: the step's time (t = {self.step_time_s + self.origin_s:.1f} s on the capture's clock, "
                f"{self.step_time_s:.1f} s from its first segment's mean time) {self.located_by}",)

    @property
    def params(self):
        return (tuple(Param(f"accel_bias_step_{a}", "ug", 1.0, 100.0, 1e5) for a in "xyz")
                + tuple(Param(f"gyro_bias_step_{a}", "deg/h", 1.0, 10.0, 1e4) for a in "xyz"))

    def _after(self, ctx):
        t = ctx.column("t_s")
        step = 0.0 if self.step_time_s is None else self.step_time_s
        return (np.where(np.isfinite(t), t, -np.inf) >= step).astype(float)[:, None]

    def accel(self, x, ctx):
        return self._after(ctx) * x[:3] * units.UG_MPS2

    def gyro(self, x, ctx):
        return self._after(ctx) * x[3:] / 3600.0

    def words(self, x, sigma) -> list[str]:
        """The step in words: "gyro z bias steps by +X °/h at t = Y s"."""
        out = []
        for k, (sensor, unit) in enumerate((("accelerometer", "µg"), ("gyro", "°/h"))):
            for i, a in enumerate("xyz"):
                j = 3 * k + i
                if abs(x[j]) > 3 * sigma[j]:
                    out.append(f"{sensor} {a} bias steps by {x[j]:+.3g} ± {sigma[j]:.2g} {unit} at t = "
                               f"{self.step_time_s + self.origin_s:.0f} s")
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
            out.append(f"the step is as likely at the boundary {alt['before']} -> {alt['after']} (chi2 only "
                       f"+{alt['chi2_more']:.1f}): the two times differ only on {names}, whose own free parameters "
                       f"(a rotation pair's Earth-rate component along its axis takes an offset the gyro about that "
                       f"axis has in both directions; a static's attitude takes part of an accelerometer's) absorb "
                       f"the step; this capture cannot say whether the bias jumped before or after {names}: record "
                       f"{between[0]} again later in the run (or a static with that axis vertical before and after "
                       f"it) to separate them")
        return out
