"""``station sim serve`` and ``station probe``: the device commands of the command line.

Only ``sim serve`` imports ``sim_devices`` (the user asked for simulation).
"""
from __future__ import annotations

import json
import signal
import sys
import threading

from station.cli import argtypes
from station.core.errors import UserError

MAX_IMUS = 32            # IMU twins one `sim serve` loop serves


def add_parsers(sub) -> None:
    """Add ``sim`` (with ``serve``) and ``probe`` to the station sub-command parsers."""
    sim = sub.add_parser("sim", help="simulated devices")
    sim_sub = sim.add_subparsers(dest="sim_command", required=True, metavar="SIM_COMMAND",
                                 parser_class=type(sim))
    serve = sim_sub.add_parser("serve", help="serve a table twin and IMU twins on pseudo-terminals")
    serve.add_argument("--speed", type=argtypes.positive, default=1.0,
                       help="device time per wall time (default 1; 50 = fifty times faster)")
    serve.add_argument("--sim-truth", metavar="FILE", action="append",
                       help="true sensor errors and bench (YAML); with --imus N once for all or N times, "
                            "one per IMU")
    serve.add_argument("--seed", type=argtypes.seed, default=1,
                       help="seed of the default truth and the noise (IMU k: seed + k - 1)")
    serve.add_argument("--imus", type=argtypes.whole(1), default=1, metavar="N",
                       help="N independent IMU twins on the one table, each on its own pseudo-terminal "
                            "(own truth, noise seed and serial number; default 1)")
    serve.add_argument("--faults", metavar="FILE", action="append",
                       help="faults to inject (YAML, docs/twins.md): once (the table and the first IMU) or, "
                            "with --imus N, N times (file k: IMU k; the table's in the first)")
    serve.add_argument("--axes", type=int, choices=(1, 2, 3),
                       help="table axes (default 3 for acutrol, 1 for aerosmith)")
    serve.add_argument("--table-protocol", choices=("acutrol", "aerosmith"), default="acutrol")
    serve.add_argument("--table-framing", choices=("tcp", "gpib"), default="tcp",
                       help="acutrol replies: tcp (error code and length first, as on TCP port 9878 "
                            "and RS-232; default) or gpib (queries only, one line)")
    serve.add_argument("--table-tcp-port", type=int, metavar="PORT",
                       help="serve the table on TCP 127.0.0.1:PORT instead of a pseudo-terminal "
                            "(0: any free port; an Acutrol listens on 9878)")
    serve.add_argument("--imu-protocol", choices=("vectornav", "csv", "xsens"), default="vectornav")
    serve.add_argument("--csv-units", metavar="SPEC", default="",
                       help="units of the csv twin, e.g. t=ms,accel=g,gyro=rad/s "
                            "(default t=s,accel=m/s^2,gyro=deg/s)")
    serve.add_argument("--chamber", action="store_true",
                       help="a temperature chamber around the table, its panel on a pseudo-terminal (printed as "
                            "'chamber: PATH'): set it with `echo 60 > PATH` when the run asks (docs/twins.md)")
    serve.add_argument("--chamber-ramp-c-per-min", type=argtypes.positive, default=2.0, metavar="R",
                       help="how fast the chamber's air follows a new setpoint, degC/min (default 2; as "
                            "station.yaml's chamber.ramp_c_per_min says, or the run's cross-check flags it)")
    serve.set_defaults(func=cmd_sim_serve)

    probe = sub.add_parser("probe", help="read an IMU and/or a rate table and report")
    probe.add_argument("--port", metavar="URL", help="IMU port (device path or pyserial URL)")
    probe.add_argument("--imu-protocol", default="vectornav", help="vectornav (default), xsens or csv")
    probe.add_argument("--seconds", type=argtypes.positive, default=10.0,
                       help="IMU device time to read, s (default 10)")
    probe.add_argument("--rate-hz", type=argtypes.positive, default=100.0, help="IMU output rate, Hz (default 100)")
    probe.add_argument("--csv-units", metavar="SPEC", default="", help="units of a csv IMU (see sim serve)")
    probe.add_argument("--imu-baud", type=int, metavar="BAUD",
                       help="vectornav: set the sensor's baud rate (register 05) after connecting, then "
                            "talk at it (--baud is the rate it answers at first)")
    probe.add_argument("--table-port", metavar="URL",
                       help="rate-table port: device path, pyserial URL (socket://host:9878) or "
                            "visa://RESOURCE (GPIB0::1::INSTR); '#gpib'/'#tcp' chooses the acutrol framing")
    probe.add_argument("--table-protocol", default="acutrol", help="acutrol (default) or aerosmith")
    probe.add_argument("--baud", type=int,
                       help="baud rate (default 115200; 9600 for --table-protocol aerosmith)")
    probe.add_argument("--scan-baud", action="store_true",
                       help="IMU: try the protocol's baud rates (vectornav 9600..921600, xsens as "
                            "mtdef.py, csv the common ones) and report which gives valid frames")
    probe.add_argument("--timeout-s", type=argtypes.positive, default=2.0,
                       help="longest wait for a reply or a frame, s (default 2)")
    probe.add_argument("--json", action="store_true", help="print JSON instead of text")
    probe.set_defaults(func=cmd_probe)


