"""Segment summaries: what the least-squares fit uses from a capture.

The fit works on a few numbers per segment, weighted by their noise, not on the raw samples:
  static    the mean accelerometer and gyro outputs over the dwell;
  rotation  the accelerometer's mean and first and second harmonics at the rotation frequency,
            over the table angle measured by the encoder, and the gyro integral over the
            segment's window [t0 - dt/2, t_{N-1} + dt/2] (the window of ``angle_deg``).
The noise of every summary comes from the white noise of the static segments (the per-sample
standard deviation, pooled per axis), so no noise figure has to be typed in.
Arrays are in m/s^2 and deg/s after the manifest's unit conversion ("raw" is taken as is).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from station.core import units
from station.core.errors import UserError
from station.estimate import hand_rotation

EDGE_SAMPLES = 3
STEADY_SPREAD = 0.3     # a rotation whose rate magnitude varies more (std/mean) is a hand turn


@dataclass
class StaticSummary:
    name: str
    up_body: np.ndarray | None      # commanded, IMU case axes
    accel: np.ndarray               # (3,) mean
    gyro: np.ndarray                # (3,) mean
    samples: int
    duration_s: float
    temp_c: float | None


@dataclass
class RotationSummary:
    name: str
    axis_body: np.ndarray           # commanded, unit, IMU case axes
    group: int                      # index of the physical axis (segments about the same axis)
    angle_deg: float                # encoder angle over the window, signed
    duration_s: float               # window length
    samples: int
    accel_dc: np.ndarray            # (3,) mean over the captured angle
    accel_cos: np.ndarray           # (3,) first harmonic: accel ~ dc + cos phi * c + sin phi * s
    accel_sin: np.ndarray           #   + cos 2phi * c2 + sin 2phi * s2
    accel_cos2: np.ndarray          # (3,) second harmonic (nonlinearity, a wobbling axis)
    accel_sin2: np.ndarray
    gyro_integral: np.ndarray       # (3,) integral over the window, deg (SI) or raw*s
    temp_c: float | None
    gyro_start: np.ndarray          # (3,) rate at the window's start and end (mean of the
    gyro_end: np.ndarray            #   first and last EDGE_SAMPLES samples)
    steady: bool = True             # the rate held within STEADY_SPREAD (a table, not a hand)
    rate_sq_factor: float = 1.0     # mean of the squared rate over the square of the mean rate
                                    #   (from the gyro's magnitude: > 1 when the rate ripples)

    @property
    def rate_dps(self) -> float:
        return self.angle_deg / self.duration_s


@dataclass
class Summaries:
    gravity_mps2: float
    latitude_deg: float | None
    accel_factor: float             # m/s^2 per raw unit (1 for raw)
    gyro_factor: float              # deg/s per raw unit (1 for raw)
    sample_rate_hz: float
    statics: list
    rotations: list
    accel_sigma: np.ndarray         # (3,) per-sample white noise, m/s^2
    gyro_sigma: np.ndarray          # (3,) per-sample white noise, deg/s
    table_angle_sigma_deg: float    # 1-sigma of one encoder angle
    mounting_offset_m: np.ndarray | None   # IMU reference point from the table's rotation centre, if known
    skipped: list = field(default_factory=list)
    hand_rotations: list = field(default_factory=list)   # hand_rotation.HandRotation: turns of unknown
                                                         #   angle between statics (no encoder)
    gyro_nominal: float | None = None   # raw gyro: nominal counts per deg/s from the manifest, if any
    gyro_raw: bool = False

    @property
    def groups(self) -> int:
        return 1 + max((r.group for r in self.rotations), default=-1)


def _window(t: np.ndarray) -> tuple[float, float]:
    dt_first, dt_last = t[1] - t[0], t[-1] - t[-2]
    return t[0] - 0.5 * dt_first, t[-1] + 0.5 * dt_last


def _turned_fraction(t, gyro, start, duration) -> np.ndarray:
    """Fraction of the segment's turn reached at each sample, from the gyro's own integral about
    its mean rate direction (scale errors cancel in the ratio; a rate that ripples or drifts is
    followed, where a uniform rate would smear the harmonics)."""
    direction = gyro.mean(axis=0)
    norm = np.linalg.norm(direction)
    if norm == 0:
        return (t - start) / duration
    rate = gyro @ (direction / norm)
    dt = np.diff(t)
    turned = np.concatenate([[0.0], np.cumsum(0.5 * (rate[1:] + rate[:-1]) * dt)])
    turned += 0.5 * rate[0] * (t[1] - t[0])                    # from the window's start
    total = turned[-1] + 0.5 * rate[-1] * (t[-1] - t[-2])
    return turned / total if total != 0 else (t - start) / duration


def rotation_summary(name, axis_body, group, angle_deg, t, accel, gyro, temp) -> RotationSummary:
    if len(t) < 8:
        raise UserError(f"segment '{name}': a rotation segment needs at least 8 samples")
    start, end = _window(t)
    duration = end - start
    # trapezoid over the samples plus half a sample at each end: the integral over the window
    gyro_integral = (np.trapezoid(gyro, t, axis=0)
                     + 0.5 * (gyro[0] * (t[1] - t[0]) + gyro[-1] * (t[-1] - t[-2])))
    phase = np.radians(angle_deg) * _turned_fraction(t, gyro, start, duration)
    basis = np.column_stack([np.ones_like(t), np.cos(phase), np.sin(phase),
                             np.cos(2 * phase), np.sin(2 * phase)])
    coef, *_ = np.linalg.lstsq(basis, accel, rcond=None)
    edge = min(EDGE_SAMPLES, len(t) // 4)
    magnitude = np.linalg.norm(gyro, axis=1)
    steady = bool(np.std(magnitude) < STEADY_SPREAD * np.mean(magnitude))
    rate_sq_factor = float(np.mean(magnitude**2) / np.mean(magnitude) ** 2)
    return RotationSummary(name=name, axis_body=axis_body, group=group, angle_deg=float(angle_deg),
                           duration_s=float(duration), samples=len(t), accel_dc=coef[0],
                           accel_cos=coef[1], accel_sin=coef[2], accel_cos2=coef[3],
                           accel_sin2=coef[4], gyro_integral=gyro_integral,
                           temp_c=None if temp is None else float(np.mean(temp)),
                           gyro_start=gyro[:edge].mean(axis=0), gyro_end=gyro[-edge:].mean(axis=0),
                           steady=steady, rate_sq_factor=rate_sq_factor)


def summarise(capture, *, table_angle_arcsec: float | None = None) -> Summaries:
    ca = units.accel_to_mps2_factor(capture.imu.accel_unit) or 1.0
    cg = units.gyro_to_dps_factor(capture.imu.gyro_unit) or 1.0
    statics, resid_a, resid_g = [], [], []
    for seg in capture.complete("static"):
        d = seg.data
        a, g = d.accel * ca, d.gyro * cg
        statics.append(StaticSummary(seg.name, seg.up_body, a.mean(axis=0), g.mean(axis=0), len(d.t),
                                     float(d.t[-1] - d.t[0]), None if d.temp is None else float(d.temp.mean())))
        # white noise: first differences remove slow drifts (temperature) from the estimate
        resid_a.append(np.diff(a, axis=0) / np.sqrt(2))
        resid_g.append(np.diff(g, axis=0) / np.sqrt(2))
    if not statics:
        raise UserError(f"{capture.path}: no complete static segment: the least-squares fit needs "
                        "static segments (biases and the noise level come from them)")
    accel_sigma = np.sqrt(np.mean(np.vstack(resid_a) ** 2, axis=0))
    gyro_sigma = np.sqrt(np.mean(np.vstack(resid_g) ** 2, axis=0))

    rotations, skipped, axes, hands = [], [], [], []
    for seg in capture.complete("rotation"):
        if hand_rotation.is_hand(seg):
            hands.append(seg)
            continue
        if seg.angle_deg is None:
            skipped.append(f"{seg.name}: no encoder angle (angle_deg); not used by the least-squares fit")
            continue
        axis = np.asarray(seg.axis_body, float) / np.linalg.norm(seg.axis_body)
        group = next((i for i, a in enumerate(axes) if np.allclose(a, axis, atol=1e-6)), None)
        if group is None:
            axes.append(axis)
            group = len(axes) - 1
        d = seg.data
        summary = rotation_summary(seg.name, axis, group, seg.angle_deg, d.t, d.accel * ca, d.gyro * cg, d.temp)
        if seg.extra.get("motion") == "hand":      # the writer says so (manual schemes)
            summary.steady = False
        rotations.append(summary)

    hand_rotations, hand_skipped = hand_rotation.collect(capture.complete("static"), hands, cg)
    skipped += hand_skipped
    nominal = capture.imu.extra.get("gyro_nominal_dps_per_count") if capture.imu.gyro_unit == "raw" else None
    nominal = 1.0 / float(nominal) if isinstance(nominal, (int, float)) and nominal > 0 else None
    table = capture.extra.get("table") if isinstance(capture.extra.get("table"), dict) else {}
    if table_angle_arcsec is None:
        table_angle_arcsec = table.get("angle_error_arcsec", 0.0)
    mounting = capture.extra.get("mounting") if isinstance(capture.extra.get("mounting"), dict) else {}
    offset = mounting.get("offset_m")
    try:
        offset = None if offset is None else np.asarray(offset, dtype=float).reshape(3)
        angle_sigma = float(table_angle_arcsec) / 3600.0
    except (TypeError, ValueError):
        raise UserError(f"{capture.path}/manifest.yaml: field 'mounting.offset_m' or "
                        "'table.angle_error_arcsec': must be numbers") from None
    return Summaries(gravity_mps2=capture.site.gravity_mps2, latitude_deg=capture.site.latitude_deg,
                     accel_factor=ca, gyro_factor=cg, sample_rate_hz=capture.imu.sample_rate_hz,
                     statics=statics, rotations=rotations, accel_sigma=accel_sigma, gyro_sigma=gyro_sigma,
                     table_angle_sigma_deg=angle_sigma, mounting_offset_m=offset, skipped=skipped,
                     hand_rotations=hand_rotations, gyro_nominal=nominal,
                     gyro_raw=capture.imu.gyro_unit == "raw")
