"""The IMU stream of a run: one thread reads the IMU driver continuously into a queue.

The sequencer takes samples from it by count (device time); while the table moves it drops
them (``drain``); a settle drops them by their time stamps, from the newest sample that had
reached this computer when the table reported its state (``sync``, ``discard_before``).  Reading all the time keeps the device's and the operating system's buffers
empty, so samples taken after a move are fresh and no frame is lost to an overflow.  Errors of
the driver (timeouts, disconnection) are raised again in the thread that takes samples.
"""
from __future__ import annotations

import collections
import contextlib
import threading
import time

import numpy as np

from drivers.samples import ImuSamples

BLOCK_S = 0.1            # device seconds per driver read: a block begun before a drain and
                         # ended after it holds at most this much stale device time
#: device time running this many times faster than wall time can only be a twin
TWIN_SPEED_RATIO = 1.5


def lost_frames_note(name: str, lost: int, device_s: float, wall_s: float) -> str:
    """What to tell the operator about ``lost`` frames in ``device_s`` of device time read in
    ``wall_s`` of wall time.  Device time far ahead of wall time is a twin at ``--speed``: one
    that loses frames cannot keep up (too fast for this machine), which is said as such."""
    ratio = device_s / wall_s if wall_s > 0 else float("inf")
    if ratio > TWIN_SPEED_RATIO:
        return (f"{name}: {lost} frames lost with device time running {ratio:.0f} x wall time: "
                "the IMU twin and this reader cannot keep up at that speed; lower --speed of "
                "station sim serve")
    return (f"{name}: {lost} frames lost while recording (the window and the angle come from "
            "the frame count)")


