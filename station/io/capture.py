"""Capture bundles (station-capture/1): read them, and write them while a run records.

The format is the public interface in shared/spec/capture-format.md; docs/capture.md says what
this reader refuses and tolerates and how the writer lays files out.
"""

from __future__ import annotations

import hashlib
import math
import os
import re
import reprlib
import stat
import tempfile
import threading
from collections import Counter
from contextlib import contextmanager
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path, PurePosixPath, PureWindowsPath

import numpy as np
import yaml

from station.core import yaml_text
from station.core.errors import CaptureError, UserError
from station.core.units import ACCEL_UNITS, GYRO_UNITS

FORMAT = "station-capture/1"
MANIFEST = "manifest.yaml"
WARMUP_FILE = "warmup.csv"     # the station's record of a warm-up (t_s,temp_c); no reader needs it
REQUIRED_COLUMNS = ("t", "ax", "ay", "az", "gx", "gy", "gz")
STATUSES = ("complete", "incomplete")
GAP_FACTOR = 1.5  # a time step longer than GAP_FACTOR periods may be a gap (lost samples: stamp_gaps)
MAX_MANIFEST_BYTES = 64 * 2**20  # a manifest is kilobytes; refuse to read more than this
MAX_CSV_VALUE = 1e12  # |value| of any CSV column: beyond any IMU output, time stamp or count
# ranges of the manifest's numbers (beyond them no bench exists, and sums of squares overflow)
SAMPLE_RATE_RANGE_HZ = (1e-3, 1e6)
GRAVITY_RANGE_MPS2 = (9.0, 10.5)  # Earth's surface: 9.76 to 9.84 m/s^2
MAX_RATE_DPS = 1e5
MAX_ANGLE_DEG = 1e9
MAX_VECTOR_COMPONENT = 1e6
TEMP_SUFFIX = ".tmp"  # temporary files of the writers: "." + name + "." + random + ".tmp"

# Manifest keys in the order the spec lists them; the writer emits them in this order.
_SEGMENT_KEYS = ("name", "kind", "file", "status", "up_body", "axis_body", "rate_dps", "angle_deg",
                 "samples", "sha256", "started_utc", "table_file", "temperature_c", "note")
_SEGMENT_FIELDS = ("name", "kind", "file", "status", "up_body", "axis_body", "rate_dps", "angle_deg",
                   "note")  # the keys that become Segment attributes; the others go to Segment.extra
_WRITER_OWNED = ("status", "samples", "sha256")  # set by SegmentWriter, never by the caller's meta

_NUMBER_TEXT = re.compile(r"[-+]?([0-9]+\.?[0-9]*|\.[0-9]+)([eE][-+]?[0-9]+)?")
_SHA256_TEXT = re.compile(r"[0-9a-fA-F]{64}")
_T_FORMAT = "%.15g"  # time: 1e-8 s resolution at 1e6 s
_VALUE_FORMAT = "%.12g"  # IMU outputs: far beyond any IMU's resolution
_WHOLE_LIMIT = 1e12      # below it "%.12g" writes a whole number as its digits, as "%d" does


def _row_format(block: np.ndarray) -> str:
    """The rows' %-format: t with _T_FORMAT, every other column with _VALUE_FORMAT, or with
    "%d" where the column is whole numbers (raw counts) that "%.12g" writes as their digits
    (|v| < 1e12, no -0.0): the same text, formatted in half the time (issue 27, item 2)."""
    values = block[:, 1:]
    whole = ((values == np.floor(values)) & (np.abs(values) < _WHOLE_LIMIT)
             & ~((values == 0) & np.signbit(values))).all(axis=0)
    return ",".join([_T_FORMAT] + ["%d" if w else _VALUE_FORMAT for w in whole]) + "\n"


@dataclass
class ImuInfo:
    sample_rate_hz: float
    accel_unit: str
    gyro_unit: str
    model: str | None = None
    serial: str | None = None
    extra: dict = field(default_factory=dict)


@dataclass
class Site:
    gravity_mps2: float
    latitude_deg: float | None = None
    extra: dict = field(default_factory=dict)


@dataclass(eq=False)
class SegmentData:
    t: np.ndarray  # (N,) seconds
    accel: np.ndarray  # (N, 3) in imu.accel_unit
    gyro: np.ndarray  # (N, 3) in imu.gyro_unit
    temp: np.ndarray | None  # (N,) deg C, None when the file has no temp column
    gaps: int  # gaps in time: steps longer than GAP_FACTOR periods where the stamps jump (stamp_gaps)

    @property
    def rows(self) -> int:
        return len(self.t)


@dataclass
class _RowCount:
    """What an incomplete segment's file holds when its rows are counted, not kept."""
    rows: int
    gaps: int


@dataclass(eq=False)
class Segment:
    name: str
    kind: str
    file: str
    status: str
    up_body: np.ndarray | None = None  # unit vector
    axis_body: np.ndarray | None = None  # unit vector
    rate_dps: float | None = None
    angle_deg: float | None = None
    note: str | None = None
    extra: dict = field(default_factory=dict)  # every other manifest key, verbatim
    data: SegmentData | None = None  # None until the samples are loaded (Capture.load_samples)
    problem: str | None = None  # why (part of) an incomplete segment's data could not be read
    content_sha256: str | None = None  # sha256 (hex) of the file's bytes, set when they are read


@dataclass(eq=False)
class Capture:
    path: Path
    imu: ImuInfo
    site: Site
    scheme: str | None
    segments: list[Segment]
    extra: dict
    warnings: list[str]

    def complete(self, kind=None):
        """Complete segments (of `kind` if given), in manifest order."""
        return [s for s in self.segments
                if s.status == "complete" and (kind is None or s.kind == kind)]

    def rotation_pairs(self):
        """(plus, minus) pairs of complete rotation segments about the same axis_body.

        plus has rate_dps > 0 and minus rate_dps < 0. Pairs of equal |rate_dps| are formed
        first, then the remaining ones, each time in manifest order; a segment is used once.
        Segments without rate_dps are never paired.
        """
        rotations = [s for s in self.complete("rotation") if s.rate_dps is not None]
        plus = [s for s in rotations if s.rate_dps > 0]
        unpaired_minus = [s for s in rotations if s.rate_dps < 0]
        partner = {}
        for same_rate_only in (True, False):
            for p in plus:
                if p.name in partner:
                    continue
                m = next((m for m in unpaired_minus
                          if np.allclose(p.axis_body, m.axis_body, rtol=0, atol=1e-6)
                          and (not same_rate_only
                               or math.isclose(p.rate_dps, -m.rate_dps, rel_tol=1e-9))), None)
                if m is not None:
                    partner[p.name] = m
                    unpaired_minus = [x for x in unpaired_minus if x is not m]
        return [(p, partner[p.name]) for p in plus if p.name in partner]

    # Samples on demand. A capture read with load_data=False holds no samples; these read a
    # segment's file when asked (once: read as bytes, hashed and parsed in one pass), so a caller
    # that summarises one segment at a time never holds more than one segment's samples.

    def read_samples(self, segment, warnings: list | None = None) -> SegmentData | None:
        """The samples of ``segment``: segment.data when loaded, else read from its file now and
        not kept (each call reads the file again).  Refuses (CaptureError) a complete segment
        whose file does not follow the format or whose sha256 does not match; None for an
        incomplete one without readable rows (segment.problem and warnings say why).  What it
        warns of goes to capture.warnings, or to ``warnings`` when given (a reading thread's: the
        caller adds them in the segments' order)."""
        if segment.data is not None:
            return segment.data
        return _read_segment_data(self, segment, self._label(segment), warnings=warnings)

    def check_incomplete(self, segment) -> None:
        """Read an incomplete segment's file for what reading it says (its readable rows, what
        is wrong with its last line, its gaps: segment.problem and capture.warnings, as
        read_samples says them), counting its rows without keeping them."""
        if segment.data is None:
            _read_segment_data(self, segment, self._label(segment), keep=False)

    def _label(self, segment) -> str:
        """"segments[k] (name)": k found through a table of the list's positions, made again when
        the list changes (list.index for each of many segments was quadratic)."""
        table = self.__dict__.get("_positions")
        if table is None or table[0] is not self.segments or table[1] != len(self.segments):
            table = (self.segments, len(self.segments), {id(s): k for k, s in enumerate(self.segments)})
            self._positions = table
        k = table[2].get(id(segment))
        if k is None or self.segments[k] is not segment:
            k = self.segments.index(segment)
        return _segment_label(k, segment.name)

    def load_samples(self, segments=None):
        """Read the samples of ``segments`` (default: every segment) into segment.data."""
        for segment in self.segments if segments is None else segments:
            if segment.data is None:
                segment.data = self.read_samples(segment)

    @contextmanager
    def lent_samples(self, segment):
        """``with capture.lent_samples(seg) as data:`` seg.data holds the samples inside the block
        (so code written for loaded captures works on them) and is dropped at its end, unless it
        was loaded before (to keep it, assign it to seg.data again after the block)."""
        if segment.data is not None:
            yield segment.data
            return
        data = segment.data = self.read_samples(segment)
        try:
            yield data
        finally:
            if segment.data is data:
                segment.data = None

    def reader_ahead(self, segments):
        """A ReaderAhead over ``segments``: ``with capture.reader_ahead(segs) as reader:`` then,
        for each segment in order, ``reader.take(seg)`` for its samples and ``reader.ahead()`` to
        read the next ones' files on other threads while working on the current one.  The reader
        :meth:`read_ahead` started for the same list (the same segments, in order) is that one,
        its files already under way; one started for another list is closed."""
        early = self.__dict__.pop("_early_reader", None)
        if early is not None:
            if early.segments_are(segments):
                return early
            early.close()
        return ReaderAhead(self, segments)

    def read_ahead(self, segments) -> None:
        """Start reading ``segments``' files now, on reading threads, for the next
        ``reader_ahead(segments)`` (which takes the reader over), while this thread does other
        work first (imports: the CSV engine's parse releases the GIL).  :meth:`stop_reading_ahead`
        ends it if no reader_ahead takes it over."""
        self.stop_reading_ahead()
        reader = ReaderAhead(self, segments)
        self._early_reader = reader     # before its threads start: a Ctrl-C meanwhile ends them
        reader.ahead()

    def stop_reading_ahead(self, wait: bool = True) -> None:
        """Close the reader :meth:`read_ahead` started, unless reader_ahead took it over (``wait``
        False: Ctrl-C, the reads under way left to their threads: ReaderAhead.close)."""
        early = self.__dict__.pop("_early_reader", None)
        if early is not None:
            early.close(wait=wait)

    def summary_order(self, every: bool = False) -> list:
        """The complete segments in the order a summary takes them: the statics first (the
        rotation summaries use their noise and gyro bias), then the rotations, then (``every``)
        the other complete segments (checked only)."""
        order = self.complete("static") + self.complete("rotation")
        if every:
            order += [seg for seg in self.complete() if seg.kind not in ("static", "rotation")]
        return order

    def segment(self, name):
        """The segment called `name`; UserError if there is none."""
        for s in self.segments:
            if s.name == name:
                return s
        names = ", ".join(s.name for s in self.segments) or "none"
        raise UserError(f"{self.path / MANIFEST}: no segment named {name!r} (segments: {names})")


