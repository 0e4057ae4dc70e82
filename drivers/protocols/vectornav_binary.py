"""VectorNav binary output frames: encoder (for the twin and tests) and a fast decoder.

The decoder looks for the expected frame header (sync byte, group byte, field masks: known
once the driver has configured the output), then checks whole runs of back-to-back frames at
once with numpy (header bytes and CRC of every frame; short runs frame by frame with
``binascii.crc_hqx``), and unpacks the valid ones with one ``np.frombuffer`` of a structured
type.  After a bad frame it searches for the next header
from the byte after that frame's sync byte, so a frame that was cut short does not take the
next, intact frame with it.
"""
from __future__ import annotations

from binascii import crc_hqx

import numpy as np

from ..samples import ImuSamples
from .crc import crc16_rows
from .vectornav import BinaryLayout

MAX_WINDOW_FRAMES = 4096
VECTORISE_FROM = 512         # frames: fewer are checked one by one (binascii.crc_hqx)


def encode_frames(layout: BinaryLayout, t_ns, accel_mps2, gyro_rad_s, temp_c=None) -> bytes:
    """Frames for N samples: time since startup (ns), m/s², rad/s, °C (if the layout has Temp)."""
    t_ns = np.asarray(t_ns, dtype=np.uint64).reshape(-1)
    n = t_ns.shape[0]
    rec = np.zeros(n, dtype=layout.dtype)
    raw = rec.view(np.uint8).reshape(n, layout.frame_length)
    raw[:, :len(layout.header)] = np.frombuffer(layout.header, dtype=np.uint8)
    rec["TimeStartup"] = t_ns
    rec["UncompAccel"] = np.asarray(accel_mps2, dtype=np.float32).reshape(n, 3)
    rec["UncompGyro"] = np.asarray(gyro_rad_s, dtype=np.float32).reshape(n, 3)
    if layout.has("Temp"):
        rec["Temp"] = np.asarray(temp_c, dtype=np.float32).reshape(n)
    crc = crc16_rows(raw[:, 1:layout.payload_end])
    rec["crc"] = crc
    return rec.tobytes()


class VectorNavDecoder:
    """Incremental decoder of one binary output layout.  :meth:`feed` never raises."""

    def __init__(self, layout: BinaryLayout):
        if not (layout.has("TimeStartup") and layout.has("UncompAccel") and layout.has("UncompGyro")):
            raise ValueError("the layout must carry TimeStartup, UncompAccel and UncompGyro")
        self.layout = layout
        self.header = np.frombuffer(layout.header, dtype=np.uint8)
        self._header_bytes = layout.header
        self.length = layout.frame_length
        self.dtype = layout.dtype
        self.has_temp = layout.has("Temp")
        self._buf = bytearray()
        self._window = MAX_WINDOW_FRAMES
        self.frames = 0
        self.checksum_errors = 0
        self.resyncs = 0
        self.bytes_discarded = 0
        self._run_open = False       # bytes being skipped continue a run already counted (or
                                     #   belong to a frame that failed its CRC): no new resync

    def feed(self, data: bytes) -> ImuSamples:
        """Decode what ``data`` completes; keep an incomplete frame for the next call."""
        buf = bytes(self._buf) + data if self._buf else bytes(data)
        H, h, L = self._header_bytes, len(self._header_bytes), self.length
        pos, good = 0, []
        while True:
            i = buf.find(H, pos)
            if i < 0:
                keep = max(pos, len(buf) - (h - 1))
                # a partial header can only be a suffix of the buffer starting with the sync byte
                j = buf.find(H[:1], keep)
                keep = j if j >= 0 else len(buf)
                self._skip(keep - pos)
                pos = keep
                break
            if i > pos:
                self._skip(i - pos)
            self._run_open = False
            k = min((len(buf) - i) // L, self._window)
            if k == 0:
                pos = i
                break
            n = self._valid_run(buf, i, k)
            if n:
                good.append(buf[i:i + n * L])
                self._window = min(MAX_WINDOW_FRAMES, self._window * 4)
            if n == k:
                pos = i + k * L
                continue
            # frame n is bad: a checksum error if it has the header, else not a frame start
            bad = i + n * L
            self._window = 8
            if buf[bad:bad + h] == H:
                self.checksum_errors += 1
                self._run_open = True       # the rest of this frame: discarded, no resync
                self.bytes_discarded += 1
                pos = bad + 1
            else:
                pos = bad           # not a frame start: the next search skips (a resync)
        self._buf = bytearray(buf[pos:])
        if not good:
            return ImuSamples.empty()
        rec = np.frombuffer(b"".join(good), dtype=self.dtype)
        self.frames += rec.shape[0]
        temp = (rec["Temp"].astype(np.float64) if self.has_temp
                else np.full(rec.shape[0], np.nan))
        return ImuSamples(t_s=rec["TimeStartup"].astype(np.float64) * 1e-9,
                          accel_mps2=rec["UncompAccel"].astype(np.float64),
                          gyro_dps=np.degrees(rec["UncompGyro"].astype(np.float64)),
                          temp_c=temp)

    def _valid_run(self, buf: bytes, i: int, k: int) -> int:
        """How many of the k back-to-back frames from ``i`` are valid before the first bad
        one: one numpy pass over long runs, frame by frame over short ones."""
        L, H, h = self.length, self._header_bytes, len(self._header_bytes)
        if k < VECTORISE_FROM:
            view = memoryview(buf)
            for j in range(k):
                s = i + j * L
                if buf[s:s + h] != H or crc_hqx(view[s + 1:s + L], 0):
                    return j
            return k
        rows = np.frombuffer(buf, dtype=np.uint8, count=k * L, offset=i).reshape(k, L)
        ok = (rows[:, :h] == self.header).all(axis=1)
        ok &= crc16_rows(rows[:, 1:]) == 0
        return k if ok.all() else int(np.argmin(ok))

    def _skip(self, n: int) -> None:
        if n > 0:
            self.bytes_discarded += n
            if not self._run_open:
                self.resyncs += 1
            self._run_open = True
