"""The designed scheme's own timeline: the order its segments are written in, and the temperature
and the time each has when the scheme is run, so that the search informs temperature-dependent
effects at the temperatures the design gives them (station/design/information.py,
``timeline=True``), and effects in the time (bias_drift) at the times it gives them (each
candidate's mean sample time less the statics' mean: time_differences; nineteenth session).

The order is the scheme writer's (designer._segments_of): mounting by mounting as the time model
covers them, within a mounting the statics first, then the rotation pairs.  The clock is the
simulated bench's, on which the design's prediction and ``station montecarlo`` record the scheme
(sim_devices/bench.py: before each segment the bench's move and settling gap, then its samples;
a rotation pair is two segments), and the temperature at a time is the simulated IMU's
(its warm-up, sim_devices/truth.py TemperatureTruth), from the end of a configured warm-up
(station.yaml ``warmup:``: the IMU powered on at 0 warms while the station waits, the first
segment's gap after it, as the dry run waits: station.simulate.dryrun.warmup_seconds; seventeenth
session); a segment's summary carries its mean
temperature (station/estimate/summaries.py), here Simpson's rule over its samples' span (the
warm-up's curvature over a 1000 s dwell: < 1e-3 degC off the mean of its samples).  The effects'
reference is the estimator's: the mean temperature of the statics.

With a temperature chamber (station.yaml ``chamber:``; fourteenth session) a candidate has a
chamber level (``Candidate.level``: None at the room's temperature, else a setpoint): the scheme
is written level by level -- the room's first, then the setpoints in station.core.chamber.order_levels'
order -- and on the timeline each new setpoint is set at the end of the segment before it (the
simulated chamber's air ramps, sim_devices/chamber.py) and waited for as the station waits
(ChamberConfig.ramp_s + settle_estimate_s: exactly the dry run's wait for a fixed soak) before
its first segment's gap.
"""
from __future__ import annotations

import numpy as np


def level_of(c):
    """A candidate's chamber level: None (the room), or the chamber's setpoint, degC."""
    return getattr(c, "level", None)


def level_rank(levels, chamber) -> dict:
    """{level: its place in the written order}: the room (None) first, then order_levels'."""
    from station.core.chamber import order_levels

    set_points = [x for x in levels if x is not None]
    rank = {None: 0}
    if set_points:
        for k, x in enumerate(order_levels(set_points, chamber.ambient_c), 1):
            rank[x] = k
    return rank


def written_order(chosen, cands, masks=None, chamber=None, order=None) -> list:
    """The chosen candidates' indices in the order the scheme file lists them: level by level
    (a chamber's), within a level mounting by mounting, within a mounting the statics first --
    or, given ``order`` (candidate indices: the sequence the search chose, search.order_search),
    within a mounting in that order (the chosen ones it does not list after those it does, as
    above).  The levels and the mountings stay in the same order either way: an order never
    costs a chamber step or a remount more."""
    return [i for group in written_groups(chosen, cands, masks, chamber, order) for i in group]


def written_groups(chosen, cands, masks=None, chamber=None, order=None) -> list:
    """written_order in its groups: one list of candidate indices per (chamber level, mounting),
    in the written order; the search may permute a group's members (search.order_search), never
    move one across groups."""
    chosen = list(chosen)
    levels = {level_of(cands[i]) for i in chosen}
    if len(levels) > 1 or levels - {None}:
        rank = level_rank(levels, chamber)
        out = []
        for level in sorted(levels, key=lambda x: rank[x]):
            out += _mounting_groups([i for i in chosen if level_of(cands[i]) == level], cands, masks, order)
        return out
    return _mounting_groups(chosen, cands, masks, order)


def _mounting_groups(chosen, cands, masks=None, order=None) -> list:
    """Mounting by mounting, within a mounting the statics first, then the rotation pairs (or in
    ``order``'s sequence)."""
    group = cover([masks[i] for i in chosen]) if masks is not None else [0] * len(chosen)
    rank: dict = {}
    for g in group:
        rank.setdefault(g, len(rank))
    of = dict(zip(chosen, group))
    statics = [i for i in chosen if cands[i].kind == "static"]
    rotations = [i for i in chosen if cands[i].kind == "rotation"]
    statics.sort(key=lambda i: (rank[of[i]], tuple(-x for x in cands[i].key[1])))
    rotations.sort(key=lambda i: (rank[of[i]], -cands[i].key[1], tuple(-x for x in cands[i].key[0]),
                                  -cands[i].key[2], -cands[i].key[3]))
    out = sorted(statics + rotations, key=lambda i: rank[of[i]])       # (a stable sort)
    if order is not None:
        at = {i: k for k, i in enumerate(order)}
        first = {i: k for k, i in enumerate(out)}
        out.sort(key=lambda i: (rank[of[i]], at.get(i, len(at)), first[i]))
    groups: list = []
    for i in out:
        if not groups or of[groups[-1][0]] != of[i]:
            groups.append([])
        groups[-1].append(i)
    return groups