class ImuStream:
    def __init__(self, imu, rate_hz: float):
        self.imu = imu
        self.rate_hz = float(rate_hz)
        self._block = max(1, int(round(BLOCK_S * self.rate_hz)))
        self._queue: collections.deque = collections.deque()
        self._queued = 0
        self._cond = threading.Condition()
        self._stop = threading.Event()
        self._error: BaseException | None = None
        self._thread: threading.Thread | None = None
        self.last: ImuSamples | None = None        # the newest block (live display)
        self._sync_asked = self._sync_done = 0
        self._newest_t: float | None = None       # device time of the newest sample received

    # ------------------------------------------------------------------ thread
    def start(self) -> None:
        """Start the stream and its reader thread (again after :meth:`stop`)."""
        self._stop.clear()
        with self._cond:
            self._queue.clear()
            self._queued = 0
            self._error = None
        self.imu.start()
        self._thread = threading.Thread(target=self._run, name="imu-stream", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        try:
            while not self._stop.is_set():
                block = self.imu.read(self._block)
                with self._cond:
                    asked = self._sync_asked
                if asked > self._sync_done:       # everything already here, asked after `asked`
                    block = ImuSamples.concat([block, self.imu.read_available()])
                with self._cond:
                    self._queue.append(block)
                    self._queued += len(block)
                    if len(block):
                        self.last = block
                        self._newest_t = float(block.t_s[-1])
                    self._sync_done = max(self._sync_done, asked)
                    self._cond.notify_all()
        except BaseException as e:          # handed to the consumer
            with self._cond:
                self._error = e
                self._cond.notify_all()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(max(2.0, 3 * self.imu.settings.frame_timeout_s))
            self._thread = None
        try:
            self.imu.stop()
        except Exception:      # the port may be gone; closing anyway
            pass

    # ------------------------------------------------------------------ consumer
    def take(self, n: int, *, wait_s: float = 0.25) -> ImuSamples:
        """Up to ``n`` samples, as soon as any are there (waits at most ``wait_s`` wall
        seconds for the first; an empty block when none came, so the caller can check for a
        pause).  Raises the reader's error, if any."""
        with self._cond:
            deadline = time.monotonic() + wait_s
            while not self._queue and self._error is None:
                left = deadline - time.monotonic()
                if left <= 0:
                    return ImuSamples.empty()
                self._cond.wait(left)
            if not self._queue:
                raise self._error
            blocks, have = [], 0
            while self._queue and have < n:
                block = self._queue.popleft()
                if have + len(block) > n:
                    head, tail = block.split(n - have)
                    self._queue.appendleft(tail)
                    block = head
                blocks.append(block)
                have += len(block)
            self._queued -= have
        return ImuSamples.concat(blocks)

    @contextlib.contextmanager
    def fine(self, frames: int = 1):
        """Read ``frames`` frames at a time (not BLOCK_S) while inside: a sync then answers within
        that many frames of the newest received, instead of up to a block later (a recorded ramp's
        table reads are placed on the IMU's clock by it: station/bench/ramp_angle.py).  The read
        under way when entered finishes at the old size."""
        block = self._block
        self._block = max(1, int(frames))
        try:
            yield self
        finally:
            self._block = block

    def ask_sync(self) -> int:
        """Ask the reader thread to read everything waiting in the port (the first half of
        :meth:`sync`, which waits for it): returns the ticket :meth:`sync` waits for.  Several
        IMUs are asked at once and then waited for, so that their readers finish their blocks
        together rather than one after the other (with 4 IMUs, up to 4 reads of BLOCK_S each)."""
        with self._cond:
            if self._sync_asked <= self._sync_done:
                self._sync_asked += 1
            return self._sync_asked

    def sync(self, *, wait_s: float = 0.25, ticket: int | None = None) -> float | None:
        """The device time of the newest sample that had reached this computer when called
        (or when ``ticket`` was asked: :meth:`ask_sync`): the reader thread reads everything
        waiting in the port before it answers.  Called once
        the table has reported its state, every sample measured before that report is then at
        or before the returned time (the device twins write every frame measured before they
        answer the table; on hardware the line's latency is milliseconds).  None when the
        reader has not answered within ``wait_s`` wall seconds (ask again: the caller can check
        for a pause in between).  Raises the reader's error, if any."""
        if ticket is None:
            ticket = self.ask_sync()
        with self._cond:
            deadline = time.monotonic() + wait_s
            while self._sync_done < ticket and self._error is None:
                left = deadline - time.monotonic()
                if left <= 0:
                    return None
                self._cond.wait(left)
            if self._sync_done < ticket:
                raise self._error
            return self._newest_t

    def discard_before(self, t_end: float, *, wait_s: float = 0.25) -> tuple[int, bool]:
        """Drop the samples time-stamped before ``t_end`` (device s).  Returns how many were
        dropped and whether a sample at or after ``t_end`` is now first in the queue (waits at
        most ``wait_s`` wall seconds for samples).  Raises the reader's error, if any."""
        dropped = 0
        with self._cond:
            deadline = time.monotonic() + wait_s
            while True:
                while self._queue:
                    block = self._queue[0]
                    keep = int(np.searchsorted(block.t_s, t_end, side="left"))
                    if keep < len(block):
                        if keep:
                            self._queue[0] = block.split(keep)[1]
                        dropped += keep
                        self._queued -= keep
                        return dropped, True
                    self._queue.popleft()
                    dropped += len(block)
                    self._queued -= len(block)
                if self._error is not None:
                    raise self._error
                left = deadline - time.monotonic()
                if left <= 0:
                    return dropped, False
                self._cond.wait(left)

    def drain(self) -> int:
        """Drop every sample received so far; returns how many."""
        with self._cond:
            n = self._queued
            self._queue.clear()
            self._queued = 0
            if self._error is not None:
                raise self._error
        return n

    @property
    def counters(self):
        return self.imu.counters

    def live(self) -> dict:
        """|f| (m/s^2), |w| (deg/s) and temperature of the newest block."""
        b = self.last
        if b is None or not len(b):
            return {}
        temp = b.temp_c[np.isfinite(b.temp_c)]
        return {"f_mps2": float(np.linalg.norm(b.accel_mps2, axis=1).mean()),
                "w_dps": float(np.linalg.norm(b.gyro_dps, axis=1).mean()),
                "temp_c": float(temp.mean()) if temp.size else None,
                "t_s": float(b.t_s[-1])}
