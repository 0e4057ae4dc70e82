"""Effects kept out of the library's ranking: what a warm-up optimal9 capture cannot reveal.

A gyro's scale that changes with the square of the temperature, its sensing axes that tilt with
temperature, and its scale that changes with the specific force are real (thermal stress on the
mounting, a suspension that sags under g), but a scheme that turns each axis at one temperature
range and in one attitude cannot size them: the fit passes and the held-out error is several
times the clean floor (docs/diagnose.md, "Fourteenth session").  They are not in
``station.model.LIBRARY``, so every diagnosis does not pay a score test for each; station
diagnose names them when the capture leaves them not revealed (station/diagnose/unrevealed.py)
and prints the ``station design --from CAPTURE --add station.model.unlisted:CLASS --reveal ...``
command that finds the segments which would.  ``station estimate --add
station.model.unlisted:CLASS`` fits them like any effect (an importable ``module:Class`` spec).

Each term is added to the raw gyro output, as the library's scale_temperature adds its own: with
G = K_g T_g R_po the gyro matrix and (G w_p)_i the raw output of axis i,

    scale in (T - T_ref)^2:  gyro_raw_i += s2_i 1e-6 (T - T_ref)^2 (G w_p)_i     (ppm/degC^2)
    axis tilt in T:          gyro_raw_i += m_ij (T - T_ref) (G w_p)_j, j != i     (arcsec/degC)
    scale in the force:      gyro_raw_i += S_ik 1e-6 (f_k / g0) (G w_p)_i         (ppm/g)
    accelerometer scale in (T - T_ref)^2: accel_raw_i += s2_i 1e-6 (T - T_ref)^2 (K_a T_a f_p)_i

T_ref is the mean temperature of the static segments (the library's temperature effects').
The simulator's physics of the same effects (sim_devices/truth.py, ``_outside_library``:
``scale_tempco2_ppm_per_c2`` of both triads, ``axis_tilt_tempco_arcsec_per_c``, ``scale_g_ppm_per_g``) is
written without this module.
"""
from __future__ import annotations

import numpy as np

from station.model.effect import Effect, Param
from station.model.temperature import TemperatureReferenced

ARCSEC = np.pi / 648000.0           # rad per arc-second
G0 = 9.80665                        # m/s^2 per g
AX = "xyz"
OTHERS = ((1, 2), (0, 2), (0, 1))   # the axes each gyro axis may tilt towards


class GyroScaleTemperatureSquared(TemperatureReferenced):
    id = "gyro_scale_temperature_squared"
    title = "Gyro scale factors second order in temperature (per axis)"
    physics = ("The scale factor's temperature dependence is not a straight line over a wide "
               "range: drive amplitude and spring stiffness bend it, so the scale at T_ref +/- 5 degC "
               "differs from the linear slope's prediction by s2 dT^2.")
    term = "gyro_raw_i += s2_i 1e-6 (T - T_ref)^2 (G w_p)_i (s2 in ppm/°C²)"
    excited_by = "rotations about each axis at three or more temperatures (the same rotations repeated as the IMU warms)"
    magnitudes = "1-20 ppm/°C² (MEMS gyros)"
    signature = "rotation segments: a scale error that follows the square of the segment's temperature offset"
    signature_variable = "temperature"
    complex_step = True

    @property
    def params(self):
        # typical 5 ppm/degC^2: the MEMS size of the benchmarks (4-5, benchmarks/emit_cases.py)
        return tuple(Param(f"gyro_scale_tempco2_{a}", "ppm/degC^2", 1.0, 5.0, 500.0) for a in AX)

    def gyro(self, x, ctx):
        dt = self._dt(ctx)
        return 1e-6 * x * dt * dt * (ctx.w_p @ ctx.gyro_matrix.T)


