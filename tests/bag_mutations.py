"""Structure-aware mutations of ROS bags as ``station import rosbag`` reads them (issue 26): the
shared part of tests/test_fuzz_bags.py and benchmarks/fuzz_bags.py (the long run).

A bag is parsed into its real structure and the mutations change one element of it at a time
(up to a few at once):

* ROS 1 (``.bag``, format 2.0): the records, each a header length, header fields (a field
  length, ``name=``, the value: ``op``, ``conn``, ``size``, ``count``, ``index_pos``, ``time``,
  ``chunk_pos``, ``compression``, ...), a data length and the data; an uncompressed chunk's data
  parsed again as the connection and message records it holds.
* MCAP (a ROS 2 bag folder): the records, each an opcode, a 64-bit length and the content,
  split into the fields of its opcode (header, footer, schema, channel, message, chunk with its
  records parsed again, message index, chunk index, statistics, summary offset, data end).
* sqlite3 (a ROS 2 ``.db3``): rows of every table set to values of another type or absurd
  ones, rows deleted or duplicated, tables dropped, columns renamed.
* ``metadata.yaml`` of a ROS 2 bag folder: its fields set to other types or absurd values.

A span is ``(kind, bytes)``: ``("int", b)`` a little-endian integer of len(b) bytes (a length,
an offset, a count, a time, an id, an opcode), ``("text", b)`` a name or value, ``("data", b)``
payload; the file is the concatenation of its spans, so that a mutated span list is a file.
"""
from __future__ import annotations

import sqlite3
import struct

from hypothesis import strategies as st

ROS1_MAGIC = b"#ROSBAG V2.0\n"
MCAP_MAGIC = b"\x89MCAP0\r\n"


def _u32(buf, pos):
    return struct.unpack_from("<I", buf, pos)[0]


# ------------------------------------------------------------------ ROS 1

def ros1_spans(buf: bytes) -> list[tuple[str, bytes]]:
    if not buf.startswith(ROS1_MAGIC):
        return [("data", buf)]
    return [("text", ROS1_MAGIC)] + _ros1_records(buf, len(ROS1_MAGIC), len(buf))


def _ros1_records(buf, pos, end):
    spans = []
    while pos < end:
        if pos + 4 > end:
            return spans + [("data", buf[pos:end])]
        hlen = _u32(buf, pos)
        hend = pos + 4 + hlen
        if hend + 4 > end:
            return spans + [("data", buf[pos:end])]
        spans.append(("int", buf[pos:pos + 4]))
        fields, p = {}, pos + 4
        while p < hend:
            flen = _u32(buf, p)
            field = buf[p + 4:p + 4 + flen]
            name, _, value = field.partition(b"=")
            fields[name] = value
            spans += [("int", buf[p:p + 4]), ("text", name + b"=")]
            spans.append(("int" if name not in (b"compression", b"topic", b"type", b"md5sum",
                                                b"message_definition", b"callerid", b"latching") else "text", value))
            p += 4 + flen
        dlen = _u32(buf, hend)
        data = buf[hend + 4:hend + 4 + dlen]
        spans.append(("int", buf[hend:hend + 4]))
        if fields.get(b"op") == b"\x05" and fields.get(b"compression") == b"none":
            spans += _ros1_records(data, 0, len(data))       # a chunk: its records
        else:
            spans.append(("data", data))
        pos = hend + 4 + dlen
    return spans


# ------------------------------------------------------------------ MCAP

# the fields of each record's content, by opcode (MCAP specification): u8/u16/u32/u64 integers,
# str (u32 length + bytes), bytes32 (u32 length + bytes), map (u32 byte length + entries),
# records (u64 length + nested records), rest (the remaining bytes)
MCAP_LAYOUT = {
    0x01: ("str", "str"),                                                  # header
    0x02: ("u64", "u64", "u32"),                                           # footer
    0x03: ("u16", "str", "str", "bytes32"),                                # schema
    0x04: ("u16", "u16", "str", "str", "map"),                             # channel
    0x05: ("u16", "u32", "u64", "u64", "rest"),                            # message
    0x06: ("u64", "u64", "u64", "u32", "str", "records"),                  # chunk
    0x07: ("u16", "map"),                                                  # message index
    0x08: ("u64", "u64", "u64", "u64", "map", "u64", "str", "u64", "u64"),  # chunk index
    0x0B: ("u64", "u16", "u32", "u32", "u32", "u32", "u64", "u64", "map"),  # statistics
    0x0E: ("u8", "u64", "u64"),                                            # summary offset
    0x0F: ("u32",),                                                        # data end
}
_WIDTH = {"u8": 1, "u16": 2, "u32": 4, "u64": 8}


