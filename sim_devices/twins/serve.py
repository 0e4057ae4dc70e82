"""Both twins on pseudo-terminals, served by one loop (``station sim serve``).

One thread runs everything: it waits (select) for commands on either port or for the next
IMU frame to fall due, answers the commands, fires the faults due, and writes the frames
due by the present device time.  Device time comes from one :class:`SimClock`, so
``speed`` changes how fast frames come, never a byte of them.
"""
from __future__ import annotations

import select
import threading
import time
from dataclasses import dataclass, field

import numpy as np

from drivers.protocols.csvlines import CsvFormat

from .clock import SimClock, StepClock
from .faults import Faults, StreamFaulter
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
    table_config: TableConfig = field(default_factory=TableConfig)
    table_framing: str = "tcp"    # acutrol replies: "tcp" (error code, length first) or "gpib"
    table_tcp_port: int | None = None   # serve the table on TCP 127.0.0.1:port (0: any free port)
    table_silent_motion: bool = False   # aerosmith: JOG, STO, SGO not answered (docs/protocols.md)
    imu_startup: str = "factory"  # vectornav power-up: "factory" ($VNYMR at 40 Hz, binary off, as a
                                  #   VN-100 leaves the factory) or "binary" (station's binary output on)
    record: bool = False          # keep the times of the frames sent intact (tests)
    lossless: bool = True         # the twins' clock is throttled to the IMU's reader: while a reader
                                  #   that is reading has not taken the frames its line could hold,
                                  #   device time stands still (and the table's commands wait), so no
                                  #   frame is lost at any --speed; False: frames the reader did not
                                  #   take are dropped, as a real IMU's UART does


READER_ACTIVE_S = 2.0             # a reader that took bytes within this (wall s) is reading
#: lossless: device time runs at most this many bytes of the stream ahead of the reader (about
#: what a pty holds: 4 KiB in the line discipline, 16 KiB in the kernel's flip buffers)
LINE_BYTES = 16384
#: a line without a reader never takes more than this in all: the kernel's flip buffers hold at
#: most 64 KiB (TTYB_DEFAULT_MEM_LIMIT, the most any tty port has) besides the unread bytes of
#: n_tty's read buffer (a pty took 14-22 KiB in all on Linux 6.18, by the size of the writes)
FLIP_MAX_BYTES = 65536
TABLE_WAIT_S = 0.1                # lossless: longest (wall s) the table's commands wait for the IMU's reader
#: lossless: a reader that takes nothing from the IMU line for this long (wall s) while device
#: time is held for it and the table's client asks something is not reading (a program busy with
#: the table that reads the IMU only now and then, not a starved reader): it is taken for absent
#: until it reads again, so the world goes on and the frames it does not take are dropped, as a
#: real IMU's UART drops them.  Before, the table was answered at the held time for up to
#: READER_ACTIVE_S: a client that moved the table without reading the IMU saw the axis stand
#: still and took it for stalled (docs/twins.md, "The twins' clock waits for the IMU's reader")
READER_STALL_S = 0.25


