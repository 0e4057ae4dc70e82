"""Schemes done by hand (``table: none``), for the sequencer: one continuous recording (a
segment of kind ``session``) while the operator follows the instructions; the data tell when
each instruction is done; at the end station/io/segment_detect.py finds the still intervals and
the turns in the whole session and they are written as the scheme's segments.

Each detected segment is a copy of part of the session (the session file stays as recorded).
A turn's ``angle_deg`` is the protocol's (``turn_deg``: the IMU goes back to where it started),
not a measurement; the bench's angle error in the manifest (1 deg) says how well a hand does it.
"""
from __future__ import annotations

import numpy as np

from drivers.samples import ImuSamples
from station.bench.plan import HandRotation, HandStatic
from station.io.segment_detect import detect, match, still_mask

SESSION = "session"
CHECK_EVERY_S = 0.5          # device time between looks at the data
STILL_ACCEL_STD_MPS2 = 0.05  # while waiting for stillness: spread of every channel over a window
STILL_GYRO_STD_DPS = 0.5
STILL_RATE_DPS = 1.0         # ... and of the mean rate from the rate at rest (segment_detect's)
WINDOW_S = 0.5
TURN_TOLERANCE = 0.25
LOOK_BACK_S = 3.0            # stillness kept before a turn that has not begun (device time)


class Session:
    """The continuous recording of a hand scheme."""

    def __init__(self, writer, rate_hz: float):
        self.rate_hz = rate_hz
        name, n = SESSION, 1
        done = {s for s in _segment_names(writer)}
        while name in done:
            n += 1
            name = f"{SESSION}{n}"
        self.segment = writer.begin_segment(name, "session", note="continuous recording of a hand "
                                            "calibration; the segments are found in it (segment_detect)")
        self.n = 0
        self._with_temp = None
        self._t = np.zeros(0)                 # every sample so far, in arrays grown by doubling:
        self._accel = np.zeros((0, 3))        #   adding a block and looking at the data cost the
        self._gyro = np.zeros((0, 3))         #   block and the part looked at, not the session
        self._temp = np.zeros(0)

    def add(self, block: ImuSamples) -> None:
        finite = np.isfinite(block.temp_c)
        if self._with_temp is None:
            self._with_temp = bool(finite.all())
        temp = np.where(finite, block.temp_c, 0.0) if self._with_temp else None
        self.segment.write(block.t_s, block.accel_mps2, block.gyro_dps, temp)
        n, end = len(block), self.n + len(block)
        if end > len(self._t):
            size = max(end, 2 * len(self._t), 1024)
            self._t, self._temp = (np.resize(a, size) for a in (self._t, self._temp))
            self._accel, self._gyro = (np.resize(a, (size, 3)) for a in (self._accel, self._gyro))
        self._t[self.n:end] = block.t_s
        self._accel[self.n:end] = block.accel_mps2
        self._gyro[self.n:end] = block.gyro_dps
        self._temp[self.n:end] = block.temp_c
        self.n = end

    def data(self, start: int = 0) -> ImuSamples:
        """The samples from ``start`` on (views: the session only grows)."""
        sl = slice(max(0, start), self.n)
        return ImuSamples(self._t[sl], self._accel[sl], self._gyro[sl], self._temp[sl])


def hand_step(seq, step) -> None:
    """Show the instruction, let the operator act, read until the data show it done."""
    session = seq._session
    seq.display.prompt(step.instruction)
    seq.operator.act(step)
    if isinstance(step, HandStatic):
        _wait_still(seq, session, step)
    else:
        _wait_turn(seq, session, step)


def _feed(seq, session, seconds: float) -> None:
    n = max(1, int(round(seconds * seq.rate_hz)))
    while n > 0:
        block = seq._take(n)
        session.add(block)
        n -= len(block)
        seq._progress(len(block))
        seq.display.values_update({**seq.stream.live(), "counters": seq.stream.counters})
        seq._check_pause()


def _wait_still(seq, session, step: HandStatic) -> None:
    spec = step.spec
    start = session.n
    need = int(round((spec.dwell_s + 2 * WINDOW_S) * seq.rate_hz))
    window = max(3, int(round(WINDOW_S * seq.rate_hz)) | 1)
    warned = False
    while True:
        _feed(seq, session, CHECK_EVERY_S)
        if session.n - start < need:
            continue
        tail = session.data(session.n - need)
        still = still_mask(tail.accel_mps2, tail.gyro_dps, window, accel_threshold=STILL_ACCEL_STD_MPS2,
                           gyro_threshold=STILL_GYRO_STD_DPS)
        if not still.all():
            continue
        up = tail.accel_mps2.mean(axis=0)
        up /= np.linalg.norm(up)
        if float(up @ np.asarray(spec.up_body)) >= np.cos(np.radians(30.0)):
            seq.display.note(f"{spec.name}: still for {spec.dwell_s:g} s")
            return
        if not warned:
            seq.display.note(f"{spec.name}: the IMU is still with up along {np.round(up, 2).tolist()} "
                             f"(IMU axes), not {list(spec.up_body)}: turn it as asked")
            warned = True


