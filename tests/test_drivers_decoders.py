"""The IMU frame decoders and the protocol tables: round trips, exact recovery of every intact
frame around garbage and corruption, and fuzzing (nothing but the driver's own errors)."""
from __future__ import annotations

import binascii

import numpy as np
import pytest
from hypothesis import assume, HealthCheck, given, settings
from hypothesis import strategies as st

from drivers.protocols import acutrol, aerosmith
from drivers.protocols import vectornav as V
from drivers.protocols.crc import crc16_rows
from drivers.protocols.csvlines import CsvDecoder, CsvFormat, encode_lines
from drivers.protocols.vectornav_binary import VectorNavDecoder, encode_frames
from drivers.samples import ImuSamples

FUZZ = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def _vn_frames(n, seed=0, layout=V.STATION_LAYOUT):
    rng = np.random.default_rng(seed)
    t_ns = (np.arange(n, dtype=np.uint64) + 1000) * np.uint64(10_000_000)
    a, g, temp = rng.normal(size=(n, 3)) * 9, rng.normal(size=(n, 3)), 25 + rng.normal(size=n)
    blob = encode_frames(layout, t_ns, a, g, temp)
    L = layout.frame_length
    return [blob[i * L:(i + 1) * L] for i in range(n)], t_ns, a, g, temp


def _csv_lines(n, seed=0, fmt=CsvFormat()):
    rng = np.random.default_rng(seed)
    t = 10.0 + np.arange(n) * 0.01
    a, g, temp = rng.normal(size=(n, 3)) * 9, rng.normal(size=(n, 3)) * 50, 25 + rng.normal(size=n)
    return encode_lines(fmt, t, a, g, temp).splitlines(keepends=True), t, a, g, temp


def _feed_chunks(decoder, data: bytes, cuts) -> ImuSamples:
    cuts = sorted({c % (len(data) + 1) for c in cuts} | {0, len(data)})
    return ImuSamples.concat([decoder.feed(data[a:b]) for a, b in zip(cuts, cuts[1:])])


# ------------------------------------------------------------------------------ vectornav

def test_vectornav_layout_is_the_documented_one():
    L = V.STATION_LAYOUT
    # sync, group byte (common + IMU), common mask TimeStartup, IMU mask UncompAccel|UncompGyro|Temp
    assert L.header == bytes([0xFA, 0x05, 0x01, 0x00, 0x1C, 0x00])
    assert [(f[0], f[1], f[2]) for f in L.fields] == [
        ("TimeStartup", 6, 8), ("UncompAccel", 14, 12), ("UncompGyro", 26, 12), ("Temp", 38, 4)]
    assert L.frame_length == 44
    assert L.register_values(1, 8) == "1,8,05,0001,001C"
    assert V.parse_register_75("1,8,05,0001,001C".split(","))[2] == L


def test_vectornav_frame_bytes_and_crc():
    frames, t_ns, a, g, temp = _vn_frames(3)
    f = frames[1]
    assert f[:6] == V.STATION_LAYOUT.header
    assert int.from_bytes(f[6:14], "little") == int(t_ns[1])
    assert np.frombuffer(f[14:26], "<f4").tolist() == a[1].astype(np.float32).tolist()
    # big-endian CRC-16/XMODEM over everything after the sync byte
    assert int.from_bytes(f[-2:], "big") == binascii.crc_hqx(f[1:-2], 0)
    assert binascii.crc_hqx(f[1:], 0) == 0
    rows = np.frombuffer(b"".join(frames), np.uint8).reshape(3, -1)
    assert crc16_rows(rows[:, 1:-2]).tolist() == [binascii.crc_hqx(x[1:-2], 0) for x in frames]


def test_vectornav_round_trip_in_any_chunks():
    frames, t_ns, a, g, temp = _vn_frames(300)
    data = b"".join(frames)
    for cuts in ([], [1], [43, 44, 45], list(range(0, len(data), 7))):
        d = VectorNavDecoder(V.STATION_LAYOUT)
        s = _feed_chunks(d, data, cuts)
        assert len(s) == 300 and d.frames == 300
        np.testing.assert_array_equal(s.t_s, t_ns * 1e-9)
        np.testing.assert_array_equal(s.accel_mps2, a.astype(np.float32))
        np.testing.assert_array_equal(s.gyro_dps, np.degrees(g.astype(np.float32).astype(float)))
        np.testing.assert_array_equal(s.temp_c, temp.astype(np.float32))
        assert (d.checksum_errors, d.resyncs, d.bytes_discarded) == (0, 0, 0)


