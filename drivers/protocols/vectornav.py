"""VectorNav: the ASCII command protocol and the binary output layout, as data.

ASCII: ``$`` body ``*`` XX ``\\r\\n``, XX the XOR of the body's bytes in two upper-case hex
digits (``XX`` literally: "no checksum", accepted by the sensor).  Replies echo the command's
body (``$VNWRG,75,...``), errors are ``$VNERR,XX`` with the code in two hex digits
(``$VNERR,0C``: error 12, insufficient baud rate; vnproglib ``Packet::parseError`` reads it
with ``to_uint8_from_hexstr``).

Binary output (VectorNav binary protocol, as documented for the VN-100/VN-200): sync byte
0xFA, the group byte (bit g-1 set: group g present), one little-endian uint16 field mask per
present group in group order, the payload (fields in group order then bit order,
little-endian), then the CRC-16/XMODEM of everything after the sync byte, big-endian (so the
CRC of group byte..CRC is 0).
"""
from __future__ import annotations

import binascii
import re
from dataclasses import dataclass

import numpy as np

SYNC = 0xFA

#: IMU sampling rate of the VN-100; binary output rate = IMU_RATE_HZ / rate divisor.
IMU_RATE_HZ = 800.0

# --- binary groups and fields (group number, bit, name, size in bytes, numpy type or None) ----
GROUP_FIELDS: dict[int, tuple[tuple[int, str, int, str | None], ...]] = {
    1: (  # Common group
        (0, "TimeStartup", 8, "<u8"),      # ns since startup
        (1, "TimeGps", 8, None),
        (2, "TimeSyncIn", 8, None),
        (3, "YawPitchRoll", 12, None),
        (4, "Quaternion", 16, None),
        (5, "AngularRate", 12, None),
        (6, "Position", 24, None),
        (7, "Velocity", 12, None),
        (8, "Accel", 12, None),
        (9, "Imu", 24, None),
        (10, "MagPres", 20, None),
        (11, "DeltaTheta", 28, None),
        (12, "InsStatus", 2, None),
        (13, "SyncInCnt", 4, None),
        (14, "TimeGpsPps", 8, None),
    ),
    3: (  # IMU group
        (0, "ImuStatus", 2, None),
        (1, "UncompMag", 12, None),
        (2, "UncompAccel", 12, "<f4"),     # m/s^2, 3 x float32
        (3, "UncompGyro", 12, "<f4"),      # rad/s, 3 x float32
        (4, "Temp", 4, "<f4"),             # deg C
        (5, "Pres", 4, None),
        (6, "DeltaTheta", 16, None),
        (7, "DeltaVel", 12, None),
        (8, "Mag", 12, None),
        (9, "Accel", 12, None),
        (10, "AngularRate", 12, None),
        (11, "SensSat", 2, None),
    ),
}
#: the fields station asks for: time since startup, uncompensated acceleration and rate, temperature
STATION_FIELDS = ("TimeStartup", "UncompAccel", "UncompGyro", "Temp")

# --- ASCII registers and error codes -------------------------------------------------------------
# register numbers and values as VectorNav's programming library (vnproglib 1.2, packet.cpp and
# types.h) reads and writes them
REG_MODEL = 1
REG_HARDWARE = 2          # hardware revision
REG_SERIAL = 3
REG_FIRMWARE = 4
REG_BAUD = 5              # serial baud rate: VNWRG,05,<baud>[,<port>]
REG_ADOR = 6              # async data output type (ASCII messages): 0 off, 14 $VNYMR, 19 $VNIMU
REG_ADOF = 7              # async data output frequency, Hz
REG_IMU = 54              # IMU measurements: mag (3), accel (3, m/s²), gyro (3, rad/s), temp (°C), pressure (kPa)
REG_BINARY_OUTPUT_1 = 75
REG_BINARY_OUTPUT_2 = 76
REG_BINARY_OUTPUT_3 = 77
ASYNC_MODE_NONE, ASYNC_MODE_PORT1, ASYNC_MODE_PORT2, ASYNC_MODE_BOTH = 0, 1, 2, 3
ADOR_OFF = 0
ADOR_VNYMR = 14           # $VNYMR: yaw, pitch, roll, mag, accel, gyro (register 27; types.h: VNYMR = 14)
ADOR_VNIMU = 19           # $VNIMU: the register 54 values (types.h: VNIMU = 19)
#: a factory-default VN-100: $VNYMR at 40 Hz on the serial port, binary outputs off
FACTORY_ADOR, FACTORY_ADOF_HZ, FACTORY_BAUD = ADOR_VNYMR, 40, 115200
BAUD_RATES = (9600, 19200, 38400, 57600, 115200, 128000, 230400, 460800, 921600)
ADOF_HZ = (1, 2, 4, 5, 10, 20, 25, 40, 50, 100, 200)
#: bits on the line per byte (8 data bits, no parity, 1 start and 1 stop bit)
BITS_PER_BYTE = 10