class ReaderAhead:
    """The samples of a list of segments, taken in their order, with the next segments' files read
    (Capture.read_samples: read, hashed, parsed, checked) on reading threads while the caller works
    on the current segment's samples.  Up to read_ahead_threads() threads read one file each at once
    (the CSV engine and sha256 release the GIL: two files parse on two cores), and the list is read
    ahead by up to READ_AHEAD_BYTES of files (always the next one, however long): at most that much
    more than the segment taken exists at once.  A read that fails raises its error when that
    segment is taken, so errors come in the segments' order, as without reading ahead; warnings
    (gaps in time) are added to capture.warnings in the segments' order too, when each is taken.
    Loaded segments (seg.data) are given as they are; nothing is stored in seg.data.

    The first ``take`` of a segment not read yet sets the reading going (that segment and the next
    ones) and waits for its own file.  Why several files at once (issue 27, seventeenth session):
    with one file read ahead the reading thread was the slower of the two and the caller waited
    for it (the 100 Hz optimal9 estimate's summaries: 200-240 ms of wall for ~70 ms of the caller's
    own CPU, measured under load); reading two files at once took the whole estimate to 0.93 x its
    wall at real-time priority under load, but gained nothing measurable on a quiet machine, for up
    to ~5 % more CPU (docs/performance.md, "Seventeenth session: reading ahead")."""

    def __init__(self, capture, segments):
        import collections

        self._capture = capture
        self._segments = list(segments)
        self._next = 0              # index of the next segment to take
        self._queued = 0            # index of the next segment to hand to the readers
        self._pending = collections.deque()     # (segment, done event, box, file bytes), in order
        self._pending_bytes = 0
        self._threads = []          # the reading threads, once started
        self._work = None           # their queue: (segment, event, box), None to end one
        self._closing = False       # set by close(): jobs not begun are dropped

    def segments_are(self, segments) -> bool:
        """Whether ``segments`` is this reader's list (the same objects, in order) and none taken."""
        segments = list(segments)
        return (self._next == 0 and len(segments) == len(self._segments)
                and all(a is b for a, b in zip(segments, self._segments)))

    def take(self, segment) -> SegmentData | None:
        """The samples of ``segment``, the next one in the list."""
        if self._next >= len(self._segments) or self._segments[self._next] is not segment:
            raise ValueError(f"segment {segment.name!r} is not the next one to take")
        if not self._pending and segment.data is None:
            self.ahead()                    # this one and the next ones, on the reading threads
        self._next += 1
        if not self._pending or self._pending[0][0] is not segment:
            self._queued = max(self._queued, self._next)
            return self._capture.read_samples(segment)
        _, done, box, size = self._pending[0]
        done.wait()
        self._pending.popleft()             # after the wait: an interrupted wait leaves it to close()
        self._pending_bytes -= size
        for message in box.get("warnings", ()):
            _warn(self._capture, message)
        if "error" in box:
            raise box["error"]
        return box["data"]

    def ahead(self):
        """Have the next segments' files read on the reading threads: the next one, and those
        after it while the files handed out and not taken stay within READ_AHEAD_BYTES (nothing
        past a loaded segment; nothing when the list is read)."""
        self._queued = max(self._queued, self._next)
        while self._queued < len(self._segments) and not self._closing:
            segment = self._segments[self._queued]
            if segment.data is not None:
                return
            try:
                size = os.stat(self._capture.path / segment.file).st_size
            except (OSError, TypeError, ValueError):
                size = 0                    # the read says what is wrong with it
            if self._pending and self._pending_bytes + size > READ_AHEAD_BYTES:
                return
            if self._work is None:
                import queue

                self._work = queue.SimpleQueue()
            box, done = {"warnings": []}, threading.Event()
            self._work.put((segment, done, box))
            self._pending.append((segment, done, box, size))
            self._pending_bytes += size
            self._queued += 1
            # a thread per file under way, up to read_ahead_threads(): where one file at a time
            # fits the limit (long segments, which the CSV engine parses on its own threads) one
            # thread reads them all, its memory reused from file to file (a second thread's own
            # malloc arena held ~50 MB more at the 4 kHz capture's peak)
            # (one thread for a small capture: its files go through the line-by-line reader, which
            # holds the GIL, so a second one only contends)
            threads = 1 if _small(self._capture) else read_ahead_threads()
            if len(self._threads) < min(threads, len(self._pending)):
                if not self._threads and not _small(self._capture):
                    _import_engine()        # here: the reading threads import nothing
                thread = threading.Thread(target=self._serve, args=(self._capture, self._work),
                                          name="capture-read-ahead", daemon=True)
                self._threads.append(thread)    # before it starts: close() ends it whatever happens
                try:
                    thread.start()
                except RuntimeError:
                    # no thread to be had (a limit on a process's threads, no memory for its
                    # stack): those started read the rest; with none, take reads on this thread
                    self._threads.pop()
                    if not self._threads:
                        self._work = None
                        self._pending.clear()
                        self._pending_bytes = 0
                        self._queued = self._next
                    return

    def _serve(self, capture, work):
        """A reading thread: each segment asked for read in turn, until None."""
        while True:
            job = work.get()
            if job is None:
                return
            segment, done, box = job
            try:
                if self._closing:
                    box["error"] = RuntimeError("not read: the reader was closed")
                else:
                    box["data"] = capture.read_samples(segment, warnings=box["warnings"])
            except BaseException as e:  # noqa: BLE001 - handed to the caller by take()
                box["error"] = e
            finally:
                done.set()
            # nothing of it held while waiting for the next file: the samples are the caller's
            job = segment = done = box = None

    def close(self, wait: bool = True):
        """Drop the reads not begun, wait for those under way (their results are dropped) and end
        the reading threads; with ``wait`` False (Ctrl-C) the threads are told to end after the
        reads under way and left to them (daemons: they end with the process), so that an
        interrupted command ends at once rather than after the files being read."""
        self._closing = True
        for _ in self._threads:
            self._work.put(None)
        if not wait:
            _left_to_end(self._threads)
            self._pending.clear()
            self._threads = []
            return
        for _, done, _, _ in self._pending:
            done.wait()
        self._pending.clear()
        self._pending_bytes = 0
        for thread in self._threads:
            thread.join()
        self._threads = []

    def __enter__(self):
        return self

    def __exit__(self, kind, *exc):
        self.close(wait=not (kind is not None and issubclass(kind, KeyboardInterrupt)))
        return False


# ---------------------------------------------------------------------------------------------
# Reading


def read_capture(path, *, load_data=True):
    """Read and check a capture bundle (a directory, or its manifest.yaml).

    Raises CaptureError for anything that does not follow the format. Incomplete segments never
    raise: what is readable of them is loaded, the rest is described in Segment.problem and in
    Capture.warnings. With load_data=False, CSV files are not read (Segment.data is None) and
    sha256 is not checked until the samples are asked for (Capture.read_samples, lent_samples,
    load_samples): the way to summarise a long capture one segment at a time.
    """
    path = Path(path)
    directory, manifest_file = (path.parent, path) if _is_file(path) else (path, path / MANIFEST)
    if manifest_file.name != MANIFEST:        # e.g. a segment's CSV given for its capture
        raise CaptureError(path, f"a file, not a capture bundle (a directory holding {MANIFEST}, or that file)")
    try:
        raw = yaml_text.safe_load(read_regular_file(manifest_file, limit=MAX_MANIFEST_BYTES))
    except FileNotFoundError:
        if not directory.exists():
            raise CaptureError(directory, "no such directory") from None
        raise CaptureError(manifest_file, "no manifest: not a capture bundle") from None
    except OSError as e:
        raise CaptureError(manifest_file, f"cannot read: {e.strerror}") from None
    except yaml.MarkedYAMLError as e:
        line = e.problem_mark.line + 1 if e.problem_mark is not None else None
        raise CaptureError(manifest_file, f"not valid YAML: {e.problem}", line=line) from None
    except (yaml.YAMLError, ValueError) as e:  # ValueError: e.g. a timestamp in month 13
        raise CaptureError(manifest_file, f"not valid YAML: {e}") from None
    except RecursionError:
        raise CaptureError(manifest_file, "not valid YAML: nested too deeply") from None

    with yaml_text.gc_paused():         # a Segment and its fields for every entry, no cycle
        imu, site, scheme, segments, extra = _parse_manifest(raw, directory, manifest_file)
    capture = Capture(path=directory, imu=imu, site=site, scheme=scheme, segments=segments,
                      extra=extra, warnings=[])
    _warn_shared_files(capture)
    _warn_unused_kinds(capture)
    if load_data:
        capture.load_samples()
    return capture


def _warn_shared_files(capture) -> None:
    """A file that two complete segments point to (a manifest edited by copying an entry): its
    samples would count twice; said, not refused (the format does not forbid it)."""
    first = {}
    for seg in capture.segments:
        if seg.status == "incomplete":
            continue
        other = first.setdefault(os.path.normcase(os.path.normpath(seg.file)), seg)
        if other is not seg:
            _warn(capture, f"{capture._label(seg)} reads the same file as {capture._label(other)} "
                           f"({_show(seg.file)}): its samples count twice")


USED_KINDS = ("static", "rotation", "session")   # the kinds station's estimators and importers read


def warmup_file(directory) -> str:
    """The name of the next warm-up record in the capture ``directory`` (docs/capture-format.md):
    ``warmup.csv`` for the run's first warm-up, then ``warmup-2.csv``, ``warmup-3.csv``, ... for
    the warm-ups of its resumptions and extensions (``station run --resume``/``--append``, on a
    bench or simulated), so that none is overwritten (issue 28: a resume rewrote the first)."""
    directory = Path(directory)             # (lexists: a link to nothing is a name taken too)
    if not os.path.lexists(directory / WARMUP_FILE):
        return WARMUP_FILE
    n = 2
    while os.path.lexists(directory / f"warmup-{n}.csv"):
        n += 1
    return f"warmup-{n}.csv"