class AccelScaleTemperatureSquared(TemperatureReferenced):
    id = "accel_scale_temperature_squared"
    title = "Accelerometer scale factors second order in temperature (per axis)"
    physics = ("The accelerometer's scale (proof-mass spring, reference voltage) bends away from a "
               "straight line in temperature over a wide range: s2 dT^2 beyond the linear slope.")
    term = "accel_raw_i += s2_i 1e-6 (T - T_ref)^2 (K_a T_a f_p)_i (s2 in ppm/°C²)"
    excited_by = "statics at +1 g and -1 g along each axis at three or more temperatures"
    magnitudes = "1-20 ppm/°C² (MEMS accelerometers)"
    signature = "static segments: an error proportional to the gravity along the axis and to dT^2"
    signature_variable = "temperature"
    complex_step = True

    @property
    def params(self):
        # typical 5 ppm/degC^2: the MEMS size of the benchmarks (5-6, benchmarks/emit_cases.py)
        return tuple(Param(f"accel_scale_tempco2_{a}", "ppm/degC^2", 1.0, 5.0, 500.0) for a in AX)

    def accel(self, x, ctx):
        dt = self._dt(ctx)
        return 1e-6 * x * dt * dt * (ctx.f_p @ ctx.accel_matrix.T)


class GyroMisalignmentTemperature(TemperatureReferenced):
    id = "gyro_misalignment_temperature"
    title = "Gyro sensing axes that tilt with temperature (six angles per degree)"
    physics = ("Thermal stress in the mounting and the package tilts each sensing element as the IMU "
               "warms: the misalignment of each gyro axis towards the two others changes linearly "
               "with temperature.")
    term = "gyro_raw_i += m_ij (T - T_ref) (G w_p)_j for j != i (m in arcsec/°C)"
    excited_by = ("rotations about each axis repeated at two or more temperatures (a misalignment at one "
                  "temperature is the base model's)")
    magnitudes = "1-30 arcsec/°C (MEMS)"
    signature = ("rotation segments: an error on the axes across the rotation, in proportion to its rate "
                 "and the segment's temperature offset")
    signature_variable = "temperature"
    complex_step = True

    @property
    def params(self):
        # typical 10 arcsec/degC: the middle of the MEMS range (magnitudes); 20 in the benchmarks
        return tuple(Param(f"gyro_misalignment_tempco_{AX[i]}{AX[j]}", "arcsec/degC", 1.0, 10.0, 3600.0)
                     for i in range(3) for j in OTHERS[i])

    def gyro(self, x, ctx):
        raw = ctx.w_p @ ctx.gyro_matrix.T
        dt = self._dt(ctx)[:, 0]
        out = np.zeros(raw.shape, dtype=np.result_type(x, raw))     # complex under the complex step
        pairs = [(i, j) for i in range(3) for j in OTHERS[i]]
        for k, (i, j) in enumerate(pairs):
            out[:, i] += x[k] * ARCSEC * dt * raw[:, j]
        return out


class GyroScaleForce(Effect):
    id = "gyro_scale_force"
    title = "Gyro scale factors that change with the specific force (3 x 3)"
    physics = ("A vibrating or spinning element's suspension deforms under the specific force, which "
               "changes its sensitivity: the scale factor of each gyro axis changes in proportion to "
               "the force along each case axis.")
    term = "gyro_raw_i += S_ik 1e-6 (f_k / g0) (G w_p)_i (S in ppm/g)"
    excited_by = ("rotations about each axis with a different force along the axes: the axis vertical, up "
                  "and then down (the IMU turned over), and horizontal")
    magnitudes = "10-1000 ppm/g (MEMS gyros)"
    signature = "rotation segments: a scale error that differs between the same rotation up and upside down"
    signature_variable = "force"
    complex_step = True

    @property
    def params(self):
        # typical 100 ppm/g: the middle of the MEMS range (magnitudes); 300-800 in the benchmarks
        return tuple(Param(f"gyro_scale_force_{AX[i]}{AX[k]}", "ppm/g", 1.0, 100.0, 1e5)
                     for i in range(3) for k in range(3))

    def gyro(self, x, ctx):
        raw = ctx.w_p @ ctx.gyro_matrix.T
        S = x.reshape(3, 3)
        return 1e-6 * raw * ((ctx.f_p / G0) @ S.T)


UNLISTED = {cls.id: cls for cls in (GyroScaleTemperatureSquared, GyroMisalignmentTemperature, GyroScaleForce,
                                     AccelScaleTemperatureSquared)}