def max_rate_hz(frame_length: int, baudrate: int) -> float:
    """The highest output rate a serial line of ``baudrate`` carries for frames of
    ``frame_length`` bytes (44-byte frames at 115200 baud: 261.8 Hz)."""
    return baudrate / (BITS_PER_BYTE * frame_length)

#: error codes (VN-100 UM001 / VN-200 UM004 "System Error Codes"); sent as two hex digits
ERROR_INSUFFICIENT_BAUD = 12
ERRORS = {
    1: "hard fault", 2: "serial buffer overflow", 3: "invalid checksum", 4: "invalid command",
    5: "not enough parameters", 6: "too many parameters", 7: "invalid parameter",
    8: "invalid register", 9: "unauthorized access", 10: "watchdog reset",
    11: "output buffer overflow", 12: "insufficient baud rate", 255: "error buffer overflow",
}



def error_body(code: int) -> str:
    """The body of the error message for ``code``: ``VNERR,0C`` for 12 (two hex digits)."""
    return f"VNERR,{code:02X}"


def parse_error_code(text: str) -> int | None:
    """The code of ``$VNERR,<text>`` (hex, as the sensor sends it), None if not hex."""
    return int(text, 16) if re.fullmatch(r"[0-9A-Fa-f]{1,2}", text.strip()) else None


def ymr_values(ypr_deg, mag_gauss, accel_mps2, gyro_rad_s) -> str:
    """The 12 fields of register 27 / ``$VNYMR`` in the manual's widths (UM001 §7.2.3 example
    ``+006.380,...,+1.0640,...,-09.758,-0.001222``)."""
    return ",".join([f"{v:+08.3f}" for v in ypr_deg] + [f"{v:+07.4f}" for v in mag_gauss]
                    + [f"{v:+07.3f}" for v in accel_mps2] + [f"{v:+09.6f}" for v in gyro_rad_s])


def imu_values(mag_gauss, accel_mps2, gyro_rad_s, temp_c, pressure_kpa) -> str:
    """The 11 fields of register 54 / ``$VNIMU``."""
    return ",".join([f"{v:+.4f}" for v in mag_gauss] + [f"{v:+.4f}" for v in accel_mps2]
                    + [f"{v:+.6f}" for v in gyro_rad_s] + [f"{temp_c:+.1f}", f"{pressure_kpa:+.3f}"])


#: bytes of one async ASCII message of each type the twin makes (fixed-width fields; at rest)
ASCII_MESSAGE_BYTES = {
    ADOR_VNYMR: len(b"$VNYMR," + ymr_values((0, 0, 0), (0, 0, 0), (0, 0, -9.81), (0, 0, 0)).encode() + b"*XX\r\n"),
    ADOR_VNIMU: len(b"$VNIMU," + imu_values((0, 0, 0), (0, 0, 9.81), (0, 0, 0), 25.0, 101.325).encode() + b"*XX\r\n"),
}