def warmup_records(directory) -> list:
    """The warm-up records in the capture ``directory`` that warmup_file names (``warmup.csv``,
    ``warmup-N.csv``), as paths."""
    return [p for p in Path(directory).glob("warmup*.csv") if re.fullmatch(r"warmup(-[0-9]+)?\.csv", p.name)]


def _warn_unused_kinds(capture) -> None:
    """Complete segments of a kind station does not use (the format allows any: they are left
    out of estimation) in one warning, with the kind they may have meant ("statc": static): a typo
    would otherwise drop a segment without a word."""
    unused = {}
    for seg in capture.segments:
        if seg.kind not in USED_KINDS and seg.status == "complete":     # (an incomplete one is said)
            unused.setdefault(seg.kind, []).append(seg)
    if not unused:
        return
    import difflib      # only for a kind to name (~1 ms of every capture read: issue 27)

    parts = []
    for kind, segs in unused.items():
        close = difflib.get_close_matches(str(kind).lower(), USED_KINDS, n=1, cutoff=0.6)
        named = ", ".join(capture._label(seg) for seg in segs[:3]) + (f" and {len(segs) - 3} more" if len(segs) > 3 else "")
        parts.append(f"kind {_show(kind)} ({named})" + (f": meant {close[0]!r}?" if close else ""))
    count = sum(len(segs) for segs in unused.values())
    _warn(capture, f"{count} segment{'s' if count > 1 else ''} of a kind station does not use, left out of "
                   f"estimation ({', '.join(USED_KINDS)} are used): " + "; ".join(parts))


def read_segment_csv(path, *, sample_rate_hz=None):
    """Read one segment CSV on its own (e.g. a file to compensate) with the same checks as in a
    bundle; CaptureError names the file and line. Gaps are counted against sample_rate_hz or,
    when it is not given, against the median time step."""
    path = Path(path)
    try:
        data, _ = read_csv_pieces(path, sample_rate_hz)
        if data is None:    # the fast reader refused: the line-by-line one names the problem
            data, problem, _ = _parse_csv_file(path, sample_rate_hz, path, None)
            if problem is not None:
                raise problem
    except OSError as e:
        raise CaptureError(path, f"cannot read: {e.strerror}") from None
    return data


class NotRegularFile(OSError):
    """A FIFO, device, socket or folder where a file is expected (reading it could block)."""


def read_regular_file(path, *, limit=None) -> bytes:
    """The bytes of a regular file: opened without blocking (O_NONBLOCK: a FIFO in its place
    must not hang the reader), checked to be a regular file on the open descriptor, and at most
    ``limit`` bytes long.  OSError (NotRegularFile, with strerror) otherwise."""
    with open_regular_file(path, limit=limit) as f:
        return f.read() if limit is None else f.read(limit + 1)


def open_regular_file(path, *, limit=None):
    """A binary file object on a regular file, opened as read_regular_file says."""
    fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0))
    try:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode):
            raise NotRegularFile(0, "not a regular file (a FIFO, device or folder)", str(path))
        if limit is not None and info.st_size > limit:
            raise NotRegularFile(0, f"{info.st_size} bytes, more than the {limit} allowed", str(path))
        f = os.fdopen(fd, "rb", closefd=True)
        fd = None
        return f
    finally:
        if fd is not None:
            os.close(fd)


def _segment_label(index, name):
    """"segments[k] (name)" for messages; a name over 60 characters shortened (the manifest's
    names have no length limit: a 30,000-character one was repeated whole in every message)."""
    if name is None:
        return f"segments[{index}]"
    text = str(name)
    if len(text) > 60:          # its start and its end (names that share a prefix differ there)
        text = f"{text[:24]}...{text[-24:]} ({len(text)} characters)"
    return f"segments[{index}] ({text})"


class _Fields:
    """Typed values from one mapping of the manifest; failures name the file, segment and field."""

    def __init__(self, file, mapping, *, prefix="", segment=None):
        self.file = file
        self.mapping = mapping
        self.prefix = prefix
        self.segment = segment

    def fail(self, key, message):
        return CaptureError(self.file, message, field=self.prefix + key, segment=self.segment)

    def get(self, key, required):
        value = self.mapping.get(key)
        if value is None and required:
            raise self.fail(key, "required, missing")
        return value

    def number(self, key, *, required=False, limit=None):
        value = self.get(key, required)
        if value is None:
            return None
        number = _finite_number(value)
        if number is None:
            raise self.fail(key, f"must be a finite number, got {_show(value)}")
        if limit is not None and abs(number) > limit:
            raise self.fail(key, f"must be at most {limit:g} in size, got {number:g}")
        return number

    def text(self, key, *, required=False):
        value = self.get(key, required)
        if value is None or isinstance(value, str):
            return value
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            return str(value)  # e.g. serial: 1234 or name: 7
        raise self.fail(key, f"must be text, got {_show(value)}")

    def choice(self, key, options):
        value = self.get(key, True)
        if value not in options:
            raise self.fail(key, f"must be one of {', '.join(options)}; got {_show(value)}")
        return value

    def vector(self, key, *, required=False):
        value = self.get(key, required)
        if value is None:
            return None
        numbers = [_finite_number(v) for v in value] if isinstance(value, list) and len(value) == 3 else []
        if len(numbers) != 3 or None in numbers:
            raise self.fail(key, f"must be a list of 3 finite numbers, got {_show(value)}")
        if max(abs(n) for n in numbers) > MAX_VECTOR_COMPONENT:
            raise self.fail(key, f"components must be at most {MAX_VECTOR_COMPONENT:g} in size")
        vector = np.array(numbers)
        norm = np.linalg.norm(vector)
        if not norm > 0:
            raise self.fail(key, "must not be the zero vector")
        return vector / norm

    def relpath(self, key, directory, *, required=False):
        value = self.text(key, required=required)
        if value is None:
            return None
        problem = _path_problem(value, directory)
        if problem:
            raise self.fail(key, f"{problem}: {_show(value)}")
        return value


def _finite_number(value):
    """`value` as a float if it is a finite number (int, float or numeric text), else None."""
    if isinstance(value, str) and _NUMBER_TEXT.fullmatch(value.strip()):
        value = float(value)  # e.g. 1e3 or 1e+06: numbers in YAML 1.2, text to PyYAML's YAML 1.1
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    return float(value) if math.isfinite(value) else None


_SHOW = reprlib.Repr()
_SHOW.maxlevel, _SHOW.maxlist, _SHOW.maxdict, _SHOW.maxstring, _SHOW.maxother = 2, 4, 4, 60, 60


def _show(value, limit=60):
    """A short repr: bounded in depth and length, so that a value built from YAML aliases (a
    "billion laughs") is never expanded."""
    text = _SHOW.repr(value)
    return text if len(text) <= limit else text[:limit - 3] + "..."


def _path_problem(relname, directory):
    """Why `relname` may not be used as a path inside the capture `directory` (None if it may)."""
    if relname == "" or "\0" in relname:
        return "not a file name"
    if PurePosixPath(relname).is_absolute() or PureWindowsPath(relname).anchor:
        return "must be relative to the capture directory"
    if ".." in re.split(r"[\\/]", relname):
        return "must not contain '..'"
    try:
        base = Path(directory).resolve()
        inside = (base / relname).resolve().is_relative_to(base)
    except (OSError, RuntimeError):  # e.g. a symbolic link loop
        return "cannot be resolved"
    if not inside:
        return "resolves (through a symbolic link) outside the capture directory"
    return None


def _is_file(path):
    try:
        return path.is_file()
    except OSError:  # e.g. a name too long for the file system
        return False


def _parse_manifest(raw, directory, manifest_file):
    """Check a loaded manifest; return (imu, site, scheme, segments, extra)."""
    if not isinstance(raw, dict):
        raise CaptureError(manifest_file, f"must be a YAML mapping, got {type(raw).__name__}")
    top = _Fields(manifest_file, raw)
    fmt = top.get("format", True)
    if fmt != FORMAT:
        raise top.fail("format", f"must be {FORMAT}, got {_show(fmt)}")

    imu = _Fields(manifest_file, _mapping(top, "imu"), prefix="imu.")
    sample_rate_hz = imu.number("sample_rate_hz", required=True)
    if not sample_rate_hz > 0:
        raise imu.fail("sample_rate_hz", f"must be > 0, got {sample_rate_hz}")
    if not SAMPLE_RATE_RANGE_HZ[0] <= sample_rate_hz <= SAMPLE_RATE_RANGE_HZ[1]:
        raise imu.fail("sample_rate_hz", f"must be within [{SAMPLE_RATE_RANGE_HZ[0]:g}, "
                       f"{SAMPLE_RATE_RANGE_HZ[1]:g}] Hz, got {sample_rate_hz:g}")
    imu_info = ImuInfo(
        sample_rate_hz=sample_rate_hz,
        accel_unit=imu.choice("accel_unit", ACCEL_UNITS),
        gyro_unit=imu.choice("gyro_unit", GYRO_UNITS),
        model=imu.text("model"),
        serial=imu.text("serial"),
        extra=_rest(imu.mapping, ("sample_rate_hz", "accel_unit", "gyro_unit", "model", "serial")))

    site = _Fields(manifest_file, _mapping(top, "site"), prefix="site.")
    gravity = site.number("gravity_mps2", required=True)
    if not gravity > 0:
        raise site.fail("gravity_mps2", f"must be > 0, got {gravity}")
    if not GRAVITY_RANGE_MPS2[0] <= gravity <= GRAVITY_RANGE_MPS2[1]:
        raise site.fail("gravity_mps2", f"must be a local gravity on Earth, within "
                        f"[{GRAVITY_RANGE_MPS2[0]:g}, {GRAVITY_RANGE_MPS2[1]:g}] m/s^2, got {gravity:g}")
    latitude = site.number("latitude_deg")
    if latitude is not None and not -90 <= latitude <= 90:
        raise site.fail("latitude_deg", f"must be within [-90, 90], got {latitude}")
    site_info = Site(gravity_mps2=gravity, latitude_deg=latitude,
                     extra=_rest(site.mapping, ("gravity_mps2", "latitude_deg")))

    entries = top.get("segments", True)
    if not isinstance(entries, list):
        raise top.fail("segments", f"must be a list, got {type(entries).__name__}")
    segments = []
    first_index = {}
    for index, entry in enumerate(entries):
        segment = _parse_segment(entry, index, directory, manifest_file)
        if segment.name in first_index:
            raise _duplicate_name(manifest_file, first_index[segment.name], index, segment.name)
        first_index[segment.name] = index
        segments.append(segment)

    scheme = top.text("scheme")
    extra = _rest(raw, ("format", "imu", "site", "scheme", "segments"))
    return imu_info, site_info, scheme, segments, extra


