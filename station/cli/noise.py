"""``station noise``: the noise of a still IMU from the Allan deviation (argument parsing and output)."""
from __future__ import annotations

from station.cli.output import out


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
    from station import api

    done = api.characterise_noise(args.source, calibration=args.cal, segment=args.segment, topic=args.topic,
                                  rate_hz=args.rate_hz, accel_unit=args.accel_unit, gyro_unit=args.gyro_unit,
                                  plot=args.plot, force=args.force)
    return _print(done)


def _print(done) -> int:
    from station.cli.calibration import print_messages

    print_messages(done.warnings)
    out.print(_table(done.result))
    kal = done.block["kalibr"]
    out.print("Kalibr imu.yaml: " + ", ".join(
        f"{k} {kal[k]:.4g}{' (upper bound)' if kal.get(k + '_is_upper_bound') else ''}"
        for k in ("accelerometer_noise_density", "accelerometer_random_walk",
                  "gyroscope_noise_density", "gyroscope_random_walk")) + f", update_rate {kal['update_rate']:g}",
              markup=False, soft_wrap=True)
    out.print(f"noise figures: {done.figures}", markup=False)
    out.print(f"Allan deviation plot: {done.plot}", markup=False)
    return 0


def is_noise_recording(segments) -> bool:
    """One static segment and no rotation: a noise recording (the ``noise`` scheme), from which
    no calibration can be estimated; ``run`` characterises its noise instead."""
    kinds = [s.kind for s in segments]
    return kinds == ["static"]


def characterise_run(directory) -> int:
    """What ``station run`` does at the end of a noise recording."""
    from station import api

    return _print(api.characterise_noise(directory))