def mcap_spans(buf: bytes) -> list[tuple[str, bytes]]:
    if not buf.startswith(MCAP_MAGIC):
        return [("data", buf)]
    spans, pos = [("text", MCAP_MAGIC)], len(MCAP_MAGIC)
    end = len(buf) - len(MCAP_MAGIC) if buf.endswith(MCAP_MAGIC) else len(buf)
    spans += _mcap_records(buf, pos, end)
    if end < len(buf):
        spans.append(("text", MCAP_MAGIC))
    return spans


def _mcap_records(buf, pos, end):
    spans = []
    while pos < end:
        if pos + 9 > end:
            return spans + [("data", buf[pos:end])]
        op = buf[pos]
        (length,) = struct.unpack_from("<Q", buf, pos + 1)
        if pos + 9 + length > end:
            return spans + [("data", buf[pos:end])]
        spans += [("int", buf[pos:pos + 1]), ("int", buf[pos + 1:pos + 9])]
        spans += _mcap_content(op, buf[pos + 9:pos + 9 + length])
        pos += 9 + length
    return spans


def _mcap_content(op, content):
    layout = MCAP_LAYOUT.get(op)
    if layout is None:
        return [("data", content)]
    spans, p, compression = [], 0, None
    try:
        for kind in layout:
            if kind in _WIDTH:
                w = _WIDTH[kind]
                if p + w > len(content):
                    raise ValueError
                spans.append(("int", content[p:p + w]))
                p += w
            elif kind in ("str", "bytes32", "map"):
                n = _u32(content, p)
                if p + 4 + n > len(content):
                    raise ValueError
                value = content[p + 4:p + 4 + n]
                spans += [("int", content[p:p + 4]), ("text" if kind == "str" else "data", value)]
                compression = value if kind == "str" else compression
                p += 4 + n
            elif kind == "records":
                (n,) = struct.unpack_from("<Q", content, p)
                if p + 8 + n > len(content):
                    raise ValueError
                inner = content[p + 8:p + 8 + n]
                spans.append(("int", content[p:p + 8]))
                spans += _mcap_records(inner, 0, len(inner)) if compression == b"" else [("data", inner)]
                p += 8 + n
            else:                                    # rest
                spans.append(("data", content[p:]))
                p = len(content)
        if p < len(content):
            spans.append(("data", content[p:]))
    except (ValueError, struct.error):
        return [("data", content)]
    return spans


# ------------------------------------------------------------------ mutations of spans

def _int_values(width):
    top = 2 ** (8 * width)
    return st.one_of(st.sampled_from([0, 1, 2, 3, 4, 7, 8, 9, 255, 256, 0x7FFF, 0xFFFF, 0x7FFFFFFF, 0xFFFFFFFF,
                                      2 ** 31, 2 ** 62, 2 ** 63 - 1, 2 ** 63, top - 1]),
                     st.integers(0, top - 1)).map(lambda v: (v % top).to_bytes(width, "little"))


