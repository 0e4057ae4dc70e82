"""Decoders on real-sized reads (issue 30, item 4): 10,000 frames in one read, with corruption
at random positions, decoded by the vectorised path and, split into small reads, by the
frame-by-frame path.  The reference is computed here, frame by frame, with binascii.crc_hqx
(VectorNav's CRC-16/XMODEM) and the XBus checksum's definition (the byte sum from the bus
identifier to the checksum is 0 mod 256): a damaged frame is never decoded, each is counted once,
and the two paths agree to the bit."""
from __future__ import annotations

import binascii

import numpy as np
import pytest

from drivers.protocols import vectornav as V
from drivers.protocols import xbus
from drivers.protocols.vectornav_binary import VECTORISE_FROM, VectorNavDecoder, encode_frames

N = 10_000


def _corrupt(blob: bytes, length: int, rng, count: int, skip_header: int) -> tuple[bytes, set]:
    """Flip one bit in ``count`` distinct frames, after their first ``skip_header`` bytes (the
    frame's start stays findable: a checksum error, not a resync); which frames."""
    data = bytearray(blob)
    hit = set(int(k) for k in rng.choice(N, size=count, replace=False))
    for k in hit:
        pos = k * length + int(rng.integers(skip_header, length))
        data[pos] ^= 1 << int(rng.integers(8))
    return bytes(data), hit


def _feed(decoder, data: bytes, chunk: int | None):
    parts = [data] if chunk is None else [data[i:i + chunk] for i in range(0, len(data), chunk)]
    return [decoder.feed(p) for p in parts]


@pytest.mark.parametrize("chunk", [None, 4099, 37])     # one read (vectorised), long, byte-sized
def test_vectornav_long_reads_with_damaged_frames(chunk):
    layout = V.STATION_LAYOUT
    L = layout.frame_length
    rng = np.random.default_rng(7)
    t_ns = (np.arange(N, dtype=np.uint64) + 1000) * np.uint64(10_000_000)
    a, g, temp = rng.normal(size=(N, 3)) * 9, rng.normal(size=(N, 3)), 25 + rng.normal(size=N)
    data, hit = _corrupt(encode_frames(layout, t_ns, a, g, temp), L, rng, 40, len(layout.header))
    # the reference: each frame checked alone with binascii's CRC (not the decoder's numpy one)
    valid = [k for k in range(N) if binascii.crc_hqx(data[k * L + 1:(k + 1) * L], 0) == 0]
    assert set(range(N)) - set(valid) == hit
    d = VectorNavDecoder(layout)
    if chunk is None:
        assert N > VECTORISE_FROM      # (the whole read goes through the vectorised path)
    out = [s for s in _feed(d, data, chunk) if len(s)]
    t = np.concatenate([s.t_s for s in out])
    np.testing.assert_array_equal(t, t_ns[valid] * 1e-9)
    np.testing.assert_array_equal(np.concatenate([s.accel_mps2 for s in out]), a[valid].astype(np.float32))
    assert d.frames == N - len(hit) and d.checksum_errors == len(hit)
    assert d.resyncs == 0 and d.bytes_discarded == len(hit) * L


@pytest.mark.parametrize("chunk", [None, 4099, 37])
def test_xsens_long_reads_with_damaged_messages(chunk):
    items = xbus.station_configuration(100)
    rng = np.random.default_rng(8)
    ticks = np.arange(N, dtype=np.int64) * 100 + 12345
    a, g, temp = rng.normal(size=(N, 3)) * 9, rng.normal(size=(N, 3)), 25 + rng.normal(size=N)
    blob = xbus.encode_mtdata2(items, ticks, a, g, temp)
    L = len(blob) // N
    assert L * N == len(blob)
    # damage the data bytes (after FA FF MID LEN), not the length: each message stays one error
    data, hit = _corrupt(blob, L, rng, 40, 4)
    # the reference: XBus's checksum, the byte sum from the bus id to the checksum is 0 mod 256
    valid = [k for k in range(N) if sum(data[k * L + 1:(k + 1) * L]) & 0xFF == 0]
    assert set(range(N)) - set(valid) == hit
    d = xbus.XsensDecoder()
    out = [s for s in _feed(d, data, chunk) if len(s)]
    t = np.concatenate([s.t_s for s in out])
    np.testing.assert_allclose(t, ticks[valid] * xbus.SAMPLE_TICK_S, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(np.concatenate([s.accel_mps2 for s in out]), a[valid].astype(np.float32))
    assert d.frames == N - len(hit) and d.checksum_errors == len(hit)


def test_the_two_vectornav_paths_agree_on_random_damage():
    """Random bytes overwritten anywhere (headers too): the vectorised path (one read) and the
    frame-by-frame path (reads of 40 bytes) decode the same samples and count the same."""
    layout = V.STATION_LAYOUT
    rng = np.random.default_rng(9)
    t_ns = (np.arange(N, dtype=np.uint64) + 1) * np.uint64(5_000_000)
    data = bytearray(encode_frames(layout, t_ns, rng.normal(size=(N, 3)), rng.normal(size=(N, 3)),
                                   25 + rng.normal(size=N)))
    for pos in rng.choice(len(data), size=300, replace=False):
        data[int(pos)] = int(rng.integers(256))
    one, many = VectorNavDecoder(layout), VectorNavDecoder(layout)
    t1 = np.concatenate([s.t_s for s in _feed(one, bytes(data), None) if len(s)])
    t2 = np.concatenate([s.t_s for s in _feed(many, bytes(data), 40) if len(s)])
    np.testing.assert_array_equal(t1, t2)
    assert (one.frames, one.checksum_errors, one.resyncs, one.bytes_discarded) == \
        (many.frames, many.checksum_errors, many.resyncs, many.bytes_discarded)
    assert one.frames < N and len(set(t1.tolist())) == len(t1)
