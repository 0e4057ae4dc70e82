"""Xsens MTi: the XBus low-level protocol and the MTData2 data message, as data.

Sources: Xsens "MT Low-Level Communication Protocol Documentation" (MTi 1/10/100 series) as
implemented by the public ROS driver ethz-asl/ethzasl_xsens_driver (``nodes/mtdef.py``,
``nodes/mtdevice.py``): message ids, XDI data identifiers, framing and checksum.

A message: preamble ``0xFA``, bus id ``0xFF`` (the master), message id (MID), length (one byte;
``0xFF`` then two bytes, most significant first, for 255 bytes or more), the data, a
checksum byte such that the sum of every byte after the preamble, checksum included, is 0
modulo 256.  A command is acknowledged by the message id + 1; a refusal is the Error message
(``0x42``) with one code byte.  Multi-byte values are big-endian.

MTData2 (``0x36``) carries packets: XDI (uint16), size (uint8), data.  The low bits of the XDI
choose the number format (``& 0x0003``: 0 float32) and the frame (``& 0x000C``: 0 ENU); the
ones used here:

| XDI | name | data |
| --- | --- | --- |
| 0x1060 | SampleTimeFine | uint32, ticks of 0.1 ms (10 kHz) |
| 0x0810 | Temperature | float32, °C |
| 0x4020 | Acceleration | 3 × float32, m/s² (calibrated by the device) |
| 0x8020 | RateOfTurn | 3 × float32, rad/s |
"""
from __future__ import annotations

import struct

import numpy as np

from ..samples import ImuSamples

PREAMBLE = 0xFA
BID = 0xFF


class MID:
    """Message ids (mtdef.py ``MID``)."""
    Error = 0x42
    WakeUp = 0x3E
    WakeUpAck = 0x3F
    GoToConfig = 0x30
    GoToMeasurement = 0x10
    Reset = 0x40
    ReqDID = 0x00
    DeviceID = 0x01
    ReqProductCode = 0x1C
    ProductCode = 0x1D
    ReqFWRev = 0x12
    FirmwareRev = 0x13
    SetBaudrate = 0x18
    SetOutputConfiguration = 0xC0
    MTData2 = 0x36


ERRORS = {0x03: "invalid period", 0x04: "invalid message", 0x1E: "timer overflow",
          0x20: "invalid baudrate", 0x21: "invalid parameter",
          0x28: "device error, try updating the firmware"}

XDI_SAMPLE_TIME_FINE = 0x1060
XDI_TEMPERATURE = 0x0810
XDI_ACCELERATION = 0x4020
XDI_RATE_OF_TURN = 0x8020
#: XDI -> (name, data size in bytes)
XDI = {XDI_SAMPLE_TIME_FINE: ("SampleTimeFine", 4), XDI_TEMPERATURE: ("Temperature", 4),
       XDI_ACCELERATION: ("Acceleration", 12), XDI_RATE_OF_TURN: ("RateOfTurn", 12)}
#: output frequency 0xFFFF: "with every message" (used for the sample time)
EVERY_PACKET = 0xFFFF
SAMPLE_TICK_S = 1e-4            # SampleTimeFine: 10 kHz
SAMPLE_TIME_WRAP = 1 << 32
#: the MTi's inertial data come at 400 Hz / N (output rates the twin accepts; MTi 1-series)
MAX_RATE_HZ = 400.0
#: XBus baud rate ids (mtdef.py ``Baudrates``)
BAUD_IDS = {0x80: 921600, 0x0A: 921600, 0x00: 460800, 0x01: 230400, 0x02: 115200, 0x03: 76800,
            0x04: 57600, 0x05: 38400, 0x06: 28800, 0x07: 19200, 0x08: 14400, 0x09: 9600, 0x0B: 4800}
MAX_DATA = 2048


def message(mid: int, data: bytes = b"") -> bytes:
    """One XBus message to/from the master."""
    data = bytes(data)
    n = len(data)
    length = bytes([n]) if n < 255 else bytes([0xFF]) + struct.pack(">H", n)
    body = bytes([BID, mid]) + length + data
    return bytes([PREAMBLE]) + body + bytes([(-sum(body)) & 0xFF])


