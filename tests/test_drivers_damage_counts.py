"""One rule for the stream counters of every IMU decoder (docs/protocols.md, "Counters and
gaps"): the same damage -- one byte flipped, one frame cut short, one sync byte corrupted,
garbage between frames -- gives the same ``frames``, ``checksum_errors``, ``resyncs`` and
``bytes_discarded`` in the VectorNav and the Xsens decoders (and in csv where a line protocol
can tell), however the stream is cut into reads."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from drivers.protocols import vectornav as V
from drivers.protocols import xbus as X
from drivers.protocols.csvlines import CsvDecoder, encode_lines, CsvFormat
from drivers.protocols.vectornav_binary import VectorNavDecoder, encode_frames

N = 20            # frames in a stream; the damage is done to frame DAMAGED
DAMAGED = 10
FUZZ = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def _samples(n, seed=0):
    rng = np.random.default_rng(seed)
    t = (np.arange(n) + 1000) * 0.01
    return t, rng.normal(size=(n, 3)) * 9, rng.normal(size=(n, 3)), 25 + rng.normal(size=n)


class Vn:
    name = "vectornav"
    start = len(V.STATION_LAYOUT.header)      # bytes that make a frame recognisable: sync, group, masks

    @staticmethod
    def frames(n=N, seed=0):
        t, a, g, temp = _samples(n, seed)
        blob = encode_frames(V.STATION_LAYOUT, np.round(t * 1e9).astype(np.uint64), a, g, temp)
        L = V.STATION_LAYOUT.frame_length
        return [blob[i * L:(i + 1) * L] for i in range(n)]

    @staticmethod
    def decoder():
        return VectorNavDecoder(V.STATION_LAYOUT)


class Xs:
    name = "xsens"
    start = 4                                 # FA FF MID LEN (the length must be intact to find the end)

    @staticmethod
    def frames(n=N, seed=0):
        t, a, g, temp = _samples(n, seed)
        items = X.station_configuration(100)
        blob = X.encode_mtdata2(items, np.round(t * 1e4).astype(np.int64), a, g, temp)
        L = X.mtdata2_length(items)
        return [blob[i * L:(i + 1) * L] for i in range(n)]

    @staticmethod
    def decoder():
        return X.XsensDecoder()


DECODERS = [Vn, Xs]


def _counts(decoder_cls, data: bytes, cuts=()):
    d = decoder_cls.decoder()
    cuts = sorted({c % (len(data) + 1) for c in cuts} | {0, len(data)})
    n = sum(len(d.feed(data[a:b])) for a, b in zip(cuts, cuts[1:]))
    assert n == d.frames
    return d.frames, d.checksum_errors, d.resyncs, d.bytes_discarded


def _flip(frame: bytes, at: int, mask: int = 0x01) -> bytes:
    b = bytearray(frame)
    b[at] ^= mask
    return bytes(b)


def _stream(frames, damaged: bytes, before: bytes = b"") -> bytes:
    return b"".join(frames[:DAMAGED]) + before + damaged + b"".join(frames[DAMAGED + 1:])


# (name, damage(frames) -> stream, the counts by the rule given the frame length L)
GARBAGE = bytes(range(1, 33))                 # 32 bytes, no sync byte 0xFA
CASES = {
    # a byte flipped in the payload: a checksum error, the whole frame discarded, no resync
    "flipped payload byte": (lambda f, L: _stream(f, _flip(f[DAMAGED], L // 2)), lambda L: (N - 1, 1, 0, L)),
    # the checksum / CRC itself damaged: the same
    "flipped last byte": (lambda f, L: _stream(f, _flip(f[DAMAGED], L - 1)), lambda L: (N - 1, 1, 0, L)),
    # cut short after its start (12 bytes arrive): a checksum error, the 12 bytes discarded
    "truncated frame": (lambda f, L: _stream(f, f[DAMAGED][:12]), lambda L: (N - 1, 1, 0, 12)),
    # the sync byte corrupted: not a frame start, so its bytes are one resync
    "corrupted sync byte": (lambda f, L: _stream(f, _flip(f[DAMAGED], 0, 0x0F)), lambda L: (N - 1, 0, 1, L)),
    # 32 bytes of garbage between two frames: one resync, 32 bytes, every frame decoded
    "garbage between frames": (lambda f, L: _stream(f, f[DAMAGED], GARBAGE), lambda L: (N, 0, 1, len(GARBAGE))),
}
CHUNKINGS = {"one read": (), "byte by byte": tuple(range(1, 2000)), "reads of 7": tuple(range(7, 2000, 7)),
             "reads of 45": tuple(range(45, 2000, 45))}


@pytest.mark.parametrize("chunks", list(CHUNKINGS), ids=list(CHUNKINGS))
@pytest.mark.parametrize("case", list(CASES), ids=list(CASES))
def test_one_damaged_frame_counts_the_same_in_both_decoders(case, chunks):
    damage, rule = CASES[case]
    got = {}
    for cls in DECODERS:
        frames = cls.frames()
        L = len(frames[0])
        got[cls.name] = _counts(cls, damage(frames, L), CHUNKINGS[chunks])
        assert got[cls.name] == rule(L), (cls.name, got[cls.name])
    # the same counts, bytes as a fraction of the damaged frame's length
    (vf, vc, vr, vb), (xf, xc, xr, xb) = got["vectornav"], got["xsens"]
    assert (vf, vc, vr) == (xf, xc, xr)


def test_csv_counts_a_damaged_line_by_the_same_rule():
    """A line is csv's frame: a flipped character makes a checksum error (the line does not
    parse), its bytes discarded, no resync -- as the binary decoders count a flipped byte."""
    t, a, g, temp = _samples(N)
    lines = encode_lines(CsvFormat(), t, a, g, temp).splitlines(keepends=True)
    bad = bytearray(lines[DAMAGED])
    bad[5] = ord("x")
    data = b"\n" + b"".join(lines[:DAMAGED]) + bytes(bad) + b"".join(lines[DAMAGED + 1:])
    for cuts in CHUNKINGS.values():
        d = CsvDecoder()
        cuts = sorted({c % (len(data) + 1) for c in cuts} | {0, len(data)})
        for x, y in zip(cuts, cuts[1:]):
            d.feed(data[x:y])
        assert (d.frames, d.checksum_errors, d.resyncs, d.bytes_discarded) == (N - 1, 1, 0, len(bad))


@FUZZ
@given(st.sampled_from(DECODERS), st.sampled_from(["flip", "cut", "sync", "garbage"]), st.data(),
       st.lists(st.integers(1, 2000), max_size=10))
def test_the_rule_holds_wherever_the_damage_is(cls, kind, data, cuts):
    frames = cls.frames()
    L = len(frames[0])
    f = frames[DAMAGED]
    before = b""
    if kind == "flip":                        # a byte after the frame's start bytes
        at = data.draw(st.integers(cls.start, L - 1))
        damaged, expected = _flip(f, at, data.draw(st.integers(1, 255))), (N - 1, 1, 0, L)
    elif kind == "cut":
        k = data.draw(st.integers(cls.start, L - 1))
        damaged, expected = f[:k], (N - 1, 1, 0, k)
    elif kind == "sync":
        damaged, expected = _flip(f, 0, data.draw(st.integers(1, 255))), (N - 1, 0, 1, L)
    else:
        before = data.draw(st.binary(min_size=1, max_size=200).filter(lambda b: 0xFA not in b))
        damaged, expected = f, (N, 0, 1, len(before))
    stream = _stream(frames, damaged, before)
    # damage that happens to make another valid-looking frame start or a valid frame is
    # indistinguishable from one (a checksum that still holds: 1 in 256 for XBus)
    body = b"".join(frames[DAMAGED - 1:DAMAGED]) + before + damaged + frames[DAMAGED + 1]
    assume(body.count(b"\xfa") == sum(x.count(b"\xfa") for x in (frames[DAMAGED - 1], frames[DAMAGED + 1], f)))
    if cls is Xs and kind in ("flip", "cut"):
        d = X.XbusParser()
        d.feed(b"".join(frames[:DAMAGED]))
        assume(len(d.feed(damaged + frames[DAMAGED + 1])) == 1)
    if cls is Vn and kind in ("flip", "cut"):
        d = cls.decoder()
        assume(len(d.feed(damaged + frames[DAMAGED + 1])) == 1)
    assert _counts(cls, stream, cuts) == expected
