"""Xsens MTi front-end of the IMU twin: XBus messages in, acknowledgements and MTData2 out.

Config and measurement states; GoToConfig, GoToMeasurement, ReqDID, ReqProductCode,
ReqFWRev, SetBaudrate and SetOutputConfiguration (in config state only: SampleTimeFine,
Acceleration, RateOfTurn, Temperature, the last three at one rate of 400 Hz / N) are
answered; anything else is the Error message 0x04 (invalid message).  A message with a bad
checksum is ignored, as by the device.  At power-up the twin measures, with station's output
configuration at the truth's sample rate.
"""
from __future__ import annotations

import struct

import numpy as np

from drivers.protocols import xbus as X

from .faults import StreamFaulter
from .imu import ImuTwin

CONFIG, MEASUREMENT = "config", "measurement"


class XsensFrontEnd:
    def __init__(self, imu: ImuTwin, faulter: StreamFaulter, *, device_id: int = 0x03700001,
                 product: str = "MTi-3-SIM", firmware: tuple[int, int, int] = (1, 8, 2)):
        self.imu = imu
        self.faulter = faulter
        self.device_id, self.product, self.firmware = device_id, product, firmware
        self.state = MEASUREMENT
        self.baud_id = 0x02
        self.items = X.station_configuration(int(round(imu.rate_hz)))
        self.frame_length = X.mtdata2_length(self.items)
        self.parser = X.XbusParser()

    @property
    def streaming(self) -> bool:
        return self.state == MEASUREMENT

    @property
    def line_baud(self) -> int:
        """The serial line's rate: 115200, the MTi's default.  SetBaudrate is stored and read
        back but, as on the device (it takes effect after a reset), does not change the line:
        the twin models no reset (**unverified** beyond mtdef.py's message list)."""
        return 115200

    def receive(self, data: bytes, now: float) -> bytes:
        return b"".join(self._execute(mid, payload, now) for mid, payload in self.parser.feed(data))

    def _execute(self, mid: int, data: bytes, now: float) -> bytes:
        ack = X.message
        if mid == X.MID.GoToConfig:
            self.state = CONFIG
            return ack(mid + 1)
        if mid == X.MID.GoToMeasurement:
            if self.state != MEASUREMENT:
                self.state = MEASUREMENT
                self.imu.restart(now)
            return ack(mid + 1)
        if mid == X.MID.WakeUpAck:
            self.state = CONFIG
            return b""
        if mid == X.MID.ReqDID:
            return ack(X.MID.DeviceID, struct.pack(">I", self.device_id))
        if mid == X.MID.ReqProductCode:
            return ack(X.MID.ProductCode, self.product.encode("ascii"))
        if mid == X.MID.ReqFWRev:
            return ack(X.MID.FirmwareRev, bytes(self.firmware))
        if mid == X.MID.SetBaudrate:
            if not data:
                return ack(mid + 1, bytes([self.baud_id]))
            if self.state != CONFIG or len(data) != 1 or data[0] not in X.BAUD_IDS:
                return self._error(0x20)
            self.baud_id = data[0]
            return ack(mid + 1)
        if mid == X.MID.SetOutputConfiguration:
            if not data:
                return ack(mid + 1, X.output_configuration(self.items))
            if self.state != CONFIG:
                return self._error(0x04)
            return self._set_outputs(data, now)
        return self._error(0x04)

    def _set_outputs(self, data: bytes, now: float) -> bytes:
        try:
            items = X.parse_output_configuration(data)
        except ValueError:
            return self._error(0x21)
        xdis = [x for x, _ in items]
        rates = {f for x, f in items if x != X.XDI_SAMPLE_TIME_FINE}
        needed = {X.XDI_SAMPLE_TIME_FINE, X.XDI_ACCELERATION, X.XDI_RATE_OF_TURN}
        if (not set(xdis) <= set(X.XDI) or len(set(xdis)) != len(xdis) or not needed <= set(xdis)
                or len(rates) != 1):
            return self._error(0x21)            # a limit of the twin: one rate, these outputs
        rate = rates.pop()
        if not 1 <= rate <= X.MAX_RATE_HZ or X.MAX_RATE_HZ % rate:
            return self._error(0x21)
        self.items = items
        self.frame_length = X.mtdata2_length(items)
        self.imu.set_rate(float(rate), now)
        return X.message(X.MID.SetOutputConfiguration + 1, data)

    def _error(self, code: int) -> bytes:
        return X.message(X.MID.Error, bytes([code]))

    def produce(self, now: float) -> bytes:
        if not self.streaming:
            return b""
        t = self.imu.sample_times_until(now)
        if not t.size:
            return b""
        accel, gyro, temp = self.imu.measure(t)
        ticks = np.round(t / X.SAMPLE_TICK_S).astype(np.int64)
        blob = X.encode_mtdata2(self.items, ticks, accel, np.radians(gyro), temp)
        if not self.faulter.faults.active and not self.faulter.record:
            self.faulter.frames_sent += t.size
            return blob
        L = self.frame_length
        return self.faulter.apply(t, [blob[i * L:(i + 1) * L] for i in range(t.size)])[0]
