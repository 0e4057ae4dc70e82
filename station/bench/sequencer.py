"""The sequencer: executes a plan (station/bench/plan.py) on the devices; the only code that touches
hardware.

Time comes from the devices: a dwell is a number of IMU samples, a rotation a whole number of
table revolutions recorded as a number of IMU samples, settling is IMU samples discarded; so a
run against the device twins at ``--speed 100`` runs the same code as one on a real bench.

Safety: every rate, acceleration and angle is checked against the configured limits before it
is commanded; whatever happens, the table is brought to rest in a ``finally``.  Ctrl-C asks for
a pause: at the next safe point (between blocks of samples, between steps) the table is brought
to rest and the segment being recorded is closed as ``incomplete`` (everything recorded is
kept); on a terminal the operator can then continue, otherwise the run stops and
``station run --resume CAPTURE`` continues later.  A second Ctrl-C, SIGTERM or SIGHUP (the
terminal or the SSH session closed) aborts at once, still stopping the table.  Hand-performed schemes (no table) are recorded as one continuous
session and split into segments by station/io/segment_detect.py.
"""
from __future__ import annotations

import contextlib
import io
import math
import signal
import threading
import time

import numpy as np

from station.io.capture import CaptureWriter, read_regular_file, warmup_file, warmup_records
from station.core.errors import UserError
from station.bench.channels import ImuChannel, Recording, segment_meta
from station.bench.imu_stream import ImuStream, lost_frames_note
from station.bench import steadiness
from station.bench.steadiness import motion_found
from station.bench.plan import (Chamber, Checkpoint, Dwell, HandRotation, HandStatic, MoveTo, Operator, Rotate, Settle,
                          WarmUp)

BLOCK_S = 1.0                 # device seconds written to a segment per write
POLL_WALL_S = 0.1             # at most this often (wall) the table is read while recording
RATE_HOLD_FRACTION = 0.01     # a rotation's rate must stay within 1 % (or 10 rate tolerances)
POSITION_HOLD_FACTOR = 10     # a dwell's angles must stay within 10 position tolerances
WHOLE_TURN_MARGIN_DEG = 90.0  # a recorded ramp's command known within less than this at the rate
MOTION_WORDS = "the IMU disagrees with the table"    # a bad recording's note, when it is this
WAYPOINT_DEG = 170.0          # largest single move of an axis with angle limits


class PauseRequested(Exception):
    """Ctrl-C: stop at the next safe point."""


class RunAborted(KeyboardInterrupt):
    """A second Ctrl-C, SIGTERM or SIGHUP."""


class RunPaused(Exception):
    """The run stopped at a safe point and can be resumed (``station run --resume``)."""


class SequencerError(UserError):
    """The bench did not do what it was told (a rate not held, a table that moved)."""


class BadRecording(Exception):
    """A recording whose metadata cannot be stated truthfully (raised by a segment's ``completed``):
    kept aside and recorded again, like one that lost data (Sequencer._record_segment)."""


class Interrupts:
    """SIGINT: the first asks for a pause, the second aborts; SIGTERM and SIGHUP (the terminal
    or SSH session gone: nobody is left to answer a pause) abort like a second Ctrl-C."""

    def __init__(self):
        self.count = 0
        self._previous = {}

    @property
    def pause_requested(self) -> bool:
        return self.count > 0

    def clear(self) -> None:
        self.count = 0

    def _sigint(self, signum, frame):
        self.count += 1
        if self.count >= 2:
            raise RunAborted()

    def _sigterm(self, signum, frame):
        raise RunAborted()

    def __enter__(self):
        if threading.current_thread() is threading.main_thread():
            self._previous = {signal.SIGINT: signal.signal(signal.SIGINT, self._sigint),
                              signal.SIGTERM: signal.signal(signal.SIGTERM, self._sigterm)}
            if hasattr(signal, "SIGHUP"):
                self._previous[signal.SIGHUP] = signal.signal(signal.SIGHUP, self._sigterm)
        return self

    def __exit__(self, *exc):
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)
        return False


