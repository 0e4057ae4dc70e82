"""Child process of test_capture_kill.py: records a capture until it is killed.

Usage: python _kill_writer.py DIRECTORY. Writes two complete segments ("complete NAME" on stdout
after each), then writes the third in blocks of BLOCK rows, printing "block K" after each block
is flushed to disk, until killed (it gives up after MAX_BLOCKS so that it never runs forever).
"""

import sys
import time

import numpy as np

from station.io.capture import CaptureWriter, ImuInfo, Site

RATE = 100.0
BLOCK = 10
MAX_BLOCKS = 2000


def samples(first, n):
    """Rows first..first+n-1: every value is a known function of the row index k."""
    k = np.arange(first, first + n, dtype=np.float64)
    t = k / RATE
    accel = np.column_stack([0.001 * k, -0.002 * k, 9.8 + 0 * k])
    gyro = np.column_stack([0 * k, 0.5 * k, -10.0 + 0 * k])
    return t, accel, gyro


def main(directory):
    writer = CaptureWriter(directory, ImuInfo(RATE, "m/s^2", "deg/s"), Site(9.80665))
    for name, kind, meta in (("pos01", "static", {"up_body": [0, 0, 1]}),
                             ("rot1p", "rotation", {"axis_body": [0, 0, 1], "rate_dps": 10.0})):
        with writer.begin_segment(name, kind, **meta) as segment:
            segment.write(*samples(0, 200))
        print(f"complete {name}", flush=True)
    segment = writer.begin_segment("rot1m", "rotation", axis_body=[0, 0, 1], rate_dps=-10.0)
    for block in range(MAX_BLOCKS):
        segment.write(*samples(block * BLOCK, BLOCK))
        print(f"block {block}", flush=True)
        time.sleep(0.002)


if __name__ == "__main__":
    main(sys.argv[1])