def _duplicate_name(manifest_file, first: int, index: int, name) -> CaptureError:
    return CaptureError(manifest_file, f"duplicate segment name (also segments[{first}])",
                        segment=_segment_label(index, name), field="name")


def _mapping(fields, key):
    value = fields.get(key, True)
    if not isinstance(value, dict):
        raise fields.fail(key, f"must be a mapping, got {type(value).__name__}")
    return value


def _rest(mapping, known):
    return {k: v for k, v in mapping.items() if k not in known}


def _parse_segment(entry, index, directory, manifest_file):
    if not isinstance(entry, dict):
        raise CaptureError(manifest_file, f"must be a mapping, got {type(entry).__name__}",
                           segment=_segment_label(index, None))
    name = entry.get("name")
    label = _segment_label(index, name if isinstance(name, (str, int)) else None)
    fields = _Fields(manifest_file, entry, segment=label)
    name = fields.text("name", required=True)
    if name == "":
        raise fields.fail("name", "must not be empty")
    kind = fields.text("kind", required=True)
    if kind == "":
        raise fields.fail("kind", "must not be empty")
    status = fields.choice("status", STATUSES)
    file = fields.relpath("file", directory, required=True)
    fields.relpath("table_file", directory)
    if status == "complete" and not _is_file(Path(directory) / file):
        raise fields.fail("file", f"no such file (or not a regular file): {_show(file)}")
    samples = entry.get("samples")
    if samples is not None and (isinstance(samples, bool) or not isinstance(samples, int)
                                or samples < 0):
        raise fields.fail("samples", f"must be a whole number >= 0, got {_show(samples)}")
    sha256 = entry.get("sha256")
    if sha256 is not None and not (isinstance(sha256, str) and _SHA256_TEXT.fullmatch(sha256)):
        raise fields.fail("sha256", f"must be 64 hexadecimal digits, got {_show(sha256)}")
    segment = Segment(
        name=name, kind=kind, file=file, status=status,
        up_body=fields.vector("up_body"),
        axis_body=fields.vector("axis_body", required=kind == "rotation"),
        rate_dps=fields.number("rate_dps", limit=MAX_RATE_DPS),
        angle_deg=fields.number("angle_deg", limit=MAX_ANGLE_DEG),
        note=fields.text("note"),
        extra=_rest(entry, _SEGMENT_FIELDS))
    return segment


def _read_segment_data(capture, segment, label, keep=True, warnings: list | None = None):
    """A segment's samples from its file, refusing (complete) or describing (incomplete).

    The file is read once as bytes; those bytes are hashed (segment.content_sha256, checked
    against the manifest's sha256) and parsed (read_csv_pieces).  Warnings (gaps, what an
    incomplete segment lacks) are added to capture.warnings once, however often it is read.
    ``keep`` False (an incomplete segment only): its rows counted, not kept; None returned.
    ``warnings``: a list for the warnings instead of capture.warnings."""
    def warn(message):
        if warnings is None:
            _warn(capture, message)
        else:
            warnings.append(message)

    csv_file = capture.path / segment.file
    complete = segment.status != "incomplete"     # "excluded" (estimate) was complete
    rate = capture.imu.sample_rate_hz
    sha_problem = "file content does not match the manifest's sha256 (changed or corrupted)"
    expected_sha = segment.extra.get("sha256")
    if complete and _small(capture):
        # a small capture: the line-by-line reader (~1 us a row), not the CSV engine, whose import
        # alone (~35 ms) is more than reading every row of the capture (issue 27)
        try:
            data, problem, segment.content_sha256 = _parse_csv_file(csv_file, rate, csv_file, label)
        except OSError as e:
            raise CaptureError(csv_file, f"cannot read: {e.strerror}", segment=label) from None
        if expected_sha is not None and segment.content_sha256 != expected_sha.lower():
            raise CaptureError(csv_file, sha_problem, segment=label, field="sha256")
        if problem is not None:
            raise problem
        samples = segment.extra.get("samples")
        if samples is not None and samples != len(data.t):
            raise CaptureError(csv_file, f"has {len(data.t)} data rows, the manifest says "
                               f"samples: {samples}", segment=label, field="samples")
    elif complete:
        try:
            data, segment.content_sha256 = read_csv_pieces(csv_file, rate)
            if expected_sha is not None and segment.content_sha256 != expected_sha.lower():
                raise CaptureError(csv_file, sha_problem, segment=label, field="sha256")
            if data is None:  # the fast reader refused: the line-by-line one names the problem
                data, problem, digest = _parse_csv_file(csv_file, rate, csv_file, label)
                if digest != segment.content_sha256:
                    raise CaptureError(csv_file, "changed while it was read", segment=label)
                if problem is not None:
                    raise problem
        except OSError as e:
            raise CaptureError(csv_file, f"cannot read: {e.strerror}", segment=label) from None
        samples = segment.extra.get("samples")
        if samples is not None and samples != len(data.t):
            raise CaptureError(csv_file, f"has {len(data.t)} data rows, the manifest says "
                               f"samples: {samples}", segment=label, field="samples")
    else:
        try:
            data, segment.problem, segment.content_sha256 = _parse_csv_file(csv_file, rate, csv_file, label,
                                                                            incomplete=True, keep=keep)
        except OSError as e:
            segment.problem = f"cannot read {segment.file}: {e.strerror}"
            warn(f"{label}: incomplete, no data: {segment.problem}")
            return None
        if segment.problem is None and expected_sha is not None \
                and segment.content_sha256 != expected_sha.lower():
            segment.problem = sha_problem
        rows = 0 if data is None else data.rows
        problem = f": {segment.problem}" if segment.problem else ""
        warn(f"{label}: incomplete, {rows} readable rows{problem}")

    if data is not None and data.gaps:
        warn(f"{label}: {data.gaps} gaps in time in {segment.file} "
                       f"(steps longer than {GAP_FACTOR} periods where the stamps jump: lost samples)")
    return data if keep else None


# a capture whose segments hold at most this many rows in all (the manifest's counts) is read by
# the line-by-line reader while the CSV engine is not imported: at ~0.8-1 us a row against the
# engine's ~0.23 us and its ~35 ms import, the engine pays above ~60,000 rows (imucal's example
# session: 4,382 rows, 5 ms; a 100 Hz optimal9 capture: 306,000 rows, the engine)
SMALL_CAPTURE_ROWS = 50_000


def is_small(capture) -> bool:
    """At most SMALL_CAPTURE_ROWS rows in all, by the manifest's counts (False when a segment
    states none)."""
    rows = 0
    for seg in capture.segments:
        samples = seg.extra.get("samples")
        if not isinstance(samples, int) or isinstance(samples, bool) or samples < 0:
            return False
        rows += samples
    return rows <= SMALL_CAPTURE_ROWS


def _small(capture) -> bool:
    """Whether ``capture`` is read line by line (is_small, and the engine not already imported).
    $STATION_CSV_ENGINE set: never."""
    import sys

    if "pyarrow" in sys.modules or os.environ.get("STATION_CSV_ENGINE"):
        return False
    return is_small(capture)


def _warn(capture, message):
    """Add ``message`` to capture.warnings unless it is there (a set of them kept beside the
    list, made again when the list changed otherwise: a scan of the list for each of many
    segments' warnings was quadratic)."""
    seen = capture.__dict__.get("_warned")
    if seen is None or seen[0] is not capture.warnings or seen[1] != len(capture.warnings):
        seen = [capture.warnings, len(capture.warnings), set(capture.warnings)]
        capture._warned = seen
    if message not in seen[2]:
        capture.warnings.append(message)
        seen[2].add(message)
        seen[1] += 1


def _csv_lines_in_pieces(f, *, partial_last_line, fail):
    """The lines of a segment CSV read from the binary file ``f`` PIECE_BYTES at a time, as
    (lines, number of the first line) pieces of whole lines: decoded (a bad byte then fails as
    "not a number"), a BOM at the start dropped, CRLF read as LF, and blank lines at the end of the
    file left out (a piece's trailing blank lines are held back until a line follows them).  A
    line still open more than MAX_LINE_BYTES after a piece's end raises fail(message, line
    number) there (a file of hundreds of megabytes without a line end took time quadratic in
    its size and seven times its size in memory; a long line inside a piece is parsed, and
    refused as a row).

    partial_last_line: the writer may have been stopped mid-line, so whatever follows the last
    line end is dropped."""
    carry, held, number, first = b"", [], 1, True

    def decoded(raw: bytes) -> str:
        nonlocal first
        text = raw.decode("utf-8", errors="replace")
        if first:
            text, first = text.removeprefix("\ufeff"), False
        return text.replace("\r\n", "\n") if "\r" in text else text

    while True:
        block = f.read(PIECE_BYTES)
        if not block:
            break
        data = carry + block
        cut = data.rfind(b"\n") + 1
        carry = data[cut:]
        if cut:
            lines = held + decoded(data[:cut]).split("\n")[:-1]    # whole lines: the last ends the piece
            k = len(lines)
            while k and not lines[k - 1].strip():
                k -= 1
            held = lines[k:]
            if k:
                yield lines[:k], number
                number += k
        if len(carry) > MAX_LINE_BYTES:     # (the lines before it parsed first: the first bad one is named)
            if held:
                yield held, number              # blank lines before a line: refused there
            raise fail(f"a line longer than {MAX_LINE_BYTES} bytes (a segment CSV's rows are a few numbers)",
                       number + len(held))
    if carry and not partial_last_line:
        lines = held + decoded(carry).split("\n")
        while lines and not lines[-1].strip():
            lines.pop()
        if lines:
            yield lines, number