class Sequencer:
    """Runs plan steps on ``table`` (a connected RateTable, or None for schemes done by hand)
    and ``imu`` (a connected Imu), recording into ``writer`` (a CaptureWriter); or, several IMUs
    on one table, on ``channels`` (station/bench/channels.py: each IMU's stream and bundle).

    Several IMUs: the table moves once; each IMU records every segment into its own bundle with
    its own data-loss checks.  An IMU whose stream fails (its port dies, it stops streaming) or
    whose every recording of a segment lost too much data is *lost*: said on the display, its
    segment being recorded closed as incomplete with the reason, and the others go on (its
    segments are recorded on ``station run --resume``).  The last IMU left failing stops the
    run as a single IMU's failure does."""

    def __init__(self, *, table, imu=None, writer: CaptureWriter | None = None, config, display, operator,
                 interrupts: Interrupts | None = None, rate_hz: float | None = None,
                 reset_faults: bool = False, channels: list | None = None):
        self.table = table
        if channels is None:
            channels = [ImuChannel("imu", ImuStream(imu, float(rate_hz)), writer, float(rate_hz))]
        self.channels = list(channels)
        self.multi = len(self.channels) > 1
        self.config = config
        self.display = display
        self.operator = operator
        self.interrupts = interrupts or Interrupts()
        self.rate_hz = float(self.channels[0].rate_hz)      # the rate segment lengths are compiled at
        self.limits = config.table.axis_limits() if table is not None else ()
        self.reset_faults = reset_faults
        self.mounting = tuple(config.table.mounting)
        self._last_poll = 0.0
        self._elapsed_s = self._estimate_s = 0.0     # device time into the present step
        self._session = None          # hand schemes: the continuous recording
        self._chamber_c = None        # the temperature chamber's setpoint in force (Chamber steps)
        self._chamber_entry: dict = {}    # segment -> the manifest's ``chamber`` entry of its step

    # the first IMU's (the only one of a one-IMU run; hand schemes use these)
    stream = property(lambda self: self.channels[0].stream)
    writer = property(lambda self: self.channels[0].writer,
                      lambda self, w: setattr(self.channels[0], "writer", w))

    def _alive(self) -> list:
        return [ch for ch in self.channels if ch.alive]

    def _reference(self):
        """The IMU whose samples measure the steps' progress: the first one still recording."""
        return self._alive()[0]

    def _lose(self, ch, error: BaseException) -> None:
        """IMU ``ch`` failed: the last one left raises ``error`` (the run stops as a one-IMU run
        does); otherwise it is marked lost, said, and the others go on."""
        if not self.multi or len(self._alive()) <= 1:
            raise error
        ch.lost = f"{type(error).__name__}: {str(error)[:200]}"
        self.display.note(f"IMU {ch.label} lost ({ch.lost}): the other IMUs go on; its segments from "
                          "here are recorded by station run --resume")
        try:
            ch.stream.stop()
        except Exception:      # noqa: BLE001 - its port is gone; nothing more to do with it
            pass

    def _each(self, fn) -> None:
        """``fn(ch)`` for every IMU still recording; a failing IMU is lost (``_lose``)."""
        for ch in self._alive():
            try:
                fn(ch)
            except PauseRequested:
                raise
            except Exception as e:          # the IMU's stream: timeouts, a port gone
                self._lose(ch, e)

    # ------------------------------------------------------------------ the run
    def run(self, steps: list) -> None:
        """Execute ``steps``; the table is at rest and the IMU stream stopped afterwards."""
        ramps = [s.segment for s in steps if isinstance(s, Rotate) and s.record_ramp]
        if ramps and self.multi:        # before anything moves: one line, exit 2
            raise SequencerError(f"{ramps[0]}: a turn with its ramp recorded (record_ramp) is placed on one IMU's "
                                 "clock (the table's reads against its frames): record it with one IMU per run")
        try:
            self._prepare()
            i = 0
            while i < len(steps):
                step = steps[i]
                try:
                    self._check_pause()
                    self.display.step(step, i, len(steps))
                    self._elapsed_s, self._estimate_s = 0.0, step.estimate_s
                    self._execute(step)
                    i += 1
                except PauseRequested:
                    i = self._pause(steps, i)
            if self._session is not None:
                self._finish_session(steps)
        finally:
            if self._session is not None and not self._session.segment.closed:
                self._session.segment.close("incomplete")
            self._shutdown()

    def _execute(self, step) -> None:
        handler = {WarmUp: self._warmup, MoveTo: self._move, Settle: self._settle, Dwell: self._dwell,
                   Rotate: self._rotate, Operator: self._operator, Checkpoint: self._checkpoint, Chamber: self._chamber,
                   HandStatic: self._hand, HandRotation: self._hand}[type(step)]
        handler(step)

    def _pause(self, steps, i) -> int:
        """At a safe point: table at rest, segment closed as incomplete (by its ``with``)."""
        if self.table is not None:
            self._stop_table()
        self.display.note("paused: the table is at rest; what was recorded is kept "
                          "(the segment being recorded is marked incomplete)")
        if self._session is not None:                  # by hand: keep what was done, stop
            self._finish_session(steps)
            raise RunPaused(str(self.writer.path))
        if not self.operator.resume_after_pause(self.interrupts):
            raise RunPaused(str(self.writer.path))
        self.interrupts.clear()
        for ch in self._alive():
            ch.writer = CaptureWriter.reopen(ch.writer.path)
        self._each(lambda ch: ch.stream.drain())
        segment = steps[i].segment
        while i > 0 and segment is not None and steps[i - 1].segment == segment:
            i -= 1
        return i

    def _check_pause(self) -> None:
        if self.interrupts.pause_requested:
            raise PauseRequested()

    # ------------------------------------------------------------------ start and end
    def _prepare(self) -> None:
        t = self.table
        if t is not None:
            st = t.status()
            if any(st.fault):
                if not self.reset_faults:
                    raise UserError(f"{t.name}: a fault is latched ({st.describe()}): find its cause, "
                                    "then reset it on the controller or run with --reset-faults")
                t.reset_interlocks()
            t.close_interlocks()
            t.stop()                          # whatever it was doing (e.g. before a crash): at rest
            for axis, lim in zip(t.axes, self.limits):
                try:
                    t.set_rate_limits(axis, "rate", lim.max_rate_dps, lim.rate_accel_dps2)
                except UserError as e:        # NotSupported: the controller's own limits apply
                    self.display.note(f"axis {axis}: rate-mode limits not set ({e}); the controller's apply")
        self._each(lambda ch: ch.stream.start())

    def _shutdown(self) -> None:
        try:
            if self.table is not None:
                self._stop_table()
        finally:
            for ch in self.channels:
                if ch.alive:
                    ch.stream.stop()

    def _stop_table(self) -> None:
        """Bring every axis to rest; one retry after clearing a half-read reply."""
        try:
            self.table.stop()
        except UserError:
            time.sleep(0.1)
            self.table.port.discard_input()
            self.table.stop()

    def _progress(self, samples: int, rate_hz: float | None = None) -> None:
        self._elapsed_s += samples / (rate_hz or self.rate_hz)
        self.display.advance(self._elapsed_s, max(self._estimate_s, self._elapsed_s))

    # ------------------------------------------------------------------ IMU samples
    def _take(self, n: int):
        """Up to ``n`` samples; checks for a pause while waiting."""
        while True:
            block = self._reference().stream.take(n)
            if len(block):
                return block
            self._check_pause()

    def _discard(self, seconds: float) -> None:
        """Settle: drop every sample measured before the table reported its state (the newest
        sample that had reached this computer then: ``ImuStream.sync``) and ``seconds`` of
        device time after it, by the samples' own time stamps.  So the settle is ``seconds`` of
        device time however fast device time runs against wall time (a twin at --speed 500:
        3 s are 6 ms of wall time, less than the pipeline's latency)."""
        t_end, tickets = {}, {}
        # every IMU's reader asked first, then each waited for: their current blocks end together
        self._each(lambda ch: tickets.__setitem__(id(ch), ch.stream.ask_sync()))

        def synced(ch):
            ticket = tickets.get(id(ch))
            while True:
                t_sync = ch.stream.sync(ticket=ticket)
                if t_sync is not None:
                    break
                ticket = None               # asked again after a pause check, as before
                self._check_pause()
            ch.stream.drain()                                # all at or before t_sync
            t_end[id(ch)] = t_sync + seconds - 0.5 / ch.rate_hz   # the sample `seconds` after t_sync is kept
        self._each(synced)
        pending = self._alive()
        wait_s = 0.05 if self.multi else 0.25
        while pending:
            ref = self._reference()
            for ch in list(pending):
                try:
                    dropped, reached = ch.stream.discard_before(t_end[id(ch)], wait_s=wait_s)
                except Exception as e:       # noqa: BLE001 - the IMU's stream failed: lost
                    self._lose(ch, e)
                    reached, dropped = True, 0
                if ch is ref:
                    self._progress(dropped, ch.rate_hz)
                if reached:
                    pending.remove(ch)
            pending = [ch for ch in pending if ch.alive]
            if pending:
                self._check_pause()

    def _record(self, recs: dict, poll) -> None:
        """Write each IMU's samples into its segment (``recs``: channel -> Recording) until every
        IMU still recording has its count, calling ``poll()`` now and then.  An IMU that fails
        meanwhile is lost: its segment is closed as incomplete with the reason."""
        wall0 = time.monotonic()
        wait_s = 0.02 if self.multi else 0.25
        while True:
            todo = [(ch, r) for ch, r in recs.items() if ch.alive and r.needed > 0]
            if not todo:
                break
            ref = self._reference()
            for ch, r in todo:
                block_n = max(1, int(round(BLOCK_S * ch.rate_hz)))
                try:
                    b = ch.stream.take(min(block_n, r.needed), wait_s=wait_s)
                except Exception as e:      # noqa: BLE001 - the IMU's stream failed: lost
                    self._lose(ch, e)
                    r.seg.close("incomplete", note=f"IMU lost while recording: {ch.lost}")
                    continue
                r.add(b)
                if ch is ref:
                    self._progress(len(b), ch.rate_hz)
            self._show_values()
            if time.monotonic() - self._last_poll >= POLL_WALL_S:
                poll()
            self._check_pause()
        poll()
        for ch, r in recs.items():
            if ch.alive and r.lost:
                name = r.seg.name if not self.multi else f"{r.seg.name} (IMU {ch.label})"
                self.display.note(lost_frames_note(name, r.lost, float(r.last_t - r.first_t),
                                                   time.monotonic() - wall0))

    def _show_values(self) -> None:
        """The live values: the first IMU's, and with several a line per IMU."""
        ref = self._reference()
        values = {**ref.stream.live(), "counters": ref.stream.counters}
        if self.multi:
            values["imus"] = [{"label": ch.label, "lost": ch.lost,
                               **({} if not ch.alive else {**ch.stream.live(), "counters": ch.stream.counters})}
                              for ch in self.channels]
        self.display.values_update(values)

    def _data_loss(self, rec, rate_hz: float | None = None) -> str | None:
        """Why a recording lost too much data (station.yaml run.max_missing_fraction and
        run.max_gap_s), or None."""
        run = self.config.run
        share = rec["gaps"] / (rec["samples"] + rec["gaps"]) if rec["samples"] else 1.0
        gap = rec["longest_step_s"] - 1.0 / (rate_hz or self.rate_hz)
        problems = []
        if share > run.max_missing_fraction:
            problems.append(f"{rec['gaps']} frames lost ({100 * share:.2f} %, limit "
                            f"{100 * run.max_missing_fraction:g} %)")
        if gap > run.max_gap_s:
            problems.append(f"no frame for {gap:.2f} s (limit {run.max_gap_s:g} s)")
        return "; ".join(problems) or None

    def _disagreement(self, kind, rec) -> str | None:
        """Why the IMU's samples say the table was not holding while they were recorded
        (station/bench/steadiness.py: every redundancy of the bench cross-checked), or None."""
        accel, gyro = rec.samples()
        table = self.config.table
        found = motion_found(kind, accel, gyro, rate_hz=1.0 / rec.period, rate_tolerance_dps=table.rate_tolerance_dps,
                             hold_deg=POSITION_HOLD_FACTOR * table.position_tolerance_deg)
        return None if found is None else f"{MOTION_WORDS}: {found}"

    def _record_segment(self, name, kind, meta, n, poll, completed, start=None, record=None, check=None) -> None:
        """Record segment ``name`` (``n`` samples); a recording over the data-loss limits is
        closed as incomplete with a note, kept aside (``.incomplete``) and recorded again, at
        most ``run.rerecord_attempts`` times.  ``completed(rec)`` gives the manifest keys of a
        good recording; ``check(recording, keys)``, if given, why the IMU disagrees with them
        (a bad recording, as one that lost data), or None."""
        attempts = 1 + self.config.run.rerecord_attempts
        pending = [ch for ch in self._alive() if name not in ch.done]
        problems: dict = {}
        if self._chamber_c is not None:     # the chamber's setpoint, and the step that set it
            meta = {**meta, "chamber_c": self._chamber_c,
                    **({"chamber": self._chamber_entry[name]} if name in self._chamber_entry else {})}
        for attempt in range(1, attempts + 1):
            if not pending:
                return
            if any(MOTION_WORDS in p for p in problems.values()):
                # the IMU saw the table move: its samples came late against the table's answer,
                # so the settle began too early; settle again from a fresh look at the stream
                self._discard(self.config.run.settle_s)
            with contextlib.ExitStack() as stack:
                recs = {}
                for ch in pending:
                    seg = stack.enter_context(ch.writer.begin_segment(name, kind, **segment_meta(meta, ch.to_case)))
                    recs[ch] = Recording(seg, int(round(n * ch.rate_hz / self.rate_hz)), ch.rate_hz)
                if start is not None:
                    start()
                (record or self._record)(recs, poll)
                problems = {}
                for ch, r in recs.items():
                    if not ch.alive:
                        continue              # closed as incomplete when it was lost
                    rec = r.result()
                    problem = self._data_loss(rec, ch.rate_hz)
                    if problem is None and record is None:      # a recorded ramp moves by design
                        problem = self._disagreement(kind, r)
                    done = None
                    if problem is None:
                        try:
                            done = completed(rec)
                        except BadRecording as e:
                            problem = str(e)
                    if problem is None and check is not None:
                        problem = check(r, done)
                    if problem is None:
                        r.seg.close("complete", **done)
                        ch.done = ch.done | {name}
                    else:
                        r.seg.close("incomplete", note=f"bad recording: {problem}")
                        problems[id(ch)] = problem
            for ch in pending:
                if id(ch) in problems:
                    ch.writer = CaptureWriter.reopen(ch.writer.path)
            pending = [ch for ch in pending if id(ch) in problems]
            if pending and attempt < attempts:
                for ch in pending:
                    who = f" (IMU {ch.label})" if self.multi else ""
                    self.display.note(f"{name}{who}: bad recording ({problems[id(ch)]}): kept aside, recording "
                                      f"it again ({attempt}/{attempts - 1})")
        for ch in pending:
            problem = problems[id(ch)]
            if MOTION_WORDS in problem:
                error = SequencerError(f"{name}: every recording disagreed with the table ({problem}; {attempts} "
                                       "attempts): check that the IMU is fixed to the platform and the line's latency "
                                       "(a USB adapter's, the computer's load), then resume")
            elif "whole turns in the window are ambiguous" in problem:
                error = SequencerError(f"{name}: every recording was refused ({problem}; {attempts} attempts): "
                                       "lower the load on this computer or the line's latency (a USB adapter's), "
                                       "or record this ramp at a lower rate, then resume")
            else:
                error = SequencerError(f"{name}: every recording lost too much data ({problem}; {attempts} "
                                       "attempts): check the IMU's connection and the computer's load, then resume")
            self._lose(ch, error)

    # ------------------------------------------------------------------ steps
    def _warmup(self, step: WarmUp) -> None:
        """Until the first IMU's temperature settles (the others warm up beside it; their
        samples are dropped).  Its readings are kept in each IMU's capture as the next warm-up
        record (station.io.capture.warmup_file: ``warmup.csv``, then ``warmup-2.csv``, ... for a
        resumed or extended run's, which never overwrites the first), also when the warm-up is
        cut short (a pause, an abort, a failing stream: what was read is kept)."""
        self._each(lambda ch: ch.stream.drain())
        t_first = None
        times, temps, rows = [], [], ["t_s,temp_c"]
        again = " again" if step.resumed else ""
        least = step.min_s
        judged = False
        try:
            while True:
                b = self._take(max(1, int(round(self.rate_hz))))
                finite = np.isfinite(b.temp_c)
                if t_first is None:
                    t_first = b.t_s[0]
                    if step.restart_min_s > least and _clock_restarted(self._reference().writer.path, t_first):
                        least = step.restart_min_s
                        self.display.note(f"the IMU's clock restarted since the run stopped (switched off?): "
                                          f"warming up again for at least {least:g} s")
                if step.restart_min_s > least and not judged and finite.any():
                    # an IMU stamped by the host's clock (which never goes back): its temperature
                    # fallen below the capture's last reading beyond the readings' noise says it was
                    # off (the first finite reading, as the record keeps it)
                    judged = True
                    fell = _temperature_fell(self._reference().writer.path, round(float(b.temp_c[finite].mean()), 4),
                                             step.window_s)
                    if fell is not None:
                        least = step.restart_min_s
                        self.display.note(f"the IMU's temperature fell {fell[0]:.3g} C since the run stopped (more "
                                          f"than its readings' noise, {fell[1]:.2g} C: switched off?): warming up "
                                          f"again for at least {least:g} s")
                elapsed = float(b.t_s[-1] - t_first)
                if finite.any():
                    # the decision is taken on the values written to warmup.csv (ms, 0.1 mK), so
                    # that the record reproduces it exactly
                    times.append(round(float(b.t_s[-1]), 3))
                    temps.append(round(float(b.temp_c[finite].mean()), 4))
                    rows.append(f"{times[-1]:.3f},{temps[-1]:.4f}")
                total = step.max_s if step.slope_c_per_h is not None else step.min_s
                reference = self._reference()
                self._each(lambda ch: ch is reference or ch.stream.drain())
                self._show_values()
                self.display.advance(min(elapsed, total), total)
                if elapsed >= least:
                    if step.slope_c_per_h is None:
                        break
                    slope = _slope_c_per_h(times, temps, step.window_s)
                    if slope is not None and abs(slope) < step.slope_c_per_h:
                        self.display.note(f"warm-up{again} done after {elapsed:.0f} s: {slope:+.3f} C/h")
                        break
                    if step.max_s is not None and elapsed >= step.max_s:
                        self.display.note(f"warm-up{again} stopped at its maximum, {step.max_s:g} s "
                                          f"(slope {slope if slope is not None else float('nan'):+.3f} C/h)")
                        break
                self._check_pause()
        except BaseException:
            with contextlib.suppress(Exception):     # the reason the warm-up stopped is what is said
                self._keep_warmup(rows)
            raise
        self._keep_warmup(rows)

    def _keep_warmup(self, rows: list) -> None:
        """The warm-up's readings (``rows``: the CSV's lines) into each IMU's capture, as its next
        warm-up record (none read: nothing written)."""
        if len(rows) > 1:
            for ch in self._alive():
                ch.writer.write_file(warmup_file(ch.writer.path), "\n".join(rows) + "\n")

    def _move(self, step: MoveTo) -> None:
        targets = list(step.positions_deg)
        self._check_targets(targets)
        for waypoint in self._waypoints(targets):
            self.table.move_to(waypoint)
        self._poll_table()

    def _settle(self, step: Settle) -> None:
        self._discard(step.duration_s)

    def _dwell(self, step: Dwell) -> None:
        spec = step.spec
        n = int(round(spec.dwell_s * self.rate_hz))
        meta = {"up_body": list(spec.up_body)}
        if spec.heading_body is not None:
            meta.update(heading_body=list(spec.heading_body), heading_deg=spec.heading_deg)
        meta.update(table_deg=list(step.table_deg), mounting=list(self.mounting))
        goal = np.array(step.table_deg)
        tol = POSITION_HOLD_FACTOR * self.config.table.position_tolerance_deg

        def poll():
            pos, _ = self._poll_table()
            off = np.abs((pos - goal + 180.0) % 360.0 - 180.0)
            if np.any(off > tol):
                raise SequencerError(f"{self.table.name}: the table moved while recording {spec.name}: "
                                     f"axes at {np.round(pos, 4).tolist()} deg, commanded "
                                     f"{np.round(goal, 4).tolist()} deg")

        self._record_segment(spec.name, "static", meta, n, poll,
                             lambda rec: _optional(temperature_c=rec["temp"]))

    def _rotate(self, step: Rotate) -> None:
        spec, axis, rate = step.spec, step.axis, step.table_rate_dps
        lim = self.limits[axis - 1]
        if lim.angle_limits is not None or not math.isfinite(rate) or abs(rate) > lim.max_rate_dps:
            raise SequencerError(f"{spec.name}: {rate:g} deg/s on axis {axis} is outside its limits "
                                 f"(max_rate_dps {lim.max_rate_dps:g}, continuous axes only)")
        if step.record_ramp:
            return self._rotate_ramp(step)
        self.table.set_rate(axis, rate)
        self._discard(step.settle_s)
        n = int(round(step.revolutions * 360.0 / abs(rate) * self.rate_hz))
        readbacks = []
        hold = max(RATE_HOLD_FRACTION * abs(rate), 10 * self.config.table.rate_tolerance_dps)

        def poll():
            _, rates = self._poll_table()
            readbacks.append(float(rates[axis - 1]))
            if abs(readbacks[-1] - rate) > hold:
                raise SequencerError(f"{self.table.name}: axis {axis} did not hold {rate:g} deg/s while "
                                     f"recording {spec.name} (read {readbacks[-1]:.6f} deg/s)")

        body_sign = spec.rate_dps / rate                 # +1: table axis along axis_body
        meta = {"axis_body": list(spec.axis_body), "rate_dps": spec.rate_dps, "table_axis": axis,
                "table_rate_dps": rate, "revolutions": step.revolutions,
                "axis_elevation_deg": round(step.elevation_deg, 9), "table_deg": list(step.table_deg),
                "mounting": list(self.mounting)}
        if not spec.encoder:
            meta["note"] = "no encoder by the scheme: rate_dps is the nominal rate and gives the direction only"

        def completed(rec):
            # the angle swept over the frames' window (frame count x period) at the rate the
            # encoder read back: never from a wall-clock time
            mean_rate = float(np.mean(readbacks))
            angle = body_sign * mean_rate * rec["window_s"]
            return _optional(angle_deg=angle if spec.encoder else None,
                             table_rate_readback_dps=mean_rate, temperature_c=rec["temp"])

        def start():               # every recording: its own readbacks, the first one now
            readbacks.clear()
            poll()

        self._record_segment(spec.name, "rotation", meta, n, poll, completed, start=start)
        self.table.set_rate(axis, 0.0)

    def _rotate_ramp(self, step: Rotate) -> None:
        """A rotation whose window keeps a ramp (issue 28 item 3): "start": settle at rest after
        the move, open the window, record ``rest_s``, command the rate (the table ramps at its
        rate_accel_dps2), record the ramp and the turns; "end": ramp up and settle at the rate,
        open the window, record the turns, command rest (the table brakes), record the brake and
        ``rest_s`` at rest.  The angle is the rest position against the turning edge's, placed on
        the IMU's clock by the frames around each read (station/bench/ramp_angle.py)."""
        from station.bench import ramp_angle

        spec, axis, rate = step.spec, step.axis, step.table_rate_dps
        start_kind = step.record_ramp == "start"
        if not start_kind:
            self.table.set_rate(axis, rate)
        self._discard(step.settle_s)
        n = int(round(step.capture_s * self.rate_hz))
        first = int(round((step.rest_s if start_kind else step.steady_s) * self.rate_hz))
        marks, rests, command_t = [], [], []
        hold = max(RATE_HOLD_FRACTION * abs(rate), 10 * self.config.table.rate_tolerance_dps)
        still = 10 * self.config.table.rate_tolerance_dps

        period = 1.0 / self.rate_hz
        # the command's moment on the IMU's clock, at most: the stamp the reader answers with right
        # after set_rate returned (every frame measured before the table's answer had arrived by
        # then); None before this attempt's command
        commanded = {"by": None}
        rest_by = []                # "end": the first read at rest after the brake, bracket's end

        def settled(m) -> bool:
            """The read came after the ramp's compiled time (a read's moment is after its t_before;
            the ramp ends |rate| / accel after the command, 5 % and a period allowed)."""
            return (commanded["by"] is not None
                    and m.t_before > commanded["by"] + period + 1.05 * step.ramp_s)

        def mark():
            stream = self._reference().stream
            t_before = stream.sync()
            pos, rates = self._poll_table()
            t_after = stream.sync()
            if t_before is None or t_after is None:
                return None
            m = ramp_angle.Mark(float(pos[axis - 1]), float(rates[axis - 1]), t_before, t_after)
            at_rate, at_rest = abs(m.rate_dps - rate) <= hold, abs(m.rate_dps) <= still
            if at_rate:
                marks.append(m)
            elif at_rest:
                rests.append(m)
            # outside the ramp the table must hold its state, as _rotate's poll (issue 28 review
            # item 3): before the command the initial one, after the ramp's time the final one
            initial_rest = start_kind
            expect = (initial_rest if commanded["by"] is None else
                      (not initial_rest) if settled(m) else None)
            if expect is not None and not (at_rest if expect else at_rate):
                want = "at rest" if expect else f"{rate:g} deg/s"
                raise SequencerError(f"{self.table.name}: axis {axis} did not hold {want} while recording "
                                     f"{spec.name} outside its ramp (read {m.rate_dps:.6f} deg/s)")
            return m

        def record(recs, poll):
            total = {id(ch): r.n for ch, r in recs.items()}
            for ch, r in recs.items():
                r.n = int(round(first * ch.rate_hz / self.rate_hz))
            self._record(recs, poll)
            mark()
            # the command's moment on the IMU's clock lies between the newest stamp before it was
            # sent and the newest after its answer (command_t .. commanded["by"]); on a slow host
            # that bracket is the host's latency (on the twins times their speed: up to 2 s of
            # device time measured at speed 8 under load, docs/twins.md "Recorded ramps under load")
            command_t.append(self._reference().stream.sync() or rec_last(recs))
            if start_kind:
                # without the driver's wait (its settle_polls reads at the rate would widen the
                # bracket by seconds of device time on the twins, and the window with it): the
                # reads at the rate in the window, after the ramp's time, confirm it (mark)
                self.table.set_rate(axis, rate, wait=False)
                commanded["by"] = self._sync_reference()
            else:
                # the brake commanded without the driver's wait: the axis read here until at rest,
                # each read bracketed on the IMU's clock, so the rest's moment is known within a
                # read (the driver's own wait confirms it only after settle_polls reads at rest:
                # on the twins at speed 8 that is ~0.8 s of device time, past the window's end)
                self.table.set_rate(axis, 0.0, wait=False)
                commanded["by"] = self._sync_reference()
                deadline = time.monotonic() + 30.0
                while True:
                    m = mark()          # a read off both the rate and rest after the brake's time stops
                    if m is not None and abs(m.rate_dps) <= still:
                        rest_by.append(m.t_after + period)     # at rest by then on the IMU's clock
                        break
                    if time.monotonic() > deadline:
                        raise SequencerError(f"{self.table.name}: axis {axis} did not come to rest after the "
                                             f"recorded brake of {spec.name}")
                    self._check_pause()
            # the window closes the compiled time after the command on the IMU's clock (the
            # ramp and the turns, or the brake and the rest), not after a count of samples: the
            # stream runs ahead of what was recorded when the command went out (what the line and
            # the reader hold), and a brake cut short would end the window still turning.  After
            # the command's latest moment (commanded["by"]), not its earliest (command_t): a command
            # that reached the table late (a slow host: the twins' clock runs on meanwhile, at
            # their speed) otherwise cut the brake ("read at rest only after the window closed",
            # the run stopped) or the turns; and a brake's window holds its first read at rest
            # (rest_by: the brake's end proved inside the window, however late that read came)
            after = step.capture_s - (step.rest_s if start_kind else step.steady_s)
            end_t = commanded["by"] + after
            if rest_by:
                end_t = max(end_t, rest_by[-1] - period)
            for ch, r in recs.items():
                r.n = max(total[id(ch)] - r.n + r.done if r.last_t is None else
                          r.done + int(round((end_t - float(r.last_t)) * ch.rate_hz)), r.done)
            self._record(recs, poll)
            if start_kind:
                mark()              # still at the rate after the window (the brake comes after)
            else:                   # at rest after the window: its position
                # a read after the window's last stamp still turning: the table was turning at
                # the window's end, which then does not hold the whole brake (the angle and the
                # rest edge would be wrong)
                after_window = mark()
                if after_window is not None and abs(after_window.rate_dps) > still:
                    raise SequencerError(f"{self.table.name}: axis {axis} was still braking after the window of "
                                         f"{spec.name} closed (read {after_window.rate_dps:.6f} deg/s): the table "
                                         f"brakes slower than its rate_accel_dps2 ({step.accel_dps2:g} deg/s^2)")
                self._wait_rest(axis)
                mark()

        body_sign = spec.rate_dps / rate
        meta = {"axis_body": list(spec.axis_body), "rate_dps": spec.rate_dps, "table_axis": axis,
                "table_rate_dps": rate, "revolutions": step.revolutions,
                "axis_elevation_deg": round(step.elevation_deg, 9), "table_deg": list(step.table_deg),
                "mounting": list(self.mounting), "record_ramp": step.record_ramp,
                "ramp_accel_dps2": step.accel_dps2}

        def completed(rec):
            edge = rec["last_t"] + 0.5 * period if start_kind else rec["first_t"] - 0.5 * period
            mean_rate = float(np.mean([m.rate_dps for m in marks])) if marks else rate
            if not start_kind and (not rest_by or rest_by[-1] > rec["last_t"] + period):
                # the brake's end must lie inside the window: the first read at rest bounds it (its
                # bracket's end and a period); later than the window's last stamp (and a period:
                # the brake's last period at most, a T^2 / 2 = 0.015 deg at 300 deg/s^2 and 100
                # Hz, far below the window's angle_sigma_deg), the window may not hold the whole
                # brake (issue 28 review item 3)
                late = (rest_by[-1] - rec["last_t"]) if rest_by else float("nan")
                raise SequencerError(f"{spec.name}: the table was read at rest only after the window closed "
                                     f"(by {late:.3f} s of the IMU's clock): "
                                     f"its brake may be cut short; check rate_accel_dps2 ({step.accel_dps2:g} "
                                     "deg/s^2) against the table's")
            # each read placed in its bracket alone, their mean, and a 1-sigma from the brackets'
            # widths not divided by the reads (docs/design.md, "Seventeenth session: recorded
            # ramps": a common moment from every bracket at once, Beta(2, 2) in each, was tried
            # this session and taken back: on a real line it refused good windows or was
            # overconfident, where this one is only conservative)
            turning = ramp_angle.position_at(marks, edge, mean_rate, period)
            sigma = ramp_angle.angle_sigma(marks, mean_rate, period)
            if turning is None or not rests:
                raise SequencerError(f"{spec.name}: the table's position was not read at the rate and at rest "
                                     "around the recorded ramp: its angle is unknown")
            # the whole turns: the profile from the command's moment (the window may hold more rest
            # than compiled: the stream runs ahead of the command by what the line holds)
            # (the command's moment: the middle of its bracket, within half of it)
            commanded_t = 0.5 * (command_t[-1] + commanded["by"])
            # the whole turns are chosen nearest the compiled profile's angle: that takes the
            # command's moment within a quarter turn at the rate (half of it is the window's
            # angle's own 1-sigma budget); a wider bracket (a slow host: the line or the reader
            # late) could put the angle a whole turn off, with nothing in angle_sigma_deg to say
            # so (this session's review: 250 deg/s, 1.6 s late, written complete one turn off)
            ambiguity = abs(rate) * 0.5 * (commanded["by"] - command_t[-1])
            if ambiguity >= WHOLE_TURN_MARGIN_DEG:
                raise BadRecording(f"the table's whole turns in the window are ambiguous: the rate's command reached "
                                   f"the table within {commanded['by'] - command_t[-1]:.3g} s of the IMU's clock, "
                                   f"{ambiguity:.0f} deg at {abs(rate):g} deg/s (limit {WHOLE_TURN_MARGIN_DEG:g} deg): "
                                   "the host or the line was late")
            turning_s = (edge - commanded_t) if start_kind else (commanded_t - edge)
            angle = ramp_angle.window_angle(rests[-1].position_deg, turning,
                                            ramp_angle.expected_angle(rate, turning_s, step.accel_dps2,
                                                                      step.record_ramp),
                                            step.record_ramp)
            rates = (0.0, mean_rate) if start_kind else (mean_rate, 0.0)
            # the reads the angle came from (position deg, rate deg/s, the IMU stamps before and after)
            reads = [[round(m.position_deg, 6), round(m.rate_dps, 6), m.t_before, m.t_after] for m in rests + marks]
            return _optional(angle_deg=body_sign * angle, table_rate_readback_dps=mean_rate,
                             rate_start_dps=body_sign * rates[0], rate_end_dps=body_sign * rates[1],
                             temperature_c=rec["temp"], table_reads=reads, angle_sigma_deg=round(sigma, 9))

        def agrees(r, done):
            # the IMU's gyro over the window against the table's angle (issue 28, seventeenth
            # session): the redundancy a recorded ramp offers, as statics' and steady turns' have
            _, head = r.samples()
            found = steadiness.ramp_disagreement(
                step.record_ramp, head, r.gyro_tail(), r.gyro_sum, r.done, window_s=(r.done + r.lost) * r.period,
                rate_hz=1.0 / r.period, rest_s=step.rest_s, turning_s=step.steady_s,
                table_rate_dps=done["table_rate_readback_dps"], table_angle_deg=done["angle_deg"],
                angle_sigma_deg=done["angle_sigma_deg"],
                position_tolerance_deg=self.config.table.position_tolerance_deg)
            return None if found is None else f"{MOTION_WORDS}: {found}"

        attempts = []

        def start():
            # every attempt from the window's initial state (issue 28 review item 2): a recording
            # kept aside leaves a "start" window's table turning and an "end" window's at rest,
            # where the next would read neither a rest nor the rate before its command
            if attempts:
                if start_kind:
                    self.table.set_rate(axis, 0.0)
                    self._wait_rest(axis)
                else:
                    self.table.set_rate(axis, rate)
                self._discard(step.settle_s)
            attempts.append(1)
            commanded["by"] = None
            rest_by.clear()
            marks.clear()
            rests.clear()
            mark()                  # at rest ("start") or at the rate ("end") before the window

        with contextlib.ExitStack() as fine:       # each IMU read frame by frame: reads placed within a frame
            for ch in self._alive():
                fine.enter_context(ch.stream.fine())
            self._record_segment(spec.name, "rotation", meta, n, mark, completed, start=start, record=record,
                                 check=agrees)
        self.table.set_rate(axis, 0.0)

    def _sync_reference(self) -> float:
        """The reference IMU's newest stamp received (``ImuStream.sync``), asked until its reader
        answers (a loaded host can take longer than one ask's 0.25 s), checking for a pause."""
        while True:
            t = self._reference().stream.sync()
            if t is not None:
                return t
            self._check_pause()

    def _wait_rest(self, axis: int, wall_s: float = 30.0) -> None:
        """Until the axis reads back at rest (within ten rate tolerances), checking for a pause."""
        still = 10 * self.config.table.rate_tolerance_dps
        deadline = time.monotonic() + wall_s
        while True:
            _, rates = self._poll_table()
            if abs(float(rates[axis - 1])) <= still:
                return
            if time.monotonic() > deadline:
                raise SequencerError(f"{self.table.name}: axis {axis} did not come to rest after the recorded "
                                     f"brake (read {float(rates[axis - 1]):.4f} deg/s)")
            self._check_pause()
            time.sleep(0.01)

    def _operator(self, step: Operator) -> None:
        opened = False
        if step.remount and self.table is not None:
            self._stop_table()
            try:
                self.table.open_interlocks()
                opened = True
                self.display.note("interlocks open: the table is unpowered")
            except UserError:
                self.display.note("this controller cannot open its interlocks: switch the drive off "
                                  "before touching the table")
        self.display.prompt(step.instruction)
        self.operator.confirm(step, self.interrupts)
        if opened:
            self.table.close_interlocks()
        if step.mounting is not None:
            self.mounting = tuple(step.mounting)

    def _chamber(self, step: Chamber) -> None:
        """Ask the operator to set the chamber, then wait: the ramp's time, then the fixed soak or
        until the first IMU's own temperature settles (station.core.chamber.SlopeSettle, at most
        ``max_s`` after the ramp); then check the IMU's temperature against the setpoint (a
        disagreement beyond ``agree_c`` is a finding in the segment's manifest entry, said)."""
        from station.core.chamber import SlopeSettle, finding

        self.display.prompt(step.instruction)
        self.operator.confirm(step, self.interrupts)
        self._each(lambda ch: ch.stream.drain())
        rule = SlopeSettle(step.slope_c_per_min, step.window_s) if step.soak_s is None else None
        total = step.ramp_s + (step.soak_s if step.soak_s is not None else step.max_s)
        t_first, last_c, settled = None, float("nan"), False
        while True:
            b = self._take(max(1, int(round(self.rate_hz))))
            t_first = b.t_s[0] if t_first is None else t_first
            elapsed = float(b.t_s[-1] - t_first)
            finite = np.isfinite(b.temp_c)
            if finite.any():
                last_c = float(b.temp_c[finite].mean())
                if rule is not None and elapsed >= step.ramp_s:
                    rule.feed(float(b.t_s[-1]), last_c)
            reference = self._reference()
            self._each(lambda ch: ch is reference or ch.stream.drain())
            self._show_values()
            self.display.advance(min(elapsed, total), total)
            if rule is None and elapsed >= total:
                settled = True
                break
            if rule is not None and rule.settled:
                settled = True
                break
            if elapsed >= total:
                break
            self._check_pause()
        entry = {"setpoint_c": step.setpoint_c, "from_c": step.from_c, "waited_s": round(elapsed, 3),
                 "imu_c": round(last_c, 4), "settled": settled}
        problem = finding(step.setpoint_c, last_c, step.agree_c)
        if not settled:
            problem = "; ".join(filter(None, [problem, f"the IMU's temperature had not settled after "
                                                       f"{step.max_s:g} s (chamber.settle_max_s)"]))
        if problem:
            entry["finding"] = problem
            self.display.note(f"chamber finding: {problem}")
        else:
            self.display.note(f"chamber at {step.setpoint_c:g} C: the IMU at {last_c:.2f} C after {elapsed:.0f} s")
        self._chamber_c = step.setpoint_c
        self._chamber_entry[step.segment] = entry

    def _checkpoint(self, step: Checkpoint) -> None:
        self.display.saved(step.segment)

    # ------------------------------------------------------------------ hand schemes
    def _hand(self, step) -> None:
        from station.bench.manual import hand_step

        if self._session is None:
            from station.bench.manual import Session

            self._session = Session(self.writer, self.rate_hz)
        hand_step(self, step)

    def _finish_session(self, steps) -> None:
        from station.bench.manual import finish_session

        finish_session(self, steps)

    # ------------------------------------------------------------------ table helpers
    def _poll_table(self):
        """(positions, rates) of the table, with a fault check; live display."""
        if self.table is None:
            return None, None
        self._last_poll = time.monotonic()
        self.table.check_ok()
        pos, rates = self.table.read_positions_deg(), self.table.read_rates_dps()
        self.display.values_update({"positions_deg": pos.tolist(), "rates_dps": rates.tolist()})
        return pos, rates

    def _check_targets(self, targets) -> None:
        for axis, (target, lim) in enumerate(zip(targets, self.limits), 1):
            if target is None:
                continue
            if not math.isfinite(target):
                raise SequencerError(f"axis {axis}: position {target!r} is not a number")
            if lim.angle_limits is not None and not lim.angle_min_deg - 1e-9 <= target <= lim.angle_max_deg + 1e-9:
                raise SequencerError(f"axis {axis}: position {target:g} deg is outside its limits "
                                     f"[{lim.angle_min_deg:g}, {lim.angle_max_deg:g}] deg")

    def _waypoints(self, targets) -> list:
        """The moves to reach ``targets``: axes with angle limits go there in steps of at most
        WAYPOINT_DEG, so that the controller's shortest way round stays inside the limits."""
        limited = [i for i, (t, lim) in enumerate(zip(targets, self.limits))
                   if t is not None and lim.angle_limits is not None]
        if not limited:
            return [targets]
        now = self.table.read_positions_deg()
        start = {i: self.limits[i].angle_min_deg + (now[i] - self.limits[i].angle_min_deg) % 360.0
                 for i in limited}
        steps = max(math.ceil(abs(targets[i] - start[i]) / WAYPOINT_DEG) for i in limited)
        out = []
        for k in range(1, steps):
            point = [None] * len(targets)
            for i in limited:
                point[i] = start[i] + (targets[i] - start[i]) * k / steps
            out.append(point)
        return out + [targets]


