"""CRC-16/XMODEM (poly 0x1021, init 0), the VectorNav binary CRC, over many frames at once.

For one message use ``binascii.crc_hqx(data, 0)``; :func:`crc16_rows` computes it for every
row of a (frames, bytes) uint8 array with one table lookup per byte column.
"""
from __future__ import annotations

import numpy as np


def _table() -> np.ndarray:
    tab = np.zeros(256, dtype=np.uint16)
    for i in range(256):
        c = i << 8
        for _ in range(8):
            c = ((c << 1) ^ 0x1021) if c & 0x8000 else (c << 1)
            c &= 0xFFFF
        tab[i] = c
    return tab


TABLE = _table()
_EIGHT = np.uint16(8)


def crc16_rows(rows: np.ndarray) -> np.ndarray:
    """CRC-16/XMODEM of each row of a 2-D uint8 array."""
    crc = np.zeros(rows.shape[0], dtype=np.uint16)
    for j in range(rows.shape[1]):
        crc = (crc << _EIGHT) ^ TABLE[(crc >> _EIGHT) ^ rows[:, j]]
    return crc
