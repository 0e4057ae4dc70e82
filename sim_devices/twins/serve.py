"""The table twin and one or several IMU twins on pseudo-terminals, served by one loop
(``station sim serve [--imus N]``).

One thread runs everything: it waits (select) for commands on any port or for the next
IMU frame to fall due, answers the commands, fires the faults due, and writes the frames
due by the present device time.  Device time comes from one :class:`SimClock`, so
``speed`` changes how fast frames come, never a byte of them.  Several IMUs (``imus``) sit
on the one table: each is its own sensor (its own truth: errors, noise seed, lever arm, and
its own serial number) on its own pseudo-terminal (:class:`ImuLine`), all measuring the
same platform motion; the lossless clock waits for the slowest reading reader.
"""
from __future__ import annotations

import dataclasses
import os
import select
import threading
import time
from dataclasses import dataclass, field

import numpy as np

from drivers.protocols.csvlines import CsvFormat
from sim_devices.chamber import ChamberAir
from sim_devices.truth import default_truth

from .chamber_panel import ChamberPanel
from .clock import SimClock, StepClock
from .faults import Faults, ImuFaults, StreamFaulter
from .geometry import TableGeometry
from .imu import ImuTwin
from .imu_csv import CsvFrontEnd
from .imu_vectornav import VectorNavFrontEnd
from .imu_xsens import XsensFrontEnd
from .pty import PtyEndpoint
from .tcp import TcpEndpoint
from .table import TableConfig, TableTwin
from .table_acutrol import AcutrolFrontEnd
from .table_aerosmith import AerosmithFrontEnd

#: the IMU port's transmit buffer holds this much wall time of the stream (at least 8 KiB): a
#: reader that keeps up on average never loses a frame to a scheduling pause, at any speed
STREAM_BUFFER_WALL_S = 2.0
MIN_STREAM_BUFFER = 8192
#: frames per wall second above which frames go out every 20 ms (not every 5 ms)
FAST_STREAM_HZ = 10000.0

TABLE_PROTOCOLS = ("acutrol", "aerosmith")
IMU_PROTOCOLS = ("vectornav", "csv", "xsens")


@dataclass
class BenchOptions:
    speed: float = 1.0
    seed: int = 1
    axes: int = 3
    table_protocol: str = "acutrol"
    imu_protocol: str = "vectornav"
    faults: Faults = field(default_factory=Faults)
    csv_format: CsvFormat = field(default_factory=CsvFormat)
    csv_clock_start_s: float = 0.0      # csv: the line's ``t`` is a host's clock, not the IMU's (a logger that
                                        #   stamps each line as it arrives): device time plus this, the host's
                                        #   clock at the IMU's power-on.  A twin started again with a later one
                                        #   is a host-stamped IMU switched off and on: its stamps go on, the
                                        #   IMU is cold again (issue 28)
    table_config: TableConfig = field(default_factory=lambda: TableConfig(angle_error_arcsec=None))
    table_framing: str = "tcp"    # acutrol replies: "tcp" (error code, length first) or "gpib"
    table_tcp_port: int | None = None   # serve the table on TCP 127.0.0.1:port (0: any free port)
    table_silent_motion: bool = False   # aerosmith: JOG, STO, SGO not answered (docs/protocols.md)
    imu_startup: str = "factory"  # vectornav power-up: "factory" ($VNYMR at 40 Hz, binary off, as a
                                  #   VN-100 leaves the factory) or "binary" (station's binary output on)
    record: bool = False          # keep the times of the frames sent intact (tests)
    imus: int = 1                 # IMU twins on the table, each on its own pseudo-terminal
    imu_faults: tuple = ()        # per IMU (ImuFaults, IMU k the k-th): its stream faults; empty:
                                  #   the first IMU has faults.imu, the others none
    lossless: bool = True         # the twins' clock is throttled to the IMU's reader: while a reader
                                  #   that is reading has not taken the frames its line could hold,
                                  #   device time stands still (and the table's commands wait), so no
                                  #   frame is lost at any --speed; False: frames the reader did not
                                  #   take are dropped, as a real IMU's UART does
    chamber: bool = False         # a temperature chamber's panel on its own pseudo-terminal (chamber_panel.py)
    chamber_ramp_c_per_min: float = 2.0     # how fast the chamber's air follows a new setpoint, degC/min
    chamber_range_c: tuple = (-70.0, 180.0)     # the setpoints the chamber can hold, degC
    chamber_said: object = None   # where the panel says what it was set to (the console), None: nowhere