def rec_last(recs) -> float:
    """The newest stamp recorded by any of ``recs`` (channel -> Recording)."""
    return max(float(r.last_t) for r in recs.values() if r.last_t is not None)


def _optional(**values) -> dict:
    return {k: v for k, v in values.items() if v is not None}


def _clock_restarted(directory, t_s) -> bool:
    """Whether the IMU's stamp ``t_s`` is earlier than the last reading of a warm-up record in the
    capture ``directory`` (warmup.csv, warmup-2.csv, ...): its clock went back, the IMU was
    restarted since (a record that cannot be read, a FIFO in its place, is left out)."""
    last = []
    for path in warmup_records(directory):
        try:
            last.append(float(read_regular_file(path).split()[-1].split(b",")[0]))
        except (OSError, ValueError, IndexError):
            pass
    last = [t for t in last if math.isfinite(t)]
    return bool(last) and float(t_s) < max(last)


NEWEST_SEGMENTS = 3     # the last segments of the manifest whose files' stamps are read (_last_temperature)


def _last_temperature(directory):
    """(stamp s, temperature degC) of the newest temperature the capture ``directory`` recorded, and
    every warm-up record's readings the noise is judged from (arrays of (t, temp), the newest
    last): the newest temperature is the mean temperature (the manifest's ``temperature_c``)
    of the last NEWEST_SEGMENTS segments the manifest lists with one, at their files' last stamps,
    or without any, the last reading of each warm-up record (warmup.csv, warmup-2.csv, ...); (None,
    None, records) when there is none.  What
    cannot be read (a record or a file missing, a FIFO in its place) is left out."""
    from station.io.capture import read_capture

    newest, warmups, records = [], [], []
    for path in warmup_records(directory):
        try:
            rows = np.loadtxt(io.BytesIO(read_regular_file(path)), delimiter=",", skiprows=1, ndmin=2)
        except (OSError, ValueError):
            continue
        rows = rows[np.all(np.isfinite(rows), axis=1)] if rows.size and rows.shape[1] >= 2 else np.zeros((0, 2))
        if len(rows):
            warmups.append((float(rows[-1, 0]), float(rows[-1, 1])))
            records.append(rows[:, :2])
    try:
        capture = read_capture(directory, load_data=False)
        segments = list(capture.segments)
    except Exception:            # (the capture's own reader says what is wrong elsewhere)
        segments = []
    found = 0
    for seg in reversed(segments):      # (the manifest lists them as recorded: the newest few)
        if found >= NEWEST_SEGMENTS:
            break
        temp = seg.extra.get("temperature_c")
        if isinstance(temp, bool) or not isinstance(temp, (int, float)) or not math.isfinite(temp):
            continue
        try:
            tail = read_regular_file(capture.path / seg.file)[-4096:].split()
            t = float(tail[-1].split(b",")[0])
        except (OSError, ValueError, IndexError):
            continue
        if math.isfinite(t):
            newest.append((t, float(temp)))
            found += 1
    records.sort(key=lambda r: r[-1, 0])          # (the newest last)
    # a segment's when there is one (recorded warm, after a warm-up that ended): a warm-up record
    # newer than it may be one cut short (Ctrl-C) while an IMU switched off warmed up again, whose
    # last reading is still cold (review of the twentieth session)
    newest = newest or warmups
    if not newest:
        return None, None, records
    t, temp = max(newest)
    return t, temp, records


