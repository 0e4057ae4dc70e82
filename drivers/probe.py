"""``station probe``: read an IMU or a table for a moment and report what came.

No simulation here: this talks to whatever is on the port (hardware or a twin).
"""
from __future__ import annotations

import time

import numpy as np

from .base import ImuSettings, TableSettings
from .registry import open_imu, open_table

#: samples read per block (stats are accumulated block by block)
BLOCK_SECONDS = 1.0


def probe_imu(url: str, protocol: str, seconds: float, settings: ImuSettings) -> dict:
    """Stream ``seconds`` of DEVICE time (round(seconds x rate) samples) and summarise."""
    wall0 = time.monotonic()
    with open_imu(url, protocol, settings) as imu:
        rate = imu.configure()
        imu.start()
        total = int(round(seconds * rate))
        block = max(1, int(round(BLOCK_SECONDS * rate)))
        n = 0
        t_first = t_last = None
        f_sum = w_sum = temp_sum = 0.0
        temp_n = 0
        while n < total:
            s = imu.read(min(block, total - n))
            if t_first is None and len(s):
                t_first = float(s.t_s[0])
            t_last = float(s.t_s[-1]) if len(s) else t_last
            f_sum += float(np.linalg.norm(s.accel_mps2, axis=1).sum())
            w_sum += float(np.linalg.norm(s.gyro_dps, axis=1).sum())
            finite = np.isfinite(s.temp_c)
            temp_sum += float(s.temp_c[finite].sum())
            temp_n += int(finite.sum())
            n += len(s)
        imu.stop()
        c = imu.counters
        span = (t_last - t_first) if (n > 1 and t_last is not None) else 0.0
        return {
            "port": url,
            "protocol": protocol,
            "identity": imu.identity,
            "frames": n,
            "device_seconds": span + (1.0 / rate if n else 0.0),
            "rate_hz": (n - 1) / span if span > 0 else None,
            "nominal_rate_hz": rate,
            "mean_accel_norm_mps2": f_sum / n if n else None,
            "mean_gyro_norm_dps": w_sum / n if n else None,
            "mean_temp_c": temp_sum / temp_n if temp_n else None,
            "checksum_errors": c.checksum_errors,
            "resyncs": c.resyncs,
            "bytes_discarded": c.bytes_discarded,
            "gaps": c.gaps,
            "missing_frames": c.missing_frames,
            "wall_seconds": time.monotonic() - wall0,
        }


def probe_table(url: str, protocol: str, settings: TableSettings) -> dict:
    """Identify the table and read its axes.  Nothing is moved, except that an axis found
    moving when the port is opened (left turning by an earlier run) is braked to rest and held:
    ``found_moving`` says which, at what rate, and where it now rests."""
    with open_table(url, protocol, settings) as table:
        st = table.status()
        return {
            "found_moving": [{"axis": m.axis, "rate_dps": m.rate_dps, "rest_deg": m.rest_deg}
                             for m in table.found_moving],
            "found_moving_note": table.describe_leftover(),
            "port": url,
            "protocol": protocol,
            "identity": table.identity,
            "axes": table.n_axes,
            "positions_deg": [float(x) for x in table.read_positions_deg()],
            "rates_dps": [float(x) for x in table.read_rates_dps()],
            "interlock_closed": list(st.interlock_closed),
            "fault": list(st.fault),
            "status": st.raw,
        }
