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
    """The bytes a receiver at ``read_baud`` delivers for ``data`` sent at ``sent_baud``.

    What the receiver samples after each falling edge, and where it looks for the next start bit,
    is worked out for every edge at once (numpy), and so is the walk from one start bit to the next
    (:func:`walk`; it was the whole receiver a byte at a time: two thirds of the twins' time in the
    baud probing tests, eighteenth session)."""
    if not data or sent_baud == read_baud:
        return bytes(data)
    line = np.frombuffer(line_bits(data), dtype=np.uint8)
    total = line.size
    # falling edges: a 0 after a 1 (the line is idle, 1, before the block)
    edges = np.flatnonzero((line == 0) & (np.concatenate(([1], line[:-1])) == 1))
    if not edges.size:
        return b""
    r = sent_baud / read_baud                      # one receiver bit, in sender bit periods
    offsets = np.array([(k + 0.5) * r for k in range(BITS)])

    def sample(starts: np.ndarray, k: int) -> np.ndarray:
        """The line at the receiver's k-th sample after each of ``starts`` (idle, 1, past the end)."""
        at = starts + offsets[k]
        inside = at < total
        return np.where(inside, line[np.where(inside, at, 0.0).astype(np.int64)], 1)

    glitch = sample(edges, 0) != 0                 # not low at mid start bit: no byte
    # the next start looked for: after a glitch from half a bit on (the next edge), after a
    # byte from its stop-bit sample on: the first edge at or after it (the edges before the
    # sample's ceiling, counted along the line: a searchsorted without its log factor)
    before = np.zeros(total + 2, dtype=np.int32)
    before[edges + 1] = 1
    np.cumsum(before, out=before)
    stop = np.minimum(np.ceil(edges + offsets[-1]), total + 1).astype(np.int64)
    after = np.where(glitch, np.arange(1, edges.size + 1), before[stop])
    visited = walk(after)
    starts = edges[visited[~glitch[visited]]]      # the start bits of the bytes delivered
    values = np.zeros(starts.size, dtype=np.uint8)
    for k in range(1, 9):                          # the data bits, least significant first
        values |= sample(starts, k) << np.uint8(k - 1)
    return values.tobytes()


def walk(after: np.ndarray) -> np.ndarray:
    """The start edges the receiver takes, in order: 0, after[0], after[after[0]], ... while
    below ``after.size`` (every ``after[i] > i``).

    By pointer doubling (numpy, no loop over the edges): with ``jump`` the 2**k-th successor,
    the first 2**k start edges give the next 2**k, and ``jump`` doubles; about log2(bytes
    received) passes over the edges.  Before, a Python loop over every start edge (0.44-1.24 s
    of CPU per 100 s of a csv stream at the wrong rate): a twin whose loop had fallen behind
    spent seconds on one turn's batch and never caught up (issue 27, twenty-first session)."""
    n = after.size
    jump = np.append(np.asarray(after, dtype=np.int32), np.int32(n))   # the end maps to itself
    visited = np.zeros(1, dtype=np.int32)                      # the first 2**k start edges
    while visited[-1] < n:
        visited = np.concatenate((visited, jump[visited]))
        jump = jump[jump]
    return visited[visited < n]
