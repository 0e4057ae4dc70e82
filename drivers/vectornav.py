"""Driver for VectorNav IMUs in binary output mode (protocol ``vectornav``).

Start-up over the ASCII protocol, as VectorNav's programming library does it: pause
asynchronous output (``$VNASY,0``), turn the ASCII async output off (register 06 = 0: a
factory-default sensor streams ``$VNYMR`` at 40 Hz, which would mix with the binary frames), read the model, hardware revision,
serial number and firmware registers (01-04), set the baud rate (register 05) when asked,
write binary output register 1 (75) with time since startup, uncompensated acceleration and
rate and temperature at 800 Hz / divisor (checked against what the baud rate carries),
resume (``$VNASY,1``).  Frames are then decoded by
:class:`drivers.protocols.vectornav_binary.VectorNavDecoder`.
"""
from __future__ import annotations

import time

from .errors import DeviceTimeout, LimitError, ProtocolError
from .imu import Imu
from .protocols import vectornav as V
from .protocols.vectornav_binary import VectorNavDecoder

MAX_REPLY_SCAN = 1 << 20


class VectorNavImu(Imu):
    protocol = "vectornav"

    def __init__(self, url, settings=None):
        super().__init__(url, settings)
        self.layout = V.STATION_LAYOUT

    def _ask(self, body: str) -> list[str]:
        """Send ``$body*XX``; return the reply's fields after the command name.

        Waits for the reply echoing the command (``VNWRG,75``, ``VNASY``, ...) or ``VNERR``;
        anything else (binary frames, other messages) is skipped; bytes after the reply are
        kept for the decoder.
        """
        head = body.split(",")[0]
        key = ",".join(body.split(",")[:2]) if head in ("VNRRG", "VNWRG") else head
        self.port.write(V.format_message(body))
        deadline = time.monotonic() + self.settings.serial.timeout_s
        buf, pos = bytearray(), 0
        while True:
            found = V.find_message(buf, pos)
            while found is not None:
                reply, end = found
                if reply == key or reply.startswith(key + ","):
                    self._carry = bytes(buf[end:])
                    return reply.split(",")[len(key.split(",")):]
                if reply.startswith("VNERR"):
                    raise ProtocolError(self.name, f"${body} refused: {self._error_text(reply)}")
                pos = end
                found = V.find_message(buf, pos)
            if len(buf) > MAX_REPLY_SCAN:
                del buf[:len(buf) - 256]
                pos = 0
            if time.monotonic() > deadline:
                raise DeviceTimeout(self.name, f"no reply to ${body} within "
                                               f"{self.settings.serial.timeout_s:g} s")
            buf += self.port.read_some()

    def _error_text(self, reply: str) -> str:
        """``VNERR 0C (error 12: insufficient baud rate; ...what to do)``: the code is hex."""
        text = reply.split(",")[1] if "," in reply else "?"
        code = V.parse_error_code(text)
        if code is None:
            return f"VNERR {text} (not a hex error code)"
        meaning = V.ERRORS.get(code, "unknown error")
        if code == V.ERROR_INSUFFICIENT_BAUD:
            baud = getattr(self, "baudrate", self.settings.serial.baudrate)
            meaning += (f": the outputs configured need more bytes per second than {baud} baud "
                        f"carries (10 bits a byte); lower the output rate, turn other outputs off "
                        f"(register 06 ASCII, 75-77 binary) or set a higher baud rate (register 05: "
                        f"ImuSettings.device_baud, station probe --imu-baud)")
        return f"VNERR {text} (error {code}: {meaning})"

    # ---------------------------------------------------------------- protocol part
    def _identify(self) -> str:
        baud = self.settings.device_baud
        if baud is not None and baud not in V.BAUD_RATES:       # before anything is sent
            raise LimitError(self.name, f"baud rate {baud} is not one of "
                                        f"{', '.join(map(str, V.BAUD_RATES))}")
        self._ask("VNASY,0")
        self.port.discard_input()
        self._ask(f"VNWRG,{V.REG_ADOR:02d},{V.ADOR_OFF}")
        model = ",".join(self._ask(f"VNRRG,{V.REG_MODEL:02d}"))
        hardware = ",".join(self._ask(f"VNRRG,{V.REG_HARDWARE:02d}"))
        serial_no = ",".join(self._ask(f"VNRRG,{V.REG_SERIAL:02d}"))
        firmware = ",".join(self._ask(f"VNRRG,{V.REG_FIRMWARE:02d}"))
        if baud is not None:
            self._ask(f"VNWRG,{V.REG_BAUD:02d},{baud}")      # answered at the old rate
            self.port.set_baudrate(baud)
        self.baudrate = baud or self.settings.serial.baudrate
        return f"{model} hardware {hardware} serial {serial_no} firmware {firmware}"

    def _configure(self, rate_hz, temperature):
        divisor = round(V.IMU_RATE_HZ / rate_hz)
        if divisor < 1 or abs(V.IMU_RATE_HZ / divisor - rate_hz) > 1e-9 * rate_hz:
            raise LimitError(self.name, f"output rate {rate_hz:g} Hz is not {V.IMU_RATE_HZ:g} Hz / N "
                                        f"(e.g. 800, 400, 200, 100, 50 Hz)")
        layout = V.STATION_LAYOUT if temperature else V.STATION_LAYOUT_NO_TEMP
        baud = getattr(self, "baudrate", self.settings.serial.baudrate)
        top = V.max_rate_hz(layout.frame_length, baud)
        if rate_hz > top:
            need = rate_hz * layout.frame_length * V.BITS_PER_BYTE
            raise LimitError(self.name, f"output rate {rate_hz:g} Hz of {layout.frame_length}-byte frames "
                                        f"needs {need:.0f} baud (10 bits a byte); at {baud} baud at most "
                                        f"{top:.1f} Hz: lower the rate or set a higher baud rate "
                                        f"(register 05: ImuSettings.device_baud, station probe --imu-baud)")
        self.layout = layout
        body = f"VNWRG,{V.REG_BINARY_OUTPUT_1},{self.layout.register_values(V.ASYNC_MODE_PORT1, divisor)}"
        if self.streaming:
            self._ask("VNASY,0")
        echo = self._ask(body)
        if ",".join(echo) != self.layout.register_values(V.ASYNC_MODE_PORT1, divisor):
            raise ProtocolError(self.name, f"${body} answered with {','.join(echo)!r}")
        self._carry = b""
        return V.IMU_RATE_HZ / divisor

    def _new_decoder(self):
        return VectorNavDecoder(self.layout)

    def _start_stream(self):
        self.port.discard_input()
        self._ask("VNASY,1")

    def _stop_stream(self):
        self._ask("VNASY,0")
        self._carry = b""
