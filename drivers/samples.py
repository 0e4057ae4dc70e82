"""What an IMU driver returns: blocks of samples, and its stream counters."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class ImuSamples:
    """A block of N samples.

    ``t_s`` device time (s, from the device's own clock: time since startup for VectorNav,
    the ``t`` column for csv), ``accel_mps2`` (N,3) specific force in m/s², ``gyro_dps`` (N,3)
    angular rate in deg/s, ``temp_c`` (N,) temperature in °C (NaN where the device gives none).
    """

    t_s: np.ndarray
    accel_mps2: np.ndarray
    gyro_dps: np.ndarray
    temp_c: np.ndarray

    def __len__(self) -> int:
        return int(self.t_s.shape[0])

    @classmethod
    def empty(cls) -> "ImuSamples":
        return cls(np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0))

    @classmethod
    def concat(cls, blocks) -> "ImuSamples":
        blocks = [b for b in blocks if len(b)]
        if not blocks:
            return cls.empty()
        if len(blocks) == 1:
            return blocks[0]
        return cls(np.concatenate([b.t_s for b in blocks]),
                   np.concatenate([b.accel_mps2 for b in blocks]),
                   np.concatenate([b.gyro_dps for b in blocks]),
                   np.concatenate([b.temp_c for b in blocks]))

    def split(self, n: int) -> tuple["ImuSamples", "ImuSamples"]:
        """The first n samples and the rest."""
        return (ImuSamples(self.t_s[:n], self.accel_mps2[:n], self.gyro_dps[:n], self.temp_c[:n]),
                ImuSamples(self.t_s[n:], self.accel_mps2[n:], self.gyro_dps[n:], self.temp_c[n:]))


@dataclass
class ImuCounters:
    """Stream health since :meth:`drivers.base.Imu.start`.

    ``frames``: valid frames decoded.  ``checksum_errors``: frames whose CRC failed (vectornav)
    or lines that do not parse (csv).  ``resyncs``: times the decoder had to skip bytes that do
    not start a frame (garbage, a frame broken off).  ``bytes_discarded``: bytes skipped.
    ``gaps``: steps of device time longer than 1.5 sample periods; ``missing_frames``: frames
    those gaps stand for (step / period - 1, rounded).
    """

    frames: int = 0
    checksum_errors: int = 0
    resyncs: int = 0
    bytes_discarded: int = 0
    gaps: int = 0
    missing_frames: int = 0

    def as_dict(self) -> dict:
        return dict(self.__dict__)