def output_configuration(items) -> bytes:
    """SetOutputConfiguration data: (XDI, frequency Hz) pairs, big-endian uint16 each."""
    return b"".join(struct.pack(">HH", xdi, freq) for xdi, freq in items)


def parse_output_configuration(data: bytes) -> list[tuple[int, int]]:
    if len(data) % 4:
        raise ValueError("output configuration: not a whole number of (XDI, frequency) pairs")
    return [struct.unpack(">HH", data[i:i + 4]) for i in range(0, len(data), 4)]


def station_configuration(rate_hz: int, temperature: bool = True) -> list[tuple[int, int]]:
    items = [(XDI_SAMPLE_TIME_FINE, EVERY_PACKET), (XDI_ACCELERATION, rate_hz), (XDI_RATE_OF_TURN, rate_hz)]
    if temperature:
        items.append((XDI_TEMPERATURE, rate_hz))
    return items


def mtdata2_length(items) -> int:
    """Bytes of a whole MTData2 message with these outputs."""
    n = sum(3 + XDI[xdi][1] for xdi, _ in items)
    return 4 + n + 1 + (2 if n >= 255 else 0)


def encode_mtdata2(items, ticks, accel_mps2, gyro_rad_s, temp_c=None) -> bytes:
    """MTData2 messages for N samples, the packets in the order of ``items``."""
    ticks = np.asarray(ticks, dtype=np.int64).reshape(-1) % SAMPLE_TIME_WRAP
    n = ticks.shape[0]
    fields = []
    for xdi, _ in items:
        name, size = XDI[xdi]
        fields.append((f"id{xdi}", ">u2"))
        fields.append((f"sz{xdi}", "u1"))
        fields.append((name, ">u4" if xdi == XDI_SAMPLE_TIME_FINE else (">f4", (size // 4,)) if size > 4 else ">f4"))
    payload = sum(3 + XDI[xdi][1] for xdi, _ in items)
    if payload >= 255:
        raise ValueError("MTData2 longer than 254 bytes is not made here")
    dt = np.dtype([("pre", "u1"), ("bid", "u1"), ("mid", "u1"), ("len", "u1")] + fields + [("cs", "u1")])
    rec = np.zeros(n, dtype=dt)
    rec["pre"], rec["bid"], rec["mid"], rec["len"] = PREAMBLE, BID, MID.MTData2, payload
    for xdi, _ in items:
        rec[f"id{xdi}"], rec[f"sz{xdi}"] = xdi, XDI[xdi][1]
    rec["SampleTimeFine"] = ticks
    rec["Acceleration"] = np.asarray(accel_mps2, dtype=np.float32).reshape(n, 3)
    rec["RateOfTurn"] = np.asarray(gyro_rad_s, dtype=np.float32).reshape(n, 3)
    if any(xdi == XDI_TEMPERATURE for xdi, _ in items):
        rec["Temperature"] = np.asarray(temp_c, dtype=np.float32).reshape(n)
    raw = rec.view(np.uint8).reshape(n, dt.itemsize)
    rec["cs"] = (-raw[:, 1:-1].sum(axis=1, dtype=np.int64)) & 0xFF
    return rec.tobytes()


def parse_mtdata2(data: bytes):
    """(sample time ticks or None, accel, gyro, temp) of one MTData2 payload; ValueError if
    the packets do not add up."""
    i, out = 0, {}
    while i < len(data):
        if i + 3 > len(data):
            raise ValueError("truncated packet header")
        xdi, size = struct.unpack_from(">HB", data, i)
        i += 3
        if i + size > len(data):
            raise ValueError("truncated packet")
        out[xdi] = data[i:i + size]
        i += size
    def floats(xdi, count):
        raw = out.get(xdi)
        if raw is None:
            return None
        if len(raw) != 4 * count:
            raise ValueError(f"XDI {xdi:#06x}: {len(raw)} bytes")
        return struct.unpack(f">{count}f", raw)
    stf = out.get(XDI_SAMPLE_TIME_FINE)
    ticks = struct.unpack(">I", stf)[0] if stf is not None and len(stf) == 4 else None
    temp = floats(XDI_TEMPERATURE, 1)
    return ticks, floats(XDI_ACCELERATION, 3), floats(XDI_RATE_OF_TURN, 3), (temp[0] if temp else None)


class XbusParser:
    """Splits a byte stream into XBus messages: :meth:`feed` returns ``[(mid, data), ...]``
    of the messages whose checksum holds; counts ``checksum_errors``, ``resyncs`` and
    ``bytes_discarded`` by the rule of docs/protocols.md "Counters and gaps" (the same as the
    VectorNav decoder's): a message whose start (``FA FF``) is found but whose checksum or
    length fails is one checksum error, and its bytes up to the next start are discarded
    without a resync; a run of bytes that is not a message start is one resync.  Never
    raises."""

    def __init__(self):
        self._buf = bytearray()
        self.checksum_errors = self.resyncs = self.bytes_discarded = 0
        self._after_bad = False      # the bytes being skipped belong to a failed message

    def feed(self, data: bytes) -> list[tuple[int, bytes]]:
        buf = self._buf
        buf += data
        out, i = [], 0
        while True:
            j = buf.find(b"\xfa\xff", i)
            if j < 0:
                # a last 0xFA may start the next message's preamble, unless it was already
                # taken (the checksum of the message just parsed: 1 in 256 messages)
                keep = 1 if len(buf) > i and buf[-1] == 0xFA else 0
                self._skip(len(buf) - keep - i)
                i = len(buf) - keep
                break
            if j > i:
                self._skip(j - i)
            if len(buf) - j < 5:
                i = j
                break
            mid, n = buf[j + 2], buf[j + 3]
            head = 4
            if n == 0xFF:
                if len(buf) - j < 7:
                    i = j
                    break
                n = (buf[j + 4] << 8) | buf[j + 5]
                head = 6
            end = j + head + n + 1
            if n > MAX_DATA or (end <= len(buf) and sum(buf[j + 1:end]) & 0xFF):
                self._bad()                 # a message start whose length or checksum fails
                i = j + 1
                continue
            if end > len(buf):
                i = j
                break
            out.append((mid, bytes(buf[j + head:end - 1])))
            self._after_bad = False
            i = end
        del buf[:i]
        return out

    def _bad(self) -> None:
        self.checksum_errors += 1
        self.bytes_discarded += 1
        self._after_bad = True

    def _skip(self, n: int) -> None:
        if n > 0:
            if not self._after_bad:
                self.resyncs += 1
            self.bytes_discarded += n
            self._after_bad = True          # one run of skipped bytes: one resync


class XsensDecoder:
    """MTData2 messages to :class:`ImuSamples` (sample time unwrapped, rad/s to deg/s); other
    messages are kept in ``others``.  Counters as the other decoders.  Never raises."""

    def __init__(self):
        self.parser = XbusParser()
        self.frames = 0
        self.others: list[tuple[int, bytes]] = []
        self._wraps = 0
        self._last_ticks: int | None = None
        self._bad = 0

    @property
    def checksum_errors(self) -> int:
        return self.parser.checksum_errors + self._bad

    @property
    def resyncs(self) -> int:
        return self.parser.resyncs

    @property
    def bytes_discarded(self) -> int:
        return self.parser.bytes_discarded

    def feed(self, data: bytes) -> ImuSamples:
        rows = []
        for mid, payload in self.parser.feed(data):
            if mid != MID.MTData2:
                if len(self.others) < 64:
                    self.others.append((mid, payload))
                continue
            try:
                ticks, acc, gyr, temp = parse_mtdata2(payload)
            except ValueError:
                self._bad += 1
                continue
            if ticks is None or acc is None or gyr is None:
                self._bad += 1
                continue
            if self._last_ticks is not None and ticks < self._last_ticks - SAMPLE_TIME_WRAP // 2:
                self._wraps += 1
            self._last_ticks = ticks
            t = (ticks + self._wraps * SAMPLE_TIME_WRAP) * SAMPLE_TICK_S
            rows.append((t, *acc, *gyr, np.nan if temp is None else temp))
        if not rows:
            return ImuSamples.empty()
        a = np.asarray(rows, dtype=float)
        self.frames += len(a)
        return ImuSamples(a[:, 0], a[:, 1:4], np.degrees(a[:, 4:7]), a[:, 7])
