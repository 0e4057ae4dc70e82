"""The motion of one table axis: piecewise profiles in deg, deg/s, deg/s².

A plan is a list of segments, each valid from its start time to the next one's.  Commands
replace the segments after the time they arrive and keep the past, so the IMU twin can
evaluate any recent instant.  Segments:

* ``poly``: constant acceleration,  p = p0 + v0 tau + a tau²/2;
* ``ripple``: constant rate with ripple, ``world.rate_profile`` (rho, f, phase) plus p0;
* ``settle``: after a position move, a damped overshoot decaying onto the target,
  e = A exp(-sigma tau) (cos w tau + sigma/w sin w tau)  (zero rate at tau = 0).

Moves are time-optimal under the rate and acceleration limits (trapezoid or triangle),
starting from any state (braking first when moving away from the target or too fast).
"""
from __future__ import annotations

import collections
import math
from dataclasses import dataclass

import numpy as np

from sim_devices import world


@dataclass(frozen=True)
class Segment:
    t0: float
    kind: str                   # poly | ripple | settle
    p0: float = 0.0
    v0: float = 0.0
    a: float = 0.0
    # ripple: rate, fraction, frequency, phase; settle: amplitude, sigma, omega
    w: float = 0.0
    rho: float = 0.0
    f: float = 1.0
    phase: float = 0.0
    amp: float = 0.0
    sigma: float = 1.0
    omega: float = 1.0

    def eval(self, t):
        tau = np.asarray(t, dtype=float) - self.t0
        if self.kind == "poly":
            return (self.p0 + self.v0 * tau + 0.5 * self.a * tau * tau,
                    self.v0 + self.a * tau, np.full_like(tau, self.a))
        if self.kind == "ripple":
            th, thd, thdd = world.rate_profile(tau, 0.0, self.w, self.rho, self.f, self.phase)
            return self.p0 + th, thd, thdd
        s, w, A = self.sigma, self.omega, self.amp
        e = np.exp(-s * tau)
        c, si = np.cos(w * tau), np.sin(w * tau)
        p = self.p0 + A * e * (c + s / w * si)
        v = -A * e * (s * s / w + w) * si
        acc = -A * e * (s * s / w + w) * (w * c - s * si)
        return p, v, acc