def _mutated_span(draw, kind, value):
    how = draw(st.sampled_from(["retype", "delete", "duplicate", "bytes"]))
    if how == "delete":
        return b""
    if how == "duplicate":
        return value + value
    if kind == "int" and how == "retype" and value:
        small = int.from_bytes(value, "little")
        near = st.sampled_from([small + 1, small - 1, small * 2, small // 2, small + 4096]).map(
            lambda v: (v % 2 ** (8 * len(value))).to_bytes(len(value), "little"))
        return draw(st.one_of(_int_values(len(value)), near))
    if kind == "text" and how == "retype":
        return draw(st.sampled_from([b"", b"=", b"none", b"bz2", b"lz4", b"zstd", b"sensor_msgs/Imu",
                                     b"sensor_msgs/msg/Imu", b"/imu/data", b"\xff\xfe", b"a" * 300, value[:-1]]))
    # bytes: flip, truncate, extend, replace
    op = draw(st.sampled_from(["flip", "truncate", "extend", "random"]))
    if op == "flip" and value:
        i = draw(st.integers(0, len(value) - 1))
        return value[:i] + bytes([value[i] ^ draw(st.integers(1, 255))]) + value[i + 1:]
    if op == "truncate":
        return value[:draw(st.integers(0, max(0, len(value) - 1)))]
    if op == "extend":
        return value + draw(st.binary(min_size=1, max_size=16))
    return draw(st.binary(max_size=max(1, len(value))))


@st.composite
def mutated_spans(draw, spans, max_changes=3):
    """The file of ``spans`` with 1..max_changes spans changed (a structure-aware mutation)."""
    spans = list(spans)
    for _ in range(draw(st.integers(1, max_changes))):
        i = draw(st.integers(0, len(spans) - 1))
        kind, value = spans[i]
        spans[i] = (kind, _mutated_span(draw, kind, value))
    return b"".join(v for _, v in spans)


# ------------------------------------------------------------------ sqlite3 (.db3)

def _sql_values():
    return st.one_of(st.sampled_from([None, 0, -1, 1, 2 ** 63 - 1, -2 ** 63, 1e308, -0.0, float("inf"), "", "x",
                                      "/imu/data", "sensor_msgs/msg/Imu", "cdr", "- {a: [", b"", b"\x00" * 3]),
                     st.integers(-2 ** 63, 2 ** 63 - 1), st.floats(allow_nan=False), st.text(max_size=12),
                     st.binary(max_size=40))


@st.composite
def db3_changes(draw, tables):
    """A list of SQL mutations of a .db3 whose tables and columns are ``tables`` ({name: [cols]}):
    (statement, parameters) pairs for db3_mutate."""
    out = []
    names = sorted(tables)
    for _ in range(draw(st.integers(1, 3))):
        table = draw(st.sampled_from(names))
        cols = tables[table]
        what = draw(st.sampled_from(["set", "set", "set", "set_all", "delete", "duplicate", "drop", "rename",
                                     "truncate_blob"]))
        row = draw(st.integers(1, 25))
        col = draw(st.sampled_from(cols))
        if what == "set":
            out.append((f'UPDATE "{table}" SET "{col}" = ? WHERE rowid = ?', (draw(_sql_values()), row)))
        elif what == "set_all":
            out.append((f'UPDATE "{table}" SET "{col}" = ?', (draw(_sql_values()),)))
        elif what == "delete":
            out.append((f'DELETE FROM "{table}" WHERE rowid = ?', (row,)))
        elif what == "duplicate":
            free = ", ".join(f'"{c}"' for c in cols if c != "id")
            out.append((f'INSERT INTO "{table}" ({free}) SELECT {free} FROM "{table}" WHERE rowid = ?', (row,)))
        elif what == "drop":
            out.append((f'DROP TABLE "{table}"', ()))
        elif what == "rename":
            out.append((f'ALTER TABLE "{table}" RENAME COLUMN "{col}" TO "{col}_x"', ()))
        else:
            out.append((f'UPDATE "{table}" SET "{col}" = substr("{col}", 1, ?) WHERE rowid = ?',
                        (draw(st.integers(0, 60)), row)))
    return out


def db3_tables(path) -> dict:
    db = sqlite3.connect(path)
    try:
        names = [r[0] for r in db.execute("SELECT name FROM sqlite_master WHERE type = 'table'")]
        return {n: [r[1] for r in db.execute(f'PRAGMA table_info("{n}")')] for n in names}
    finally:
        db.close()


def db3_mutate(path, changes) -> None:
    """Apply ``changes`` to the .db3 at ``path`` (a change SQLite itself refuses is skipped: the
    NOT NULL and key constraints are part of the structure a writer keeps)."""
    db = sqlite3.connect(path, isolation_level=None)
    try:
        db.execute("PRAGMA writable_schema = OFF")
        for sql, params in changes:
            try:
                db.execute(sql, params)
            except sqlite3.Error:
                pass
    finally:
        db.close()
