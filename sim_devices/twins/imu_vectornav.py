"""VectorNav front-end of the IMU twin: the ASCII commands and the binary output frames.

Implements ``$VNRRG``/``$VNWRG`` of registers 1 (model), 2 (hardware revision), 3 (serial
number), 4 (firmware), 5 (baud rate), 6 (async ASCII output type: 0 off, 14 ``$VNYMR`` or 19
``$VNIMU``), 7 (its frequency), 27 (yaw, pitch, roll, mag, accel, gyro), 54 (IMU
measurements), 75-77 (binary outputs; only 75 may stream), ``$VNASY``, ``$VNWNV`` (save the
settings) and ``$VNRST`` (back to the saved settings); everything else is answered ``$VNERR``
with the code in two hex digits (``$VNERR,0C``), as the sensor sends it.  Commands may carry
the 8-bit checksum, the 16-bit CRC or ``*XX``; a reply is protected the same way as its
command.  Binary output register 1 may select any of TimeStartup, UncompAccel, UncompGyro and
Temp (the first three required): other fields are refused with ``$VNERR,07`` (a limit of the
twin, not of the protocol).

A write of register 06, 07 or 75 after which the async outputs (the ASCII message at its
frequency plus binary output 1 at 800 Hz / divisor) would need more than the baud rate carries
(10 bits a byte) is refused with ``$VNERR,0C``, insufficient baud rate (VN-200 UM004 table 20:
"The baud rate is not high enough to support the requested asynchronous data output at the
requested data rate"; a public VN-100 transcript: ``$VNWRG,07,100`` with ``$VNYMR`` at 115200
baud → ``$VNERR,0C``, 40 and 50 Hz accepted).

Power-up (``startup``): ``"factory"`` (the default) as a VN-100 leaves the factory: ``$VNYMR``
at 40 Hz on, binary outputs off, 115200 baud; ``"binary"``: binary output 1 already on with
station's layout at the truth's sample rate, ASCII output as ``ador``/``adof`` say (default
off) -- for tests that read frames from the front end without a driver.
"""
from __future__ import annotations

import numpy as np

from drivers.protocols import vectornav as V
from drivers.protocols.vectornav_binary import encode_frames

from scipy.spatial.transform import Rotation

from .faults import StreamFaulter
from .imu import ImuTwin
from .lines import take_lines

MAX_LINE = 512
TWIN_FIELDS = set(V.STATION_FIELDS)
STARTUPS = ("factory", "binary")
REG_YMR = 27
#: the magnetic field the twin's $VNYMR shows, gauss, in ENU (a plausible mid-latitude field;
#: the twin simulates no magnetometer: **unverified**, not a model of any site)
MAG_ENU_GAUSS = np.array([0.0, 0.2, -0.45])