# ---------------------------------------------------------------------------------- sim serve

def cmd_sim_serve(args) -> int:
    axes = args.axes or (1 if args.table_protocol == "aerosmith" else 3)
    if args.table_protocol == "aerosmith" and axes != 1:
        raise UserError("the aerosmith (three-letter) protocol drives single-axis tables: use --axes 1")
    csv_format = _csv_format(args.csv_units)
    if args.table_tcp_port is not None and not 0 <= args.table_tcp_port <= 65535:
        raise UserError(f"--table-tcp-port must be 0..65535, got {args.table_tcp_port}")
    from sim_devices.truth import Truth, default_truth
    from sim_devices.twins.faults import load_faults_per_imu

    n = int(args.imus)
    if n > MAX_IMUS:
        raise UserError(f"--imus {n}: at most {MAX_IMUS} IMU twins on one table")
    files = args.sim_truth or []
    if len(files) not in (0, 1, n):
        raise UserError(f"--sim-truth: give it once (every IMU) or once per IMU ({n}), got {len(files)}")
    if not files:
        truth = [default_truth(args.seed + k) for k in range(n)]
    else:
        loaded = [Truth.from_yaml(f) for f in files]
        truth = loaded * n if len(loaded) == 1 else loaded
    faults, imu_faults = load_faults_per_imu(args.faults, n, axes)
    try:
        server = _bench_server(truth, args, axes, faults, csv_format, imu_faults)
    except OSError as e:
        raise UserError(f"--table-tcp-port {args.table_tcp_port}: {e}") from None
    stop = threading.Event()
    previous = {s: signal.signal(s, lambda *_: stop.set())
                for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)}
    try:
        print(f"table: {server.table_path}", flush=True)
        if n == 1:
            print(f"imu: {server.imu_path}", flush=True)
        else:
            for k, line in enumerate(server.lines, 1):
                print(f"imu{k}: {line.port.path}" + (f" serial {line.serial_number}" if line.serial_number else ""),
                      flush=True)
        if server.chamber_path is not None:
            print(f"chamber: {server.chamber_path}", flush=True)
        what = f"{args.imu_protocol} IMU" if n == 1 else f"{n} {args.imu_protocol} IMUs"
        print(f"station sim serve: {axes}-axis {args.table_protocol} table, {what} "
              f"at {truth[0].sample_rate_hz:g} Hz, speed {args.speed:g}; stop with Ctrl-C",
              file=sys.stderr, flush=True)
        server.serve_forever(stop)
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
    return 0


# ---------------------------------------------------------------------------------- probe

