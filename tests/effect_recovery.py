"""Shared by the hidden-effect recovery tests: a simulated capture with an effect hidden in the
truth (sim_devices, written independently of station.model), the fit with and without the
library effect, and the calibration's error on held-out samples that the truth itself produces."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

import simhelpers
from station.core import units
from station.estimate import lsq
from station.io.scheme import scheme_from_text
from station.model.compensate import compensate_with_effects
from station.model.registry import EffectRegistry
from station.simulate import dryrun


def scheme(text: str, name: str = "recovery"):
    return scheme_from_text(text, f"<{name}>")


def simulate(truth, scheme_, seed=3):
    return dryrun.simulate_capture(scheme_, truth, seed)


def fit(capture, *effect_ids):
    reg = EffectRegistry(entry_points=False, environment=False)
    return lsq.fit(lsq.summarise(capture), [reg.create(e) for e in effect_ids])


def estimates(result) -> dict:
    """name -> (value, 1-sigma) of every effect parameter, reported units."""
    names, values, _, cov = lsq.reported(result, "m/s^2", "deg/s")
    sigma = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    return {n: (float(v), float(s)) for n, v, s in list(zip(names, values, sigma))[21:]}


@dataclass
class HeldOut:
    accel_ug: float        # RMS error of the compensated specific force, µg
    gyro_ppm: float        # RMS error of the compensated rate, ppm of the rate's RMS
    gyro_dph: float        # RMS error of the compensated rate, deg/h


def held_out_error(result, truth, *, n=400, rate_dps=150.0, temp_c=None, t_s=None, seed=11) -> HeldOut:
    """Compensate noise-free raw samples that the simulated truth gives at random attitudes,
    rates (up to ``rate_dps`` about random axes), temperatures (uniform over ``temp_c``, a
    (lo, hi) pair; the truth's reference when None) and bench times (evenly from 0 to ``t_s``) with
    the fitted calibration and its effects; compare with the true specific force and rate in
    frame p (the truth's own C_pb)."""
    rng = np.random.default_rng(seed)
    g = 9.80619920                                   # ~ local gravity at 45 deg; any value will do
    up = rng.normal(size=(n, 3))
    f_b = g * up / np.linalg.norm(up, axis=1, keepdims=True)
    axis = rng.normal(size=(n, 3))
    w_b = (rng.uniform(-rate_dps, rate_dps, n)[:, None] * axis / np.linalg.norm(axis, axis=1, keepdims=True))
    lo, hi = temp_c if temp_c is not None else (truth.temperature.reference_c,) * 2
    temp = rng.uniform(lo, hi, n)
    t = np.linspace(0.0, t_s if t_s is not None else 0.01 * n, n)   # bench time, from 0
    accel_raw, gyro_raw = truth.measure(f_b, w_b, temp, None, t=t)
    C_pb = truth.paper_parameters()["C_pb"]
    f_p, w_p = f_b @ C_pb.T, w_b @ C_pb.T
    cal = lsq.to_calibration(result, "m/s^2", "deg/s")
    comp = {"accel_matrix": cal.accel_matrix, "gyro_matrix": cal.gyro_matrix,
            "accel_bias": cal.accel_bias, "gyro_bias": cal.gyro_bias}
    L = result.model.layout
    effects = [(e, result.x[L[f"effect:{e.id}"]]) for e in result.model.effects]
    _, f, w = compensate_with_effects(comp, effects, t, accel_raw, gyro_raw, temp)
    ea, ew = f - f_p, w - w_p
    return HeldOut(accel_ug=float(np.sqrt(np.mean(ea**2)) / units.UG_MPS2),
                   gyro_ppm=float(np.sqrt(np.mean(ew**2)) / np.sqrt(np.mean(w_p**2)) * 1e6),
                   gyro_dph=float(np.sqrt(np.mean(ew**2)) * 3600.0))


def mems(seed_imu=0, **hidden):
    from sim_devices.truth import mems_truth

    return simhelpers.hide(mems_truth(seed_imu), **hidden)
