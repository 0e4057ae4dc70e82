"""``station noise``: the noise of a still IMU from the Allan deviation (argument parsing and output)."""
from __future__ import annotations

from pathlib import Path

from station.cli.output import err, out


def add_parsers(sub) -> None:
    n = sub.add_parser("noise", help="Allan deviation of a static recording: white noise, bias "
                       "instability, random walk, Kalibr's numbers")
    n.add_argument("source", metavar="CAPTURE|FILE|BAG",
                   help="a capture bundle (its longest static segment), a CSV t,ax,ay,az,gx,gy,gz, or a "
                        "ROS bag of a still IMU (sensor_msgs/Imu: ROS 1 .bag, ROS 2 folder, .mcap)")
    n.add_argument("--topic", help="the bag's Imu topic (needed when it has several)")
    n.add_argument("--segment", help="the static segment of the capture to use")
    n.add_argument("--cal", metavar="CAL.yaml", help="write the figures into this calibration file "
                   "(default: CAPTURE/calibration.yaml when it exists; else CAPTURE/noise.yaml)")
    n.add_argument("--rate-hz", type=float, help="sample rate of a CSV (default: from its t column)")
    n.add_argument("--accel-unit", default="m/s^2", choices=("m/s^2", "g", "raw"), help="unit of a CSV")
    n.add_argument("--gyro-unit", default="deg/s", choices=("deg/s", "rad/s", "raw"), help="unit of a CSV")
    n.add_argument("--plot", metavar="PNG", help="default: allan.png next to the figures")
    n.add_argument("--force", action="store_true",
                   help="write into a calibration of another IMU serial than the recording's")
    n.set_defaults(func=cmd_noise)


def _table(result) -> Table:
    from rich.table import Table

    t = Table(title=f"noise from the overlapping Allan deviation ({result.duration_s:.0f} s at "
                    f"{result.sample_rate_hz:g} Hz)")
    for col in ("axis", "white noise ± 1σ", "random walk of angle/velocity", "bias instability",
                "bias random walk"):
        t.add_column(col, justify="left" if col == "axis" else "right")
    for a in result.axes:
        r = a.report()
        if a.sensor == "accel":
            white = f"{r['white_noise_ug_rthz']:.4g} ± {r['white_noise_sigma_ug_rthz']:.2g} µg/√Hz"
            arw = f"{r['velocity_random_walk_mps_rth']:.4g} m/s/√h"
            bi = r["bias_instability_ug"]
            bi = f"{bi:.3g} µg" if bi is not None else f"< {r['bias_instability_upper_ug']:.3g} µg"
            rw = r["random_walk_ug_rth"]
            rw = f"{rw:.3g} µg/√h" if rw is not None else f"< {r['random_walk_upper_ug_rth']:.3g} µg/√h"
        else:
            white = f"{r['white_noise_dph_rthz']:.4g} ± {r['white_noise_sigma_dph_rthz']:.2g} °/h/√Hz"
            arw = f"{r['angle_random_walk_deg_rth']:.4g} °/√h"
            bi = r["bias_instability_dph"]
            bi = f"{bi:.3g} °/h" if bi is not None else f"< {r['bias_instability_upper_dph']:.3g} °/h"
            rw = r["random_walk_dph_rth"]
            rw = f"{rw:.3g} °/h/√h" if rw is not None else f"< {r['random_walk_upper_dph_rth']:.3g} °/h/√h"
        t.add_row(f"{a.sensor} {a.axis}", white, arw, bi, rw)
    return t


