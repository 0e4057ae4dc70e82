"""VectorNav front-end of the IMU twin: the ASCII commands and the binary output frames.

Implements ``$VNRRG`` (registers 1, 3, 4, 75), ``$VNWRG,75`` and ``$VNASY``; everything else
is answered ``$VNERR``.  Binary output register 1 may select any of TimeStartup,
UncompAccel, UncompGyro and Temp (the first three required): other fields are refused with
``$VNERR,07`` (a limit of the twin, not of the protocol).  At power-up, binary output 1 is
already on: station's layout at the truth's sample rate.
"""
from __future__ import annotations

import numpy as np

from drivers.protocols import vectornav as V
from drivers.protocols.vectornav_binary import encode_frames

from .faults import StreamFaulter
from .imu import ImuTwin
from .lines import take_lines

MAX_LINE = 512
TWIN_FIELDS = set(V.STATION_FIELDS)


class VectorNavFrontEnd:
    def __init__(self, imu: ImuTwin, faulter: StreamFaulter, *, serial_number: str = "0100000001",
                 model: str = "VN-100T-SIM", firmware: str = "2.1.0.0"):
        self.imu = imu
        self.faulter = faulter
        self.registers = {V.REG_MODEL: model, V.REG_SERIAL: serial_number, V.REG_FIRMWARE: firmware}
        self.layout = V.STATION_LAYOUT
        self.divisor = max(1, round(V.IMU_RATE_HZ / imu.rate_hz))
        self.async_mode = V.ASYNC_MODE_PORT1
        self.async_on = True
        self._rx = bytearray()
        self._restart_at: float | None = None
        self.frame_length = self.layout.frame_length

    # ---------------------------------------------------------------- commands
    def receive(self, data: bytes, now: float) -> bytes:
        self._rx += data
        # a message is recognised with its line end
        out = [self.execute(line + b"\n", now) for line in take_lines(self._rx) if line.strip()]
        if len(self._rx) > MAX_LINE:
            self._rx.clear()
            out.append(V.format_message("VNERR,02"))
        return b"".join(out)

    def execute(self, line: bytes, now: float) -> bytes:
        found = V.find_message(line, allow_no_checksum=True)
        if found is None:
            return V.format_message("VNERR,03")
        fields = found[0].split(",")
        try:
            if fields[0] == "VNRRG":
                return V.format_message(self._read_register(fields[1:]))
            if fields[0] == "VNWRG":
                return V.format_message(self._write_register(fields[1:], now))
            if fields[0] == "VNASY":
                if len(fields) != 2 or fields[1] not in ("0", "1"):
                    return V.format_message("VNERR,07")
                on = fields[1] == "1"
                if on and not self.async_on:
                    self.imu.restart(now)
                self.async_on = on
                return V.format_message(found[0])
        except _VnError as e:
            return V.format_message(f"VNERR,{e.code:02d}")
        return V.format_message("VNERR,04")

    def _read_register(self, args) -> str:
        if len(args) != 1:
            raise _VnError(5 if not args else 6)
        reg = _int(args[0])
        if reg == V.REG_BINARY_OUTPUT_1:
            return f"VNRRG,{reg:02d},{self.layout.register_values(self.async_mode, self.divisor)}"
        if reg not in self.registers:
            raise _VnError(8)
        return f"VNRRG,{reg:02d},{self.registers[reg]}"

    def _write_register(self, args, now) -> str:
        if not args:
            raise _VnError(5)
        reg = _int(args[0])
        if reg != V.REG_BINARY_OUTPUT_1:
            raise _VnError(8 if reg not in self.registers else 9)
        try:
            async_mode, divisor, layout = V.parse_register_75(args[1:])
        except ValueError:
            raise _VnError(7) from None
        names = {f[0] for f in layout.fields}
        if not names <= TWIN_FIELDS or not {"TimeStartup", "UncompAccel", "UncompGyro"} <= names:
            raise _VnError(7)
        self.async_mode, self.divisor, self.layout = async_mode, divisor, layout
        self.frame_length = layout.frame_length
        self.imu.set_rate(V.IMU_RATE_HZ / divisor, now)
        return "VNWRG," + ",".join(args)

    # ---------------------------------------------------------------- frames
    @property
    def streaming(self) -> bool:
        return self.async_on and self.async_mode != V.ASYNC_MODE_NONE

    def produce(self, now: float) -> bytes:
        """The frames due by ``now`` (with the stream faults applied)."""
        if not self.streaming:
            return b""
        t = self.imu.sample_times_until(now)
        if not t.size:
            return b""
        accel, gyro, temp = self.imu.measure(t)
        blob = encode_frames(self.layout, np.round(t * 1e9).astype(np.uint64), accel,
                             np.radians(gyro), temp)
        if not self.faulter.faults.active and not self.faulter.record:
            self.faulter.frames_sent += t.size
            return blob
        L = self.frame_length
        frames = [blob[i * L:(i + 1) * L] for i in range(t.size)]
        return self.faulter.apply(t, frames)[0]


class _VnError(Exception):
    def __init__(self, code: int):
        self.code = code


def _int(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise _VnError(7) from None
