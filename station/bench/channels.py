"""The IMUs of a run: one :class:`ImuChannel` per IMU (its stream, its capture bundle, what it
has recorded, whether it was lost), the bookkeeping of one recording of one segment
(:class:`Recording`: frames lost, longest step, temperature), and how a segment's description
reads for an IMU mounted otherwise than the one the scheme was compiled for
(:func:`segment_meta`).

Several IMUs on one table (station.yaml ``imus:``) share the table's motion: the scheme is
compiled for the first IMU's mounting, the table moves once, and each IMU records every segment
into its own bundle, ``count`` frames of its own at its own rate, with its own data-loss checks.
An IMU mounted with another orientation sees the same table attitudes as other body
directions: ``R = M_k^T M_0`` (case of IMU 0 -> case of IMU k, both mounting matrices case ->
platform; a signed permutation) turns the scheme's body vectors (``up_body``, ``heading_body``,
``axis_body``) into IMU k's.  A remount of the fixture (an operator step) turns every IMU
together, so ``R`` stays.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from station.bench import steadiness
from station.bench.config import AXIS_NAMES

BODY_VECTORS = ("up_body", "heading_body", "axis_body")


@dataclass(eq=False)          # hashed by identity: a key of the recordings
class ImuChannel:
    """One IMU of a run."""

    label: str                      # how messages name it (serial number or name)
    stream: object                  # station.bench.imu_stream.ImuStream
    writer: object                  # station.io.capture.CaptureWriter of its bundle
    rate_hz: float
    to_case: np.ndarray = field(default_factory=lambda: np.eye(3))   # R: case of IMU 0 -> this case
    done: frozenset = frozenset()   # segments complete before this run (resume)
    lost: str | None = None         # why it was lost, once lost

    @property
    def alive(self) -> bool:
        return self.lost is None


def relative_mounting(mounting0: np.ndarray, mounting_k: np.ndarray) -> np.ndarray:
    """R = M_k^T M_0: a body vector of IMU 0 as the same platform direction in IMU k's case."""
    return np.asarray(mounting_k, dtype=float).T @ np.asarray(mounting0, dtype=float)


def segment_meta(meta: dict, to_case: np.ndarray) -> dict:
    """``meta`` of a segment compiled for IMU 0, as IMU k (``to_case``) records it: its body
    vectors turned, ``mounting`` (platform directions of the case axes) turned back."""
    if np.array_equal(to_case, np.eye(3)):
        return dict(meta)
    out = dict(meta)
    for key in BODY_VECTORS:
        if meta.get(key) is not None:
            out[key] = [float(x) + 0.0 for x in to_case @ np.asarray(meta[key], dtype=float)]
    if meta.get("mounting") is not None:
        m0 = np.column_stack([AXIS_NAMES[m] for m in meta["mounting"]]).astype(float)
        mk = m0 @ to_case.T                           # case k -> case 0 -> platform
        names = {v: k for k, v in AXIS_NAMES.items()}
        out["mounting"] = [names[tuple(int(round(x)) for x in mk[:, j])] for j in range(3)]
    return out


class Recording:
    """One recording of one segment by one IMU: the samples counted, frames lost (from the
    device's sample times), the longest step between frames and the mean temperature."""

    def __init__(self, seg, n: int, rate_hz: float):
        self.seg, self.n = seg, int(n)
        self.period = 1.0 / float(rate_hz)
        self.done = self.lost = 0
        self.longest = self.period
        self.first_t = self.last_t = None
        self.with_temp = None
        self.temp_sum, self.temp_n = 0.0, 0
        # the window's first seconds, kept for the IMU's agreement with the table (steadiness.py
        # reads its first HEAD_S s: the memory of a recording stays bounded however long it is)
        self._accel, self._gyro = [], []
        self._head = int(math.ceil(steadiness.HEAD_S * float(rate_hz))) + 1
        self._kept = 0
        # and, for a recorded ramp's check (steadiness.ramp_disagreement), the sum of every gyro
        # sample of the window and its last HEAD_S seconds (a brake's rest is at the window's end)
        self.gyro_sum = np.zeros(3)
        self._tail: list = []
        self._tail_n = 0

    @property
    def needed(self) -> int:
        return self.n - self.done

    def add(self, b) -> None:
        """Write block ``b`` (drivers.samples.ImuSamples) into the segment and count it."""
        if not len(b):
            return
        if self.first_t is None:
            self.first_t = b.t_s[0]
        t = b.t_s if self.last_t is None else np.concatenate([[self.last_t], b.t_s])
        steps = np.diff(t)
        if len(steps):
            self.longest = max(self.longest, float(steps.max()))
            big = steps > 1.5 * self.period
            self.lost += int(np.round(steps[big] / self.period - 1.0).sum())
        self.last_t = b.t_s[-1]
        finite = np.isfinite(b.temp_c)
        if self.with_temp is None:
            self.with_temp = bool(finite.all())
        temp = None
        if self.with_temp:
            temp = np.where(finite, b.temp_c, np.nanmean(b.temp_c) if finite.any() else 0.0)
            self.temp_sum += float(temp.sum())
            self.temp_n += len(temp)
        self.seg.write(b.t_s, b.accel_mps2, b.gyro_dps, temp)
        gyro = np.asarray(b.gyro_dps, dtype=float)
        self.gyro_sum = self.gyro_sum + gyro.sum(axis=0)
        self._tail.append(gyro[-self._head:].copy())
        self._tail_n += len(self._tail[-1])
        while self._tail_n - len(self._tail[0]) >= self._head:
            self._tail_n -= len(self._tail.pop(0))
        if self._kept < self._head:
            take = self._head - self._kept
            self._accel.append(np.array(b.accel_mps2[:take], dtype=float))
            self._gyro.append(np.array(b.gyro_dps[:take], dtype=float))
            self._kept += len(self._gyro[-1])
        self.done += len(b)

    def samples(self) -> tuple:
        """(accel (n, 3) m/s^2, gyro (n, 3) deg/s) of the recording's first samples (its first
        steadiness.HEAD_S seconds, or all of a shorter one)."""
        if not self._accel:
            return np.zeros((0, 3)), np.zeros((0, 3))
        return np.concatenate(self._accel), np.concatenate(self._gyro)

    def gyro_tail(self) -> np.ndarray:
        """The gyro samples (n, 3) deg/s of the recording's last steadiness.HEAD_S seconds (or all
        of a shorter one)."""
        if not self._tail:
            return np.zeros((0, 3))
        return np.concatenate(self._tail)[-self._head:]

    def result(self) -> dict:
        """The window the samples stand for, from the frame count (received plus lost frames
        times one period; never from wall-clock time), the frames lost, the longest step and
        the mean temperature."""
        return {"window_s": (self.done + self.lost) * self.period, "gaps": self.lost, "samples": self.done,
                "first_t": self.first_t, "last_t": self.last_t,
                "longest_step_s": self.longest, "temp": self.temp_sum / self.temp_n if self.temp_n else None}