#: the ASCII commands used: (syntax, meaning, example body sent, example body answered)
ASCII_COMMANDS = (
    ("VNRRG,<reg>", "read register: 01 model, 03 serial number, 04 firmware, 75 binary output 1",
     "VNRRG,01", "VNRRG,01,VN-100T-SIM"),
    ("VNWRG,75,<async>,<divisor>,<groups>,<fields>...",
     "write binary output 1: async mode (1 = port 1), rate divisor (800 Hz / divisor), "
     "group byte and one field mask per group, in hex",
     "VNWRG,75,1,8,05,0001,001C", "VNWRG,75,1,8,05,0001,001C"),
    ("VNASY,<0|1>", "pause (0) or resume (1) asynchronous output", "VNASY,0", "VNASY,0"),
    ("VNRRG,02", "read the hardware revision", "VNRRG,02", "VNRRG,02,2"),
    ("VNWRG,05,<baud>[,<port>]", "serial baud rate; the reply comes at the old rate",
     "VNWRG,05,230400", "VNWRG,05,230400"),
    ("VNWRG,06,<type>[,<port>]", "async ASCII output type: 0 off, 14 $VNYMR (factory default), 19 $VNIMU",
     "VNWRG,06,0", "VNWRG,06,0"),
    ("VNWRG,07,<Hz>[,<port>]", "async ASCII output frequency", "VNWRG,07,40", "VNWRG,07,40"),
    ("VNRRG,54", "IMU measurements: mag, accel m/s², gyro rad/s, temp °C, pressure kPa", "VNRRG,54",
     "VNRRG,54,+0.0000,+0.0000,+0.0000,+0.0100,-0.0200,+9.8100,+0.001000,+0.000000,-0.000500,+25.0,+101.325"),
    ("VNWNV", "write the settings to non-volatile memory", "VNWNV", "VNWNV"),
    ("VNRST", "reset: the settings come back from non-volatile memory", "VNRST", "VNRST"),
    ("(error)", "any command the sensor cannot execute", "VNWRG,75,1,8,40,0001", "VNERR,07"),
    ("(error 12)", "an output that needs more bytes per second than the baud rate carries "
     "(a public VN-100 transcript: $VNYMR at 100 Hz on 115200 baud)", "VNWRG,07,100", "VNERR,0C"),
)


def checksum(body: bytes) -> bytes:
    """The two upper-case hex digits of the XOR of ``body``'s bytes."""
    c = 0
    for b in body:
        c ^= b
    return b"%02X" % c


def crc16(body: bytes) -> bytes:
    """The four upper-case hex digits of the CRC-16/XMODEM of ``body`` (the ASCII 16-bit CRC
    mode; vnproglib error_detection.cpp Crc16::compute is this CRC)."""
    return b"%04X" % binascii.crc_hqx(bytes(body), 0)


def format_message(body: str, crc: bool = False) -> bytes:
    """``$body*XX\\r\\n`` with its checksum (``crc``: ``*XXXX``, the 16-bit CRC)."""
    raw = body.encode("ascii")
    return b"$" + raw + b"*" + (crc16(raw) if crc else checksum(raw)) + b"\r\n"


_MESSAGE = re.compile(rb"\$([\x20-\x29\x2b-\x7e]{1,200})\*([0-9A-Fa-f]{4}|[0-9A-Fa-f]{2}|XX)\r?\n")


def find_message(buf: bytes | bytearray, start: int = 0, *, allow_no_checksum: bool = False):
    """The first well-formed ASCII message at or after ``start``: (body, end index) or None.

    Checked by the 8-bit checksum (``*XX``, two hex digits) or the 16-bit CRC (four); messages
    that do not match are skipped (and so are ``*XX`` unless allowed).
    """
    for m in _MESSAGE.finditer(buf, start):
        body, cs = m.group(1), m.group(2).upper()
        if cs == b"XX":
            if allow_no_checksum:
                return body.decode("ascii"), m.end()
            continue
        if (crc16(body) if len(cs) == 4 else checksum(body)) == cs:
            return body.decode("ascii"), m.end()
    return None


def uses_crc(line: bytes) -> bool:
    """Whether a message is protected by the 16-bit CRC (``*XXXX``)."""
    m = _MESSAGE.search(line)
    return bool(m) and len(m.group(2)) == 4