def cmd_probe(args) -> int:
    if not args.port and not args.table_port:
        raise UserError("give --port (an IMU) and/or --table-port (a rate table)")
    if args.scan_baud:
        return _scan_baud(args)
    from drivers.base import ImuSettings, TableSettings
    from drivers.probe import probe_imu, probe_table
    from drivers.registry import imu_driver, table_driver
    from drivers.transport import SerialSettings

    def line(default_baud):
        try:
            return SerialSettings(baudrate=args.baud or default_baud, timeout_s=args.timeout_s)
        except ValueError as e:
            raise UserError(str(e)) from None
    serial = line(115200)
    report = {}
    if args.table_port:
        table_driver(args.table_protocol)            # an unknown name fails before any I/O
        table_line = line(9600 if args.table_protocol == "aerosmith" else 115200)
        report["table"] = probe_table(args.table_port, args.table_protocol, TableSettings(serial=table_line))
    if args.port:
        imu_driver(args.imu_protocol)
        settings = ImuSettings(serial=serial, rate_hz=args.rate_hz, frame_timeout_s=args.timeout_s,
                               csv_format=_csv_format(args.csv_units), device_baud=args.imu_baud)
        report["imu"] = probe_imu(args.port, args.imu_protocol, args.seconds, settings)
    if args.json:
        print(json.dumps(report if len(report) == 2 else next(iter(report.values())), indent=2))
        return 0
    if "table" in report:
        t = report["table"]
        print(f"table {t['port']} ({t['protocol']}): {t['identity']}")
        if t["found_moving_note"]:
            print(f"  {t['found_moving_note']}")
        for i in range(t["axes"]):
            print(f"  axis {i + 1}: {t['positions_deg'][i]:.6f} deg, {t['rates_dps'][i]:.6f} deg/s, "
                  f"interlock {'closed' if t['interlock_closed'][i] else 'open'}"
                  f"{', FAULT' if t['fault'][i] else ''}")
    if "imu" in report:
        r = report["imu"]
        print(f"imu {r['port']} ({r['protocol']}): {r['identity']}")
        rate = f"{r['rate_hz']:.4f} Hz" if r["rate_hz"] else "n/a"
        print(f"  {r['frames']} frames over {r['device_seconds']:.3f} s of device time "
              f"({r['wall_seconds']:.2f} s wall), measured rate {rate}")
        if r["frames"]:
            temp = f", mean temperature {r['mean_temp_c']:.2f} C" if r["mean_temp_c"] is not None else ""
            print(f"  mean |f| {r['mean_accel_norm_mps2']:.6f} m/s^2, mean |w| "
                  f"{r['mean_gyro_norm_dps']:.6f} deg/s{temp}")
        print(f"  checksum errors {r['checksum_errors']}, resyncs {r['resyncs']}, gaps {r['gaps']} "
              f"({r['missing_frames']} frames missing), {r['bytes_discarded']} bytes discarded")
    return 0


def _scan_baud(args) -> int:
    """``station probe --port P --scan-baud``: which baud rate gives valid frames."""
    if not args.port:
        raise UserError("--scan-baud needs --port (an IMU)")
    from drivers.base import ImuSettings
    from drivers.probe import SCAN_WINDOW_S, scan_imu_baud
    from drivers.registry import imu_driver
    from drivers.transport import SerialSettings

    imu_driver(args.imu_protocol)                    # an unknown name fails before any I/O
    settings = ImuSettings(serial=SerialSettings(timeout_s=args.timeout_s))
    r = scan_imu_baud(args.port, args.imu_protocol, settings, min(SCAN_WINDOW_S, args.timeout_s))
    if args.json:
        print(json.dumps(r, indent=2))
    else:
        print(f"imu {r['port']} ({r['protocol']}): {len(r['rates'])} baud rates, "
              f"{r['window_s']:g} s each")
        for rate in r["rates"]:
            what = (f"{rate['valid']} valid frames or replies" if rate["valid"]
                    else "no valid frame or reply")
            mark = "  <- the device" if rate["baud"] == r["baud"] else ""
            print(f"  {rate['baud']:>7d} baud: {rate['bytes']:>7d} bytes, {what}{mark}")
        if r["baud"] is not None:
            print(f"the device answers at {r['baud']} baud: use --baud {r['baud']}")
    if r["baud"] is None:
        raise UserError(f"imu {args.port} ({args.imu_protocol}): no baud rate gave a valid frame or "
                        f"reply: check the protocol (--imu-protocol), the wiring and the power")
    return 0


def _bench_server(truth, args, axes, faults, csv_format, imu_faults=()):
    from sim_devices.twins.serve import BenchOptions, BenchServer

    return BenchServer(truth, BenchOptions(speed=args.speed, seed=args.seed, axes=axes,
                                           table_protocol=args.table_protocol,
                                           imu_protocol=args.imu_protocol, faults=faults,
                                           csv_format=csv_format, table_framing=args.table_framing,
                                           table_tcp_port=args.table_tcp_port, imus=int(args.imus),
                                           imu_faults=tuple(imu_faults), chamber=bool(args.chamber),
                                           chamber_ramp_c_per_min=float(args.chamber_ramp_c_per_min),
                                           chamber_said=lambda text: print(text, file=sys.stderr, flush=True)))


def _csv_format(spec: str):
    from drivers.protocols.csvlines import CsvFormat

    try:
        return CsvFormat.parse(spec)
    except ValueError as e:
        raise UserError(f"--csv-units: {e}") from None
