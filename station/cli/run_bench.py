"""The pieces of a ``station run`` on a bench that a one-IMU run (station/cli/run.py) and a
several-IMU run (station/cli/run_multi.py) share: the run's files, opening the devices, the
operator on the terminal, a new or reopened capture bundle, the steps left on resume, and the
estimate at the end.  Parsing and output only."""
from __future__ import annotations

import datetime as _dt
import re
import select
import sys
from pathlib import Path

import yaml

from station.cli.calibration import report_calibration
from station.cli.output import err, out
from station.core.errors import UserError

RUN_FILE = "run.yaml"


def read_run_text(path: Path) -> str:
    """The text of a file of a run's capture (run.yaml, the scheme, an appended scheme, an IMU's
    manifest): OSError when it is absent, as ``Path.read_text``; a FIFO or device in its place
    (a capture from elsewhere) is a UserError, never read (it hung ``--resume``)."""
    import os

    if os.path.lexists(path):
        from station.core.user_files import read_user_text

        return read_user_text(path, "file of the run")
    return Path(path).read_text()
SCHEME_FILE = "scheme.yaml"
RUN_FORMAT = "station-run/1"
try:                                     # a serial port that hangs up mid-call raises termios.error
    import termios
    DEVICE_ERRORS: tuple = (OSError, termios.error)
except ImportError:                      # not on Windows
    DEVICE_ERRORS = (OSError,)
CONNECTION = {"imu": ("port", "protocol", "serial", "csv_units", "frame_timeout_s"),
              "table": ("port", "protocol", "serial")}


# ------------------------------------------------------------------------------------ operator

class ConsoleOperator:
    """Operator confirmations on the terminal: Enter confirms; Ctrl-C asks for a pause."""

    def __init__(self, display):
        self.display = display

    def confirm(self, step, interrupts) -> None:
        from station.bench.sequencer import PauseRequested

        if not sys.stdin.isatty():
            raise UserError(f"an operator step needs a terminal ({step.instruction}); run from a "
                            "terminal, or unattended (--unattended, run.operator: false)")
        self.display.prompt("press Enter when done (Ctrl-C pauses)")
        while True:
            if interrupts.pause_requested:
                raise PauseRequested()
            ready, _, _ = select.select([sys.stdin], [], [], 0.2)
            if ready:
                sys.stdin.readline()
                return

    def act(self, step) -> None:
        """Hand steps: the operator acts on the prompt; the data tell when it is done."""

    def resume_after_pause(self, interrupts) -> bool:
        if not sys.stdin.isatty():
            return False
        interrupts.clear()
        self.display.prompt("paused: press Enter to continue, Ctrl-C to stop (resume later with --resume)")
        while not interrupts.pause_requested:
            ready, _, _ = select.select([sys.stdin], [], [], 0.2)
            if ready:
                sys.stdin.readline()
                return True
        return False


# ------------------------------------------------------------------------------------ helpers

def _overrides(args) -> dict:
    return {k: v for k, v in (("dwell_s", args.dwell_s), ("rate_dps", args.rate_dps),
                              ("rotation_s", args.rotation_s)) if v is not None}


def _open_devices(config, scheme):
    table = _open_table(config) if scheme.table else None
    try:
        imu = _open_imu(config)
    except BaseException:
        if table is not None:
            table.close()
        raise
    return imu, table


def _open_table(config):
    from drivers.base import AxisLimits, TableSettings
    from drivers.registry import open_table, table_driver

    table_driver(config.table.protocol)
    t = config.table
    limits = tuple(AxisLimits(max_rate_dps=lim.max_rate_dps, max_accel_dps2=lim.max_accel_dps2,
                              move_rate_dps=lim.move_rate_dps, move_accel_dps2=lim.move_accel_dps2)
                   for lim in t.axis_limits())
    # the driver's waits assume ramps at max_accel_dps2; ours are at rate_accel_dps2: allow for them
    ramp_s = max(lim.max_rate_dps / lim.rate_accel_dps2 for lim in t.axis_limits())
    return open_table(t.port, t.protocol, TableSettings(
        serial=t.serial, axes=t.axes, limits=limits, wait_margin_s=10.0 + ramp_s,
        position_tolerance_deg=t.position_tolerance_deg, rate_tolerance_dps=t.rate_tolerance_dps,
        poll_interval_s=t.poll_interval_s))


