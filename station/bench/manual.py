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
WINDOW_S = 0.5
TURN_TOLERANCE = 0.25


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
        self.blocks: list[ImuSamples] = []
        self.n = 0
        self._with_temp = None

    def add(self, block: ImuSamples) -> None:
        finite = np.isfinite(block.temp_c)
        if self._with_temp is None:
            self._with_temp = bool(finite.all())
        temp = np.where(finite, block.temp_c, 0.0) if self._with_temp else None
        self.segment.write(block.t_s, block.accel_mps2, block.gyro_dps, temp)
        self.blocks.append(block)
        self.n += len(block)

    def data(self, start: int = 0) -> ImuSamples:
        whole = ImuSamples.concat(self.blocks)
        self.blocks = [whole]
        return ImuSamples(whole.t_s[start:], whole.accel_mps2[start:], whole.gyro_dps[start:],
                          whole.temp_c[start:])


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
    spec = step.spec
    turn = spec.turn_deg or 360.0
    start = max(0, session.n - int(round(3.0 * seq.rate_hz)))       # some stillness before
    while True:
        _feed(seq, session, CHECK_EVERY_S)
        data = session.data(start)
        if len(data) < 4:
            continue
        det = detect(data.t_s, data.accel_mps2, data.gyro_dps, window_s=WINDOW_S)
        motions = det.motions()
        if not motions:
            continue
        motion = motions[-1]
        if motion.angle < (1 - TURN_TOLERANCE) * turn * 0.5:     # a small move, not the turn: wait on
            continue
        if abs(motion.angle - turn) <= TURN_TOLERANCE * turn:
            seq.display.note(f"{spec.name}: turned {motion.angle:.0f} deg")
            return
        seq.display.note(f"{spec.name}: turned {motion.angle:.0f} deg, not {turn:g}: put the IMU back "
                         "and turn it again")
        start = session.n - int(round(2.0 * seq.rate_hz))


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