class AxisMotion:
    """One axis's plan.  Times in device s; positions unwrapped (deg)."""

    def __init__(self, *, ripple_fraction: float = 0.0, ripple_hz: float = 1.0,
                 settle_s: float = 1.0, overshoot_deg_per_dps: float = 2e-4, rng=None):
        self.segments: list[Segment] = [Segment(-1e9, "poly")]
        self.ripple_fraction = ripple_fraction
        self.ripple_hz = ripple_hz
        self.settle_s = settle_s
        self.overshoot = overshoot_deg_per_dps
        self.rng = rng if rng is not None else np.random.default_rng(0)
        #: (command time, time from which the axis is in its final state: at the goal and
        #: settling, at the demanded rate, at rest), device s, for the last 10,000 commands
        self.history: collections.deque = collections.deque(maxlen=10000)

    # ------------------------------------------------------------------ evaluation
    def state(self, t: float) -> tuple[float, float, float]:
        p, v, a = self.eval(np.array([t]))
        return float(p[0]), float(v[0]), float(a[0])

    def eval(self, t):
        t = np.asarray(t, dtype=float)
        starts = np.array([s.t0 for s in self.segments])
        idx = np.searchsorted(starts, t, side="right") - 1
        p, v, a = np.empty_like(t), np.empty_like(t), np.empty_like(t)
        for i in np.unique(idx):
            m = idx == i
            p[m], v[m], a[m] = self.segments[i].eval(t[m])
        return p, v, a

    def prune(self, before_t: float) -> None:
        """Forget segments that ended before ``before_t``."""
        while len(self.segments) > 1 and self.segments[1].t0 < before_t:
            self.segments.pop(0)

    # ------------------------------------------------------------------ planning
    def _replace_from(self, t: float, new: list[Segment]) -> None:
        keep = [s for s in self.segments if s.t0 < t]
        self.segments = keep + new
        self.history.append((t, new[-1].t0))

    def plan_position(self, t: float, goal_deg: float, vmax: float, amax: float) -> None:
        """Move to the unwrapped position ``goal_deg``, then settle and hold."""
        p, v, _ = self.state(t)
        segs, t, p, v = self._brake_if_needed(t, p, v, goal_deg, amax, vmax)
        d = goal_deg - p
        if abs(d) > 1e-12:
            s = math.copysign(1.0, d)
            u = abs(v)
            # overshoot by amp, then settle back: position and rate stay continuous
            peak = min(vmax, math.sqrt(amax * abs(d) + 0.5 * u * u))
            amp = s * min(0.01, self.overshoot * peak) if self.settle_s > 0 else 0.0
            D = abs(d) + abs(amp)
            vp = math.sqrt(amax * D + 0.5 * u * u)
            if vp <= vmax:
                t_acc, t_cruise = (vp - u) / amax, 0.0
            else:
                vp = vmax
                t_acc = (vmax - u) / amax
                d_acc = (vmax * vmax - u * u) / (2 * amax)
                t_cruise = max(0.0, (D - d_acc - vmax * vmax / (2 * amax)) / vmax)
            for dur, acc in ((t_acc, s * amax), (t_cruise, 0.0), (vp / amax, -s * amax)):
                if dur > 0:
                    segs.append(Segment(t, "poly", p, v, acc))
                    p, v, t = p + v * dur + 0.5 * acc * dur * dur, v + acc * dur, t + dur
            if amp:     # the last segment: decays onto the goal for ever
                segs.append(Segment(t, "settle", goal_deg, amp=amp, sigma=5.0 / self.settle_s,
                                    omega=2 * math.pi * 2.0))
                self._replace_from(segs[0].t0, segs)
                return
        segs.append(Segment(t, "poly", goal_deg, 0.0, 0.0))
        self._replace_from(segs[0].t0, segs)

    def plan_rate(self, t: float, rate_dps: float, amax: float) -> None:
        """Reach ``rate_dps`` at ``amax``, then turn at it (with the ripple, if any)."""
        p, v, _ = self.state(t)
        segs = []
        dv = rate_dps - v
        if abs(dv) > 0:
            dur = abs(dv) / amax
            acc = math.copysign(amax, dv)
            segs.append(Segment(t, "poly", p, v, acc))
            p, t = p + v * dur + 0.5 * acc * dur * dur, t + dur
        if self.ripple_fraction > 0 and rate_dps != 0.0:
            phase = float(self.rng.uniform(0, 2 * math.pi))
            segs.append(Segment(t, "ripple", p, w=rate_dps, rho=self.ripple_fraction,
                                f=self.ripple_hz, phase=phase))
        else:
            segs.append(Segment(t, "poly", p, rate_dps, 0.0))
        self._replace_from(segs[0].t0, segs)

    def plan_stop(self, t: float, amax: float) -> None:
        """Brake at ``amax`` to rest and hold there."""
        p, v, _ = self.state(t)
        segs = []
        if v != 0.0:
            dur = abs(v) / amax
            acc = -math.copysign(amax, v)
            segs.append(Segment(t, "poly", p, v, acc))
            p, t = p + v * dur + 0.5 * acc * dur * dur, t + dur
        segs.append(Segment(t, "poly", p, 0.0, 0.0))
        self._replace_from(segs[0].t0, segs)

    @staticmethod
    def _brake_if_needed(t, p, v, goal, amax, vmax):
        """Segments bringing (p, v) to a state from which a single accelerate-cruise-brake
        profile reaches ``goal``: brake to rest when moving away or unable to stop in time,
        slow to ``vmax`` when faster."""
        segs = []
        if v == 0.0:
            return segs, t, p, v
        d = goal - p
        stop_dist = v * abs(v) / (2 * amax)
        if v * d < 0 or abs(stop_dist) > abs(d) + 1e-12:
            dur = abs(v) / amax
            acc = -math.copysign(amax, v)
            segs.append(Segment(t, "poly", p, v, acc))
            return segs, t + dur, p + v * dur + 0.5 * acc * dur * dur, 0.0
        if abs(v) > vmax:
            dur = (abs(v) - vmax) / amax
            acc = -math.copysign(amax, v)
            segs.append(Segment(t, "poly", p, v, acc))
            return segs, t + dur, p + v * dur + 0.5 * acc * dur * dur, math.copysign(vmax, v)
        return segs, t, p, v