def _wait_turn(seq, session, step: HandRotation) -> None:
    """Read until the data show the turn.  While the IMU has been still for LOOK_BACK_S with no
    turn found, only that stillness is kept to look at: each look costs the stillness before the
    turn and the turn, however long the operator takes.  A turn of the wrong angle is said, and
    the operator is asked again (``operator.act``)."""
    spec = step.spec
    turn = spec.turn_deg or 360.0
    look_back = int(round(LOOK_BACK_S * seq.rate_hz))
    window = max(3, int(round(WINDOW_S * seq.rate_hz)) | 1)
    start = max(0, session.n - look_back)                           # some stillness before
    before = session.data(start)
    rest_rate = before.gyro_dps.mean(axis=0) if len(before) else None    # the gyro at rest before
    while True:
        _feed(seq, session, CHECK_EVERY_S)
        data = session.data(start)
        if len(data) < 4:
            continue
        det = detect(data.t_s, data.accel_mps2, data.gyro_dps, window_s=WINDOW_S)
        motions = det.motions()
        if motions and motions[-1].angle >= (1 - TURN_TOLERANCE) * turn * 0.5:
            motion = motions[-1]
            if abs(motion.angle - turn) <= TURN_TOLERANCE * turn:
                seq.display.note(f"{spec.name}: turned {motion.angle:.0f} deg")
                return
            seq.display.note(f"{spec.name}: turned {motion.angle:.0f} deg, not {turn:g}: put the IMU "
                             "back and turn it again")
            start = session.n - int(round(2.0 * seq.rate_hz))
            seq.display.prompt(step.instruction)
            seq.operator.act(step)
            continue
        # no turn yet (or a small move, not the turn): once still for LOOK_BACK_S, look at that
        # stillness only (a turn not begun yet starts after it).  Still by absolute thresholds
        # and the rate at rest before the step: detect's are relative to the data (a steady turn
        # longer than the stillness around it looks still to them until enough stillness
        # follows), so nothing is dropped while the data hold a motion detect has not judged
        still = still_mask(data.accel_mps2, data.gyro_dps, window, accel_threshold=STILL_ACCEL_STD_MPS2,
                           gyro_threshold=STILL_GYRO_STD_DPS, bias=rest_rate,
                           rate_threshold_dps=STILL_RATE_DPS)
        if len(data) > look_back and still[-look_back:].all() and (motions or still.all()):
            start = session.n - look_back


def finish_session(seq, steps) -> list[str]:
    """Close the session, find the segments in it, write them; returns the names not found."""
    session = seq._session
    session.segment.close("complete")
    data = session.data()
    specs = [s.spec for s in steps if isinstance(s, (HandStatic, HandRotation))]
    det = detect(data.t_s, data.accel_mps2, data.gyro_dps, window_s=WINDOW_S)
    found = match(det, specs, turn_tolerance=TURN_TOLERANCE)
    temp = data.temp_c if np.isfinite(data.temp_c).all() else None
    for spec in specs:
        if spec.name not in found:
            continue
        interval, sign = found[spec.name]
        sl = slice(interval.start, interval.stop)
        note = f"found in {session.segment.name} (samples {interval.start}..{interval.stop - 1})"
        if spec.kind == "static":
            meta = {"up_body": list(spec.up_body), "note": note}
        else:
            turn = spec.turn_deg or 360.0
            duration = (interval.stop - interval.start) / seq.rate_hz
            meta = {"axis_body": list(spec.axis_body), "rate_dps": sign * turn / duration,
                    "angle_deg": sign * turn, "motion": "hand",
                    "note": note + f"; angle_deg is the protocol's turn ({turn:g} deg by hand), not "
                                   "an encoder reading; rate_dps is its mean"}
        with seq.writer.begin_segment(spec.name, spec.kind, **meta) as seg:
            seg.write(data.t_s[sl], data.accel_mps2[sl], data.gyro_dps[sl], None if temp is None else temp[sl])
            seg.close("complete")
    missing = [s.name for s in specs if s.name not in found]
    if missing:
        seq.display.note(f"not found in the recording: {', '.join(missing)} (station run --resume "
                         "records them in a new session)")
    return missing


def _segment_names(writer) -> list[str]:
    from station.io.capture import read_capture

    return [s.name for s in read_capture(writer.path, load_data=False).segments]