def _open_imu(config, field: str = "imu"):
    """The IMU of ``config.imu`` (``field``: how a bad csv_units is named)."""
    from drivers.base import ImuSettings
    from drivers.protocols.csvlines import CsvFormat
    from drivers.registry import imu_driver, open_imu

    imu_driver(config.imu.protocol)
    try:
        csv_format = CsvFormat.parse(config.imu.csv_units)
    except ValueError as e:
        raise UserError(f"{config.source}: field '{field}.csv_units': {e}") from None
    return open_imu(config.imu.port, config.imu.protocol, ImuSettings(
        serial=config.imu.serial, rate_hz=config.imu.rate_hz,
        frame_timeout_s=config.imu.frame_timeout_s, csv_format=csv_format))


def table_geometry(t) -> dict:
    """The table's geometry as the capture records it (manifest ``table.geometry``; the
    estimator's station/estimate/table_geometry.py reads it)."""
    out = {"axes_intersect": bool(t.axes_intersect)}
    if t.level_arcsec is not None:
        out["level_arcsec"] = float(t.level_arcsec)
    return out


def _out_dir(args, config, scheme) -> Path:
    if args.out:
        return Path(args.out)
    stamp = _dt.datetime.now(_dt.timezone.utc).strftime("%Y%m%dT%H%M%SZ")
    return Path(config.run.output_dir) / f"{scheme.name}-{stamp}"


def _new_capture(directory, scheme, scheme_text_, overrides, config, imu, rate_hz, lost_at_start: str | None = None):
    """A new capture bundle for ``imu`` (None: an IMU of a several-IMU run lost at the start, its
    bundle marked ``lost_at_start`` with the reason and begun again when a resume reaches it)."""
    from station.io.capture import CaptureWriter, ImuInfo, Site

    t = config.table
    extra = {"run": {"file": RUN_FILE, "scheme_file": SCHEME_FILE}}
    if lost_at_start is not None:
        extra["lost_at_start"] = {"why": lost_at_start,
                                  "utc": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
                                  "note": "the IMU did not start: nothing recorded; station run --resume on "
                                          "the run records it"}
    if scheme.table:
        extra["table"] = {"protocol": t.protocol, "axes": t.axes, "axes_enu": t.axis_list(),
                          "mounting": list(t.mounting), "angle_error_arcsec": t.angle_error_arcsec,
                          "geometry": table_geometry(t)}
    else:
        extra["table"] = {"angle_error_arcsec": 3600.0,
                          "note": "no table: the IMU was placed and turned by hand (1 deg)"}
    if t.imu_offset_m is not None:
        extra["mounting"] = {"offset_m": list(t.imu_offset_m)}
    elif scheme.centred:
        extra["mounting"] = {"offset_m": [0.0, 0.0, 0.0]}
    ident = imu_identity(getattr(imu, "identity", None))
    writer = CaptureWriter(directory, ImuInfo(rate_hz, "m/s^2", "deg/s", model=ident.get("model"),
                                              serial=ident.get("serial"),
                                              extra={**({"firmware": ident["firmware"]} if "firmware" in ident else {}),
                                                     **({"lot": config.imu.lot} if config.imu.lot else {})}),
                           Site(config.site.gravity, latitude_deg=config.site.latitude_deg),
                           scheme.name, extra=extra)
    writer.write_file(SCHEME_FILE, scheme_text_)
    writer.write_file(RUN_FILE, yaml.safe_dump({
        "format": RUN_FORMAT, "scheme": scheme.name, "overrides": overrides,
        "started_utc": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "config": config.to_dict()}, sort_keys=False))
    return writer


