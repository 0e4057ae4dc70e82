"""Driver for Xsens MTi IMUs over XBus, MTData2 output (protocol ``xsens``).

Start-up as the public ROS driver (ethzasl_xsens_driver ``mtdevice.py``) does it: GoToConfig
(acknowledged while the device may still be sending data), device id, product code, firmware
revision; ``configure``: SetOutputConfiguration with SampleTimeFine (every packet),
Acceleration, RateOfTurn and Temperature at the rate, the acknowledgement checked;
``start``: GoToMeasurement; ``stop``: GoToConfig.  See docs/protocols.md.
"""
from __future__ import annotations

import struct
import time

from .errors import DeviceTimeout, LimitError, ProtocolError
from .imu import Imu
from .protocols import xbus as X


class XsensImu(Imu):
    protocol = "xsens"

    def __init__(self, url, settings=None):
        super().__init__(url, settings)
        self._parser = X.XbusParser()
        self._items = X.station_configuration(int(self.rate_hz))

    def _ask(self, mid: int, data: bytes = b"", what: str = "") -> bytes:
        """Send a message; the data of its acknowledgement (``mid + 1``).  Data messages and
        other traffic meanwhile are skipped; the bytes after the acknowledgement are kept for
        the decoder.  An Error message is a ProtocolError."""
        what = what or f"MID {mid:#04x}"
        self._parser = X.XbusParser()
        self.port.write(X.message(mid, data))
        deadline = time.monotonic() + self.settings.serial.timeout_s
        while time.monotonic() < deadline:
            chunk = self.port.read_some()
            if not chunk:
                continue
            messages = self._parser.feed(chunk)
            for k, (got, payload) in enumerate(messages):
                if got == mid + 1:
                    # what came after the acknowledgement goes to the decoder, as it came
                    self._carry = (b"".join(X.message(m, d) for m, d in messages[k + 1:])
                                   + bytes(self._parser._buf))
                    return payload
                if got == X.MID.Error:
                    code = payload[0] if payload else -1
                    raise ProtocolError(self.name, f"{what} refused: error {code:#04x} "
                                                   f"({X.ERRORS.get(code, 'unknown error')})")
        raise DeviceTimeout(self.name, f"no acknowledgement of {what} within {self.settings.serial.timeout_s:g} s")

    # ---------------------------------------------------------------- protocol part
    def _identify(self) -> str:
        self._ask(X.MID.GoToConfig, what="GoToConfig")
        self.port.discard_input()
        did = self._ask(X.MID.ReqDID, what="ReqDID")
        product = self._ask(X.MID.ReqProductCode, what="ReqProductCode").decode("ascii", "replace").strip()
        fw = self._ask(X.MID.ReqFWRev, what="ReqFWRev")
        if len(did) != 4 or len(fw) < 3:
            raise ProtocolError(self.name, f"bad device id {did.hex()} or firmware revision {fw.hex()}")
        device_id = struct.unpack(">I", did)[0]
        return f"{product} device id {device_id:08X} firmware {fw[0]}.{fw[1]}.{fw[2]}"

    def _configure(self, rate_hz, temperature):
        n = X.MAX_RATE_HZ / rate_hz
        if abs(n - round(n)) > 1e-9 or round(n) < 1:
            raise LimitError(self.name, f"output rate {rate_hz:g} Hz is not {X.MAX_RATE_HZ:g} Hz / N "
                                        f"(e.g. 400, 200, 100, 50 Hz)")
        items = X.station_configuration(int(round(rate_hz)), temperature)
        length = X.mtdata2_length(items)
        baud = self.settings.serial.baudrate
        if rate_hz * length * 10 > baud:
            raise LimitError(self.name, f"output rate {rate_hz:g} Hz of {length}-byte messages needs "
                                        f"{rate_hz * length * 10:.0f} baud (10 bits a byte); at {baud} baud "
                                        f"at most {baud / (10 * length):.1f} Hz")
        if self.streaming:
            self._ask(X.MID.GoToConfig, what="GoToConfig")
        data = X.output_configuration(items)
        ack = self._ask(X.MID.SetOutputConfiguration, data, "SetOutputConfiguration")
        if ack != data:
            raise ProtocolError(self.name, f"SetOutputConfiguration acknowledged with {ack.hex()}, "
                                           f"sent {data.hex()}")
        self._items = items
        self._carry = b""
        return float(rate_hz)

    def _new_decoder(self):
        return X.XsensDecoder()

    def _start_stream(self):
        self._ask(X.MID.GoToMeasurement, what="GoToMeasurement")

    def _stop_stream(self):
        self._ask(X.MID.GoToConfig, what="GoToConfig")
