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

from .clock import SimClock
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
    record: bool = False          # keep the times of the frames sent intact (tests)
    lossless: bool = False        # device time waits while a reader that is reading falls behind,
                                  #   instead of frames being lost (tests on a loaded machine, where
                                  #   --speed 100 outruns a descheduled reader; a real IMU drops them)


READER_ACTIVE_S = 0.5             # lossless: a reader that took bytes within this (wall) is reading


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
        geo_rng, fault_rng = (np.random.default_rng(s) for s in np.random.SeedSequence(o.seed).spawn(2))
        geometry = TableGeometry.default(o.axes, truth.bench.lever_arm_m)
        self.table = TableTwin(geometry, self.clock, config=o.table_config,
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
            self.table_frontend = AerosmithFrontEnd(self.table)
        if o.imu_protocol == "vectornav":
            self.imu_frontend = VectorNavFrontEnd(self.imu, self.faulter,
                                                  serial_number=f"01{o.seed:08d}"[-10:])
        elif o.imu_protocol == "xsens":
            self.imu_frontend = XsensFrontEnd(self.imu, self.faulter)
        else:
            self.imu_frontend = CsvFrontEnd(self.imu, self.faulter, o.csv_format)
        self.table_port = PtyEndpoint() if o.table_tcp_port is None else TcpEndpoint(o.table_tcp_port)
        self.imu_port = PtyEndpoint()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.error: BaseException | None = None
        self._last_wall = self._last_taken_wall = time.monotonic()

    @property
    def table_path(self) -> str:
        return self.table_port.path

    @property
    def imu_path(self) -> str:
        return self.imu_port.path

    # ------------------------------------------------------------------ the loop
    def step(self, timeout_s: float) -> None:
        ports = [p for p in (self.table_port, self.imu_port) if not p.closed]
        writers = [p for p in ports if p.backlog]
        readable, _, _ = select.select(ports, writers, [], timeout_s) if ports else ([], [], [])
        wall = time.monotonic()
        held = (self.options.lossless and self._imu_behind()
                and wall - self._last_taken_wall < READER_ACTIVE_S)
        if held:
            self.clock.hold(wall - self._last_wall)      # the simulated world waits for the reader
        self._last_wall = wall
        now = self.clock.now()
        self.table.update(now)
        tf, imf = self.options.faults.table, self.options.faults.imu
        if tf.disconnect_at_s is not None and now >= tf.disconnect_at_s:
            self.table_port.close()
        if imf.disconnect_at_s is not None and now >= imf.disconnect_at_s:
            self.imu_port.close()
        if self.table_port in readable:
            data = self.table_port.read()
            if data and not self.table.stalled(now):
                self.table_port.write(self.table_frontend.receive(data))
        if self.imu_port in readable:
            data = self.imu_port.read()
            if data:
                self.imu_port.write(self.imu_frontend.receive(data, now))
        if not self.imu_port.closed:
            if held:
                pass                     # nothing came due: device time stood still
            elif self._imu_behind():
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
        backlog = self.imu_port.backlog
        for p in (self.table_port, self.imu_port):
            p.flush()
        if self.imu_port.backlog < backlog or not self.imu_port.backlog:
            self._last_taken_wall = time.monotonic()

    def _imu_behind(self) -> bool:
        return (not self.imu_port.closed and self.imu_frontend.streaming
                and self.imu_port.backlog > self.imu_port.max_backlog // 2)

    def _size_stream_buffer(self, bytes_per_frame: float) -> None:
        """Transmit buffer for ``STREAM_BUFFER_WALL_S`` of the stream at the present speed."""
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