class _LineParser:
    """The line-by-line reader: a segment CSV fed as pieces of its lines (header first), every
    line checked, the first violation in the file's order refused by CaptureError naming its
    line, column and text; the rows before it kept (an incomplete segment's)."""

    def __init__(self, sample_rate_hz, csv_file, label, keep=True):
        self.sample_rate_hz, self.csv_file, self.label = sample_rate_hz, csv_file, label
        self.names = self.wanted = self.usecols = None
        self.values = []           # (rows, k) arrays of the pieces read (keep)
        self.keep, self.rows, self.gaps = keep, 0, 0      # (not keep: counted only)
        self.last_t = None

    def fail(self, message, line):
        return CaptureError(self.csv_file, message, line=line, segment=self.label)

    def feed(self, lines, number):
        """Parse ``lines`` (the first is line ``number``); CaptureError at the first bad one."""
        if self.names is None:
            self.names, self.wanted, self.usecols = _parse_header(lines[0], self.fail)
            lines, number = lines[1:], number + 1
        if not lines:
            return
        values, error = self._values(lines)
        if len(values):
            checked = self._checks(values, lines)
            if checked is not None and (error is None or checked[1] < error[1]):
                error = checked
            rows = len(values) if error is None else min(error[1], len(values))
            if rows:
                if self.keep:
                    self.values.append(values[:rows])
                else:
                    t = values[:rows, 0] if self.last_t is None else np.concatenate([[self.last_t], values[:rows, 0]])
                    self.rows += rows
                    self.gaps += stamp_gaps(t, self.sample_rate_hz)[0]
                self.last_t = float(values[rows - 1, 0])
        if error is not None:
            raise self.fail(error[0], number + error[1])

    def _values(self, lines):
        """(values of the rows before the first that has the wrong fields or does not parse,
        (message, index) of that row or None)."""
        commas = len(self.names) - 1
        bad = next((i for i, line in enumerate(lines) if line.count(",") != commas or '"' in line), None)
        error = None
        if bad is not None:
            if '"' in lines[bad]:
                error = ("quoting is not allowed", bad)
            elif not lines[bad].strip():
                error = ("blank line (only allowed at the end of the file)", bad)
            else:
                error = (f"{lines[bad].count(',') + 1} fields, the header has {len(self.names)}", bad)
            lines = lines[:bad]
        values = _loadtxt(lines, self.usecols) if lines else np.empty((0, len(self.wanted)))
        if values is None:
            index = _first_unparsable(lines, self.usecols)
            fields = lines[index].split(",")
            column = next((c for c in self.usecols if _loadtxt([f"0,{fields[c]}"], [1]) is None), None)
            error = (("cannot parse the numbers" if column is None else
                      f"column '{self.names[column]}': not a number: {_show(fields[column].strip())}"), index)
            values = _loadtxt(lines[:index], self.usecols) if index else np.empty((0, len(self.wanted)))
        return values, error

    def _checks(self, values, lines):
        """(message, index) of the first row not finite, out of range or not later than the one
        before it (the previous piece's last for the first), or None."""
        found = []
        finite = np.isfinite(values)
        if not finite.all():
            row, col = np.argwhere(~finite)[0]
            text = lines[row].split(",")[self.usecols[col]].strip()
            found.append((f"column '{self.wanted[col]}': not a finite number: {_show(text)}", row))
        huge = np.abs(values) > MAX_CSV_VALUE
        if huge.any():
            row, col = np.argwhere(huge)[0]
            text = lines[row].split(",")[self.usecols[col]].strip()
            found.append((f"column '{self.wanted[col]}': out of range (|value| > {MAX_CSV_VALUE:g}): "
                          f"{_show(text)}", row))
        t = values[:, 0]
        before = np.concatenate([[-math.inf if self.last_t is None else self.last_t], t[:-1]])
        backwards = np.flatnonzero(~(t > before))      # (a NaN is not finite first)
        if len(backwards):
            i = backwards[0]
            found.append((f"time does not increase: t={t[i]:.15g} after t={before[i]:.15g}", i))
        return min(found, key=lambda e: e[1], default=None)

    def result(self, *, require_rows) -> SegmentData | _RowCount:
        if self.names is None:
            raise self.fail(f"empty file: line 1 must be the header {','.join(REQUIRED_COLUMNS)}", 1)
        if not self.keep:
            if not self.rows and require_rows:
                raise self.fail("no data rows after the header", 2)
            return _RowCount(self.rows, self.gaps)
        values = np.concatenate(self.values) if self.values else np.empty((0, len(self.wanted)))
        self.values = []
        if not len(values) and require_rows:
            raise self.fail("no data rows after the header", 2)
        t = np.ascontiguousarray(values[:, 0])
        return SegmentData(
            t=t,
            accel=np.ascontiguousarray(values[:, 1:4]),
            gyro=np.ascontiguousarray(values[:, 4:7]),
            temp=np.ascontiguousarray(values[:, 7]) if len(self.wanted) == 8 else None,
            gaps=stamp_gaps(t, self.sample_rate_hz)[0])


class _Hashing:
    """A binary file read through, every byte read added to ``digest``."""

    def __init__(self, f, digest):
        self.f, self.digest = f, digest

    def read(self, n):
        block = self.f.read(n)
        self.digest.update(block)
        return block


def _parse_csv_file(path, sample_rate_hz, csv_file, label, *, incomplete=False, keep=True):
    """(SegmentData or None, the first problem or None, sha256 hex of the bytes read) of a
    segment CSV read line by line, a piece at a time (memory: a piece and the samples, not the
    file's text).  A complete segment's file (``incomplete`` False) with a bad line gives no data
    and the CaptureError naming the line, once the whole file is hashed (the caller compares the
    digest first: a file that changed while it was read is said so); an incomplete one gives the
    rows before its first bad line (None: not even a header) and that line's problem (a str),
    and drops a partial last line.  ``keep`` False: the rows counted, not kept (a _RowCount
    instead of the SegmentData).  OSError when the file cannot be read."""
    digest = hashlib.sha256()
    parser = _LineParser(sample_rate_hz, csv_file, label, keep=keep)
    with open_regular_file(path) as f:
        source = _Hashing(f, digest)
        try:
            for lines, number in _csv_lines_in_pieces(source, partial_last_line=incomplete, fail=parser.fail):
                parser.feed(lines, number)
            return parser.result(require_rows=not incomplete), None, digest.hexdigest()
        except CaptureError as e:
            while source.read(PIECE_BYTES):     # the rest hashed all the same
                pass
            if not incomplete:
                return None, e, digest.hexdigest()
            data = parser.result(require_rows=False) if parser.names is not None else None
            return data, str(e), digest.hexdigest()


JUMP_WINDOW = 8      # stamps each side of a long step over which stamp_gaps averages them


def stamp_gaps(t, sample_rate_hz=None) -> tuple[int, int, float]:
    """(gaps, frames missing, period) of time stamps ``t``.  The period is the median step (a
    device a few % off its stated rate loses nothing), or the stated one (1/sample_rate_hz) when
    the median is not within half of it (every other frame lost: each step longer than
    GAP_FACTOR periods is then a gap of its length in periods less one).  A step longer than
    GAP_FACTOR periods is a gap only if the stamps jump there: the mean offset of the
    JUMP_WINDOW stamps after it from a steady clock, less that of the ones before (neither
    window past the long steps beside it), rounded, is the frames lost.  Stamps that jitter (a
    late one lengthens a step by as much as it shortens the next: host stamps of ±0.3 period
    made steps of 1.6 periods, each a "gap" before) average out over the windows; a lost frame
    does not."""
    t = np.asarray(t, float)
    n = len(t)
    if n < 2:
        return 0, 0, (1.0 / sample_rate_hz if sample_rate_hz else math.inf)
    steps = np.diff(t)
    shortest, longest = float(steps.min()), float(steps.max())
    if longest <= GAP_FACTOR * shortest and (not sample_rate_hz or 0.5 < shortest * sample_rate_hz
                                             and longest * sample_rate_hz < 1.5):
        # no step 1.5 times another, all near the stated one (the usual case): no long step
        # whatever the median, which is not computed (it made reading 20 times slower here)
        return 0, 0, float(t[-1] - t[0]) / (n - 1)
    median = float(np.median(steps))
    nominal = 1.0 / sample_rate_hz if sample_rate_hz else median
    steady = 0.5 * nominal < median < 1.5 * nominal
    period = median if steady else nominal
    long = np.flatnonzero(steps > GAP_FACTOR * period)
    if not len(long):
        return 0, 0, period
    if not steady:
        lost = np.round(steps[long] / period - 1.0)
    else:
        offset = t / period - np.arange(n)                     # in periods, from a steady clock
        total = np.concatenate([[0.0], np.cumsum(offset - offset[0])])
        before = np.concatenate([[-1], long[:-1]]) + 1
        after = np.concatenate([long[1:], [n - 1]]) + 1
        cut = long + 1
        lo, hi = np.maximum(cut - JUMP_WINDOW, before), np.minimum(cut + JUMP_WINDOW, after)
        jump = (total[hi] - total[cut]) / (hi - cut) - (total[cut] - total[lo]) / (cut - lo)
        lost = np.maximum(np.round(jump), 0.0)
    return int(np.count_nonzero(lost > 0)), int(lost.sum()), period


def _parse_header(header, fail):
    """(names, wanted, usecols) from a segment CSV's first line; fail(message, line) otherwise."""
    if '"' in header:
        raise fail("quoting is not allowed", 1)
    names = [name.strip() for name in header.split(",")]
    if _NUMBER_TEXT.fullmatch(names[0]):
        raise fail(f"no header: line 1 must name the columns {','.join(REQUIRED_COLUMNS)}", 1)
    duplicates = sorted(n for n, count in Counter(names).items() if count > 1)
    if duplicates:
        raise fail(f"duplicate column name(s) {', '.join(map(repr, duplicates))}", 1)
    missing = [n for n in REQUIRED_COLUMNS if n not in names]
    if missing:
        raise fail(f"missing required column(s) {', '.join(map(repr, missing))} in the header", 1)
    wanted = list(REQUIRED_COLUMNS) + (["temp"] if "temp" in names else [])
    return names, wanted, [names.index(n) for n in wanted]


# Reading ahead (ReaderAhead): files read at once, and how far ahead of the segment taken the
# files handed to the reading threads may reach (the next one is always read, however long)
READ_AHEAD_BYTES = 64 * 2**20


def read_ahead_threads() -> int:
    """Files read at once by a ReaderAhead: two where the process may run on two cores (its CPU
    affinity: taskset, a container's cpuset; one file each), else one."""
    from station.core.forked import usable_cores

    return 2 if usable_cores() >= 2 else 1


_LEFT = []      # reading threads left to end by ReaderAhead.close(wait=False), joined at exit
LEFT_READS_WAIT_S = 2.0     # at most this long (a 4 kHz segment's file: ~0.5 s; a stuck read: not for ever)


