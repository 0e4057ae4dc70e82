"""``station probe``: read an IMU or a table for a moment and report what came.

No simulation here: this talks to whatever is on the port (hardware or a twin).

Line diagnostics (IMU): when bytes arrive but no valid frame or reply does, the error says how
many bytes came at which baud rate and that this looks like a baud-rate mismatch;
:func:`scan_imu_baud` tries the protocol's baud rates and reports which gives valid frames.
"""
from __future__ import annotations

import dataclasses
import logging
import time

import numpy as np

from .base import ImuSettings, TableSettings
from .errors import DeviceError, DeviceTimeout
from .protocols import vectornav as V
from .protocols import xbus as X
from .protocols.csvlines import MAX_LINE_BYTES, CsvDecoder
from .protocols.vectornav_binary import VectorNavDecoder
from .registry import imu_driver, open_table
from .transport import Port

#: samples read per block (stats are accumulated block by block)
BLOCK_SECONDS = 1.0
#: baud rates tried by --scan-baud: VectorNav's register 05 values (VN-100 UM001 / VN-200 UM004
#: "Serial Baud Rate Register"), the Xsens ones of mtdef.py ``Baudrates``, for csv the same
#: common rates as VectorNav's
SCAN_BAUDS = {"vectornav": V.BAUD_RATES,
              "xsens": tuple(sorted(set(X.BAUD_IDS.values()))),
              "csv": V.BAUD_RATES}
#: longest time a scanned rate is listened to, s
SCAN_WINDOW_S = 0.5
#: after switching to a rate, bytes that were on their way are dropped for this long, s
SCAN_SETTLE_S = 0.05
#: the longest message of each protocol, bytes: a VectorNav ASCII message (a body of at most 200
#: characters, ``find_message``; station's binary frames are shorter), an Xsens message with
#: MAX_DATA bytes of data (extended length: 7 bytes around it), a csv line (MAX_LINE_BYTES)
LONGEST_MESSAGE = {"vectornav": 210, "xsens": X.MAX_DATA + 7, "csv": MAX_LINE_BYTES + 2}
#: a rate is given up before its window ends once this many longest messages' worth of bytes came
#: without one valid message: at the device's own rate those bytes hold a message cut at the start
#: (the first boundary comes within one longest message) and two whole ones after it, which count
#: as valid (_valid_messages: one VectorNav message, two Xsens messages or csv lines)
SCAN_GIVE_UP_MESSAGES = 3
#: ... but a VectorNav rate not before this long after the query (s): of binary frames only
#: station's own layout is counted, so a device streaming another layout at its own rate shows
#: as valid only its reply to the query, which comes within a few ms (at 115200 baud the 840
#: bytes of the rule above take 73 ms; at 921600, 9 ms)
SCAN_REPLY_S = {"vectornav": 0.1}


def _mismatch_note(imu, settings: ImuSettings) -> str | None:
    """What to say when bytes came but no valid frame or reply: None if nothing came, or
    frames did."""
    n = imu.bytes_received
    if n == 0 or imu.counters.frames:
        return None
    return (f"{n} bytes arrived at {settings.serial.baudrate} baud but no valid frame or reply: "
            f"this looks like a baud-rate mismatch (the device sends at another rate); find its "
            f"rate with station probe --port {imu.url} --imu-protocol {imu.protocol} --scan-baud, "
            f"then give it with --baud")


def probe_imu(url: str, protocol: str, seconds: float, settings: ImuSettings) -> dict:
    """Stream ``seconds`` of DEVICE time (round(seconds x rate) samples) and summarise."""
    imu = imu_driver(protocol)(url, settings)
    try:
        return _probe_imu(imu, url, protocol, seconds)
    except DeviceTimeout as e:
        note = _mismatch_note(imu, settings)
        if note is None:
            raise
        raise DeviceTimeout(e.device, f"{e.message}; {note}") from None
    finally:
        imu.close()


def _probe_imu(imu, url: str, protocol: str, seconds: float) -> dict:
    wall0 = time.monotonic()
    imu.connect()
    with imu:
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


def _valid_messages(protocol: str, data: bytes) -> int:
    """How many valid frames, lines or replies of ``protocol`` are in ``data``."""
    if protocol == "vectornav":
        n, pos = 0, 0
        while (found := V.find_message(data, pos)) is not None:
            n, pos = n + 1, found[1]
        d = VectorNavDecoder(V.STATION_LAYOUT)       # station's frames, if it left them on
        d.feed(data)
        return n + d.frames
    if protocol == "xsens":
        messages = X.XbusParser().feed(data)
        # garbage holds a valid-looking message now and then (1 in 256 FA FF pairs): one
        # message counts only if it answers the query
        return len(messages) if len(messages) >= 2 or any(m == X.MID.DeviceID for m, _ in messages) else 0
    d = CsvDecoder()
    d.feed(data)
    return d.frames if d.frames >= 2 else 0


def _scan_query(protocol: str) -> bytes:
    """A harmless query the device answers in any state (nothing for csv)."""
    if protocol == "vectornav":
        return V.format_message(f"VNRRG,{V.REG_MODEL:02d}")
    if protocol == "xsens":
        return X.message(X.MID.ReqDID)
    return b""


def scan_imu_baud(url: str, protocol: str, settings: ImuSettings,
                  window_s: float = SCAN_WINDOW_S) -> dict:
    """Listen at each of the protocol's baud rates (after a harmless query: VectorNav
    ``$VNRRG,01``, Xsens ReqDID) and count the valid frames, lines or replies; the rate with
    the most is the device's.  Nothing is written to the device's settings.

    A rate is listened to for ``window_s`` at most: less once it has given 3 valid messages
    (the device's rate), or SCAN_GIVE_UP_MESSAGES longest messages' worth of bytes without a
    valid one (garbage: not the device's rate)."""
    if protocol not in SCAN_BAUDS:
        raise DeviceError(f"imu {url} ({protocol})", f"--scan-baud knows the baud rates of "
                                                     f"{', '.join(SCAN_BAUDS)} only")
    name = f"imu {url} ({protocol})"
    log = logging.getLogger(f"drivers.{protocol}")
    rates = []
    for baud in SCAN_BAUDS[protocol]:
        line = dataclasses.replace(settings.serial, baudrate=baud)
        port = Port(url, line, name, log)
        try:
            port.discard_input()            # what came at the previous rate, and, a moment
            time.sleep(SCAN_SETTLE_S)       #   later, what was still on its way
            port.read_waiting()
            port.discard_input()
            query = _scan_query(protocol)
            if query:
                port.write(query)
            start = time.monotonic()
            data, end = bytearray(), start + window_s
            give_up = SCAN_GIVE_UP_MESSAGES * LONGEST_MESSAGE[protocol]
            reply_by = start + SCAN_REPLY_S.get(protocol, 0.0)
            while time.monotonic() < end:
                data += port.read_some()
                if len(data) > 256:
                    valid = _valid_messages(protocol, bytes(data))
                    if valid >= 3 or (valid == 0 and len(data) >= give_up and time.monotonic() >= reply_by):
                        break
        finally:
            port.close()
        rates.append({"baud": baud, "bytes": len(data), "valid": _valid_messages(protocol, bytes(data))})
    best = max(rates, key=lambda r: r["valid"])
    return {"port": url, "protocol": protocol, "window_s": window_s, "rates": rates,
            "baud": best["baud"] if best["valid"] else None}


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
