"""The encoder angle of a rotation whose recorded window keeps a ramp (issue 28 item 3).

A steady turn's angle is its rate read back times the frames' window (station/bench/sequencer.py):
no moment has to be placed on the IMU's clock.  A window that keeps a ramp cannot be measured
that way: its angle is the table's position at one edge of the window (where the table is at
rest: read at any moment) against its position at the other edge, where it turns at the rate.
That edge is on the IMU's clock (the first or last frame's stamp, half a period out); the table's
positions are read on the table's.  Each position read while the table turns at the rate is
placed on the IMU's clock by the frames around the read: every frame that had reached the
computer before the query was measured before the table answered, and every frame measured
before the answer had reached it when the reader was asked again afterwards (ImuStream.sync), so
the answer's moment lies between the newest stamp before (``t_before``) and the newest after
(``t_after``) plus one period; where in that bracket is said in ``placed``.  At the rate, each
read is carried to the window's edge; their mean is taken (position_at).  What is left of the placement is
not the encoder's 2": each read's moment is known only within its bracket (tens of ms on the
twins' pseudo-terminals, 10-80 ms measured), ~ms of it per window at the rate, so the window's
angle carries an uncertainty of its own (``angle_sigma``), written into the manifest
(``angle_sigma_deg``) and added to that rotation's gyro-integral variance by the estimator
(issue 28 review item 1).  The part of the placement shared by every window is what the
estimator's time offset measures: on a bench that is the IMU's clock against the table's reads as
the station placed them (the reads' latency and the reader's blocks included), not the IMU's
clock against the table's motion -- a compensation of the IMU's own time stamps must not take it
for that.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Mark:
    """One read of the turning axis: its position (deg, as the table reports it), its rate
    (deg/s) and the IMU stamps around the read (s: ``t_before`` <= the table's moment <=
    ``t_after`` + one period)."""

    position_deg: float
    rate_dps: float
    t_before: float
    t_after: float


def placed(mark: Mark, period_s: float) -> float:
    """The read's moment on the IMU's clock: the middle of its bracket, ``t_before`` ..
    ``t_after`` + one period (the answer's moment lies anywhere in it: ``angle_sigma``'s w / sqrt 12).
    Before (issue 28, fifteenth session), the newest stamp before the query plus half a period,
    because the reader thread answered the second sync only when its block of frames (0.1 s) was
    complete, which made ``t_after`` loose by up to a block (measured at --speed 1: the bracket's
    middle 43 ms after the reads).  A ramp's window reads the IMU frame by frame
    (``ImuStream.fine``), so ``t_after`` is the newest frame after the answer; what is left between
    the stamps is the host's latency on both sides of the query, and on a loaded host the moment
    lies well inside the bracket: on the twins at --speed 8 under load (brackets 0.2-1.9 s of
    device time) the stamp before placed the reads too early, the windows' angles off their gyro
    integrals by 1.3-1.5 of their 1-sigma rms (84 windows, always in that sense) and the fit's
    gyro integrals at chi2 75-666 on 11 (tests/test_ramp_twins.py, six copies at once: 1 of 6
    passed); at the middle, 0.22-0.29 rms and 6 of 6 (docs/twins.md, "Recorded ramps under load")."""
    return 0.5 * (mark.t_before + mark.t_after + period_s)


def position_at(marks: list, t: float, rate_dps: float, period_s: float) -> float | None:
    """The axis' position (deg, unwrapped about the first mark's) at IMU time ``t`` from the marks
    read while it turned at ``rate_dps``: each mark, placed on the IMU's clock (placed), carried
    to ``t`` at the rate; their mean.  None without a mark."""
    if not marks:
        return None
    return float(np.mean([p + rate_dps * (t - tm) for tm, p in _unwrapped(marks, rate_dps, period_s)]))


def _unwrapped(marks: list, rate_dps: float, period_s: float) -> list:
    """(IMU time, position unwrapped about the first mark's, deg) of each mark read while the axis
    turned at ``rate_dps``: the whole turns a mark's reading lost, restored from where the rate
    carries the first mark to its time."""
    first = marks[0]
    t0 = placed(first, period_s)
    out = []
    for m in marks:
        tm = placed(m, period_s)
        expected = first.position_deg + rate_dps * (tm - t0)
        out.append((tm, m.position_deg + 360.0 * np.round((expected - m.position_deg) / 360.0)))
    return out


def window_angle(rest_deg: float, turning_deg: float, expected_deg: float, ramp: str) -> float:
    """The table angle over the window (deg, the table axis' sense): from the rest position to the
    turning edge's (ramp "start") or from it to the rest position ("end"), the whole turns chosen
    nearest ``expected_deg`` (the compiled profile's angle: the rest, the ramp r^2 / 2a and the
    turns at the rate, far nearer than half a turn)."""
    d = (turning_deg - rest_deg) if ramp == "start" else (rest_deg - turning_deg)
    return float(d + 360.0 * np.round((expected_deg - d) / 360.0))


def expected_angle(rate_dps: float, moving_s: float, accel_dps2: float, ramp: str) -> float:
    """The angle a ramp's window holds (signed like the rate) when ``moving_s`` of it lies between
    the rate's command and the window's end (ramp "start": the ramp up is in that time, r^2 / 2a
    less than the rate's), or between the window's start and the brake's command ("end": the brake
    adds r^2 / 2a after it)."""
    ramp_deg = np.sign(rate_dps) * rate_dps ** 2 / (2.0 * accel_dps2)
    return float(rate_dps * moving_s + (-ramp_deg if ramp == "start" else ramp_deg))


def angle_sigma(marks: list, rate_dps: float, period_s: float) -> float:
    """The 1-sigma (deg) of a window's angle from placing its reads at the rate on the IMU's
    clock (``position_at``; the reads at rest need no placement).  Two parts, in quadrature:

    - the placement: a read's moment is known only to lie in its bracket, ``t_before`` ..
      ``t_after`` + one period, wide ``w``; anywhere in it equally likely gives w / sqrt 12 (s).
      Not divided by the reads' number: their placements share the reader's block phase and the
      line's latency, so their errors need not average out (on the twins, speed 2, 100 Hz, 5 ms
      clock offset: per-read spread 4-7 ms, but the windows' angles off by 2-4 ms beyond a common
      offset -- more than the spread over sqrt 18 reads).  The rms of w / sqrt 12 over the reads,
      times |rate|.
    - the reads' own spread about one another once carried to a common moment (the table's rate
      ripple, the positions' quantisation, placement jitter beyond the brackets): their standard
      deviation over sqrt(n), the mean's.

    0 without reads at the rate."""
    if not marks:
        return 0.0
    widths = np.array([m.t_after + period_s - m.t_before for m in marks])
    placement = abs(rate_dps) * float(np.sqrt(np.mean(widths ** 2) / 12.0))
    spread = 0.0
    if len(marks) > 1:
        t0 = placed(marks[0], period_s)
        carried = [p - rate_dps * (tm - t0) for tm, p in _unwrapped(marks, rate_dps, period_s)]
        spread = float(np.std(carried, ddof=1) / np.sqrt(len(carried)))
    return float(np.hypot(placement, spread))