READER_ACTIVE_S = 2.0             # a reader that took bytes within this (wall s) is reading
#: lossless: device time runs at most this many bytes of the stream ahead of the reader (about
#: what a pty holds: 4 KiB in the line discipline, 16 KiB in the kernel's flip buffers)
LINE_BYTES = 16384
#: a line without a reader never takes more than this in all: the kernel's flip buffers hold at
#: most 64 KiB (TTYB_DEFAULT_MEM_LIMIT, the most any tty port has) besides the unread bytes of
#: n_tty's read buffer (a pty took 14-22 KiB in all on Linux 6.18, by the size of the writes)
FLIP_MAX_BYTES = 65536
#: lossless: a reader that takes nothing from the IMU line for this long (wall s) while device
#: time is held for it and the table's client asks something is not reading (a program busy with
#: the table that reads the IMU only now and then, not a starved reader): it is taken for absent
#: until it reads again, so the world goes on and the frames it does not take are dropped, as a
#: real IMU's UART drops them.  Before, the table was answered at the held time for up to
#: READER_ACTIVE_S: a client that moved the table without reading the IMU saw the axis stand
#: still and took it for stalled (docs/twins.md, "The twins' clock waits for the IMU's reader")
READER_STALL_S = 0.25
#: the loop looks at every line at least every 20 ms of wall time (``_timeout``); a look longer
#: after the previous one than this is the loop's own absence, not the reader's
LOOP_AWAY_S = 0.1
#: Lossless, and no longer a bound of its own (issue 29, the kill/resume flake): the table's
#: commands wait while a reading reader still has frames in its transmit queue, for as long as it
#: takes them; a reader that takes nothing for READER_STALL_S is judged absent and its queue
#: dropped (as a UART's).  Before, they waited at most 0.1 s of wall time (TABLE_WAIT_S): under
#: load a reader thread descheduled that long found the table's answer ("at rest") before the
#: frames measured before it -- up to 7.4 s of device time (16 KiB of a 50 Hz stream) and, once
#: its queue had grown while it was judged absent, 52 s -- and the settle that counts from the
#: newest frame received began inside the move: a static recorded while the table turned.


