"""Monte Carlo: repeat simulate -> estimate with seeds and collect the errors per parameter."""
from __future__ import annotations

import dataclasses
import os
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass

import numpy as np

from station.scheme import Scheme


@dataclass
class Settings:
    accel_noise_ug: float = 100.0         # µg/√Hz
    gyro_noise_dph: float = 0.03          # °/h/√Hz
    table_angle_arcsec: float = 2.0       # 1σ
    accel_disturbance_ug: float = 50.0    # the paper's "perturbed acceleration", 1σ
    truth_seed: int = 0                   # the true sensor errors, the same in every run


def _truth(settings: Settings):
    from sim_devices.truth import default_truth

    truth = default_truth(settings.truth_seed)
    truth.accel.noise_density = settings.accel_noise_ug
    truth.gyro.noise_density = settings.gyro_noise_dph
    truth.bench.table_angle_error_arcsec = settings.table_angle_arcsec
    truth.bench.accel_disturbance_ug = settings.accel_disturbance_ug
    return truth


def one_run(args) -> list[float]:
    scheme, settings, seed = args
    from station import simrun
    from station.calibration import parameter_errors
    from station.estimate import zhang2010

    truth = _truth(settings)
    cal = zhang2010.estimate(simrun.simulate_capture(scheme, truth, seed))
    return [e[3] for e in parameter_errors(cal, simrun.truth_calibration(truth))]


def run(scheme: Scheme, settings: Settings, runs: int, first_seed: int = 1000,
        workers: int | None = None) -> tuple[list[tuple[str, str]], np.ndarray]:
    """Errors of ``runs`` dry runs: ((name, unit) per parameter, array runs x parameters)."""
    from station import simrun
    from station.calibration import parameter_errors

    truth_cal = simrun.truth_calibration(_truth(settings))
    names = [(e[0], e[4]) for e in parameter_errors(truth_cal, truth_cal)]
    jobs = [(scheme, settings, first_seed + i) for i in range(runs)]
    workers = workers or min(os.cpu_count() or 1, runs)
    if workers == 1:
        rows = [one_run(j) for j in jobs]
    else:
        with ProcessPoolExecutor(workers) as pool:
            rows = list(pool.map(one_run, jobs, chunksize=max(1, runs // (4 * workers))))
    return names, np.array(rows)
