"""station probe and station sim serve, end to end over pseudo-terminals.

The twin streams at 100 Hz at --speed 50: 60 s of device time take about 1.2 s.
"""
from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from drivers.base import ImuSettings
from server_guard import guard
from drivers.registry import open_imu, open_table
from drivers.samples import ImuSamples
from sim_devices.truth import default_truth
from sim_devices.twins.faults import Faults, ImuFaults
from sim_devices.twins.serve import BenchOptions, BenchServer
from station.cli import main


@pytest.mark.parametrize("protocol", ["vectornav", "csv"])
def test_probe_loses_no_frame_over_60_s_of_device_time_at_speed_50(protocol, capsys):
    with BenchServer(default_truth(2), BenchOptions(speed=50, imu_protocol=protocol)) as server:
        t0 = time.monotonic()
        assert main(["probe", "--port", server.imu_path, "--imu-protocol", protocol,
                     "--seconds", "60", "--json"]) == 0
        wall = time.monotonic() - t0
    r = json.loads(capsys.readouterr().out)
    assert r["frames"] == 6000
    assert r["gaps"] == 0 and r["missing_frames"] == 0
    assert r["checksum_errors"] == 0
    assert abs(r["rate_hz"] - 100.0) < 1e-6
    assert abs(r["device_seconds"] - 60.0) < 1e-6
    assert abs(r["mean_accel_norm_mps2"] - 9.806) < 0.05
    assert wall < 10.0                         # device time, not wall time (about 1.3 s)


@pytest.mark.parametrize("protocol", ["vectornav", "csv"])
def test_with_garbage_and_corruption_every_intact_frame_is_decoded(protocol):
    faults = Faults(imu=ImuFaults(garbage_every_s=0.25, garbage_bytes=48, corrupt_probability=0.02))
    opts = BenchOptions(speed=50, imu_protocol=protocol, faults=faults, record=True)
    with BenchServer(default_truth(2), opts) as server:
        with open_imu(server.imu_path, protocol) as imu:
            s = imu.read(3000)
            counters = imu.counters
            s = ImuSamples.concat([s, imu.read(counters.frames - 3000)])   # all decoded: no I/O
            assert counters.frames == len(s)
        sent = np.concatenate(server.faulter.intact_times)
        corrupted, garbage = server.faulter.frames_corrupted, server.faulter.garbage_blocks
    window = sent[(sent >= s.t_s[0] - 1e-9) & (sent <= s.t_s[-1] + 1e-9)]
    np.testing.assert_allclose(s.t_s, window, rtol=0, atol=1e-9)    # all of them, nothing else
    assert len(window) == len(s) >= 3000
    # the frames that were not intact are the gaps
    assert counters.missing_frames == round((s.t_s[-1] - s.t_s[0]) * 100) + 1 - len(s)
    assert counters.checksum_errors > 0 and counters.resyncs > 0
    assert counters.checksum_errors <= corrupted + garbage
    assert garbage >= 0.9 * 4 * 30              # 30 s of device time read, 4 blocks a second


def test_probe_table_json(capsys):
    with BenchServer(default_truth(2), BenchOptions(speed=50, axes=2)) as server:
        with open_table(server.table_path) as table:
            table.close_interlocks()
            table.move_to([30.0, 200.0])
        assert main(["probe", "--table-port", server.table_path, "--json"]) == 0
    r = json.loads(capsys.readouterr().out)
    assert r["identity"].startswith("Acutronic,")
    assert r["axes"] == 2
    np.testing.assert_allclose(r["positions_deg"], [30.0, 200.0], atol=0.002)
    assert r["interlock_closed"] == [True, True] and r["fault"] == [False, False]


def test_probe_both_as_text(capsys):
    with BenchServer(default_truth(2), BenchOptions(speed=50, axes=1, table_protocol="aerosmith")) as server:
        assert main(["probe", "--table-port", server.table_path, "--table-protocol", "aerosmith",
                     "--port", server.imu_path, "--seconds", "2"]) == 0
    out = capsys.readouterr().out
    assert "axis 1: 0.000000 deg" in out and "interlock closed" in out
    assert "200 frames over 2.000 s of device time" in out and "gaps 0" in out