@FUZZ
@given(st.lists(st.tuples(st.sampled_from(["ok", "garbage", "corrupt", "cut"]),
                          st.binary(min_size=1, max_size=60), st.integers(0, 43)),
                min_size=1, max_size=40),
       st.lists(st.integers(0, 5000), max_size=8))
def test_vectornav_every_intact_frame_survives_garbage_corruption_and_cuts(events, cuts):
    frames, t_ns, *_ = _vn_frames(len(events), seed=len(events))
    stream, intact, cut_at = [], [], []
    offset = 0
    for (kind, junk, pos), frame, t in zip(events, frames, t_ns):
        if kind == "garbage":
            stream.append(junk)
            offset += len(junk)
        if kind == "corrupt":
            b = bytearray(frame)
            b[pos] ^= junk[0] or 1
            frame = bytes(b)
        elif kind == "cut":
            frame = frame[:pos]
            cut_at.append(offset)
        else:
            intact.append(t)
        stream.append(frame)
        offset += len(frame)
    data = b"".join(stream)
    # a frame cut short, followed by bytes that happen to complete its CRC (1 chance in 256 per
    # missing byte), is indistinguishable from an intact frame: no decoder can tell them apart
    full = len(frames[0])
    for at in cut_at:
        if at + full <= len(data) and data[at] == frames[0][0]:
            assume(binascii.crc_hqx(data[at + 1:at + full], 0) != 0)
    d = VectorNavDecoder(V.STATION_LAYOUT)
    s = _feed_chunks(d, data, cuts)
    assert s.t_s.tolist() == (np.array(intact, dtype=np.uint64) * 1e-9).tolist()
    assert d.frames == len(intact)
    n_corrupt = sum(k == "corrupt" for k, _, _ in events)
    assert d.checksum_errors <= n_corrupt + sum(k == "cut" for k, _, _ in events)


@FUZZ
@given(st.binary(max_size=3000), st.lists(st.integers(0, 3000), max_size=6))
def test_vectornav_decoder_never_raises_on_noise(data, cuts):
    d = VectorNavDecoder(V.STATION_LAYOUT)
    s = _feed_chunks(d, data, cuts)
    assert s.accel_mps2.shape == (len(s), 3)
    assert d.bytes_discarded <= len(data)


@FUZZ
@given(st.binary(max_size=400))
def test_vectornav_ascii_scanner_never_raises(data):
    found = V.find_message(data)
    if found is not None:
        body, end = found
        assert 0 < end <= len(data) and V.format_message(body).rstrip(b"\r\n") in data


def test_vectornav_ascii_checksum():
    # XOR of the body's bytes, two upper-case hex digits
    assert V.format_message("VNRRG,01") == b"$VNRRG,01*" + b"%02X" % (
        np.bitwise_xor.reduce(np.frombuffer(b"VNRRG,01", np.uint8))) + b"\r\n"
    assert V.find_message(b"junk$VNASY,0*4F\r\nmore") == ("VNASY,0", 17)
    assert V.find_message(b"$VNASY,0*4E\r\n") is None                    # wrong checksum
    assert V.find_message(b"$VNASY,0*XX\r\n") is None
    assert V.find_message(b"$VNASY,0*XX\r\n", allow_no_checksum=True) == ("VNASY,0", 13)


@pytest.mark.parametrize("groups,masks,why", [
    (0x00, [], "no output group"), (0x05, [1], "need 2 field masks"),
    (0x02, [1], "group 2 is not decoded"), (0x01, [0x8000], "unknown fields"),
])
def test_vectornav_layout_refuses_what_it_cannot_decode(groups, masks, why):
    with pytest.raises(ValueError, match=why):
        V.BinaryLayout.from_masks(groups, masks)


# ------------------------------------------------------------------------------ csv

def test_csv_round_trip_in_any_chunks():
    lines, t, a, g, temp = _csv_lines(300)
    data = b"\n" + b"".join(lines)          # the decoder drops what precedes the first line end
    for cuts in ([], [1, 2, 3], list(range(0, len(data), 11))):
        d = CsvDecoder()
        s = _feed_chunks(d, data, cuts)
        assert len(s) == 300
        np.testing.assert_allclose(s.t_s, t, rtol=0, atol=1e-9)
        np.testing.assert_allclose(s.accel_mps2, a, rtol=1e-8)
        np.testing.assert_allclose(s.gyro_dps, g, rtol=1e-8)
        np.testing.assert_allclose(s.temp_c, temp, atol=1e-3)
        assert (d.checksum_errors, d.resyncs) == (0, 0)


