"""IMU frame decoding throughput, frames per second on one core, for each IMU protocol.

The stream is cut into serial-sized reads (--chunk bytes) and fed to the protocol's decoder,
as the driver does; a second run has 1 % of the frames corrupted and a garbage block every
100 frames.  Goal: >= 100,000 frames/s.

Usage: python benchmarks/decode_throughput.py [--frames 200000] [--chunk 4096] [--repeat 3]
"""
import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")                 # one core

import argparse                                       # noqa: E402
import time                                           # noqa: E402

import numpy as np                                    # noqa: E402

from drivers.protocols.csvlines import CsvDecoder, CsvFormat, encode_lines    # noqa: E402
from drivers.protocols.vectornav import STATION_LAYOUT                        # noqa: E402
from drivers.protocols.vectornav_binary import VectorNavDecoder, encode_frames  # noqa: E402


def streams(n, rng):
    t = np.arange(n) * 0.01
    a, g, temp = rng.normal(size=(n, 3)), rng.normal(size=(n, 3)), 25 + rng.normal(size=n)
    vn = encode_frames(STATION_LAYOUT, (t * 1e9).astype(np.uint64), a, np.radians(g), temp)
    L = STATION_LAYOUT.frame_length
    vn_frames = [vn[i * L:(i + 1) * L] for i in range(n)]
    csv_lines = encode_lines(CsvFormat(), t, a, g, temp).splitlines(keepends=True)
    return {"vectornav": (vn_frames, lambda: VectorNavDecoder(STATION_LAYOUT), False),
            "csv": (csv_lines, CsvDecoder, True)}


def damage(frames, rng, line_protocol):
    out = [b"\n"] if line_protocol else []
    for i, f in enumerate(frames):
        if i % 100 == 50:
            junk = rng.integers(0, 256, 40, dtype=np.uint8).tobytes()
            out.append(junk.replace(b"\n", b"?") + b"\n" if line_protocol else junk)
        if rng.random() < 0.01:
            b = bytearray(f)
            b[int(rng.integers(0, len(b) - 1))] = ord("x") if line_protocol else b[0] ^ 0x55
            f = bytes(b)
        out.append(f)
    return b"".join(out)


def run(make_decoder, data, chunk, repeat):
    best, frames = float("inf"), 0
    for _ in range(repeat):
        d = make_decoder()
        t0 = time.perf_counter()
        for i in range(0, len(data), chunk):
            d.feed(data[i:i + chunk])
        best = min(best, time.perf_counter() - t0)
        frames = d.frames
    return frames, best


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--frames", type=int, default=200_000)
    ap.add_argument("--chunk", type=int, default=4096, help="bytes per read (default 4096)")
    ap.add_argument("--repeat", type=int, default=3)
    a = ap.parse_args()
    rng = np.random.default_rng(1)
    print(f"{a.frames} frames, reads of {a.chunk} bytes, best of {a.repeat}, one core")
    print(f"{'protocol':10s} {'stream':22s} {'frames':>9s} {'seconds':>8s} {'frames/s':>12s}")
    for name, (frames, make, line) in streams(a.frames, rng).items():
        clean = (b"\n" if line else b"") + b"".join(frames)
        for label, data in (("clean", clean), ("1% corrupt + garbage", damage(frames, rng, line))):
            n, dt = run(make, data, a.chunk, a.repeat)
            print(f"{name:10s} {label:22s} {n:9d} {dt:8.3f} {n / dt:12,.0f}")


if __name__ == "__main__":
    main()