def test_probe_user_errors(capsys):
    assert main(["probe"]) == 2
    assert main(["probe", "--port", "/dev/nope-no-such-port", "--seconds", "1"]) == 2
    assert main(["probe", "--port", "x", "--imu-protocol", "nope"]) == 2
    with pytest.raises(SystemExit) as refused:              # by its type, before anything runs
        main(["probe", "--port", "x", "--seconds", "-1"])
    assert refused.value.code == 2
    err = capsys.readouterr().err
    assert "give --port" in err and "cannot open /dev/nope-no-such-port" in err
    assert "unknown IMU protocol 'nope'" in err and "argument --seconds: must be a positive number" in err


def _serve(*args):
    """``station sim serve`` (it serves until stopped), guarded: stopped if pytest is killed first
    (tests/server_guard.py; the guard ends with it otherwise)."""
    proc = subprocess.Popen([sys.executable, "-m", "station.cli", "sim", "serve", *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    guarded = guard(pids=[proc.pid], sig=signal.SIGTERM, grace_s=3.0)
    lines = [proc.stdout.readline(), proc.stdout.readline()]
    return proc, lines, guarded


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_sim_serve_prints_two_paths_serves_and_stops_cleanly(sig):
    proc, lines, guarded = _serve("--speed", "50", "--axes", "2", "--seed", "4")
    try:
        assert lines[0].startswith("table: /dev/") and lines[1].startswith("imu: /dev/")
        table_path, imu_path = lines[0].split(": ", 1)[1].strip(), lines[1].split(": ", 1)[1].strip()
        with open_table(table_path) as table:
            assert table.n_axes == 2
        with open_imu(imu_path, "vectornav", ImuSettings()) as imu:
            assert imu.identity.endswith("firmware 2.1.0.0") and "serial 0100000004" in imu.identity
            assert len(imu.read(100)) == 100
        proc.send_signal(sig)
        assert proc.wait(10) == 0
        assert proc.stdout.read() == ""            # exactly the two lines on stdout
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        guarded.release()


def test_sim_serve_user_errors(tmp_path):
    bad = tmp_path / "faults.yaml"
    bad.write_text("imu:\n  drop: {probability: 2}\n")
    for args, message in ((["--faults", str(bad)], "field 'imu.drop.probability': must be <= 1.0"),
                          (["--table-protocol", "aerosmith", "--axes", "3"], "single-axis"),
                          (["--speed", "0"], "argument --speed: must be a positive number")):
        r = subprocess.run([sys.executable, "-m", "station.cli", "sim", "serve", *args],
                           capture_output=True, text=True, timeout=30)
        assert r.returncode == 2 and message in r.stderr and r.stdout == ""
        assert len(r.stderr.strip().splitlines()) == 1


# ------------------------------------------------------------------------------ baud rates

@pytest.mark.parametrize("protocol", ["vectornav", "xsens", "csv"])
def test_a_probe_at_the_wrong_baud_rate_says_so(protocol, capsys):
    """Bytes arrive but no valid frame or reply: the message counts them and names the likely
    cause, instead of only "no reply within 2 s"."""
    with BenchServer(default_truth(2), BenchOptions(speed=50, imu_protocol=protocol)) as server:
        assert main(["probe", "--port", server.imu_path, "--imu-protocol", protocol, "--baud", "9600",
                     "--seconds", "1", "--timeout-s", "1"]) == 2
    err = capsys.readouterr().err
    assert f"imu {server.imu_path} ({protocol}): " in err
    assert " bytes arrived at 9600 baud but no valid frame or reply: this looks like a baud-rate " \
           "mismatch" in err
    assert int(err.split(" bytes arrived")[0].rsplit(" ", 1)[1]) > 100
    assert f"--imu-protocol {protocol} --scan-baud" in err
    assert len(err.strip().splitlines()) == 1


def test_no_bytes_at_all_is_not_called_a_baud_mismatch(capsys):
    with BenchServer(default_truth(2), BenchOptions(speed=50, faults=Faults(imu=ImuFaults(stall_at_s=0.0)),
                                                   imu_protocol="csv")) as server:
        assert main(["probe", "--port", server.imu_path, "--imu-protocol", "csv", "--seconds", "1",
                     "--timeout-s", "0.5"]) == 2
    err = capsys.readouterr().err
    assert "no csv line within 0.5 s" in err and "baud" in err and "mismatch" not in err


def _scan_words(out: str) -> dict:
    """The scan's result as --json gives it (baud, and per rate: baud, bytes, valid), read from
    the words of ``station probe --scan-baud`` (a line per rate, the device's marked)."""
    rates, baud = [], None
    for m in re.finditer(r"^ +(\d+) baud: +(\d+) bytes, (?:(\d+) valid frames or replies|no valid frame or reply)"
                         r"(  <- the device)?$", out, re.M):
        rates.append({"baud": int(m[1]), "bytes": int(m[2]), "valid": int(m[3] or 0)})
        if m[4]:
            baud = int(m[1])
    return {"baud": baud, "rates": rates}


@pytest.mark.parametrize("protocol,device_baud", [("vectornav", 115200), ("vectornav", 57600),
                                                  ("xsens", 115200), ("csv", 115200)])
def test_scan_baud_finds_the_rate_that_gives_valid_frames(protocol, device_baud, capsys):
    with BenchServer(default_truth(2), BenchOptions(speed=50, imu_protocol=protocol)) as server:
        if device_baud != 115200:
            server.imu_frontend.baudrate = device_baud          # as if register 05 had been saved
        # each rate listened to for 0.25 s (--timeout-s; 0.5 s by default): a twin at --speed 50
        # sends 3 valid frames or replies within a few ms of wall time at the right rate
        # the words once (at 57600), the JSON for the other rates: one scan each, the same checks
        # below on the rates read from either (a scan waits out its window at each wrong rate:
        # ~2.4 s of wall here, which a second scan of the same twin only repeated)
        if device_baud != 115200:
            assert main(["probe", "--port", server.imu_path, "--imu-protocol", protocol, "--scan-baud",
                         "--timeout-s", "0.25"]) == 0
            out = capsys.readouterr().out
            assert f"the device answers at {device_baud} baud: use --baud {device_baud}" in out
            r = _scan_words(out)
        else:
            assert main(["probe", "--port", server.imu_path, "--imu-protocol", protocol, "--scan-baud",
                         "--timeout-s", "0.25", "--json"]) == 0
            r = json.loads(capsys.readouterr().out)
        # and the rate it found works
        if protocol == "vectornav":
            # (a reply waited for up to 5 s: in a suite on 2 busy cores the twin's thread once did
            # not answer within the default 2 s)
            assert main(["probe", "--port", server.imu_path, "--baud", str(device_baud), "--seconds", "1",
                         "--timeout-s", "5", "--json"]) == 0
            assert json.loads(capsys.readouterr().out)["frames"] == 100
    assert r["baud"] == device_baud
    rates = {x["baud"]: x for x in r["rates"]}
    from drivers.probe import SCAN_BAUDS
    assert list(rates) == list(SCAN_BAUDS[protocol])
    assert rates[device_baud]["valid"] >= 3
    assert all(x["valid"] == 0 for b, x in rates.items() if b != device_baud)
    # garbage, not silence, at the wrong rates (the twin's UART model); on a loaded machine (a
    # load of 30 on 2 cores) its writer thread was starved for a whole window at two of eight
    # rates in 2 of 3 scans (0 or 1 bytes there)
    assert sum(x["bytes"] > 0 for b, x in rates.items() if b != device_baud) > (len(rates) - 1) // 2


def test_scan_baud_says_when_nothing_answers(capsys, tmp_path):
    import pty as _pty
    master, slave = _pty.openpty()                # a silent line: nothing on it
    try:
        # a silent line gives 0 bytes in any window: each rate's window (a ceiling waited out
        # here) as short as the line's 0.05 s settle
        assert main(["probe", "--port", os.ttyname(slave), "--scan-baud", "--timeout-s", "0.05"]) == 2
    finally:
        os.close(master)
        os.close(slave)
    cap = capsys.readouterr()
    assert "0 bytes, no valid frame or reply" in cap.out
    assert "no baud rate gave a valid frame or reply" in cap.err