def test_csv_seven_columns_headers_comments_and_crlf():
    d = CsvDecoder(CsvFormat(time_unit="ms", accel_unit="g", gyro_unit="rad/s"))
    s = d.feed(b"boot\nt,ax,ay,az,gx,gy,gz\n# hello\n\r\n10,0,0,1,0,0,3.14159265358979\r\n"
               b"20,0,0,1,0,0,0,24.5\n30,1,2\n40,a,0,1,0,0,0\n50,0,0,1,0,0,inf\n")
    assert s.t_s.tolist() == [0.01, 0.02]
    assert s.accel_mps2[0].tolist() == [0, 0, 9.80665]
    assert abs(s.gyro_dps[0, 2] - 180.0) < 1e-9
    assert np.isnan(s.temp_c[0]) and s.temp_c[1] == 24.5
    assert (d.checksum_errors, d.resyncs, d.frames) == (3, 1, 2)


@FUZZ
@given(st.lists(st.tuples(st.sampled_from(["ok", "garbage", "corrupt"]),
                          st.binary(min_size=1, max_size=40), st.integers(0, 200)),
                min_size=1, max_size=40),
       st.lists(st.integers(0, 5000), max_size=8))
def test_csv_every_intact_line_survives_garbage_lines_and_corruption(events, cuts):
    lines, t, *_ = _csv_lines(len(events), seed=len(events))
    stream, intact = [b"\n"], []
    for (kind, junk, pos), line, ti in zip(events, lines, t):
        if kind == "garbage":            # garbage is a line of its own (docs/twins.md)
            stream.append(junk.replace(b"\n", b"?") + b"\n")
        if kind == "corrupt":
            b = bytearray(line)
            b[pos % (len(b) - 1)] = ord("x")
            line = bytes(b)
        else:
            intact.append(ti)
        stream.append(line)
    d = CsvDecoder()
    s = _feed_chunks(d, b"".join(stream), cuts)
    np.testing.assert_allclose(s.t_s, intact, atol=1e-9)
    assert d.checksum_errors >= sum(k == "corrupt" for k, _, _ in events)


@FUZZ
@given(st.binary(max_size=3000), st.lists(st.integers(0, 3000), max_size=6))
def test_csv_decoder_never_raises_on_noise(data, cuts):
    d = CsvDecoder()
    s = _feed_chunks(d, data, cuts)
    assert s.accel_mps2.shape == (len(s), 3)
    assert np.all(np.isfinite(s.accel_mps2)) and np.all(np.isfinite(s.t_s))


def test_csv_units_spec():
    assert CsvFormat.parse("t=ms, gyro=rad/s") == CsvFormat("ms", "m/s^2", "rad/s")
    for bad in ("t=hours", "speed=1", "t"):
        with pytest.raises(ValueError):
            CsvFormat.parse(bad)


# ------------------------------------------------------------------------------ command tables

@pytest.mark.parametrize("cs", [aerosmith.COMMANDS], ids=["aerosmith"])
def test_every_command_formats_and_parses_back(cs):
    samples = {"axis": 2, "int": 7, "float": -12.5, "choice": "R", "text": "x"}
    for cmd in cs.commands:
        values = [samples[a.kind] for a in cmd.args]
        text = cs.format(cmd.name, *values)
        back, parsed = cs.parse(text)
        assert back is cmd and parsed == values
        assert cs.parse(text.lower())[0] is cmd                  # case-insensitive
        if cmd.example:
            sent = cs.split_line(cmd.example[0])
            assert any(cs.parse(p)[0] is cmd for p in sent)


@FUZZ
@given(st.text(max_size=80))
def test_command_parsers_raise_only_value_error(text):
    for cs in (aerosmith.COMMANDS,):
        for part in cs.split_line(text) or [text]:
            try:
                cs.parse(part)
            except ValueError:
                pass


def test_docs_list_every_command_with_its_example():
    from pathlib import Path
    doc = (Path(__file__).resolve().parents[1] / "docs" / "protocols.md").read_text()
    for cmd in acutrol.COMMANDS:
        assert f"`{cmd.text}" in doc, cmd.text
    for cs in (aerosmith.COMMANDS,):
        for cmd in cs.commands:
            assert f"`{cmd.header}" in doc, cmd.header
            assert f"`{cmd.example[0]}`" in doc, cmd.example
    for syntax, _, sent, answered in V.ASCII_COMMANDS:
        assert V.format_message(sent).decode().strip() in doc
        assert V.format_message(answered).decode().strip() in doc
    frame = encode_frames(V.STATION_LAYOUT, [1_000_000_000], [[0.01, -0.02, 9.81]],
                          [[0.001, 0.0, -0.0005]], [25.0]).hex(" ")
    assert frame[:77] in doc and frame[78:] in doc