class BenchServer:
    """The two twins, their pseudo-terminals and the loop serving them."""

    def __init__(self, truth, options: BenchOptions | None = None):
        o = options or BenchOptions()
        if o.table_protocol not in TABLE_PROTOCOLS:
            raise ValueError(f"table protocol must be one of {TABLE_PROTOCOLS}")
        if o.imu_protocol not in IMU_PROTOCOLS:
            raise ValueError(f"IMU protocol must be one of {IMU_PROTOCOLS}")
        self.options = o
        truth0 = truth[0] if isinstance(truth, (list, tuple)) else truth
        self.truth = truth0
        self.clock = SimClock(o.speed)
        self.step_clock = StepClock(self.clock)     # the table's: commands at the step's time
        geo_rng, fault_rng = (np.random.default_rng(s) for s in np.random.SeedSequence(o.seed).spawn(2))
        geometry = TableGeometry.default(o.axes, truth0.bench.lever_arm_m)
        table_config = o.table_config
        if table_config.angle_error_arcsec is None:       # the truth's table angle error
            table_config = dataclasses.replace(table_config,
                                               angle_error_arcsec=truth0.bench.table_angle_error_arcsec)
        self.table = TableTwin(geometry, self.step_clock, config=table_config,
                               ripple_fraction=truth0.bench.rate_ripple_fraction,
                               ripple_hz=truth0.bench.rate_ripple_hz, rng=geo_rng,
                               faults=o.faults.table,
                               interlocks_closed=o.table_protocol == "aerosmith")
        # the temperature chamber around the table: its air at the room's temperature until it is
        # set (the panel, or set_chamber); every IMU on the table follows it (sim_devices/chamber.py)
        self.chamber = ChamberAir(truth0.temperature.start_c)
        self.chamber_panel = (ChamberPanel(self.chamber, o.chamber_ramp_c_per_min, o.chamber_range_c,
                                           said=o.chamber_said) if o.chamber else None)
        truths = list(truth) if isinstance(truth, (list, tuple)) else [truth]
        if o.imus < 1 or len(truths) not in (1, o.imus):
            raise ValueError(f"{o.imus} IMUs need one truth or one per IMU, got {len(truths)}")
        self.truths = truths if len(truths) == o.imus else truths + [None] * (o.imus - 1)
        self.lines = [ImuLine(self.table, t, o, k, fault_rng if k == 0 else None, air=self.chamber)
                      for k, t in enumerate(self.truths)]
        if o.table_protocol == "acutrol":
            self.table_frontend = AcutrolFrontEnd(self.table, o.table_framing)
        else:
            self.table_frontend = AerosmithFrontEnd(self.table, silent_motion=o.table_silent_motion)
        self.table_port = PtyEndpoint() if o.table_tcp_port is None else TcpEndpoint(o.table_tcp_port)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.error: BaseException | None = None
        self.table_deferred_steps = 0     # loop steps in which the table's commands waited (lossless)
        self._table_asked = False         # a table command came (or waited) in the last step
        self._requests: list = []         # (function, done event): run by the loop between steps
        self.steps = 0                    # turns of the loop begun
        self._cap: float | None = None    # lossless: the device time the clock stops at (set each step)
        self._wake_fds: tuple[int, int] | None = None   # a pipe: a byte written wakes the loop's select

    # the first IMU (the only one of a one-IMU bench) by its old names
    imu = property(lambda self: self.lines[0].imu, lambda self, v: setattr(self.lines[0], "imu", v))
    faulter = property(lambda self: self.lines[0].faulter, lambda self, v: setattr(self.lines[0], "faulter", v))
    imu_frontend = property(lambda self: self.lines[0].frontend,
                            lambda self, v: setattr(self.lines[0], "frontend", v))
    imu_port = property(lambda self: self.lines[0].port, lambda self, v: setattr(self.lines[0], "port", v))
    _reader_seen = property(lambda self: self.lines[0].reader_seen)

    @property
    def readers_given_up(self) -> int:
        """Times a reader was judged not reading (READER_STALL_S), all IMUs."""
        return sum(line.readers_given_up for line in self.lines)

    @property
    def table_path(self) -> str:
        return self.table_port.path

    @property
    def imu_path(self) -> str:
        return self.lines[0].port.path

    @property
    def imu_paths(self) -> list:
        return [line.port.path for line in self.lines]

    @property
    def chamber_path(self) -> str | None:
        """The chamber panel's pseudo-terminal (``chamber=True``), else None."""
        return None if self.chamber_panel is None else self.chamber_panel.path

    # ------------------------------------------------------------------ the loop
    def step(self, timeout_s: float) -> None:
        """One turn of the loop: commands, the IMU frames due, faults.

        Every command of a step happens at the step's device time ``now`` (the table sees a
        :class:`StepClock`).  While the IMU has a reader, the frames measured up to ``now`` are
        written to the IMU's line before the table's answers are written to the table's (with
        no reader, the table is answered first: nobody waits for the frames).  Lossless: while
        the IMU's transmit queue holds frames its line could not take yet and its reader is
        reading, device time stands still and the table's commands wait (a few ms: the reader
        is taking the frames).  So a reader that has received the table's answer and then
        reads what is waiting on the IMU line has every frame measured before that answer
        (``station.bench.imu_stream.ImuStream.sync``), at any speed."""
        self.steps += 1
        while self._requests:
            fn, done = self._requests.pop(0)
            fn()
            done.set()
        wall = time.monotonic()
        for line in self.lines:
            self._judge_reader(wall, line)
        defer_table = self._defer_table([wall - line.last_taken_wall < READER_ACTIVE_S for line in self.lines])
        if defer_table:
            self.table_deferred_steps += 1
        if self.clock.capped:
            timeout_s = min(timeout_s, 0.001)        # waiting for the reader
        imu_ports = [line.port for line in self.lines]
        panel = [self.chamber_panel.port] if self.chamber_panel is not None and not self.chamber_panel.port.closed else []
        ports = [p for p in (*imu_ports, self.table_port, *panel)
                 if not p.closed and not (p is self.table_port and defer_table)]
        writers = [p for p in (self.table_port, *imu_ports) if not p.closed and p.backlog]
        wake = [self._wake_fds[0]] if self._wake_fds is not None else []
        if ports or writers or wake:
            readable, _, _ = select.select(ports + wake, writers, [], timeout_s)
        else:       # every line closed, no wake pipe (serve_forever in the caller's thread): wait
            readable = []       #   the turn's timeout, not a turn as fast as the loop can go
            time.sleep(timeout_s)
        if wake and wake[0] in readable:
            os.read(wake[0], 4096)
        self._table_asked = self.table_port in readable or (
            defer_table and not self.table_port.closed and bool(select.select([self.table_port], [], [], 0)[0]))
        wall = time.monotonic()
        active = [wall - line.last_taken_wall < READER_ACTIVE_S for line in self.lines]
        now = self.clock.now()
        self.step_clock.set(now)
        self.table.update(now)
        if self.chamber_panel is not None:       # set before the frames of this step are measured
            self.chamber_panel.serve(readable, now)
        tf = self.options.faults.table
        if tf.disconnect_at_s is not None and now >= tf.disconnect_at_s:
            self.table_port.close()
        for line in self.lines:
            if line.faults.disconnect_at_s is not None and now >= line.faults.disconnect_at_s:
                line.port.close()
        table_first = not any(active)
        if table_first:
            self._serve_table(readable, now, defer_table)
        active = [self._serve_imu(readable, now, a, line) for a, line in zip(active, self.lines)]
        if not table_first:
            self._serve_table(readable, now, self._defer_table(active))
        cap = None
        for a, line in zip(active, self.lines):
            if (self.options.lossless and a and not line.port.closed and line.frontend.streaming
                    and not line.faults.muted(now)):
                # the world waits for the reader: device time runs at most as far as the frames
                # the line holds (none while frames are still queued); several IMUs: the slowest
                lead = 0.0 if line.port.backlog else LINE_BYTES / (line.bytes_per_frame * line.imu.rate_hz)
                cap = now + lead if cap is None else min(cap, now + lead)
        self.clock.limit(cap)
        self._cap = cap

    def _serve_table(self, readable, now: float, defer: bool) -> None:
        if self.table_port in readable and not defer:
            data = self.table_port.read()
            if data and not self.table.stalled(now):
                self.table_port.write(self.table_frontend.receive(data))
        self.table_port.flush()

    def _serve_imu(self, readable, now: float, reader_active: bool, line=None) -> bool:
        """One IMU's commands and the frames due by ``now``; returns whether its reader is active."""
        line = self.lines[0] if line is None else line
        port, frontend, faulter = line.port, line.frontend, line.faulter
        if line.faults.muted(now):
            # a mute sensor (faults imu.mute): its commands heard and not answered, no frames (the
            # frames due are consumed unmade: the stream goes on from the present when it speaks)
            if port in readable:
                port.read()
            if not port.closed and frontend.streaming:
                faulter.overflowed(line.imu.sample_times_until(now).size, recorded=False)
            port.flush()
            line.unread = port.unread()
            return False
        sent = port.sent_bytes
        if port in readable:
            data = port.read()
            if data:
                self._drop_stale(line)
            if data:
                # the replies go out at the rate in effect when the commands came (a new baud
                # rate, register 05, applies after its reply)
                baud = frontend.line_baud
                port.write(frontend.receive(data, now), baud=baud)
        if not port.closed:
            if self._imu_behind(port.max_backlog // 2, line) and not (self.options.lossless and reader_active):
                # nobody reads: the frames due are lost anyway, do not compute them
                faulter.overflowed(line.imu.sample_times_until(now).size, recorded=False)
            else:
                before = faulter.frames_sent
                frames = frontend.produce(now)
                if frames and faulter.frames_sent > before:
                    self._size_stream_buffer(len(frames) / (faulter.frames_sent - before), line)
                # lossless: a batch larger than the backlog (this loop itself was descheduled) is kept
                if frames and not port.write(frames, droppable=not self.options.lossless):
                    faulter.overflowed(faulter.frames_sent - before)
        unread = port.unread()
        port.flush()
        # the reader took bytes: fewer wait on the line (only a reader takes them), or, once a
        # reader was seen, the line took bytes in this step (when writing the frames or
        # flushing: without a reader the line fills once, ~20 KiB, and takes nothing more).  A
        # reader is seen when fewer wait on the line, or when the line has passed on more than
        # it can hold without one: while the queue keeps the line full, the kernel refills the
        # read buffer from its flip buffers as soon as the reader has read, so the unread count
        # may never be seen to fall (the reader was then taken for absent and frames dropped)
        took = port.sent_bytes > sent
        line.reader_seen = (line.reader_seen or unread < line.unread
                            or port.sent_bytes - unread > FLIP_MAX_BYTES)
        if unread < line.unread or (line.reader_seen and took):
            line.last_taken_wall = time.monotonic()
            reader_active = True
        line.unread = port.unread()
        if not reader_active:       # what is queued now was made while nobody read the line
            line.stale_end = port.sent_bytes + port.backlog
        return reader_active

    def _drop_stale(self, line) -> None:
        """A driver's command has come: the frames still queued that were made while nobody read
        the line (a port just opened, an adapter plugged in again: up to half the transmit
        buffer, two seconds of wall time of the stream) are dropped, as a real IMU's bytes on a
        line nobody reads are gone (counted as overflowed); the reply then follows what the line
        itself holds and what was queued for a reading reader, not seconds of queued stream
        (issue 29: 1.2 MB queued on the replugged line of tests/test_multi_imu.py, "no reply
        to $VNASY,0 within 10 s" at load 17).  The reader may already be seen when its command
        comes (a serial library flushes the input when it opens the port), so the frames are
        judged by when they were made, not by the reader's state at the command."""
        stale = min(line.stale_end - line.port.sent_bytes, line.port.backlog)
        if stale > 0:
            line.port.discard_front(stale)
            line.faulter.overflowed(int(round(stale / line.bytes_per_frame)), recorded=False)
        line.stale_end = line.port.sent_bytes

    def _defer_table(self, readers_active) -> bool:
        """Lossless: the table's commands wait while frames already measured are still in an
        IMU's transmit queue and its reader is taking them, however long it takes (the frames
        measured before an answer are on the IMU line when the answer is written: the reader's
        settle counts from them).  A reader that takes nothing meanwhile is judged absent after
        READER_STALL_S (:meth:`_judge_reader`), its queue dropped, and the table answered: a
        reader that has just died does not hold up the table long.  What the kernel holds
        reaches the reader when it reads what is waiting (``drivers.transport.Port.read_waiting``)."""
        if isinstance(readers_active, bool):
            readers_active = [readers_active] + [False] * (len(self.lines) - 1)
        return self.options.lossless and any(
            a and not line.port.closed and line.frontend.streaming and line.port.backlog > 0
            for a, line in zip(readers_active, self.lines))

    def _judge_reader(self, wall: float, line=None) -> None:
        """Lossless: while device time is held for an IMU's reader (frames wait in the
        transmit queue) and the table's client asks something, a reader that takes nothing for
        READER_STALL_S is not reading: taken for absent until it reads again (the clock runs
        free, the frames it does not take are dropped).  A reader that is merely slow takes
        bytes and is waited for; with no table client asking, nobody sees the world wait and a
        silent reader is waited for up to READER_ACTIVE_S, as before."""
        line = self.lines[0] if line is None else line
        # what the loop saw of the reader is as old as the loop's previous look: a loop that was
        # itself away (descheduled: a loaded host, the GIL of an in-process run) for more than
        # LOOP_AWAY_S has not seen the reader meanwhile, so it looks at the line first (the reader
        # took bytes: the queue moves on into the line) and counts the reader's silence again
        # from its return.  Before (issue 28, seventeenth session), a loop away 0.3 s judged a
        # reader that had been reading all along absent on its return and dropped its queue.
        away = wall - line.looked_wall > LOOP_AWAY_S
        line.looked_wall = wall
        if away and not line.port.closed:
            sent, unread = line.port.sent_bytes, line.port.unread()
            line.port.flush()
            if line.port.sent_bytes > sent or line.port.unread() < unread:
                line.last_taken_wall = wall
            line.unread = line.port.unread()
            if line.held_table_since is not None:
                line.held_table_since = wall
        held = (self.options.lossless and not line.port.closed and line.frontend.streaming
                and line.port.backlog > 0 and wall - line.last_taken_wall < READER_ACTIVE_S)
        if not held:
            line.held_table_since = None
            return
        if self._table_asked and line.held_table_since is None:
            line.held_table_since = wall
        if (line.held_table_since is not None
                and wall - max(line.last_taken_wall, line.held_table_since) >= READER_STALL_S):
            line.last_taken_wall = wall - READER_ACTIVE_S            # absent until it reads
            line.held_table_since = None
            line.readers_given_up += 1
            self._drop_queue(line)

    def _drop_queue(self, line) -> None:
        """Lossless, a reader judged absent: the frames waiting in its transmit queue are lost,
        as a UART's that nobody empties (counted: ``faulter.frames_overflowed``, the port's
        ``dropped_bytes``).  Kept, they would reach the reader when it reads again, after the
        table's answers given meanwhile: measured before those answers and received after them,
        they would break what a settle counts from (issue 29)."""
        queued = line.port.backlog
        if queued:
            line.port.dropped_bytes += queued
            line.port.clear_output()
            line.faulter.overflowed(int(round(queued / line.bytes_per_frame)), recorded=False)

    def _imu_behind(self, limit: int, line=None) -> bool:
        """The IMU's transmit queue holds more than ``limit`` bytes its line could not take."""
        line = self.lines[0] if line is None else line
        return (not line.port.closed and line.frontend.streaming
                and line.port.backlog > limit)

    def _size_stream_buffer(self, bytes_per_frame: float, line=None) -> None:
        """Transmit buffer for ``STREAM_BUFFER_WALL_S`` of the stream at the present speed."""
        line = self.lines[0] if line is None else line
        line.bytes_per_frame = bytes_per_frame
        wanted = STREAM_BUFFER_WALL_S * self.clock.speed * line.imu.rate_hz * bytes_per_frame
        line.port.max_backlog = max(MIN_STREAM_BUFFER, int(wanted))

    def _timeout(self) -> float:
        """Until the next frame of any IMU is due (wall s), within [5 ms, 20 ms]: frames go out
        in batches of at most 5 ms of wall time; commands are answered at once."""
        waits = []
        for line in self.lines:
            if not line.frontend.streaming or line.imu.next_k is None or line.port.closed:
                continue
            if line.imu.rate_hz * self.clock.speed >= FAST_STREAM_HZ:
                waits.append(0.02)    # large batches: the cost of a batch is mostly per call
            else:
                waits.append(self.clock.wall_until(line.imu.next_k / line.imu.rate_hz))
        if not waits:
            return 0.02
        wait = min(0.02, max(0.005, min(waits)))
        if self._cap is not None:
            # lossless: the clock stops at the cap (its line is full as far as the loop knows):
            # look again then, not a whole batch later (at --speed 200 a csv stream's cap came
            # 12 ms into a 20 ms batch, and its reader, having read everything, waited 8 ms)
            wait = min(wait, max(0.001, self.clock.wall_until(self._cap)))
        return wait

    def serve_forever(self, stop: threading.Event | None = None) -> None:
        stop = stop or self._stop
        try:
            while not stop.is_set():
                self.step(self._timeout())
        finally:
            self.close_ports()

    # ------------------------------------------------------------------ cables (tests)
    def _between_steps(self, fn) -> None:
        """``fn()`` run by the loop between two steps (at once when no loop runs)."""
        if self._thread is None:
            fn()
            return
        done = threading.Event()
        self._requests.append((fn, done))
        self._wake()
        if not done.wait(10.0):
            raise RuntimeError("the twins' loop did not take the request")

    def served(self) -> None:
        """Return once the loop has read and answered every command written to the table's line
        before the call (tests): the turn under way has ended then, and so has the next one (the
        one under way may have read the line just before the bytes came; the next reads them).
        Every byte of the answers is then written to the line or queued (``table_port.sent_bytes``
        + ``backlog``).  Not for a table whose commands wait for an IMU reader (``lossless``, a
        reader reading)."""
        target = self.steps + 2         # the turn under way may have missed them; the next reads them
        while self._thread is not None and self.steps < target:
            self._between_steps(lambda: None)

    def unplug_imu(self, k: int) -> None:
        """IMU ``k``'s line hangs up (its pseudo-terminal closed): its reader gets end of file
        or EIO, as when a USB serial adapter is pulled out.  The twin stays powered."""
        self._between_steps(lambda: self.lines[k].port.close())

    def replug_imu(self, k: int) -> str:
        """IMU ``k`` on a fresh pseudo-terminal (the adapter plugged in again; a new device
        path, returned); the twin kept its state (rate, output settings) meanwhile."""
        self._between_steps(self.lines[k].replug)
        return self.lines[k].port.path

    # ------------------------------------------------------------------ in a thread (tests)
    def start(self) -> "BenchServer":
        def run():
            try:
                self.serve_forever(self._stop)
            except BaseException as e:       # reported by stop()
                self.error = e

        self._wake_fds = os.pipe()
        for fd in self._wake_fds:
            os.set_blocking(fd, False)
        self._thread = threading.Thread(target=run, name="bench-twins", daemon=True)
        self._thread.start()
        return self

    def _wake(self) -> None:
        """The loop's select returns now (a request or a stop waits no turn's timeout, <= 20 ms)."""
        if self._wake_fds is not None:
            try:
                os.write(self._wake_fds[1], b"\0")
            except OSError:             # full (it wakes anyway) or closed
                pass

    def stop(self) -> None:
        self._stop.set()
        self._wake()
        if self._thread is not None:
            self._thread.join(5.0)
            if not self._thread.is_alive() and self._wake_fds is not None:
                for fd in self._wake_fds:
                    os.close(fd)
                self._wake_fds = None
            self._thread = None
        if self.error is not None:
            raise RuntimeError("the twins' loop failed") from self.error

    def set_chamber(self, setpoint_c: float) -> None:
        """The chamber set to ``setpoint_c`` degC now (device time), as at its panel (tests; without
        a panel the air is set directly)."""
        lo, hi = self.options.chamber_range_c
        if not lo <= float(setpoint_c) <= hi:
            raise ValueError(f"setpoint {setpoint_c:g} degC outside the chamber's range {lo:g}..{hi:g} degC")

        def apply():
            if self.chamber_panel is None:
                self.chamber.set(self.clock.now(), float(setpoint_c), self.options.chamber_ramp_c_per_min)
            else:
                self.chamber_panel.set(self.clock.now(), float(setpoint_c))
        self._between_steps(apply)

    def close_ports(self) -> None:
        if self.chamber_panel is not None:
            self.chamber_panel.close()
        self.table_port.close()
        for line in self.lines:
            line.port.close()

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc):
        self.stop()