@dataclass(frozen=True)
class BinaryLayout:
    """Which fields a binary output message carries, and where they sit in a frame."""

    groups: int                      # the group byte
    masks: tuple[int, ...]           # one field mask per present group, in group order
    fields: tuple[tuple[str, int, int, str | None], ...]   # (name, offset, size, numpy type)

    @classmethod
    def from_masks(cls, groups: int, masks) -> "BinaryLayout":
        """The layout of a group byte and its field masks; ValueError if not decodable here."""
        masks = tuple(int(m) for m in masks)
        present = [g for g in range(1, 9) if groups >> (g - 1) & 1]
        if not present or not 0 < groups < 256:
            raise ValueError("no output group selected")
        if len(masks) != len(present):
            raise ValueError(f"{len(present)} groups need {len(present)} field masks, got {len(masks)}")
        offset = 2 + 2 * len(present)       # after sync, group byte and masks
        fields = []
        for g, mask in zip(present, masks):
            table = GROUP_FIELDS.get(g)
            if table is None:
                raise ValueError(f"binary group {g} is not decoded by station")
            if not 0 < mask < 1 << 16:
                raise ValueError(f"group {g}: field mask {mask:#06x} selects nothing")
            known = 0
            for bit, name, size, np_type in table:
                known |= 1 << bit
                if mask >> bit & 1:
                    fields.append((name, offset, size, np_type))
                    offset += size
            if mask & ~known:
                raise ValueError(f"group {g}: unknown fields in mask {mask:#06x}")
        return cls(groups, masks, tuple(fields))

    @classmethod
    def from_fields(cls, names) -> "BinaryLayout":
        groups, masks = 0, {}
        for name in names:
            for g, table in GROUP_FIELDS.items():
                hit = [bit for bit, n, _, _ in table if n == name]
                if hit:
                    groups |= 1 << (g - 1)
                    masks[g] = masks.get(g, 0) | 1 << hit[0]
                    break
            else:
                raise ValueError(f"unknown binary output field {name!r}")
        return cls.from_masks(groups, [masks[g] for g in sorted(masks)])

    # --------------------------------------------------------------------- geometry
    @property
    def header(self) -> bytes:
        return bytes([SYNC, self.groups]) + b"".join(m.to_bytes(2, "little") for m in self.masks)

    @property
    def payload_end(self) -> int:
        return self.fields[-1][1] + self.fields[-1][2]

    @property
    def frame_length(self) -> int:
        return self.payload_end + 2

    def has(self, name: str) -> bool:
        return any(f[0] == name for f in self.fields)

    @property
    def dtype(self) -> np.dtype:
        """Structured numpy type of one whole frame (decodable fields, and the CRC)."""
        names, formats, offsets = [], [], []
        for name, offset, size, np_type in self.fields:
            if np_type is None:
                continue
            count = size // np.dtype(np_type).itemsize
            names.append(name)
            formats.append(np_type if count == 1 else (np_type, (count,)))
            offsets.append(offset)
        names.append("crc")
        formats.append(">u2")
        offsets.append(self.payload_end)
        return np.dtype({"names": names, "formats": formats, "offsets": offsets,
                         "itemsize": self.frame_length})

    def register_values(self, async_mode: int, rate_divisor: int) -> str:
        """The values of register 75 for this layout: ``1,8,05,0001,001C``."""
        return ",".join([str(async_mode), str(rate_divisor), f"{self.groups:02X}"]
                        + [f"{m:04X}" for m in self.masks])


def parse_register_75(values: list[str]) -> tuple[int, int, BinaryLayout]:
    """(async mode, rate divisor, layout) of register 75's values; ValueError if invalid."""
    if len(values) < 4:
        raise ValueError("not enough parameters")
    async_mode, divisor = int(values[0]), int(values[1])
    groups = int(values[2], 16)
    masks = [int(v, 16) for v in values[3:]]
    if async_mode not in (0, 1, 2, 3) or not 1 <= divisor <= 65535:
        raise ValueError("invalid parameter")
    return async_mode, divisor, BinaryLayout.from_masks(groups, masks)


STATION_LAYOUT = BinaryLayout.from_fields(STATION_FIELDS)
STATION_LAYOUT_NO_TEMP = BinaryLayout.from_fields(STATION_FIELDS[:3])