class BenchServer:
    """The two twins, their pseudo-terminals and the loop serving them."""

    def __init__(self, truth, options: BenchOptions | None = None):
        o = options or BenchOptions()
        if o.table_protocol not in TABLE_PROTOCOLS:
            raise ValueError(f"table protocol must be one of {TABLE_PROTOCOLS}")
        if o.imu_protocol not in IMU_PROTOCOLS:
            raise ValueError(f"IMU protocol must be one of {IMU_PROTOCOLS}")
        self.options = o
        self.truth = truth
        self.clock = SimClock(o.speed)
        self.step_clock = StepClock(self.clock)     # the table's: commands at the step's time
        geo_rng, fault_rng = (np.random.default_rng(s) for s in np.random.SeedSequence(o.seed).spawn(2))
        geometry = TableGeometry.default(o.axes, truth.bench.lever_arm_m)
        self.table = TableTwin(geometry, self.step_clock, config=o.table_config,
                               ripple_fraction=truth.bench.rate_ripple_fraction,
                               ripple_hz=truth.bench.rate_ripple_hz, rng=geo_rng,
                               faults=o.faults.table,
                               interlocks_closed=o.table_protocol == "aerosmith")
        self.imu = ImuTwin(self.table, truth, seed=o.seed)
        self.faulter = StreamFaulter(o.faults.imu, fault_rng,
                                     line_protocol=o.imu_protocol == "csv", record=o.record)
        if o.table_protocol == "acutrol":
            self.table_frontend = AcutrolFrontEnd(self.table, o.table_framing)
        else:
            self.table_frontend = AerosmithFrontEnd(self.table, silent_motion=o.table_silent_motion)
        if o.imu_protocol == "vectornav":
            self.imu_frontend = VectorNavFrontEnd(self.imu, self.faulter, startup=o.imu_startup,
                                                  serial_number=f"01{o.seed:08d}"[-10:])
        elif o.imu_protocol == "xsens":
            self.imu_frontend = XsensFrontEnd(self.imu, self.faulter)
        else:
            self.imu_frontend = CsvFrontEnd(self.imu, self.faulter, o.csv_format)
        self.table_port = PtyEndpoint() if o.table_tcp_port is None else TcpEndpoint(o.table_tcp_port)
        self.imu_port = PtyEndpoint()
        # a driver at another baud rate than the IMU's reads garbage, as on a serial line
        self.imu_port.emulate_baud(lambda: self.imu_frontend.line_baud)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.error: BaseException | None = None
        self._last_taken_wall = time.monotonic() - READER_ACTIVE_S   # no reader yet
        self._unread = 0                  # bytes on the IMU line not read by its reader, last step
        self._reader_seen = False         # a reader has taken bytes from the IMU line
        self._bytes_per_frame = 44.0      # of the IMU stream (measured as frames go out)
        self._table_wait_since: float | None = None
        self.table_deferred_steps = 0     # loop steps in which the table's commands waited (lossless)
        self._table_asked = False         # a table command came (or waited) in the last step
        self._held_table_since: float | None = None   # the table asked while time was held since
        self.readers_given_up = 0         # times a reader was judged not reading (READER_STALL_S)

    @property
    def table_path(self) -> str:
        return self.table_port.path

    @property
    def imu_path(self) -> str:
        return self.imu_port.path

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
        wall = time.monotonic()
        self._judge_reader(wall)
        defer_table = self._defer_table(wall - self._last_taken_wall < READER_ACTIVE_S)
        if defer_table:
            self.table_deferred_steps += 1
        if self.clock.capped:
            timeout_s = min(timeout_s, 0.001)        # waiting for the reader
        ports = [p for p in (self.imu_port, self.table_port)
                 if not p.closed and not (p is self.table_port and defer_table)]
        writers = [p for p in (self.table_port, self.imu_port) if not p.closed and p.backlog]
        readable, _, _ = select.select(ports, writers, [], timeout_s) if ports or writers else ([], [], [])
        self._table_asked = self.table_port in readable or (
            defer_table and not self.table_port.closed and bool(select.select([self.table_port], [], [], 0)[0]))
        reader_active = time.monotonic() - self._last_taken_wall < READER_ACTIVE_S
        now = self.clock.now()
        self.step_clock.set(now)
        self.table.update(now)
        tf, imf = self.options.faults.table, self.options.faults.imu
        if tf.disconnect_at_s is not None and now >= tf.disconnect_at_s:
            self.table_port.close()
        if imf.disconnect_at_s is not None and now >= imf.disconnect_at_s:
            self.imu_port.close()
        table_first = not reader_active
        if table_first:
            self._serve_table(readable, now, defer_table)
        reader_active = self._serve_imu(readable, now, reader_active)
        if not table_first:
            self._serve_table(readable, now, self._defer_table(reader_active))
        if self.options.lossless and reader_active and self.imu_frontend.streaming:
            # the world waits for the reader: device time runs at most as far as the frames
            # the line holds (none while frames are still queued)
            lead = 0.0 if self.imu_port.backlog else LINE_BYTES / (self._bytes_per_frame * self.imu.rate_hz)
            self.clock.limit(now + lead)
        else:
            self.clock.limit(None)

    def _serve_table(self, readable, now: float, defer: bool) -> None:
        if self.table_port in readable and not defer:
            data = self.table_port.read()
            if data and not self.table.stalled(now):
                self.table_port.write(self.table_frontend.receive(data))
        self.table_port.flush()

    def _serve_imu(self, readable, now: float, reader_active: bool) -> bool:
        """IMU commands and the frames due by ``now``; returns whether the reader is active."""
        sent = self.imu_port.sent_bytes
        if self.imu_port in readable:
            data = self.imu_port.read()
            if data:
                # the replies go out at the rate in effect when the commands came (a new baud
                # rate, register 05, applies after its reply)
                baud = self.imu_frontend.line_baud
                self.imu_port.write(self.imu_frontend.receive(data, now), baud=baud)
        if not self.imu_port.closed:
            if self._imu_behind(self.imu_port.max_backlog // 2) and not (self.options.lossless and reader_active):
                # nobody reads: the frames due are lost anyway, do not compute them
                self.faulter.overflowed(self.imu.sample_times_until(now).size, recorded=False)
            else:
                before = self.faulter.frames_sent
                frames = self.imu_frontend.produce(now)
                if frames and self.faulter.frames_sent > before:
                    self._size_stream_buffer(len(frames) / (self.faulter.frames_sent - before))
                # lossless: a batch larger than the backlog (this loop itself was descheduled) is kept
                if frames and not self.imu_port.write(frames, droppable=not self.options.lossless):
                    self.faulter.overflowed(self.faulter.frames_sent - before)
        unread = self.imu_port.unread()
        self.imu_port.flush()
        # the reader took bytes: fewer wait on the line (only a reader takes them), or, once a
        # reader was seen, the line took bytes in this step (when writing the frames or
        # flushing: without a reader the line fills once, ~20 KiB, and takes nothing more).  A
        # reader is seen when fewer wait on the line, or when the line has passed on more than
        # it can hold without one: while the queue keeps the line full, the kernel refills the
        # read buffer from its flip buffers as soon as the reader has read, so the unread count
        # may never be seen to fall (the reader was then taken for absent and frames dropped)
        took = self.imu_port.sent_bytes > sent
        self._reader_seen = (self._reader_seen or unread < self._unread
                             or self.imu_port.sent_bytes - unread > FLIP_MAX_BYTES)
        if unread < self._unread or (self._reader_seen and took):
            self._last_taken_wall = time.monotonic()
            reader_active = True
        self._unread = self.imu_port.unread()
        return reader_active

    def _defer_table(self, reader_active: bool) -> bool:
        """Lossless: the table's commands wait while frames already measured are still in the
        IMU's transmit queue and its reader is taking them (at most TABLE_WAIT_S: a reader
        that has just died does not hold up the table long).  What the kernel holds reaches
        the reader when it reads what is waiting (``drivers.transport.Port.read_waiting``)."""
        wait = (self.options.lossless and reader_active and not self.imu_port.closed
                and self.imu_frontend.streaming and self.imu_port.backlog > 0)
        if not wait:
            self._table_wait_since = None
            return False
        now = time.monotonic()
        if self._table_wait_since is None:
            self._table_wait_since = now
        return now - self._table_wait_since < TABLE_WAIT_S

    def _judge_reader(self, wall: float) -> None:
        """Lossless: while device time is held for the IMU's reader (frames wait in the
        transmit queue) and the table's client asks something, a reader that takes nothing for
        READER_STALL_S is not reading: taken for absent until it reads again (the clock runs
        free, the frames it does not take are dropped).  A reader that is merely slow takes
        bytes and is waited for; with no table client asking, nobody sees the world wait and a
        silent reader is waited for up to READER_ACTIVE_S, as before."""
        held = (self.options.lossless and not self.imu_port.closed and self.imu_frontend.streaming
                and self.imu_port.backlog > 0 and wall - self._last_taken_wall < READER_ACTIVE_S)
        if not held:
            self._held_table_since = None
            return
        if self._table_asked and self._held_table_since is None:
            self._held_table_since = wall
        if (self._held_table_since is not None
                and wall - max(self._last_taken_wall, self._held_table_since) >= READER_STALL_S):
            self._last_taken_wall = wall - READER_ACTIVE_S            # absent until it reads
            self._held_table_since = None
            self.readers_given_up += 1

    def _imu_behind(self, limit: int) -> bool:
        """The IMU's transmit queue holds more than ``limit`` bytes its line could not take."""
        return (not self.imu_port.closed and self.imu_frontend.streaming
                and self.imu_port.backlog > limit)

    def _size_stream_buffer(self, bytes_per_frame: float) -> None:
        """Transmit buffer for ``STREAM_BUFFER_WALL_S`` of the stream at the present speed."""
        self._bytes_per_frame = bytes_per_frame
        wanted = STREAM_BUFFER_WALL_S * self.clock.speed * self.imu.rate_hz * bytes_per_frame
        self.imu_port.max_backlog = max(MIN_STREAM_BUFFER, int(wanted))

    def _timeout(self) -> float:
        """Until the next frame is due (wall s), within [5 ms, 20 ms]: frames go out in
        batches of at most 5 ms of wall time; commands are answered at once."""
        if not self.imu_frontend.streaming or self.imu.next_k is None:
            return 0.02
        if self.imu.rate_hz * self.clock.speed >= FAST_STREAM_HZ:
            return 0.02            # large batches: the cost of a batch is mostly per call
        wall = self.clock.wall_until(self.imu.next_k / self.imu.rate_hz)
        return min(0.02, max(0.005, wall))

    def serve_forever(self, stop: threading.Event | None = None) -> None:
        stop = stop or self._stop
        try:
            while not stop.is_set():
                self.step(self._timeout())
        finally:
            self.close_ports()

    # ------------------------------------------------------------------ in a thread (tests)
    def start(self) -> "BenchServer":
        def run():
            try:
                self.serve_forever(self._stop)
            except BaseException as e:       # reported by stop()
                self.error = e

        self._thread = threading.Thread(target=run, name="bench-twins", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(5.0)
            self._thread = None
        if self.error is not None:
            raise RuntimeError("the twins' loop failed") from self.error

    def close_ports(self) -> None:
        self.table_port.close()
        self.imu_port.close()

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc):
        self.stop()
