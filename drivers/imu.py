"""The abstract streaming-IMU interface :class:`Imu` and its settings.

The public methods do the common work (rate checks, reading with a frame timeout,
keeping samples across reads, counting gaps in device time) and call one small
protocol-specific method (``_name``) that a driver implements; decoding is done by the
protocol's decoder (``drivers/protocols``).
"""
from __future__ import annotations

import abc
import math
import time
from dataclasses import dataclass, field

import numpy as np

from .device import Device
from .errors import DeviceTimeout, LimitError
from .samples import ImuCounters, ImuSamples
from .transport import SerialSettings


@dataclass(frozen=True)
class ImuSettings:
    """Settings of an IMU driver.

    ``rate_hz``: output rate asked for (vectornav) or expected (csv, for gap counting);
    ``temperature``: ask for the temperature where the protocol can; ``device_baud``: set the
    device's serial baud rate at connect and switch the port to it; ``frame_timeout_s``:
    longest wait for the next valid frame before DeviceTimeout; ``csv_format``: units of the
    csv columns (see :mod:`drivers.protocols.csvlines`).
    """

    serial: SerialSettings = field(default_factory=SerialSettings)
    rate_hz: float = 100.0
    temperature: bool = True
    frame_timeout_s: float = 1.0
    csv_format: object = None
    device_baud: int | None = None     # vectornav: write it to the sensor (register 05), then use it


class Imu(Device):
    """A streaming IMU.  Samples come in device time (:class:`ImuSamples`)."""

    kind = "imu"

    def __init__(self, url: str, settings: ImuSettings | None = None):
        super().__init__(url, settings or ImuSettings())
        self.rate_hz = float(self.settings.rate_hz)
        self.counters = ImuCounters()
        self.streaming = False
        self._decoder = None
        self._configured = False
        self._carry = b""                 # bytes received while waiting for a reply: stream data
        self._pending = ImuSamples.empty()
        self._last_t: float | None = None

    # ------------------------------------------------------------------ connection
    def _on_connect(self) -> str:
        """Identify the device."""
        self.identity = self._identify()
        return self.identity

    def _before_close(self) -> None:
        if self.streaming:
            try:
                self.stop()
            except Exception:        # closing anyway
                pass

    # ------------------------------------------------------------------ stream
    def configure(self, rate_hz: float | None = None, *, temperature: bool | None = None) -> float:
        """Set the output rate (Hz) and contents; returns the rate the device will use."""
        rate = float(self.settings.rate_hz if rate_hz is None else rate_hz)
        if not (math.isfinite(rate) and 0.0 < rate <= 10000.0):
            raise LimitError(self.name, f"output rate {rate_hz!r} Hz outside (0, 10000]")
        temp = self.settings.temperature if temperature is None else bool(temperature)
        self.rate_hz = self._configure(rate, temp)
        self._configured = True
        return self.rate_hz

    def start(self) -> None:
        """Start the stream (counters and buffers start afresh)."""
        if not self._configured:
            self.configure()
        self.counters = ImuCounters()
        self._pending = ImuSamples.empty()
        self._last_t = None
        self._decoder = self._new_decoder()
        self._start_stream()
        self.streaming = True

    def stop(self) -> None:
        self._stop_stream()
        self.streaming = False

    def read(self, n: int, *, timeout_s: float | None = None) -> ImuSamples:
        """The next ``n`` samples.  DeviceTimeout when no valid frame comes for ``timeout_s``
        (default ``settings.frame_timeout_s``)."""
        if not self.streaming:
            self.start()
        n = int(n)
        if n < 0:
            raise ValueError("n must be >= 0")
        timeout = self.settings.frame_timeout_s if timeout_s is None else float(timeout_s)
        blocks, have = [self._pending], len(self._pending)
        last_frame = time.monotonic()
        while have < n:
            data, self._carry = (self._carry, b"") if self._carry else (self.port.read_some(), b"")
            now = time.monotonic()
            if data:
                block = self._decode(data)
                if len(block):
                    blocks.append(block)
                    have += len(block)
                    last_frame = now
                    continue
            if now - last_frame > timeout:
                c = self.counters
                raise DeviceTimeout(self.name, f"no valid frame for {timeout:g} s (after {c.frames} "
                                               f"frames, {c.checksum_errors} checksum errors, "
                                               f"{c.resyncs} resyncs)")
        out, self._pending = ImuSamples.concat(blocks).split(n)
        return out

    def read_available(self) -> ImuSamples:
        """Every sample whose bytes have already reached this computer: those kept from
        earlier reads and those decoded from what is waiting in the port now.  Never waits for
        more (the sequencer's settle starts after the newest of them)."""
        if not self.streaming:
            self.start()
        data, self._carry = self._carry + self.port.read_waiting(), b""
        blocks = [self._pending]
        if data:
            blocks.append(self._decode(data))
        self._pending = ImuSamples.empty()
        return ImuSamples.concat(blocks)

    def read_seconds(self, seconds: float, **kw) -> ImuSamples:
        """``seconds`` of DEVICE time: round(seconds x rate) samples."""
        return self.read(int(round(float(seconds) * self.rate_hz)), **kw)

    def _decode(self, data: bytes) -> ImuSamples:
        d = self._decoder
        block = d.feed(data)
        c = self.counters
        c.frames, c.checksum_errors = d.frames, d.checksum_errors
        c.resyncs, c.bytes_discarded = d.resyncs, d.bytes_discarded
        if len(block):
            t = block.t_s
            period = 1.0 / self.rate_hz
            prev = self._last_t if self._last_t is not None else t[0]
            steps = np.diff(t, prepend=prev)
            big = steps > 1.5 * period
            if big.any():
                c.gaps += int(big.sum())
                c.missing_frames += int(np.round(steps[big] / period - 1.0).sum())
            self._last_t = float(t[-1])
        return block

    # ------------------------------------------------------------------ protocol part
    @abc.abstractmethod
    def _identify(self) -> str: ...

    @abc.abstractmethod
    def _configure(self, rate_hz: float, temperature: bool) -> float: ...

    @abc.abstractmethod
    def _new_decoder(self):
        """A fresh decoder with ``feed(bytes) -> ImuSamples`` and its counters."""

    @abc.abstractmethod
    def _start_stream(self) -> None: ...

    @abc.abstractmethod
    def _stop_stream(self) -> None: ...
