"""Apply a calibration's compensation to raw samples: the inverse of the forward model.

Forward model (what the sensors do; station/model/calibration.py and the effects):
  a_si = K_a T_a f_p + b_a + sum_e accel_e(f_p, w_p, ...)      (a_si = accel_raw * unit factor)
  w_si = K_g T_g R_po w_p + b_g + sum_e gyro_e(f_p, w_p, ...)
Compensation solves these for f_p (m/s^2) and w_p (deg/s), frame p.  Every effect's term is
evaluated at the current compensated estimate and subtracted, and this is repeated until nothing
changes (a fixed-point iteration: the terms are small, so it converges in a few steps; a term that
depends only on the rate, as the size effect's, is exact after the first).  Effects that shift the
time stamps (a clock offset) correct ``t`` first.
"""
from __future__ import annotations

import numpy as np

from station.core import units
from station.model.effect import SampleContext
from station.model.geometry import cross

MAX_ITERATIONS = 20
TOLERANCE = 1e-13         # relative change of the compensated values that ends the iteration

# The effects the legacy compensation keys (files without ``compensation.effects``) carry.
LEGACY_EFFECTS = ("base_triads", "inter_triad", "accel_lever_arm", "temperature_bias")


def factors(comp: dict) -> tuple[float, float]:
    raw = comp.get("raw_units") or {}
    fa = units.accel_to_mps2_factor(raw.get("accel", "m/s^2")) or 1.0
    fg = units.gyro_to_dps_factor(raw.get("gyro", "deg/s")) or 1.0
    return fa, fg


def compensate_with_effects(comp: dict, effects, t, accel_raw, gyro_raw, temp=None):
    """Raw samples (N,3) -> (t corrected, f_p m/s^2, w_p deg/s).  ``effects``: (Effect, x) pairs,
    x the effect's parameters in the model's internal units."""
    t = np.asarray(t, float)
    fa, fg = factors(comp)
    Ca, Cg = np.asarray(comp["accel_matrix"], float), np.asarray(comp["gyro_matrix"], float)
    Ma, Mg = fa * np.linalg.inv(Ca), fg * np.linalg.inv(Cg)       # the forward matrices
    a_si = (np.asarray(accel_raw, float) - comp["accel_bias"]) * fa
    w_si = (np.asarray(gyro_raw, float) - comp["gyro_bias"]) * fg
    for effect, x in effects:
        t = np.asarray(effect.compensate_time(x, t), float)
    f, w = a_si @ Ca.T / fa, w_si @ Cg.T / fg
    if not effects:
        return t, f, w
    n = len(t)
    temp_c = np.full(n, np.nan) if temp is None else np.asarray(temp, float)
    temp_rate = np.gradient(temp_c, t) if temp is not None and n > 1 else None
    for _ in range(MAX_ITERATIONS):
        w_rad = np.radians(w)
        ctx = SampleContext(f_p=f, w_p=w, w_table=w_rad,
                            wdot_table=np.gradient(w_rad, t, axis=0) if n > 1 else np.zeros_like(w_rad),
                            temp_c=temp_c, accel_matrix=Ma, gyro_matrix=Mg, t_s=t - t[0],
                            temp_rate_c_per_s=temp_rate)
        da, dw = np.zeros_like(f), np.zeros_like(w)
        for effect, x in effects:
            ta, tg = effect.accel(x, ctx), effect.gyro(x, ctx)
            if ta is not None:
                da = da + ta
            if tg is not None:
                dw = dw + tg
        f_new, w_new = (a_si - da) @ Ca.T / fa, (w_si - dw) @ Cg.T / fg
        change = max(np.max(np.abs(f_new - f), initial=0.0) / max(np.max(np.abs(f_new), initial=0.0), 1e-300),
                     np.max(np.abs(w_new - w), initial=0.0) / max(np.max(np.abs(w_new), initial=0.0), 1e-300))
        f, w = f_new, w_new
        if change < TOLERANCE:
            break
    return t, f, w


def compensate(comp: dict, t: np.ndarray, accel_raw: np.ndarray, gyro_raw: np.ndarray, temp=None):
    """The legacy compensation keys only (files written before ``compensation.effects``): raw
    samples (N,3) in the calibration's raw units -> specific force (m/s^2) and rate (deg/s) in
    frame p.  With ``accel_lever_arm_m`` (row i: accelerometer i's position from the reference
    point, m, frame p) the specific force is moved to the reference point using the calibrated
    rate and its time derivative: f_i -= w x (w x p_i) + dw/dt x p_i.  With the temperature
    coefficients and a temperature column (deg C), the biases follow it."""
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