def segment_seconds(c, ramp_accel_dps2: float | None = None) -> list:
    """The recorded lengths of a candidate's segments (a static: its dwell; a rotation pair: its
    two directions, whole revolutions each; a recorded ramp's at ``ramp_accel_dps2``, the
    configured table's: the dry run's default without it)."""
    if c.kind == "static":
        return [float(c.dwell_s)]
    axis, e, rate, rev = c.key[:4]
    if len(c.key) > 4:          # a recorded ramp: the rest and the ramp at the simulated bench's acceleration
        from station.io.scheme import RAMP_REST_S
        from station.simulate.dryrun import RAMP_ACCEL_DPS2

        return [rev * 360.0 / rate + rate / (ramp_accel_dps2 or RAMP_ACCEL_DPS2) + RAMP_REST_S] * 2
    return [rev * 360.0 / rate] * 2


def mean_temperatures(sequence, cands, temperature, clock, chamber=None, start_s: float = 0.0) -> np.ndarray:
    """Each candidate's mean temperature (degC) when ``sequence`` (candidate indices, in order)
    is recorded from the bench clock's ``start_s`` (the configured warm-up's end, the IMU powered
    on at 0: information.Information.start_s): ``clock`` = (the gap before each segment, s; the
    sample rate, Hz); ``temperature.at(t)`` the IMU's temperature at bench time t; ``chamber``
    (station.core.chamber.ChamberConfig) the chamber the candidates' levels set."""
    levels = [level_of(cands[i]) for i in sequence]
    accel = clock[2] if len(clock) > 2 else None        # the recorded ramps' (information.Information.clock)
    return seconds_temperatures([segment_seconds(cands[i], accel) for i in sequence], temperature, clock,
                                levels if chamber is not None and any(x is not None for x in levels) else None,
                                chamber, start_s)


def seconds_temperatures(items, temperature, clock, levels=None, chamber=None, start_s: float = 0.0) -> np.ndarray:
    """mean_temperatures of items given as the lengths of their segments, in order (``levels``:
    each item's chamber level, None: no chamber; ``start_s``: the bench's clock at the first
    item's gap)."""
    return seconds_timeline(items, temperature, clock, levels, chamber, start_s)[0]


def mean_times(sequence, cands, clock, chamber=None, start_s: float = 0.0, temperature=None) -> np.ndarray:
    """Each candidate's time on the bench's clock when ``sequence`` is recorded (mean_temperatures'
    timeline): the mean of its segments' mean sample times (a static's one segment; a rotation
    pair's two), s -- the time the estimator's summaries give a segment (t_mid_s: the mean of its
    samples' times), which is what an effect in the time (bias_drift) reads."""
    levels = [level_of(cands[i]) for i in sequence]
    accel = clock[2] if len(clock) > 2 else None
    return seconds_timeline([segment_seconds(cands[i], accel) for i in sequence], temperature, clock,
                            levels if chamber is not None and any(x is not None for x in levels) else None,
                            chamber, start_s)[1]


def seconds_timeline(items, temperature, clock, levels=None, chamber=None, start_s: float = 0.0):
    """(mean temperatures, mean times) of items given as the lengths of their segments, in order
    (seconds_temperatures; ``temperature`` None: the times only, the temperatures nan; the time
    of an item: the mean of its segments' mean sample times, s on the bench's clock)."""
    gap, fs = clock[:2]
    dt = 1.0 / fs
    end = float(start_s)
    out = np.full(len(items), np.nan)
    mids = np.zeros(len(items))
    air, setpoint = None, None
    if levels is not None and temperature is None:
        raise ValueError("a chamber's timeline needs the temperature model (its waits)")
    if levels is not None:
        from station.simulate.dryrun import chamber_air

        air, setpoint = chamber_air(temperature.start_c), chamber.ambient_c
    for k, lengths in enumerate(items):
        if air is not None and levels[k] is not None and levels[k] != setpoint:
            air.set(end, levels[k], chamber.ramp_c_per_min)          # as the dry run: chamber_step
            end += chamber.ramp_s(setpoint, levels[k]) + chamber.settle_estimate_s(setpoint, levels[k])
            setpoint = levels[k]
        temps, weights, centres = [], [], []
        for seconds in lengths:
            n = max(1, int(round(seconds * fs)))
            a = end + gap + 0.5 * dt
            b = a + (n - 1) * dt
            end = b + 0.5 * dt
            centres.append(0.5 * (a + b))
            weights.append(n)
            if temperature is None:
                continue
            tt = np.array([a, 0.5 * (a + b), b])
            ta, tm, tb = temperature.at(tt) if air is None else temperature.at(tt, air)
            temps.append((ta + 4.0 * tm + tb) / 6.0)
        if temperature is not None:
            out[k] = float(np.average(temps, weights=weights))
        mids[k] = float(np.mean(centres))
    return out, mids