def cmd_noise(args) -> int:
    from station.core.errors import UserError, cannot_write
    from station.diagnose.figures import allan_figure
    from station.estimate import noise
    from station.io.calfile import read_calfile
    from station.io.capture import read_capture, read_segment_csv
    from station.io.noise_file import write_into_calibration, write_noise_file

    src = Path(args.source)
    cal_doc = read_calfile(args.cal) if args.cal else None
    model = serial = None
    bag = (src.suffix in (".bag", ".mcap", ".db3")
           or (src.is_dir() and (src / "metadata.yaml").is_file() and not (src / "manifest.yaml").exists()))
    if bag:          # a still IMU recorded as a ROS bag (allan_variance_ros's use): its whole length
        from types import SimpleNamespace

        from station.io.importers.rosbag import read_rosbag

        if args.segment:
            raise UserError("--segment applies to a capture bundle, not to a bag")
        rec = read_rosbag(src, topic=args.topic)
        here = src.parent
        result = noise.from_samples(src, SimpleNamespace(t=rec.t, accel=rec.accel, gyro=rec.gyro), args.rate_hz,
                                    rec.accel_unit, rec.gyro_unit, cal_doc)
    elif src.is_dir() or src.name == "manifest.yaml":
        capture = read_capture(src, load_data=False)     # from_capture reads the static segments
        here = capture.path
        default_cal = here / "calibration.yaml"
        if cal_doc is None and default_cal.exists():
            args.cal, cal_doc = str(default_cal), read_calfile(default_cal)
        result = noise.from_capture(capture, args.segment, cal_doc)
        model, serial = capture.imu.model, capture.imu.serial
        cal_serial = ((cal_doc or {}).get("provenance") or {}).get("imu_serial")
        if serial and cal_serial and serial != cal_serial and not getattr(args, "force", False):
            raise UserError(f"{args.cal}: calibration of IMU {cal_serial!r}, recording of IMU {serial!r}: "
                            "the noise belongs to the IMU recorded (--force to write it anyway)")
        used = capture.segment(result.segment)
        if used.data.gaps:
            err.print("warning: the recording has gaps; the Allan deviation assumes even sampling")
        if used.status == "incomplete":
            err.print(f"warning: segment {used.name} is incomplete (the recording stopped): its "
                      f"{len(used.data.t)} samples before it stopped are characterised", markup=False, soft_wrap=True)
    else:
        if args.segment:
            raise UserError("--segment applies to a capture bundle, not to a CSV file")
        data = read_segment_csv(src, sample_rate_hz=args.rate_hz)
        here = src.parent
        result = noise.from_samples(src, data, args.rate_hz, args.accel_unit, args.gyro_unit, cal_doc)
    block = result.block()
    # a capture holds one noise file and plot; a CSV's are named after it (two recordings in one
    # folder do not overwrite each other's)
    stem = f"{src.stem}-" if bag or not (src.is_dir() or src.name == "manifest.yaml") else ""
    if args.cal:
        target = write_into_calibration(args.cal, block)
    else:
        target = write_noise_file(here / f"{stem}noise.yaml", block, model, serial)
    png = Path(args.plot) if args.plot else Path(target).with_name(f"{stem}allan.png")
    try:
        allan_figure(result, png)
    except OSError as e:
        raise cannot_write(png, e) from None
    out.print(_table(result))
    kal = block["kalibr"]
    out.print("Kalibr imu.yaml: " + ", ".join(
        f"{k} {kal[k]:.4g}{' (upper bound)' if kal.get(k + '_is_upper_bound') else ''}"
        for k in ("accelerometer_noise_density", "accelerometer_random_walk",
                  "gyroscope_noise_density", "gyroscope_random_walk")) + f", update_rate {kal['update_rate']:g}",
              markup=False, soft_wrap=True)
    out.print(f"noise figures: {target}", markup=False)
    out.print(f"Allan deviation plot: {png}", markup=False)
    return 0


def is_noise_recording(segments) -> bool:
    """One static segment and no rotation: a noise recording (the ``noise`` scheme), from which
    no calibration can be estimated; ``run`` characterises its noise instead."""
    kinds = [s.kind for s in segments]
    return kinds == ["static"]


def characterise_run(directory) -> int:
    """What ``station run`` does at the end of a noise recording."""
    import argparse

    return cmd_noise(argparse.Namespace(source=str(directory), segment=None, cal=None, rate_hz=None,
                                        accel_unit="m/s^2", gyro_unit="deg/s", plot=None, force=False))
