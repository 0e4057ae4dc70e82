"""csv front-end of the IMU twin: one ``t,ax,ay,az,gx,gy,gz,temp`` line per sample, from
power-up, in the units of a :class:`drivers.protocols.csvlines.CsvFormat`.  Input is ignored
(hobby firmware takes no commands).  ``clock_start_s``: the ``t`` column is a host's clock (a logger
that stamps each line as it arrives), the device time plus the host's clock at the IMU's power-on
(0: the IMU's own time since power-up)."""
from __future__ import annotations

from drivers.protocols.csvlines import CsvFormat, encode_lines

from .faults import StreamFaulter
from .imu import ImuTwin


class CsvFrontEnd:
    def __init__(self, imu: ImuTwin, faulter: StreamFaulter, fmt: CsvFormat = CsvFormat(), clock_start_s: float = 0.0):
        self.imu = imu
        self.clock_start_s = float(clock_start_s)
        self.faulter = faulter
        self.fmt = fmt
        self.streaming = True
        self.line_baud = 115200         # the serial line's rate (a microcontroller's fixed UART)

    def receive(self, data: bytes, now: float) -> bytes:
        return b""

    def produce(self, now: float) -> bytes:
        t = self.imu.sample_times_until(now)
        if not t.size:
            return b""
        accel, gyro, temp = self.imu.measure(t)
        blob = encode_lines(self.fmt, t + self.clock_start_s, accel, gyro, temp)
        if not self.faulter.faults.active and not self.faulter.record:
            self.faulter.frames_sent += t.size
            return blob
        return self.faulter.apply(t, blob.splitlines(keepends=True))[0]