def _resume_steps(plan, scheme, done, config):
    """The steps left; the operator's first check names the mounting the first segment left
    was compiled for (a remount may have come before it)."""
    from station.bench.compile import mounting_step
    from station.bench.plan import Operator

    steps = plan.remaining(done)
    first = next((s.segment for s in steps if s.segment is not None), None)
    if first is None or plan.manual:
        return steps
    needed = plan.mounting_of[first]
    check = next((i for i, s in enumerate(steps) if isinstance(s, Operator) and s.segment is None), None)
    if check is not None:
        steps[check] = mounting_step(scheme, config, needed, check=True)
    elif tuple(needed) != tuple(config.table.mounting):
        raise UserError(f"the run resumes at {first}, recorded with the IMU mounted {list(needed)} on the "
                        "platform: an operator must check the mounting (leave out --unattended)")
    return steps


def _reopen(directory, rate_hz, serial=None):
    from station.io.capture import CaptureWriter, read_capture

    capture = read_capture(directory, load_data=False)
    if serial is not None and capture.imu.serial is not None and str(capture.imu.serial) != serial:
        raise UserError(f"{directory}/manifest.yaml: field 'imu.serial': recorded with IMU serial "
                        f"{capture.imu.serial}, the IMU connected now is serial {serial}: connect the "
                        "same IMU to resume")
    if abs(capture.imu.sample_rate_hz - rate_hz) > 1e-9:
        raise UserError(f"{directory}: recorded at {capture.imu.sample_rate_hz:g} Hz, the IMU now gives "
                        f"{rate_hz:g} Hz: set imu.rate_hz as in the run")
    return CaptureWriter.reopen(directory)


def _estimate(directory, accept_poor_fit: bool = False, config=None, history: bool | None = None) -> int:
    from station import api
    from station.cli.noise import characterise_run, is_noise_recording

    if is_noise_recording(api.read_capture(directory, samples=False).segments):
        return characterise_run(directory)
    limits = {} if config is None else {"max_missing_fraction": config.run.max_missing_fraction,
                                        "max_gap_s": config.run.max_gap_s}
    est = api.estimate(directory, **limits)
    for w in est.capture.warnings:
        err.print(f"warning: {w}", markup=False, soft_wrap=True)
    path = est.save(Path(directory) / "calibration.yaml")
    from station.cli.history import file_quietly

    file_quietly(path, asked=True if history is None else history)
    return report_calibration(est.calibration, f"calibration of {directory} ({est.provenance['method']})", path,
                              accept_poor_fit)


_IDENTITY = re.compile(r"(?P<model>.*?) serial (?P<serial>.*?) firmware (?P<firmware>.*)")


def imu_identity(identity: str | None) -> dict:
    """model, serial, firmware from the driver's identity text ("VN-100 serial 0100 firmware
    1.0"); a text in another form is the model."""
    text = (identity or "").strip()
    if not text:
        return {}
    m = _IDENTITY.fullmatch(text)
    if m is None:
        return {"model": text[:200]}
    return {k: v.strip()[:200] for k, v in m.groupdict().items() if v.strip()}


def sequence(steps, display, directory, **devices) -> int | None:
    """The steps run by the sequencer on the devices (station.bench.sequencer.Sequencer's
    arguments: table, imu and writer, or channels; config; rate_hz; reset_faults), with the
    operator at this console and Ctrl-C as a pause: None when they ran to the end, 130 when the
    run was paused or aborted (said, with the command that continues it); a device fault is a
    UserError that says the same.  Shared by one- and several-IMU runs."""
    from station.bench.sequencer import Interrupts, RunAborted, RunPaused, Sequencer

    try:
        with Interrupts() as interrupts, display:
            Sequencer(display=display, operator=ConsoleOperator(display), interrupts=interrupts, **devices).run(steps)
    except UserError as e:           # a device fault, a table that did not hold: the run stops
        raise UserError(f"{e}; the table was brought to rest where it answered, what was recorded is "
                        f"kept: continue with station run --resume {directory}") from None
    except (RunPaused, RunAborted) as e:
        what = "paused" if isinstance(e, RunPaused) else "aborted"
        err.print(f"station run: {what}; the table is at rest and everything recorded is kept; "
                  f"continue with: station run --resume {directory}", markup=False, soft_wrap=True)
        return 130
    return None
