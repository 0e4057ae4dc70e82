"""What a UART receiving at one baud rate makes of bytes sent at another (8N1).

From first principles: the sender puts each byte on the line as a start bit (0), 8 data bits
(least significant first) and a stop bit (1), back to back within a block, the line idle (1)
between blocks.  The receiver waits for a falling edge, takes it as a start bit, samples the
line in the middle of each of its own bit periods (start, 8 data bits, stop), delivers the 8
data bits as a byte, and looks for the next falling edge after its stop-bit sample.  A start
bit that is no longer low at its middle is a glitch (no byte); a stop bit sampled low is a
framing error, and the byte is delivered anyway (what Linux passes on with INPCK off, as in raw
mode).  A slower receiver sees fewer bytes than were sent, a faster one more: roughly in
proportion to the ratio of the rates, and garbage in both cases.
"""
from __future__ import annotations

from bisect import bisect_left

import numpy as np

BITS = 10      # start, 8 data, stop


def line_bits(data: bytes) -> bytes:
    """The line levels of ``data`` sent back to back, one entry (0 or 1) per bit period."""
    a = np.frombuffer(bytes(data), dtype=np.uint8)
    bits = np.ones((a.size, BITS), dtype=np.uint8)
    bits[:, 0] = 0
    bits[:, 1:9] = (a[:, None] >> np.arange(8, dtype=np.uint8)) & 1
    return bits.tobytes()


def reframe(data: bytes, sent_baud: float, read_baud: float) -> bytes:
    """The bytes a receiver at ``read_baud`` delivers for ``data`` sent at ``sent_baud``."""
    if not data or sent_baud == read_baud:
        return bytes(data)
    line = line_bits(data)
    total = len(line)
    # falling edges: a 0 after a 1 (the line is idle, 1, before the block)
    a = np.frombuffer(line, dtype=np.uint8)
    edges = np.flatnonzero((a == 0) & (np.concatenate(([1], a[:-1])) == 1)).tolist()
    r = sent_baud / read_baud                      # one receiver bit, in sender bit periods
    offsets = [(k + 0.5) * r for k in range(BITS)]
    out = bytearray()
    t = 0.0
    while True:
        i = bisect_left(edges, t)
        if i >= len(edges):
            break
        e = edges[i]
        samples = [line[int(e + o)] if e + o < total else 1 for o in offsets]
        if samples[0]:                             # not low at mid start bit: a glitch
            t = e + 0.5
            continue
        byte = 0
        for k in range(8):
            byte |= samples[1 + k] << k
        out.append(byte)
        t = e + offsets[-1]                        # the next start after the stop-bit sample
    return bytes(out)
