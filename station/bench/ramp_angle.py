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
(``t_after``) plus one period.  At the rate, the reads' positions give their moments relative
to one another, so every bracket bounds one common moment (``moment``: their intersection, and
where in it the host's waits put it); the first read is carried from there to the window's edge
(position_at).  What is left of the placement is not the encoder's 2": the common moment is known
only within the brackets (tens of ms on the twins' pseudo-terminals, 10-80 ms measured), so the
window's angle carries an uncertainty of its own (``angle_sigma``), written into the manifest
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
    """The read's moment on the IMU's clock taken alone: the middle of its bracket, ``t_before`` ..
    ``t_after`` + one period (used to restore the whole turns a read lost; the window's angle
    places every read at once: ``moment``).
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


def position_at(marks: list, t: float, rate_dps: float, period_s: float, *, accel_dps2: float | None = None,
                tolerance_deg: float = 0.0) -> float | None:
    """The axis' position (deg, unwrapped about the first mark's) at IMU time ``t`` from the marks
    read while it turned at ``rate_dps``: the first mark's position carried from its moment on the
    IMU's clock (``moment``: every read's bracket at once) to ``t`` at the rate.  None without a
    mark.  Raises Inconsistent when no moment fits every read's bracket."""
    if not marks:
        return None
    t0, _ = moment(marks, rate_dps, period_s, accel_dps2=accel_dps2, tolerance_deg=tolerance_deg)
    return float(marks[0].position_deg + rate_dps * (t - t0))


class Inconsistent(ValueError):
    """The table's reads at the rate cannot all have been answered inside their brackets on the
    IMU's clock: the IMU's frames came later than the table's answers (a line's or a reader's
    latency beyond what a sync sees), or the axis did not turn at the rate between the reads."""


#: the host's delays on either side of a read's moment (ask the reader, write the query, the
#: table's answer; read the answer, the rate's query and its answer, ask the reader again): each
#: side a sum of at least two independent waits of the same kind, i.e. Gamma(2) with a common
#: scale, so the moment's fraction of its bracket is Beta(2, 2) (independent of the bracket's width)
BRACKET_BETA = 2.0
GRID = 401
QUANTA = 4               # points per period where a sync's answer lies after its stamp


def moment(marks: list, rate_dps: float, period_s: float, *, accel_dps2: float | None = None,
           tolerance_deg: float = 0.0) -> tuple[float, float]:
    """(mean, 1-sigma) of the first mark's moment on the IMU's clock (s), from every mark read at
    ``rate_dps``.  The marks' positions give their moments relative to the first (k_i = (p_i -
    p_0) / rate: the axis turns at the rate between them), so each bracket ``t_before`` ..
    ``t_after`` + one period, less k_i, bounds the one unknown moment: it lies in their
    intersection (widened by what the positions leave of k_i: ``tolerance_deg``, the encoder's
    read, and a read on the ramp's last 1 % short of the line by (r - r_i)^2 / 2a).  Where in
    its bracket a read was answered: a fraction u of it with density ~ (u (1 - u))^(BRACKET_BETA -
    1) (BRACKET_BETA: the host's waits either side of the moment); the product over the reads,
    on the intersection, is the moment's distribution: its mean and standard deviation.
    Before (issue 28, sixteenth session), each read was placed at its bracket's middle, their mean
    taken, and the 1-sigma was the brackets' rms w / sqrt 12, not divided by their number: on the
    twins at speed 8 (17 windows quiet, 10 under two busy loops) the windows' errors were 0.22 and
    0.25 of that 1-sigma rms (docs/design.md, "Seventeenth session: recorded ramps")."""
    if not marks:
        raise ValueError("no mark")
    rate = float(rate_dps)
    times = _unwrapped_k(marks, rate, period_s)
    k = np.array([kk for kk, _ in times])
    a = np.array([m.t_before for m in marks]) - k
    b = np.array([m.t_after + period_s for m in marks]) - k
    dev = np.full(len(marks), float(tolerance_deg))
    if accel_dps2:
        dev = dev + np.array([(m.rate_dps - rate) ** 2 for m in marks]) / (2.0 * abs(float(accel_dps2)))
    margin = dev / abs(rate)
    a, b = a - margin, b + margin
    lo, hi = float(np.max(a)), float(np.min(b))
    if lo > hi:
        raise Inconsistent(f"the table's {len(marks)} reads at {rate:g} deg/s fit no common moment on the "
                           f"IMU's clock (their brackets miss one another by {lo - hi:.3g} s)")
    c = np.linspace(lo, hi, GRID)
    # the host's waits run from the first sync's answer to the moment and on to the second's: each
    # answer lies within the period after its stamp (the next frame had not arrived), so the
    # waits' bracket is (s1, s2), s1 uniform in t_before .. + period, s2 in t_after .. + period;
    # the moment's density given them (BRACKET_BETA's fraction of s2 - s1, over s2 - s1) averaged
    # over both (QUANTA points each)
    q = (np.arange(QUANTA) + 0.5) / QUANTA * period_s
    s1 = (a + margin)[:, None, None] + q[None, :, None]        # (read, s1, s2) less k_i
    s2 = (b - margin - period_s)[:, None, None] + q[None, None, :]
    width = s2 - s1
    ok = width > 0
    width = np.where(ok, width, 1.0)
    logw = np.zeros(len(c))
    for i in range(len(marks)):
        u = (c[:, None, None] - s1[i][None]) / width[i][None]
        dens = np.where(ok[i][None] & (u > 0) & (u < 1), (u * (1.0 - u)) ** (BRACKET_BETA - 1.0) / width[i][None], 0.0)
        m = dens.mean(axis=(1, 2))
        if m.max() > 0:          # within the margins only (a read outside its waits' bracket): no weight
            logw += np.log(np.maximum(m / m.max(), 1e-300))
    w = np.exp(logw - logw.max())
    w /= w.sum()
    mean = float(c @ w)
    sd = float(np.sqrt(((c - mean) ** 2) @ w))
    # the grid's own resolution (its step / sqrt 12) bounds the 1-sigma from below
    return mean, max(sd, (hi - lo) / (GRID - 1) / np.sqrt(12.0))


def _unwrapped_k(marks: list, rate_dps: float, period_s: float) -> list:
    """(k_i, position unwrapped, deg) of each mark: its moment after the first's (s) from the
    positions at the rate."""
    p0 = marks[0].position_deg
    return [(float((p - p0) / rate_dps), p) for _, p in _unwrapped(marks, rate_dps, period_s)]


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


def angle_sigma(marks: list, rate_dps: float, period_s: float, *, accel_dps2: float | None = None,
                tolerance_deg: float = 0.0) -> float:
    """The 1-sigma (deg) of a window's angle from placing its reads at the rate on the IMU's
    clock: the 1-sigma of their common moment (``moment``) times |rate| (the reads at rest need
    no placement).  0 without reads at the rate."""
    if not marks:
        return 0.0
    _, sd = moment(marks, rate_dps, period_s, accel_dps2=accel_dps2, tolerance_deg=tolerance_deg)
    return abs(float(rate_dps)) * sd
