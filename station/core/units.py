"""Unit names of the capture format and the few conversion constants the station uses."""

import math

STANDARD_GRAVITY = 9.80665  # m/s^2; the "g" unit, never local gravity

ACCEL_UNITS = ("m/s^2", "g", "raw")
GYRO_UNITS = ("deg/s", "rad/s", "raw")

DEG_RAD = math.pi / 180.0  # radians per degree
ARCSEC_RAD = DEG_RAD / 3600.0  # radians per arcsecond
UG_MPS2 = STANDARD_GRAVITY * 1e-6  # m/s^2 per micro-g
MG_MPS2 = STANDARD_GRAVITY * 1e-3  # m/s^2 per milli-g
DPH_DPS = 1.0 / 3600.0  # deg/s per deg/h
PPM = 1e-6  # a scale-factor error of one part per million
EARTH_RATE_DPS = 360.0 / 86164.0905  # sidereal rotation of the Earth, deg/s (~15.04 deg/h)


def accel_to_mps2_factor(unit):
    """Factor that turns accelerometer output in `unit` into m/s^2; None for "raw"."""
    factors = {"m/s^2": 1.0, "g": STANDARD_GRAVITY, "raw": None}
    if unit not in factors:
        raise ValueError(f"unknown accelerometer unit {unit!r}: use one of {', '.join(ACCEL_UNITS)}")
    return factors[unit]


def gyro_to_dps_factor(unit):
    """Factor that turns gyroscope output in `unit` into deg/s; None for "raw"."""
    factors = {"deg/s": 1.0, "rad/s": 180.0 / math.pi, "raw": None}
    if unit not in factors:
        raise ValueError(f"unknown gyroscope unit {unit!r}: use one of {', '.join(GYRO_UNITS)}")
    return factors[unit]