def _left_to_end(threads) -> None:
    """The process, when it ends, waits for ``threads`` (told to end after the reads under way),
    up to LEFT_READS_WAIT_S: a reading thread still in the CSV engine while the interpreter ended
    crashed it (exit status -11 instead of 130 after Ctrl-C; review of issue 27: ~1 Ctrl-C in 6
    while a 1 kHz estimate reads).  "interrupted" is said at once; a second Ctrl-C ends the wait."""
    import atexit

    atexit.unregister(_join_left)       # registered once
    atexit.register(_join_left)
    _LEFT[:] = [t for t in _LEFT if t.is_alive()] + list(threads)


def _join_left() -> None:
    import time

    deadline = time.monotonic() + LEFT_READS_WAIT_S
    try:
        while _LEFT:
            thread = _LEFT.pop()
            if thread.ident is not None:    # started
                thread.join(max(0.0, deadline - time.monotonic()))
    except KeyboardInterrupt:
        pass


def _import_engine() -> None:
    """Import the CSV engine (pyarrow.csv) on this thread, before the reading threads that use it
    start.  A reading thread that imports while the main thread imports (estimate_capture's early
    reader: the fit's modules meanwhile) holds the import lock at times, and a Ctrl-C that lands
    while the main thread waits for it is raised inside importlib's own lock handling
    (``_get_module_lock``'s callback): the Ctrl-C is lost and the lock never given back, the
    reading thread waits for it for ever and the estimate for the reading thread (review of
    issue 27: ~1 Ctrl-C in 20 in a 1 kHz estimate's first 0.7 s)."""
    try:
        import pyarrow.csv  # noqa: F401
    except ImportError:  # pragma: no cover - a dependency; the line-by-line reader still works
        pass


PIECE_BYTES = 8 * 2**20   # a segment file is read, hashed and parsed this many bytes at a time
MAX_LINE_BYTES = 2**16    # a line still open after this many bytes at a piece's end is refused
# a block this long is parsed on the engine's threads; a shorter one (a 100 Hz segment: ~2 MB) on
# this thread: the pool's start and hand-overs cost more CPU than they save there (issue 27: a
# 100 Hz optimal9 capture read with 0.14-0.16 s of CPU against 0.16-0.25 s, and no later)
THREADED_BLOCK_BYTES = 4 * 2**20
_DUMPER = getattr(yaml, "CSafeDumper", yaml.SafeDumper)
_BOM = b"\xef\xbb\xbf"
_BLANK = b" \t\r\n"


def read_csv_pieces(path, sample_rate_hz) -> tuple[SegmentData | None, str]:
    """(samples or None, sha256 hex) of a segment CSV, read once.

    The file is read PIECE_BYTES at a time; each piece is hashed and its whole lines parsed in
    one pass of a C++ CSV engine (pyarrow.csv, on the machine's cores) into arrays that grow to
    the segment's length, so that neither the file's bytes nor the engine's tables are ever held
    whole.  It takes only files it reads exactly as the line-by-line reader (_LineParser) would:
    anything unusual (quotes, a lone CR, spaces around values, a blank line inside, a field it
    cannot convert, a non-finite or out-of-range value, time that does not increase, no data
    row) makes it return None for the samples, and the caller gives the file to that reader,
    which accepts it or names the line, column and text.  OSError if the file cannot be read."""
    digest = hashlib.sha256()
    parser = _PieceParser(sample_rate_hz)
    held = 0            # bytes at the buffer's start: the partial line carried over
    with open_regular_file(path) as f:
        parser.size = os.fstat(f.fileno()).st_size
        # One buffer for the whole file: a partial last line is moved to its start and the next
        # piece read in after it (no copy of a piece to join it to the line it ends).  A file
        # shorter than a piece gets a buffer its size (+1: the read that finds its end): a
        # zeroed 8 MB buffer for a 100 Hz segment's 1.7 MB was ~2 ms of page faults and
        # zeroing per file (issue 27)
        piece = min(PIECE_BYTES, parser.size + 1)
        buffer = bytearray(piece + 4096)
        total = 0
        while True:
            if len(buffer) < held + piece:    # a line longer than the room left
                grown = bytearray(held + piece)
                grown[:held] = buffer[:held]
                buffer = grown
            with memoryview(buffer) as view:
                got = f.readinto(view[held:held + piece])
                if not got:
                    break
                total += got
                last = False
                if total >= parser.size and held + got < len(buffer):
                    # the file's length is read: one more read says whether it ended there (a file
                    # still growing gives more), so that its last line is parsed with the others,
                    # not in an engine call of its own (~0.1 ms a file; issue 27)
                    more = f.readinto(view[held + got:held + got + 1])
                    total += more
                    got += more
                    last = not more
                # hashlib and the engine both release the GIL: hashing overlaps parsing
                # (a thread per piece: measured again on a quiet machine, 14 interleaved rounds of
                # the 100 Hz estimate, 298 against 320 ms of wall, 351 against 346 ms of CPU, for
                # hashing on the reading thread; at real-time priority beside other work the
                # other way round, 280 against 285 ms: the quiet machine is the one that counts)
                hashing = threading.Thread(target=digest.update, args=(view[held:held + got],),
                                           daemon=True)
                hashing.start()
                end = held + got
                cut = 0
                if not parser.failed:
                    # whole lines only, and blank lines at the end held back (allowed only at the
                    # file's end)
                    stop = end
                    while stop > 0 and buffer[stop - 1] in _BLANK:
                        stop -= 1
                    cut = buffer.rfind(b"\n", 0, stop) + 1
                    if last and end - cut <= MAX_LINE_BYTES:
                        parser.feed(buffer, stop)       # the file's end: every line, its last too
                        cut = end
                    elif cut > 0:
                        parser.feed(buffer, cut)
                    if end - cut > MAX_LINE_BYTES:     # a line without end: the line reader names
                        parser.failed = True            # it (grown here, quadratic in its length)
                hashing.join()          # before the buffer's bytes are moved or read over
            held = 0 if parser.failed else end - cut
            if held:        # same length: the buffer is never resized (views of it may live on)
                buffer[:held] = buffer[cut:end]
        if not parser.failed:
            stop = held
            while stop > 0 and buffer[stop - 1] in _BLANK:
                stop -= 1
            parser.feed(buffer, stop)
    return parser.result(), digest.hexdigest()


class _PieceParser:
    """Parses a segment CSV fed as pieces of whole lines (see read_csv_pieces)."""

    def __init__(self, sample_rate_hz):
        self.sample_rate_hz = sample_rate_hz
        self.size = 0
        self.failed = False
        self.columns = None     # engine column names; None until the header is read
        self.n = 0
        self.arrays = None      # t (N,), accel (N, 3), gyro (N, 3), temp (N,) or None

    def feed(self, text: bytes, end: int, start: int = 0):
        """Parse text[start:end]: whole lines (the last one may lack its line end at the file's
        end)."""
        if self.failed or end <= start:
            return
        if text.find(b'"', start, end) >= 0 or (text.find(b"\r", start, end) >= 0 and text.count(
                b"\r", start, end) != text.count(b"\r\n", start, end)):
            self.failed = True      # quoting, or a CR that does not end a line
            return
        if self.columns is None:
            self._header(text, end, start)
            return
        block = memoryview(text)[start:end]
        table = _arrow_table(block, self.columns, self.usecols)
        if table is None or table.num_columns != len(self.wanted):
            self.failed = True
            return
        rows = table.num_rows
        self._reserve(self.n + rows, len(block), rows)
        t, accel, gyro, temp = self.arrays
        targets = [t, accel[:, 0], accel[:, 1], accel[:, 2], gyro[:, 0], gyro[:, 1], gyro[:, 2], temp]
        if not all(_copy_column(table.column(k), targets[k][self.n:self.n + rows])
                   for k in range(len(self.wanted))):
            self.failed = True
            return
        self.n += rows

    def _header(self, text, end, start):
        """Read the header off the first block, then feed the rest of it."""
        if text.startswith(_BOM, start):
            start += len(_BOM)
        newline = text.find(b"\n", start, end)
        if newline < 0:
            self.failed = True      # no data row
            return
        try:
            header = text[start:newline].decode("utf-8").removesuffix("\r")
            names, self.wanted, self.usecols = _parse_header(header, lambda message, line: ValueError(message))
        except ValueError:  # UnicodeDecodeError too
            self.failed = True
            return
        self.columns = [f"c{i}" for i in range(len(names))]
        self.feed(text, end, newline + 1)

    def _reserve(self, rows, block_bytes, block_rows):
        """Room for ``rows`` rows: first sized from the file's length and the rows per byte seen."""
        if self.arrays is not None and len(self.arrays[0]) >= rows:
            return
        estimate = int(self.size * block_rows / max(block_bytes, 1) * 1.02) + 16
        capacity = max(rows, estimate if self.arrays is None else 2 * len(self.arrays[0]))
        temp = len(self.wanted) == 8
        new = (np.empty(capacity), np.empty((capacity, 3)), np.empty((capacity, 3)),
               np.empty(capacity) if temp else None)
        if self.arrays is not None:
            for old, grown in zip(self.arrays, new):
                if old is not None:
                    grown[:self.n] = old[:self.n]
        self.arrays = new

    def result(self) -> SegmentData | None:
        if self.failed or self.n == 0:
            return None
        t, accel, gyro, temp = (None if a is None else a[:self.n] for a in self.arrays)
        if len(self.arrays[0]) > self.n + self.n // 8:     # far more room than rows: give it back
            t, accel, gyro = t.copy(), accel.copy(), gyro.copy()
            temp = None if temp is None else temp.copy()
        self.arrays = None
        for values in (t, accel, gyro) + (() if temp is None else (temp,)):
            # finite and in range (NaN fails both): the line-by-line reader names the first that is not
            if not (values.min() >= -MAX_CSV_VALUE and values.max() <= MAX_CSV_VALUE):
                return None
        steps = np.diff(t)
        if not np.all(steps > 0):
            return None
        return SegmentData(t=t, accel=accel, gyro=gyro, temp=temp,
                           gaps=stamp_gaps(t, self.sample_rate_hz)[0])


def _arrow_table(block, columns, usecols):
    """The wanted columns of a block of whole CSV lines as a pyarrow Table of float64, or None
    where the engine refuses it."""
    try:
        import pyarrow as pa
        import pyarrow.csv as pacsv
    except ImportError:  # pragma: no cover - a dependency; the line-by-line reader still works
        return None
    try:
        return pacsv.read_csv(
            pa.py_buffer(block),
            read_options=_read_options(pacsv, columns, len(block)),
            parse_options=pacsv.ParseOptions(delimiter=",", quote_char=False, double_quote=False,
                                             escape_char=False, newlines_in_values=False,
                                             ignore_empty_lines=False),
            convert_options=pacsv.ConvertOptions(
                include_columns=[columns[c] for c in usecols],
                column_types={columns[c]: pa.float64() for c in usecols},
                null_values=[], strings_can_be_null=False, quoted_strings_can_be_null=False))
    except (pa.ArrowException, ValueError):
        return None