class VectorNavFrontEnd:
    def __init__(self, imu: ImuTwin, faulter: StreamFaulter, *, serial_number: str = "0100000001",
                 model: str = "VN-100T-SIM", firmware: str = "2.1.0.0", hardware: str = "2",
                 startup: str = "factory", ador: int | None = None, adof_hz: int = V.FACTORY_ADOF_HZ):
        if startup not in STARTUPS:
            raise ValueError(f"startup must be one of {STARTUPS}, got {startup!r}")
        self.imu = imu
        self.faulter = faulter
        self.registers = {V.REG_MODEL: model, V.REG_HARDWARE: hardware, V.REG_SERIAL: serial_number,
                          V.REG_FIRMWARE: firmware}
        self.layout = V.STATION_LAYOUT
        self.divisor = max(1, round(V.IMU_RATE_HZ / imu.rate_hz))
        factory = startup == "factory"
        self.async_mode = V.ASYNC_MODE_NONE if factory else V.ASYNC_MODE_PORT1
        self.binary_set = not factory        # register 75 reads 0,0,00 until it is written
        self.async_on = True
        self.baudrate = V.FACTORY_BAUD
        if ador is None:
            ador = V.FACTORY_ADOR if factory else V.ADOR_OFF
        self.ador, self.adof_hz = ador, adof_hz
        self.other_outputs = {V.REG_BINARY_OUTPUT_2: "0,0,00", V.REG_BINARY_OUTPUT_3: "0,0,00"}
        self._next_ascii_k: int | None = None
        self._rx = bytearray()
        self._restart_at: float | None = None
        self.frame_length = self.layout.frame_length
        self.resets = 0
        self._saved = self._settings()

    # ---------------------------------------------------------------- commands
    def receive(self, data: bytes, now: float) -> bytes:
        self._rx += data
        # a message is recognised with its line end
        out = [self.execute(line + b"\n", now) for line in take_lines(self._rx) if line.strip()]
        if len(self._rx) > MAX_LINE:
            self._rx.clear()
            out.append(V.format_message(V.error_body(2)))
        return b"".join(out)

    def execute(self, line: bytes, now: float) -> bytes:
        found = V.find_message(line, allow_no_checksum=True)
        if found is None:
            return V.format_message(V.error_body(3))
        crc = V.uses_crc(line)

        def reply(body):
            return V.format_message(body, crc=crc)

        fields = found[0].split(",")
        try:
            if fields[0] == "VNRRG":
                return reply(self._read_register(fields[1:], now))
            if fields[0] == "VNWRG":
                return reply(self._write_register(fields[1:], now))
            if fields[0] == "VNASY":
                if len(fields) != 2 or fields[1] not in ("0", "1"):
                    return reply(V.error_body(7))
                on = fields[1] == "1"
                if on and not self.async_on:
                    self.imu.restart(now)
                    self._next_ascii_k = None
                self.async_on = on
                return reply(found[0])
            if fields[0] in ("VNWNV", "VNRST"):
                if len(fields) != 1:
                    raise _VnError(6)
                if fields[0] == "VNWNV":
                    self._saved = self._settings()
                else:
                    self._restore(self._saved, now)
                    self.resets += 1
                return reply(fields[0])
        except _VnError as e:
            return reply(V.error_body(e.code))
        return reply(V.error_body(4))

    # ---------------------------------------------------------------- settings
    def _settings(self) -> dict:
        return {"layout": self.layout, "divisor": self.divisor, "async_mode": self.async_mode,
                "binary_set": self.binary_set, "baudrate": self.baudrate, "ador": self.ador, "adof_hz": self.adof_hz,
                "other_outputs": dict(self.other_outputs)}

    def _restore(self, saved: dict, now: float) -> None:
        for key, value in saved.items():
            setattr(self, key, dict(value) if isinstance(value, dict) else value)
        self.frame_length = self.layout.frame_length
        self.async_on = True                   # after a reset the sensor streams again
        self._next_ascii_k = None
        self.imu.set_rate(V.IMU_RATE_HZ / self.divisor, now)

    def _read_register(self, args, now) -> str:
        if not args:
            raise _VnError(5)
        reg = _int(args[0])
        if len(args) > (2 if reg in (V.REG_BAUD, V.REG_ADOR, V.REG_ADOF) else 1):   # [,port]
            raise _VnError(6)
        if reg == V.REG_BINARY_OUTPUT_1:
            value = (self.layout.register_values(self.async_mode, self.divisor) if self.binary_set
                     else "0,0,00")
        elif reg in self.other_outputs:
            value = self.other_outputs[reg]
        elif reg == V.REG_BAUD:
            value = str(self.baudrate)
        elif reg == V.REG_ADOR:
            value = str(self.ador)
        elif reg == V.REG_ADOF:
            value = str(self.adof_hz)
        elif reg == V.REG_IMU:
            value = self._imu_values(now)
        elif reg == REG_YMR:
            value = self._ymr_values(now)
        elif reg in self.registers:
            value = self.registers[reg]
        else:
            raise _VnError(8)
        return f"VNRRG,{reg:02d},{value}"

    def _imu_values(self, now: float) -> str:
        """Register 54 / $VNIMU: the newest sample on the output grid (no magnetometer or
        barometer in the twin: mag 0, pressure 101.325 kPa)."""
        return self._imu_lines(np.array([now]))[0]

    def _ymr_values(self, now: float) -> str:
        return self._ymr_lines(np.array([now]))[0]

    def _grid(self, times) -> np.ndarray:
        """The newest sample time on the output grid at each of ``times``."""
        return np.floor(np.asarray(times, dtype=float) * self.imu.rate_hz) / self.imu.rate_hz

    def _imu_lines(self, times) -> list[str]:
        accel, gyro, temp = self.imu.measure(self._grid(times))
        w = np.radians(gyro)
        return [V.imu_values((0.0, 0.0, 0.0), a, g, float(c), 101.325) for a, g, c in zip(accel, w, temp)]

    def _ymr_lines(self, times) -> list[str]:
        """Register 27 / $VNYMR at each of ``times`` (one measurement for all).  Yaw, pitch,
        roll: the case axes' attitude relative to ENU from the table twin (intrinsic Z-Y-X
        angles; the sensor's own filter estimates it relative to NED: the twin has none); mag:
        a constant field (MAG_ENU_GAUSS) in the case axes; accel (m/s²) and gyro (rad/s) as
        measured."""
        t = self._grid(times)
        accel, gyro, _ = self.imu.measure(t)
        C_bn = self.imu.table.kinematics_at(t)[0]
        m = C_bn.as_matrix().reshape(-1, 3, 3)
        ypr = Rotation.from_matrix(np.swapaxes(m, 1, 2)).as_euler("ZYX", degrees=True)
        mag = m @ MAG_ENU_GAUSS
        w = np.radians(gyro)
        return [V.ymr_values(*row) for row in zip(ypr, mag, accel, w)]

    def _output_bytes_per_s(self, ador=None, adof_hz=None, async_mode=None, divisor=None,
                            frame_length=None) -> float:
        """Bytes a second of the async outputs with these settings (the present ones where
        not given): the ASCII message at its frequency and binary output 1."""
        ador = self.ador if ador is None else ador
        adof_hz = self.adof_hz if adof_hz is None else adof_hz
        async_mode = self.async_mode if async_mode is None else async_mode
        divisor = self.divisor if divisor is None else divisor
        frame_length = self.frame_length if frame_length is None else frame_length
        total = V.ASCII_MESSAGE_BYTES.get(ador, 0) * adof_hz if ador != V.ADOR_OFF else 0.0
        if async_mode != V.ASYNC_MODE_NONE:
            total += frame_length * V.IMU_RATE_HZ / divisor
        return total

    def _check_bandwidth(self, **settings) -> None:
        """``$VNERR,0C`` if the outputs with ``settings`` would not fit the baud rate."""
        if self._output_bytes_per_s(**settings) * V.BITS_PER_BYTE > self.baudrate:
            raise _VnError(V.ERROR_INSUFFICIENT_BAUD)

    def _write_register(self, args, now) -> str:
        if not args:
            raise _VnError(5)
        reg = _int(args[0])
        if reg in (V.REG_BAUD, V.REG_ADOR, V.REG_ADOF):
            if not 2 <= len(args) <= 3:
                raise _VnError(5 if len(args) < 2 else 6)
            value = _int(args[1])
            if reg == V.REG_BAUD and value not in V.BAUD_RATES:
                raise _VnError(7)
            if reg == V.REG_ADOR and value not in (V.ADOR_OFF, V.ADOR_VNYMR, V.ADOR_VNIMU):
                raise _VnError(7)              # other ASCII outputs: not made by the twin
            if reg == V.REG_ADOF and value not in V.ADOF_HZ:
                raise _VnError(7)
            if reg == V.REG_ADOR:
                self._check_bandwidth(ador=value)
            elif reg == V.REG_ADOF:
                self._check_bandwidth(adof_hz=value)
            if reg == V.REG_BAUD:
                self.baudrate = value
            elif reg == V.REG_ADOR:
                self.ador = value
                self._next_ascii_k = None
            else:
                self.adof_hz = value
                self._next_ascii_k = None
            return "VNWRG," + ",".join(args)
        if reg in self.other_outputs:
            if len(args) < 2 or _int(args[1]) != V.ASYNC_MODE_NONE:
                raise _VnError(7)              # the twin streams binary output 1 only
            self.other_outputs[reg] = ",".join(args[1:])
            return "VNWRG," + ",".join(args)
        if reg != V.REG_BINARY_OUTPUT_1:
            raise _VnError(8 if reg not in self.registers else 9)
        if len(args) >= 2 and _int(args[1]) == V.ASYNC_MODE_NONE and all(_int(a, 16) == 0 for a in args[2:4]):
            # output off as VectorNav's own library writes it ($VNWRG,75,0,0,0: its default
            # BinaryOutputRegister): async mode 0, no group; reads back 0,0,00 as at power-up
            self.async_mode, self.binary_set = V.ASYNC_MODE_NONE, False
            return "VNWRG," + ",".join(args)
        try:
            async_mode, divisor, layout = V.parse_register_75(args[1:])
        except ValueError:
            raise _VnError(7) from None
        names = {f[0] for f in layout.fields}
        if not names <= TWIN_FIELDS or not {"TimeStartup", "UncompAccel", "UncompGyro"} <= names:
            raise _VnError(7)
        self._check_bandwidth(async_mode=async_mode, divisor=divisor, frame_length=layout.frame_length)
        self.async_mode, self.divisor, self.layout = async_mode, divisor, layout
        self.binary_set = True
        self.frame_length = layout.frame_length
        self.imu.set_rate(V.IMU_RATE_HZ / divisor, now)
        return "VNWRG," + ",".join(args)

    # ---------------------------------------------------------------- frames
    @property
    def streaming(self) -> bool:
        """Whether async output goes out: binary output 1 or the ASCII message."""
        return self.async_on and (self.async_mode != V.ASYNC_MODE_NONE or self.ador != V.ADOR_OFF)

    @property
    def line_baud(self) -> int:
        """The baud rate the sensor's serial port runs at (register 05)."""
        return self.baudrate

    def produce(self, now: float) -> bytes:
        """The frames due by ``now`` (with the stream faults applied), then the ASCII async
        messages due (``$VNYMR`` or ``$VNIMU`` when register 06 is 14 or 19)."""
        return self._produce_binary(now) + self._produce_ascii(now)

    def _produce_ascii(self, now: float) -> bytes:
        if not self.async_on or self.ador not in (V.ADOR_VNYMR, V.ADOR_VNIMU):
            return b""
        header, lines = (("VNYMR,", self._ymr_lines) if self.ador == V.ADOR_VNYMR
                         else ("VNIMU,", self._imu_lines))
        last = int(np.floor(now * self.adof_hz))
        if self._next_ascii_k is None:
            self._next_ascii_k = last + 1
        first = max(self._next_ascii_k, last - 50)
        self._next_ascii_k = last + 1
        if first > last:
            return b""
        bodies = lines(np.arange(first, last + 1) / self.adof_hz)
        return b"".join(V.format_message(header + body) for body in bodies)

    def _produce_binary(self, now: float) -> bytes:
        if not self.async_on or self.async_mode == V.ASYNC_MODE_NONE:
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


def _int(text: str, base: int = 10) -> int:
    try:
        return int(text, base)
    except ValueError:
        raise _VnError(7) from None
