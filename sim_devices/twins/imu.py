"""The IMU twin: samples at its output rate, from the table twin's state.

For sample times t_k = k / rate (device time, s) it asks the table twin for the platform's
attitude, rate and angular acceleration (``TableTwin.kinematics_at``), turns them into the
true specific force and inertial rate at the IMU (gravity, Earth rate, centripetal and
tangential acceleration from the lever arm; ``world.body_kinematics``), adds the white
acceleration disturbance if the truth has one, and measures them with the true error model
and noise (``Truth.measure``; noise per sample from the densities at the output rate).  Its
temperature is the truth's warm-up over the room's, or, in a temperature chamber
(``station sim serve --chamber``), over the case's first-order lag behind the chamber's air.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np

from sim_devices import world
from sim_devices.world import MICRO_G

#: at most this many samples are made at once (a long stall is not caught up)
MAX_BATCH = 20000
#: noise is drawn in blocks of this many samples, keyed by (seed, draw, block)
NOISE_BLOCK = 4096


class IndexedNormal:
    """A stand-in for a numpy Generator whose ``standard_normal`` values depend on the
    sample indices only, not on how the samples are batched.

    ``Truth.measure`` and ``world.perturb_specific_force`` draw ``standard_normal((N, 3))``
    once per quantity; the j-th draw of a batch gets, for sample k, row k of stream j.  So the
    same seed gives the same bytes at any ``--speed`` (any batching of the samples).
    """

    def __init__(self, seed: int):
        self.seed = int(seed)
        self._cache: dict[tuple[int, int], np.ndarray] = {}
        self._k = np.zeros(0, dtype=np.int64)
        self._draw = 0
        self._epoch = 0

    def batch(self, k: np.ndarray, first_stream: int = 0, epoch: int = 0) -> "IndexedNormal":
        """Draws for the samples ``k`` follow, the first from stream ``first_stream``."""
        self._k = np.asarray(k, dtype=np.int64)
        self._draw = first_stream
        self._epoch = epoch
        return self

    def _block(self, stream: int, b: int) -> np.ndarray:
        key = (self._epoch, stream, b)
        blk = self._cache.get(key)
        if blk is None:
            if len(self._cache) > 64:
                self._cache.clear()
            blk = np.random.default_rng([self.seed, self._epoch, stream, b]).standard_normal((NOISE_BLOCK, 3))
            self._cache[key] = blk
        return blk

    def standard_normal(self, shape):
        n, m = shape
        if n != self._k.size or m != 3:
            raise ValueError("IndexedNormal draws (N, 3) for the current batch only")
        stream, self._draw = self._draw, self._draw + 1
        out = np.empty((n, 3))
        blocks = self._k // NOISE_BLOCK
        for b in np.unique(blocks):
            sel = blocks == b
            out[sel] = self._block(stream, int(b))[self._k[sel] % NOISE_BLOCK]
        return out


class ImuTwin:
    def __init__(self, table, truth, seed: int = 0, air=None):
        """``air``: the temperature chamber around the table (sim_devices/chamber.py ChamberAir,
        shared by every IMU on it), None: the room's air only."""
        self.table = table
        self.air = air
        self.site = world.Site(truth.bench.latitude_deg, truth.bench.height_m)
        self.lever_arm_m = np.asarray(truth.bench.lever_arm_m, dtype=float)
        self.disturbance_mps2 = truth.bench.accel_disturbance_ug * MICRO_G
        self.noise = IndexedNormal(seed)
        self.epoch = 0          # bumped on every rate change: new noise streams
        self._base_truth = truth
        self.truth = truth
        self.rate_hz = float(truth.sample_rate_hz)
        self.next_k: int | None = None
        self.frames_skipped = 0       # not made: the loop was held up longer than MAX_BATCH samples
        # the IMU's clock against the table's (truth.bench.time_offset_s, as the simulated bench's):
        # the sample stamped t was taken at table time t + time_offset_s
        self.time_offset_s = float(truth.bench.time_offset_s)

    def set_rate(self, rate_hz: float, now: float) -> None:
        """Output rate (Hz); the noise per sample follows (densities are per √Hz)."""
        self.rate_hz = float(rate_hz)
        self.truth = dataclasses.replace(self._base_truth, sample_rate_hz=self.rate_hz)
        self.epoch += 1
        self.restart(now)

    def restart(self, now: float) -> None:
        """The next sample is the first one after ``now`` on the grid k / rate."""
        self.next_k = int(math.floor(now * self.rate_hz)) + 1

    def sample_times_until(self, now: float) -> np.ndarray:
        """The grid times not yet produced, up to ``now`` (and consumes them)."""
        if self.next_k is None:
            self.restart(now)
        last = int(math.floor(now * self.rate_hz))
        if last < self.next_k:
            return np.zeros(0)
        if last - self.next_k + 1 > MAX_BATCH:
            self.frames_skipped += last - MAX_BATCH + 1 - self.next_k
            self.next_k = last - MAX_BATCH + 1
        k = np.arange(self.next_k, last + 1)
        self.next_k = last + 1
        return k / self.rate_hz

    def measure(self, t: np.ndarray):
        """(accel m/s², gyro deg/s, temp °C) of the samples at device times ``t`` (on the
        output grid: t = k / rate)."""
        k = np.round(np.asarray(t) * self.rate_hz).astype(np.int64)
        # stamped t, taken at table time t + time_offset_s (a few ms: the table's plan already holds
        # that moment, except a command that arrives within it)
        t = np.asarray(t, float) + self.time_offset_s if self.time_offset_s else t
        C_bn, w_b, wd_b = self.table.kinematics_at(t)
        f_b, w_ib = world.body_kinematics(C_bn, w_b, wd_b, self.lever_arm_m, self.site)
        f_b = world.perturb_specific_force(f_b, self.disturbance_mps2,
                                           self.noise.batch(k, 0, self.epoch))
        # in a chamber: the case follows its air as a first-order lag, plus the warm-up (the
        # physics of the dry run's bench: TemperatureTruth.at, sim_devices/chamber.py)
        temp = self.truth.temperature.at(t, self.air)
        self.noise.batch(k, 1, self.epoch)         # streams 1 (accel) and 2 (gyro)
        # each accelerometer senses the specific force at its own position (the size effect,
        # truth.accel.position_m): the platform's rate and its derivative relative to the Earth
        accel, gyro = self.truth.measure(f_b, np.degrees(w_ib), temp, self.noise, w_eb_b=w_b, wdot_eb_b=wd_b, t=t,
                                         air=self.air)
        return accel, gyro, temp