def _read_options(pacsv, columns, size: int):
    """The engine's reading options for a block of ``size`` bytes: a long block on its threads
    (its default 1 MB blocks parsed in parallel), a shorter one on this thread in one block (one
    chunk per column: 2.3 ms of CPU for a 100 Hz segment's 1.7 MB against 3.4 ms in 1 MB blocks)."""
    if size >= THREADED_BLOCK_BYTES:
        return pacsv.ReadOptions(column_names=columns, use_threads=True)
    return pacsv.ReadOptions(column_names=columns, use_threads=False, block_size=max(size + 1, 2**20))


def _copy_column(chunked, out):
    """Copy a float64 pyarrow column without nulls into the numpy array ``out``, chunk by chunk
    (straight from the Arrow buffers: no pandas, no intermediate array); False if it has nulls
    or another length (which the options given to the engine rule out)."""
    if chunked.null_count or chunked.type != "double":
        return False
    i = 0
    for chunk in chunked.chunks:
        n = len(chunk)
        out[i:i + n] = np.frombuffer(chunk.buffers()[1], dtype=np.float64, count=n,
                                     offset=chunk.offset * 8)
        i += n
    return i == len(out)


def _loadtxt(rows, usecols):
    """The selected columns of `rows` (non-empty list of lines) as an (N, k) array, or None."""
    try:
        return np.loadtxt(rows, delimiter=",", comments=None, usecols=usecols, ndmin=2,
                          dtype=np.float64)
    except ValueError:
        return None


def _first_unparsable(rows, usecols):
    """Index of the first row np.loadtxt refuses, knowing that it refuses `rows`."""
    lo, hi = 0, len(rows)  # the first bad row is in rows[lo:hi]
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if _loadtxt(rows[lo:mid], usecols) is None:
            hi = mid
        else:
            lo = mid
    return lo


# ---------------------------------------------------------------------------------------------
# Writing


class CaptureWriter:
    """Writes a capture bundle as a run records it.

    The manifest is rewritten atomically whenever a segment begins or ends, so a bundle whose
    writer was killed at any moment is readable: finished segments are complete, the one being
    recorded is incomplete with every row flushed before the kill.
    """

    sync_segments = True      # every block of samples fsynced when written (ImportCaptureWriter: not)

    def __init__(self, directory, imu: ImuInfo, site: Site, scheme: str | None = None,
                 extra: dict | None = None):
        from station.core.user_files import output_path

        directory = Path(output_path(directory, "the capture directory"))
        if (directory / MANIFEST).exists():
            raise UserError(f"{directory}: already holds a capture ({MANIFEST}); "
                            "reopen it to append segments, or choose a new directory")
        manifest = {
            "format": FORMAT,
            "imu": _without_none({"sample_rate_hz": imu.sample_rate_hz,
                                  "accel_unit": imu.accel_unit, "gyro_unit": imu.gyro_unit,
                                  "model": imu.model, "serial": imu.serial, **imu.extra}),
            "site": _without_none({"gravity_mps2": site.gravity_mps2,
                                   "latitude_deg": site.latitude_deg, **site.extra}),
            "scheme": scheme,
            "segments": [],
        }
        for key, value in (extra or {}).items():
            if key in manifest:
                raise ValueError(f"extra key {key!r} is a manifest key of its own")
            manifest[key] = value
        manifest = _without_none(_plain(manifest))
        _check(manifest, directory)
        try:
            directory.mkdir(parents=True, exist_ok=True)
        except FileExistsError:         # a file, or a symbolic link to nothing (never followed)
            kind = "a symbolic link to nothing" if directory.is_symlink() else "not a directory"
            raise UserError(f"{directory}: {kind}: cannot create the capture directory there; "
                            "choose a new directory") from None
        except OSError as e:
            raise UserError(f"{directory}: cannot create the capture directory: {e.strerror}") from None
        remove_stray_temporaries(directory)     # a writer killed before its first manifest
        self._dir = directory
        self.segment_extra: dict = {}           # segment name -> manifest keys its entry gets too
        self._keep(manifest)

    @classmethod
    def reopen(cls, directory):
        """A writer that appends to an existing bundle.

        Complete segments are kept untouched; incomplete ones are dropped from the manifest and
        their files (whatever they are: a FIFO too) renamed aside (rot1p.csv ->
        rot1p.csv.incomplete), so they can be recorded again under the same name.  Temporary
        files left by a writer that was killed (``.NAME.RANDOM.tmp``) are removed.
        """
        directory = Path(directory)
        capture = read_capture(directory, load_data=False)
        manifest = yaml_text.safe_load(read_regular_file(directory / MANIFEST, limit=MAX_MANIFEST_BYTES))
        kept, names = [], []
        for entry, segment in zip(manifest["segments"], capture.segments):
            if segment.status == "complete":
                kept.append(entry)
                names.append(segment.name)
            elif os.path.lexists(directory / segment.file):
                os.replace(directory / segment.file, _aside_name(directory / segment.file))
        manifest["segments"] = kept
        remove_stray_temporaries(directory)
        writer = cls.__new__(cls)
        writer._dir = directory
        writer.segment_extra = {}
        writer._keep(manifest, names)
        return writer

    def _keep(self, manifest, names=()):
        """Hold ``manifest`` (checked whole: the reader's checks) as the text of its parts, the
        segments' one by one, and save it.  A segment that begins or ends is then checked alone
        (its fields and its name against the others) and only its text made again: checking
        and writing the whole manifest at each segment's start and end made a run quadratic in
        its segments (600 segments: 41 s).  ``names``: the segments' names as the reader parsed them."""
        keys = list(manifest)
        at = keys.index("segments")
        self._head = _yaml({k: manifest[k] for k in keys[:at]}) if at else ""
        self._tail = _yaml({k: manifest[k] for k in keys[at + 1:]}) if at + 1 < len(keys) else ""
        self._texts = [_yaml([entry]) for entry in manifest["segments"]]
        self._first = {}
        for index, name in enumerate(names):
            self._first.setdefault(name, index)
        self._manifest = manifest
        self._save()

    @property
    def path(self):
        return self._dir

    def begin_segment(self, name, kind, *, file=None, **meta):
        """Start recording a segment: creates its CSV and lists it as incomplete.

        meta: up_body, axis_body, rate_dps, angle_deg, note, started_utc (default: now), ...;
        numpy values become plain numbers and lists.
        """
        meta = {**getattr(self, "segment_extra", {}).get(name, {}), **meta}
        _refuse_owned_keys(meta)
        entry = {"name": name, "kind": kind, "file": file or f"{name}.csv",
                 "status": "incomplete",
                 "started_utc": datetime.now(timezone.utc).isoformat(timespec="seconds"),
                 **_plain(meta)}
        entry = _ordered_entry(entry)
        segments = self._manifest["segments"]
        name = self._validate(entry, len(segments))
        csv_path = self._dir / entry["file"]
        csv_path.parent.mkdir(parents=True, exist_ok=True)
        if os.path.lexists(csv_path):
            listed = any(Path(e["file"]) == Path(entry["file"]) for e in self._manifest["segments"])
            if listed:
                raise UserError(f"{csv_path}: already exists; will not overwrite it")
            # not in the manifest: left by a writer killed before it listed the file (older
            # versions created the file first); kept aside, never overwritten
            os.replace(csv_path, _aside_name(csv_path, ".unlisted"))
        # the manifest lists the segment (incomplete) before its file exists: a kill between
        # the two leaves an incomplete segment without a file, which readers accept
        segments.append(entry)
        self._texts.append(self._entry_text(entry))
        try:
            self._save()
        except BaseException:
            segments.pop()
            self._texts.pop()
            raise
        self._first.setdefault(name, len(segments) - 1)
        try:
            fd = os.open(csv_path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0)
                         | getattr(os, "O_CLOEXEC", 0), 0o644)
        except FileExistsError:
            raise UserError(f"{csv_path}: appeared while the segment began; will not overwrite it") from None
        handle = os.fdopen(fd, "wb")
        return SegmentWriter(self, entry, handle)

    def write_file(self, relname, text):
        """Write an extra file into the bundle (text or bytes), atomically."""
        problem = _path_problem(relname, self._dir)
        if not problem and (self._dir / relname).resolve() == (self._dir / MANIFEST).resolve():
            problem = "the manifest is written by the writer itself"
        if problem:
            raise ValueError(f"{relname!r}: {problem}")
        path = self._dir / relname
        path.parent.mkdir(parents=True, exist_ok=True)
        _atomic_write(path, text.encode("utf-8") if isinstance(text, str) else text)

    def _update_segment(self, entry, changes):
        """Apply `changes` to a segment entry and save the manifest, refusing invalid values."""
        segments = self._manifest["segments"]
        index = next(i for i in range(len(segments) - 1, -1, -1) if segments[i] is entry)   # (the last, mostly)
        updated = _ordered_entry({**entry, **_plain(changes)})
        if updated["name"] != entry["name"]:
            raise ValueError("a segment's name is not changed once it began")
        self._validate(updated, index)
        before = segments[index], self._texts[index]
        segments[index], self._texts[index] = updated, self._entry_text(updated)
        try:
            self._save()
        except BaseException:
            segments[index], self._texts[index] = before
            raise
        return updated

    def _validate(self, entry, index):
        """Refuse (CaptureError) a segment entry at ``index`` that a reader would refuse (before
        it is saved): its own fields, and its name if an earlier segment has it.  Its name as the
        reader reads it."""
        manifest_file = self._dir / MANIFEST
        segment = _parse_segment(entry, index, self._dir, manifest_file)
        first = self._first.get(segment.name, index)
        if first < index:
            raise _duplicate_name(manifest_file, first, index, segment.name)
        return segment.name

    def _entry_text(self, entry):
        """A segment entry's text in the manifest (None: made when the manifest is saved)."""
        return _yaml([entry])

    def _save(self):
        """Make the manifest held (its parts' texts) the bundle's manifest, atomically."""
        segments = self._manifest["segments"]
        self._texts = [_yaml([segments[i]]) if text is None else text for i, text in enumerate(self._texts)]
        body = "segments:\n" + "".join(self._texts) if self._texts else "segments: []\n"
        _atomic_write(self._dir / MANIFEST, (self._head + body + self._tail).encode("utf-8"))


