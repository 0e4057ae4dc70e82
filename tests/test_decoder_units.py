"""The decoders' parts that long reads do not reach (issue 30 item 6: survivors of mutation
testing of drivers/protocols): the CRC table recomputed at test time against binascii, and the
MTData2 payload parser on payloads packed here with struct from the Xsens packet layout
(XDI: 2 bytes big-endian, size: 1 byte, data), not by the twins' encoder.  Milliseconds each."""
from __future__ import annotations

import struct
from binascii import crc_hqx

import numpy as np
import pytest

from drivers.protocols import crc, xbus


def test_the_crc_table_is_crc16_xmodem_of_each_byte():
    """With init 0 one byte's CRC is its table entry (crc = table[(0 >> 8) ^ b]).  _table() runs
    at import; called here so that a change to it is seen by the tests, not only by the import."""
    table = crc._table()
    assert table.dtype == np.uint16 and table.shape == (256,)
    assert table.tolist() == [crc_hqx(bytes([i]), 0) for i in range(256)]
    assert crc.TABLE.tolist() == table.tolist()


def packet(xdi, data):
    return struct.pack(">HB", xdi, len(data)) + data


def test_mtdata2_fields_and_their_absence():
    acc, gyr = struct.pack(">3f", 0.5, -1.0, 9.75), struct.pack(">3f", 0.25, 0.125, -2.0)
    payload = (packet(xbus.XDI_SAMPLE_TIME_FINE, struct.pack(">I", 123456)) + packet(xbus.XDI_ACCELERATION, acc)
               + packet(xbus.XDI_RATE_OF_TURN, gyr) + packet(xbus.XDI_TEMPERATURE, struct.pack(">f", 31.5)))
    assert xbus.parse_mtdata2(payload) == (123456, (0.5, -1.0, 9.75), (0.25, 0.125, -2.0), 31.5)
    # no sample time, no temperature: None for each, the rest still read
    payload = packet(xbus.XDI_ACCELERATION, acc) + packet(xbus.XDI_RATE_OF_TURN, gyr)
    assert xbus.parse_mtdata2(payload) == (None, (0.5, -1.0, 9.75), (0.25, 0.125, -2.0), None)
    # an empty packet last (the header ends exactly at the payload's end) is a packet
    assert xbus.parse_mtdata2(payload + packet(0x7777, b""))[1] == (0.5, -1.0, 9.75)


def test_truncated_mtdata2_payloads_are_refused_in_words():
    acc = packet(xbus.XDI_ACCELERATION, struct.pack(">3f", 1.0, 2.0, 3.0))
    with pytest.raises(ValueError, match="^truncated packet header$"):
        xbus.parse_mtdata2(acc + b"\x10\x60")              # 2 bytes of a 3-byte header
    with pytest.raises(ValueError, match="^truncated packet$"):
        xbus.parse_mtdata2(acc + struct.pack(">HB", xbus.XDI_TEMPERATURE, 4) + b"\x00\x00")
    with pytest.raises(ValueError, match="^truncated packet$"):
        xbus.parse_mtdata2(acc[:-1])
