"""Driver for microcontroller IMUs printing csv lines (protocol ``csv``).

Nothing is sent to the device: the stream runs from power-up, the rate is the setting's
(used to count gaps), the units come from ``ImuSettings.csv_format``.
"""
from __future__ import annotations

import time

from .errors import DeviceTimeout
from .imu import Imu
from .protocols.csvlines import COLUMNS, MAX_LINE_BYTES, CsvDecoder, CsvFormat


class CsvImu(Imu):
    protocol = "csv"

    @property
    def format(self) -> CsvFormat:
        return self.settings.csv_format or CsvFormat()

    def _identify(self) -> str:
        """Waits for two line ends and names the number of columns of the line between."""
        self.port.discard_input()
        buf = bytearray()
        wait = max(self.settings.frame_timeout_s, self.settings.serial.timeout_s)
        deadline = time.monotonic() + wait
        while buf.count(b"\n") < 2:
            if time.monotonic() > deadline:
                raise DeviceTimeout(self.name, f"no csv line within {wait:g} s (is the device "
                                               "streaming, at this baud rate?)")
            buf += self.port.read_some()
            if len(buf) > 4 * MAX_LINE_BYTES and buf.count(b"\n") < 2:
                raise DeviceTimeout(self.name, "no line ends in the stream: not a csv line stream")
        line = bytes(buf).split(b"\n")[1].strip()
        n = line.count(b",") + 1
        cols = ",".join(COLUMNS[:n]) if n in (7, 8) else f"{n} fields"
        return f"csv line stream ({cols}; units t {self.format.time_unit}, accel " \
               f"{self.format.accel_unit}, gyro {self.format.gyro_unit})"

    def _configure(self, rate_hz, temperature):
        return rate_hz

    def _new_decoder(self):
        return CsvDecoder(self.format)

    def _start_stream(self):
        self.port.discard_input()

    def _stop_stream(self):
        pass
