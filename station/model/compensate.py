"""Apply a calibration file's compensation to raw samples."""
from __future__ import annotations

import numpy as np

from station.model.geometry import cross


COMPENSATED_EFFECTS = ("base_triads", "inter_triad", "accel_lever_arm", "temperature_bias")


def compensate(comp: dict, t: np.ndarray, accel_raw: np.ndarray, gyro_raw: np.ndarray, temp=None):
    """Raw samples (N,3) in the calibration's raw units -> specific force (m/s^2) and rate
    (deg/s) in frame p.  With ``accel_lever_arm_m`` (row i: accelerometer i's position from the
    reference point, m, frame p) the specific force is moved to the reference point using the
    calibrated rate and its time derivative: f_i -= w x (w x p_i) + dw/dt x p_i.  With the
    temperature coefficients and a temperature column (deg C), the biases follow it."""
    accel_bias, gyro_bias = comp["accel_bias"], comp["gyro_bias"]
    if temp is not None and "temperature_reference_c" in comp:
        dT = (np.asarray(temp, float) - float(comp["temperature_reference_c"]))[:, None]
        accel_bias = accel_bias + dT * np.asarray(comp["accel_bias_tempco_raw_per_c"], float)
        gyro_bias = gyro_bias + dT * np.asarray(comp["gyro_bias_tempco_raw_per_c"], float)
    w = (gyro_raw - gyro_bias) @ comp["gyro_matrix"].T
    corrected = accel_raw - accel_bias
    positions = comp.get("accel_lever_arm_m")
    if positions is not None and len(t) > 1:
        w_rad = np.radians(w)
        wdot = np.gradient(w_rad, t, axis=0)
        raw_per_si = np.linalg.inv(comp["accel_matrix"])       # rows: (K_a T_a)_i / unit factor
        for i in range(3):
            a = cross(wdot, positions[i]) + cross(w_rad, cross(w_rad, positions[i]))
            corrected[:, i] -= a @ raw_per_si[i]
    f = corrected @ comp["accel_matrix"].T
    return f, w