class DeferredCaptureWriter(CaptureWriter):
    """A CaptureWriter that writes the manifest when created and when ``finish`` is called, not
    at every segment's start and end (each segment is still checked as it begins and ends, as a
    run's).  A run on a bench rewrites the whole manifest twice a segment so that a killed run
    can resume: O(segments) a rewrite, quadratic over a run (100,000 segments: 200,000 rewrites
    of a 20 MB manifest).  What is redone rather than resumed (an import: its source is
    untouched; a dry run: ``run --resume`` is for bench runs) writes it twice, linear.  Call
    ``finish`` in a ``finally``: a writer stopped by an error or Ctrl-C then leaves the manifest
    of what it wrote, the segment being written incomplete."""

    _deferred = False

    def _entry_text(self, entry):
        return None if self._deferred else super()._entry_text(entry)     # dumped once, at the save

    def _save(self):
        if not self._deferred:
            super()._save()
            self._deferred = True

    def finish(self):
        self._deferred = False
        self._save()


class ImportCaptureWriter(DeferredCaptureWriter):
    """An import's writer: a DeferredCaptureWriter whose segment files are not fsynced block by
    block.  An import is redone from its source, not resumed, and the fsync of each of its files
    was most of its wall time (77 files of imu_tk's Xsens log: 0.4-1 s on this machine, the
    whole import's CPU 0.5 s; issue 27).  The manifest is still replaced atomically (fsynced,
    renamed, the folder fsynced) once at the start and once at the end, with every segment's
    sha256: a segment torn by a crash after the import is refused by its hash when it is read
    (CaptureError naming the file), never read as data."""

    sync_segments = False


class FormattedRows:
    """Samples formatted once as segment CSV rows (SegmentWriter.write's format), any run of
    which SegmentWriter.write_rows writes.  ValueError as write() for bad arrays."""

    def __init__(self, t, accel, gyro, temp=None):
        columns = [np.asarray(a, dtype=np.float64)
                   for a in ((t, accel, gyro) if temp is None else (t, accel, gyro, temp))]
        n = len(columns[0]) if columns[0].ndim == 1 else -1
        expected = [(n,), (n, 3), (n, 3), (n,)][:len(columns)]
        if n < 0 or [c.shape for c in columns] != expected:
            raise ValueError("FormattedRows needs t (N,), accel (N, 3), gyro (N, 3) and temp (N,) or None")
        block = np.column_stack(columns)
        if not np.isfinite(block).all():
            raise ValueError("non-finite values cannot be recorded")
        if n > 1 and not (np.diff(columns[0]) > 0).all():
            raise ValueError("time must strictly increase")
        self.t, self.count, self.with_temp = columns[0], n, temp is not None
        row_format = _row_format(block)
        text = (row_format * n) % tuple(block.ravel().tolist())
        self.data = text.encode("ascii")
        self.offsets = np.zeros(n + 1, dtype=np.int64)       # byte offset of each row (ASCII)
        np.cumsum(np.fromiter(map(len, text.split("\n")[:n]), np.int64, n) + 1, out=self.offsets[1:])


class SegmentWriter:
    """Appends IMU samples to one segment's CSV; every write is on disk when it returns."""

    def __init__(self, capture_writer, entry, handle):
        self._writer = capture_writer
        self._entry = entry
        self._file = handle
        self._sha = hashlib.sha256()
        self._samples = 0
        self._last_t = -math.inf
        self._with_temp = None  # decided by the first write
        self.closed = False

    @property
    def name(self):
        return self._entry["name"]

    @property
    def samples(self):
        return self._samples

    def write(self, t, accel, gyro, temp=None):
        """Append N rows: t (N,), accel (N, 3), gyro (N, 3), temp (N,) or None.

        Whether the file has a temp column is decided by the first write. ValueError for
        arrays of the wrong shape, non-finite values or time that does not increase.
        """
        if self.closed:
            raise ValueError(f"segment {self.name!r} is closed")
        columns = [np.asarray(a, dtype=np.float64)
                   for a in ((t, accel, gyro) if temp is None else (t, accel, gyro, temp))]
        n = len(columns[0]) if columns[0].ndim == 1 else -1
        expected = [(n,), (n, 3), (n, 3), (n,)][:len(columns)]
        if n < 0 or [c.shape for c in columns] != expected:
            raise ValueError("write() needs t (N,), accel (N, 3), gyro (N, 3) and temp (N,) or None")
        if self._with_temp is not None and (temp is not None) != self._with_temp:
            raise ValueError(f"segment {self.name!r}: temp must be given in every write or in none")
        if n == 0:
            return
        block = np.column_stack(columns)
        t = columns[0]
        if not np.isfinite(block).all():
            raise ValueError(f"segment {self.name!r}: non-finite values cannot be recorded")
        if t[0] <= self._last_t or (n > 1 and not (np.diff(t) > 0).all()):
            raise ValueError(f"segment {self.name!r}: time must strictly increase")

        row_format = _row_format(block)
        self._append(((row_format * n) % tuple(block.ravel().tolist())).encode("ascii"), n, t[-1], temp is not None)

    def write_rows(self, rows: "FormattedRows", start: int, stop: int) -> None:
        """Append rows start..stop-1 of samples formatted once (FormattedRows): the same bytes as
        write() of those samples, without formatting them again (an import writes the session and
        then its parts: issue 27, item 2)."""
        if self.closed:
            raise ValueError(f"segment {self.name!r} is closed")
        if not 0 <= start <= stop <= rows.count:
            raise ValueError(f"rows {start}..{stop}: outside the {rows.count} formatted")
        if self._with_temp is not None and rows.with_temp != self._with_temp:
            raise ValueError(f"segment {self.name!r}: temp must be given in every write or in none")
        if stop == start:
            return
        if rows.t[start] <= self._last_t:
            raise ValueError(f"segment {self.name!r}: time must strictly increase")
        self._append(rows.data[rows.offsets[start]:rows.offsets[stop]], stop - start, rows.t[stop - 1],
                     rows.with_temp)

    def _append(self, data: bytes, n: int, last_t: float, with_temp: bool) -> None:
        if self._with_temp is None:
            self._with_temp = with_temp
            data = (",".join(REQUIRED_COLUMNS) + (",temp" if with_temp else "") + "\n").encode("ascii") + data
        self._file.write(data)
        self._file.flush()
        if self._writer.sync_segments:
            os.fsync(self._file.fileno())
        self._sha.update(data)
        self._samples += n
        self._last_t = last_t

    def close(self, status="complete", **meta):
        """Finish the segment: record status, samples, sha256 and `meta` (e.g. the encoder's
        angle_deg) in the manifest. A complete segment needs at least one sample (ValueError;
        the segment is then recorded as incomplete)."""
        if self.closed:
            raise ValueError(f"segment {self.name!r} is already closed")
        _refuse_owned_keys(meta)
        self._file.close()
        self.closed = True
        if status == "complete" and self._samples == 0:
            self._entry = self._writer._update_segment(self._entry, {"status": "incomplete", **meta})
            raise ValueError(f"segment {self.name!r}: no samples; recorded as incomplete")
        self._entry = self._writer._update_segment(
            self._entry, {"status": status, "samples": self._samples,
                          "sha256": self._sha.hexdigest(), **meta})

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        if not self.closed:
            self.close(status="complete" if exc_type is None else "incomplete")
        return False


class _PartDumper(_DUMPER):
    """The writer's dumper: no anchors and aliases (each part of the manifest is dumped on its
    own, so two parts would each define ``&id001``, a duplicate anchor that PyYAML refuses: an
    object that appears twice is written twice)."""

    def ignore_aliases(self, data):
        return True


def _yaml(value) -> str:
    """A manifest's part as the writer writes it: libyaml's emitter when PyYAML has it (four times
    faster), block style with lists of plain values in flow style ([x, y, z]), keys in order."""
    return yaml.dump(value, Dumper=_PartDumper, sort_keys=False, default_flow_style=None, allow_unicode=True)


def _check(manifest, directory):
    """Refuse (CaptureError) a manifest that a reader would refuse."""
    _parse_manifest(manifest, directory, Path(directory) / MANIFEST)


def _refuse_owned_keys(meta):
    owned = sorted(set(meta) & set(_WRITER_OWNED))
    if owned:
        raise TypeError(f"{', '.join(owned)} are recorded by the writer, not passed in")


def _ordered_entry(entry):
    known = [k for k in _SEGMENT_KEYS if k in entry]
    return {k: entry[k] for k in known + [k for k in entry if k not in _SEGMENT_KEYS]}


def _without_none(mapping):
    return {k: v for k, v in mapping.items() if v is not None}


def _plain(value):
    """`value` with numpy arrays and scalars (also nested in dicts, lists and tuples) turned into
    plain Python lists and numbers that yaml.safe_dump can write."""
    if isinstance(value, np.ndarray):
        return value.astype(np.float64).tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


def _aside_name(path, suffix=".incomplete"):
    candidate = path.with_name(path.name + suffix)
    number = 2
    while os.path.lexists(candidate):
        candidate = path.with_name(f"{path.name}{suffix}{number}")
        number += 1
    return candidate


_TEMP_NAME = re.compile(r"\..+\.[A-Za-z0-9_]{6,}" + re.escape(TEMP_SUFFIX))


def remove_stray_temporaries(directory) -> list:
    """Remove the temporary files (``.NAME.RANDOM.tmp``) that writers killed mid-write left in
    ``directory`` (symbolic links of that name are removed, never followed); returns their names."""
    removed = []
    try:
        names = os.listdir(directory)
    except OSError:
        return removed
    for name in names:
        if _TEMP_NAME.fullmatch(name):
            try:
                os.unlink(Path(directory) / name)
                removed.append(name)
            except (IsADirectoryError, PermissionError, FileNotFoundError):
                pass
    return removed


def _atomic_write(path, data):
    """Replace `path` with `data` so that a reader sees either the old or the new file, even
    after a crash: write a temporary file, flush and fsync it, rename it over, fsync the folder.
    The temporary file has a random name in the same folder and is created with O_EXCL and
    O_NOFOLLOW (tempfile.mkstemp), never through a link; it is removed on every path out."""
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=TEMP_SUFFIX)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    dir_fd = os.open(path.parent, os.O_RDONLY)
    try:
        os.fsync(dir_fd)
    finally:
        os.close(dir_fd)