class ImuLine:
    """One IMU twin on its own pseudo-terminal, and what the loop knows of its reader.

    IMU ``index`` 0 is the bench's first IMU (seed ``options.seed``, the faults of the
    ``--faults`` file); IMU k is seeded ``seed + k`` (its noise; its truth, unless given:
    ``default_truth(seed + k)``) and answers with its own serial number."""

    def __init__(self, table, truth, o: BenchOptions, index: int, fault_rng=None, air=None):
        seed = o.seed + index
        if truth is None:
            truth = default_truth(seed)
        self.index = index
        self.truth = truth
        self.imu = ImuTwin(table, truth, seed=seed, air=air)
        if o.imu_faults:
            self.faults = o.imu_faults[index] if index < len(o.imu_faults) else ImuFaults()
        else:
            self.faults = o.faults.imu if index == 0 else ImuFaults()
        if fault_rng is None:
            fault_rng = np.random.default_rng(np.random.SeedSequence(seed).spawn(2)[1])
        self.faulter = StreamFaulter(self.faults, fault_rng,
                                     line_protocol=o.imu_protocol == "csv", record=o.record)
        if o.imu_protocol == "vectornav":
            self.serial_number = f"01{seed:08d}"[-10:]
            self.frontend = VectorNavFrontEnd(self.imu, self.faulter, startup=o.imu_startup,
                                              serial_number=self.serial_number)
        elif o.imu_protocol == "xsens":
            self.frontend = XsensFrontEnd(self.imu, self.faulter, device_id=0x03700001 + index)
            self.serial_number = f"{self.frontend.device_id:08X}"
        else:
            self.frontend = CsvFrontEnd(self.imu, self.faulter, o.csv_format, clock_start_s=o.csv_clock_start_s)
            self.serial_number = None          # a csv line says no identity
        self._open_port()

    def _open_port(self) -> None:
        self.port = PtyEndpoint()
        # a driver at another baud rate than the IMU's reads garbage, as on a serial line
        self.port.emulate_baud(lambda: self.frontend.line_baud)
        self.last_taken_wall = time.monotonic() - READER_ACTIVE_S   # no reader yet
        self.unread = 0                   # bytes on the line not read by its reader, last step
        self.reader_seen = False          # a reader has taken bytes from the line
        self.bytes_per_frame = 44.0       # of the stream (measured as frames go out)
        self.held_table_since: float | None = None   # the table asked while time was held since
        self.looked_wall = time.monotonic()   # the loop's last look at its reader (_judge_reader)
        self.readers_given_up = getattr(self, "readers_given_up", 0)   # its reader judged not reading (READER_STALL_S)
        self.stale_end = 0                # the port's byte count up to which what it sends was made while nobody read

    def replug(self) -> None:
        """A fresh pseudo-terminal (the old one closed); the twin keeps its state."""
        self.port.close()
        self._open_port()