def _temperature_fell(directory, temp_c, window_s):
    """(how far, the threshold) in degC when the IMU's first reading ``temp_c`` of a resumed
    warm-up is below the newest temperature the capture recorded (_last_temperature) by more than
    its readings' noise allows; None otherwise.  For an IMU whose stamps are the host's clock
    (they never go back, _clock_restarted cannot tell): left on, its self-heating holds it where
    the run left it (a warm-up's slope is never negative); switched off, it cooled toward the
    room.  The noise: the readings of the newest warm-up record with three in its last
    ``window_s`` (the slope rule's window) about a straight line there, and their resolution (the
    smallest step between readings of any record, as a uniform quantisation, q^2/12), for both
    readings (x sqrt 2), 4 sigma: a drop
    beyond that is not noise.  A room that cooled meanwhile counts as a drop too (the IMU is not
    where the run left it: the minimum is waited)."""
    _, last, records = _last_temperature(directory)
    if last is None or not math.isfinite(temp_c):
        return None
    var = 0.0
    # the scatter: the newest record with 3 readings in its last window (one cut short after a
    # reading or two says nothing of it); the resolution: the smallest step of any record (a
    # quantised sensor steady in the newest shows none)
    for readings in reversed(records):
        t, temp = readings[:, 0], readings[:, 1]
        sel = t >= t[-1] - window_s
        if np.count_nonzero(sel) >= 3:
            fit = np.polyfit(t[sel], temp[sel], 1)
            resid = temp[sel] - np.polyval(fit, t[sel])
            var += float(np.sum(resid ** 2) / max(np.count_nonzero(sel) - 2, 1))
            break
    steps = np.concatenate([np.abs(np.diff(r[:, 1])) for r in records] or [np.zeros(0)])
    steps = steps[steps > 0]
    if len(steps):
        var += float(np.min(steps)) ** 2 / 12.0
    # (no record to judge the noise by: the last digit the record keeps, 0.1 mK, as a resolution)
    threshold = 4.0 * math.sqrt(2.0 * max(var, 1e-8 / 12.0))
    drop = last - float(temp_c)
    return (drop, threshold) if drop > threshold else None


def _slope_c_per_h(times, temps, window_s):
    """Least-squares temperature slope over the last ``window_s`` (None before a full window)."""
    if len(times) < 3 or times[-1] - times[0] < window_s:
        return None
    t = np.asarray(times)
    sel = t >= t[-1] - window_s
    return float(np.polyfit(t[sel], np.asarray(temps)[sel], 1)[0] * 3600.0)