def differences(chosen, cands, temperature, clock, masks=None, chamber=None, with_reference: bool = False,
                order=None, sequence=None, start_s: float = 0.0):
    """Per chosen candidate its temperature less the effects' reference (the mean over the chosen
    statics), in the written order's timeline (``order``: written_order's; ``sequence``: the
    chosen candidates' sequence itself, as written_order gives it; ``start_s``: the bench's clock
    when the scheme starts, mean_temperatures): {index: dT, degC} (``with_reference``: and the
    reference, degC)."""
    if sequence is None:
        sequence = written_order(chosen, cands, masks, chamber, order)
    temps = mean_temperatures(sequence, cands, temperature, clock, chamber, start_s)
    statics = [t for i, t in zip(sequence, temps) if cands[i].kind == "static"]
    reference = float(np.mean(statics)) if statics else float(np.mean(temps)) if len(temps) else 0.0
    out = {i: float(t - reference) for i, t in zip(sequence, temps)}
    return (out, reference) if with_reference else out


def time_differences(chosen, cands, clock, masks=None, chamber=None, order=None, sequence=None,
                     start_s: float = 0.0, temperature=None) -> dict:
    """Per chosen candidate its time less the reference of an effect in the time (bias_drift: the
    mean time of the statics, station.model.bias_drift), in the written order's timeline (as
    differences; ``temperature``: the IMU's, needed for a chamber's waits only): {index: s}."""
    if sequence is None:
        sequence = written_order(chosen, cands, masks, chamber, order)
    times = mean_times(sequence, cands, clock, chamber, start_s, temperature)
    statics = [t for i, t in zip(sequence, times) if cands[i].kind == "static"]
    reference = float(np.mean(statics)) if statics else float(np.mean(times)) if len(times) else 0.0
    return {i: float(t - reference) for i, t in zip(sequence, times)}


def notional_times(cands, budget_s: float) -> dict:
    """Each candidate's time less the statics' mean before there is a design (notional's rule:
    the statics in the first third of the budget, the rotations in the rest), s."""
    half = 0.5 * float(budget_s)            # (the rest's middle, 2/3 B, less the first third's, B/6)
    return {i: (0.0 if c.kind == "static" else half) for i, c in enumerate(cands)}


def notional(cands, temperature, clock, budget_s: float, start_s: float = 0.0) -> dict:
    """Each candidate's temperature difference before there is a design to place it in: the
    statics in the first third of the budget (the writer lists them first), the rotations in the
    rest, the reference the statics' mean (the budget from the bench's clock ``start_s``: the
    warm-up's end).  The search then places every candidate on the design's own timeline at each
    exchange pass (search.Scorer.retime)."""
    t = float(start_s) + np.linspace(0.0, float(budget_s), 301)
    T = temperature.at(t)
    split = t <= float(start_s) + budget_s / 3.0
    static_c, rotation_c = float(np.mean(T[split])), float(np.mean(T[~split]))
    return {i: (0.0 if c.kind == "static" else rotation_c - static_c) for i, c in enumerate(cands)}


def cover(chosen_masks) -> list:
    """For each chosen candidate the mounting (bit) of the greedy cover mountings_needed counts:
    the scheme is written mounting by mounting, so that the compiler remounts as often as the
    time model says."""
    left = dict(enumerate(chosen_masks))
    out = [0] * len(chosen_masks)
    while left:
        best, best_count = 0, -1
        bit = 1
        while bit <= max(left.values()):
            count = sum(1 for m in left.values() if m & bit)
            if count > best_count:
                best, best_count = bit, count
            bit <<= 1
        for k in [k for k, m in left.items() if m & best]:
            out[k] = best
            del left[k]
    return out
