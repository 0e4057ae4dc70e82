"""Monte Carlo: repeat simulate -> estimate with seeds; compare the spread of the errors with
the Cramér-Rao bound of the scheme and with the uncertainties the estimator reports."""
from __future__ import annotations

import copy
import multiprocessing
import signal
from dataclasses import dataclass
from typing import Callable

import numpy as np

from station.core.forked import usable_cores
from station.io.scheme import Scheme

BASE_PARAMETERS = 21


@dataclass
class Settings:
    accel_noise_ug: float = 100.0         # µg/√Hz
    gyro_noise_dph: float = 0.03          # °/h/√Hz
    table_angle_arcsec: float = 2.0       # 1σ, every encoder angle and table attitude
    accel_disturbance_ug: float = 50.0    # the 2010 paper's "perturbed acceleration", 1σ
    truth_seed: int = 0                   # the true sensor errors, the same in every run
    method: str = "lsq"                   # lsq | zhang2010
    # the effects the lsq fit adds (station estimate --add): library ids, or Effect instances where
    # the model has one the library has not (a plugin, station/model/unlisted.py; _effects)
    effects: tuple = ()
    chamber: object = None                # the configured temperature chamber (station.core.chamber.ChamberConfig)
    # the recorded ramps' acceleration, deg/s^2: the configured table's, as the dry run (station run
    # --sim) takes it (dryrun.table_ramp_accel); None: the dry run's default without a configuration
    ramp_accel_dps2: float | None = None
    # the configured warm-up (station.yaml warmup:, station.bench.config.WarmupConfig), waited for
    # before the first segment as the dry run waits for it (dryrun.warmup_seconds); None: none
    warmup: object = None


def make_truth(settings: Settings):
    from sim_devices.truth import default_truth

    truth = default_truth(settings.truth_seed)
    truth.accel.noise_density = settings.accel_noise_ug
    truth.gyro.noise_density = settings.gyro_noise_dph
    truth.bench.table_angle_error_arcsec = settings.table_angle_arcsec
    truth.bench.accel_disturbance_ug = settings.accel_disturbance_ug
    return truth


def _effects(settings: Settings) -> list:
    """New instances of the settings' effects: a library id's, or a copy of an instance given (a
    plugin's or an unlisted effect's: the same model station estimate and station design fit)."""
    from station.model import LIBRARY

    return [LIBRARY[e]() if isinstance(e, str) else copy.deepcopy(e) for e in settings.effects]


def effect_settings(effects) -> tuple:
    """Settings.effects for a model's effects (instances): their library ids when every one is
    the library's (what a Dask worker unpickles without the user's files), else the instances."""
    from station.model import LIBRARY

    ids = tuple(e.id for e in effects)
    return ids if all(i in LIBRARY and isinstance(e, LIBRARY[i]) for i, e in zip(ids, effects)) else tuple(effects)


def _estimate(capture, settings: Settings):
    from station.estimate import lsq, zhang2010

    if settings.method == "lsq":
        return lsq.estimate(capture, _effects(settings))
    return zhang2010.estimate(capture)


def effect_parameters(cal, effects=()) -> list:
    """(name, value, unit) of the effects' parameters of a calibration, in their reported units
    (the library's, or those of the instances ``effects``: a plugin's); not those the capture
    does not reveal (an entry's not_determined: held by their priors, not written; the tables
    show them as not revealed, NaN)."""
    from station.model import LIBRARY

    units_ = {p.name: p.unit for e in effects for p in e.params}
    for e in cal.effect_compensation or []:
        cls = LIBRARY.get(e["id"])
        if cls is not None:
            units_.update({p.name: p.unit for p in cls().params})
    return [(name, float(v), units_.get(name, "")) for e in cal.effect_compensation or []
            for name, v in e["parameters"].items() if name not in e.get("not_determined", ())]


def _error_sigmas(cal) -> np.ndarray:
    """Reported 1σ in the units of parameter_errors (scale factors relative, in ppm), then the
    effects' parameters' in their units."""
    out = []
    for name, value, _ in cal.parameters()[:BASE_PARAMETERS]:
        sigma = cal.sigma.get(name, np.nan)
        out.append(sigma / value * 1e6 if "_scale_" in name else sigma)
    return np.array(out)


def _effect_values(cal, settings: Settings, sigma: bool = False) -> list:
    """The effects' parameters (or their 1σ) in the order of their full lists, NaN for one the
    calibration does not carry (fixed by the effect's convention, e.g. the size effect's own-axis
    positions when the mounting offset is unknown)."""
    got = {name: (cal.sigma.get(name, np.nan) if sigma else value) for name, value, _ in effect_parameters(cal)}
    held = {name: (np.inf if sigma else np.nan) for name in cal.fit.get("not_determined", [])}
    return [got.get(p.name, held.get(p.name, np.nan)) for e in _effects(settings) for p in e.params]


def one_run(args) -> tuple[list[float], np.ndarray]:
    """One noisy dry run of the scheme estimated: (errors, the fit's own 1σ), parameter_errors'
    units, the effects' parameters after the base model's (run_one)."""
    _, errors, sigmas, _ = run_one(*args)
    return list(errors), sigmas


def run_one(scheme: Scheme, settings: Settings, seed: int) -> tuple:
    """One noisy dry run (seed) of ``scheme`` on the simulated bench (the configured table's ramps,
    its chamber), estimated with the settings' method and effects: (names, errors, the fit's own
    1σ, the fit's notes); errors in parameter_errors' units (scale factors relative, in ppm), each
    effect parameter against zero (the simulator's default IMU has none of the effects: NaN where
    the calibration does not carry it; a 1σ of inf where the capture does not reveal it).  station montecarlo's runs and station design's
    verification (designer.verify_one) are this one function."""
    from station.simulate import dryrun
    from station.model.calibration import parameter_errors

    truth = make_truth(settings)
    capture = dryrun.simulate_capture(scheme, truth, seed, chamber=settings.chamber,
                                      ramp_accel_dps2=settings.ramp_accel_dps2, warmup=settings.warmup)
    effects = _effects(settings)
    if settings.method == "lsq":
        from station.estimate import lsq

        cal = lsq.estimate(capture, effects)
    else:
        cal = _estimate(capture, settings)
    rows = parameter_errors(cal, dryrun.truth_calibration(truth))
    # the effects' full parameter lists, as study() names its columns: new instances (the fit's
    # own were set up on the capture, and an effect may drop there what its convention fixes --
    # the size effect's own-axis positions: a shorter list, every column after it shifted)
    listed = [p for e in _effects(settings) for p in e.params]
    names = [e[0] for e in rows] + [p.name for p in listed]
    got = {name: (value, cal.sigma.get(name, np.nan)) for name, value, _ in effect_parameters(cal, effects)}
    # a parameter the capture does not reveal (held by its prior, not written): no error, an
    # infinite 1σ (NaN and NaN: one its convention fixes)
    got.update({name: (np.nan, np.inf) for name in cal.fit.get("not_determined", []) if name not in got})
    errors = [e[3] for e in rows] + [got.get(p.name, (np.nan, np.nan))[0] for p in listed]
    sigmas = np.concatenate([_error_sigmas(cal), [got.get(p.name, (np.nan, np.nan))[1] for p in listed]])
    return names, np.array(errors, float), np.asarray(sigmas, float), list(cal.fit.get("notes", []))


def cramer_rao(scheme: Scheme, settings: Settings, seed: int = 0) -> np.ndarray:
    """Cramér-Rao lower bound (1σ, units of parameter_errors) of every base parameter for this
    scheme and noise, with the bench nuisances unknown and the static attitudes as the estimator
    takes them (lsq's attitudes="auto": unknown from nine statics on, else the table's, known to
    its angle error -- sizeeffect's six): the inverse Fisher information of the summaries' model
    at the truth, noise from the densities."""
    from station.simulate import dryrun
    from station.estimate import lsq
    from station.estimate.summaries import summarise

    truth = make_truth(settings)
    quiet = copy.deepcopy(truth)
    quiet.accel.noise_density = quiet.gyro.noise_density = 0.0
    quiet.bench.accel_disturbance_ug = quiet.bench.table_angle_error_arcsec = 0.0
    capture = dryrun.simulate_capture(scheme, quiet, seed, chamber=settings.chamber,
                                      ramp_accel_dps2=settings.ramp_accel_dps2, warmup=settings.warmup)
    capture.extra["noise_free"] = True          # (no data-fault scan: station/estimate/data_faults.py)
    s = summarise(capture, table_angle_arcsec=settings.table_angle_arcsec)
    fs = s.sample_rate_hz
    accel_sigma = np.hypot(settings.accel_noise_ug * np.sqrt(fs), settings.accel_disturbance_ug)
    s.accel_sigma = np.full(3, accel_sigma * 9.80665e-6)
    s.gyro_sigma = np.full(3, settings.gyro_noise_dph * np.sqrt(fs) / 3600.0)
    result = lsq.fit(s, _effects(settings))
    cal = lsq.to_calibration(result, capture.imu.accel_unit, capture.imu.gyro_unit)
    return np.concatenate([_error_sigmas(cal), _effect_values(cal, settings, sigma=True)])


def _one_blas_thread() -> None:
    """Each worker process computes with one BLAS thread: the workers already fill the cores,
    and a thread pool per worker on top only contends (the fit's matrices are small)."""
    from threadpoolctl import threadpool_limits

    global _BLAS_LIMIT
    _BLAS_LIMIT = threadpool_limits(limits=1, user_api="blas")


_BLAS_LIMIT = None


def _worker_start() -> None:
    """A worker ignores Ctrl-C (the parent gets it too, ends the workers and exits with
    "interrupted"; no traceback from them) and computes with one BLAS thread."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _one_blas_thread()


@dataclass
class Study:
    """A Monte Carlo study: per base parameter its (name, unit), the errors against the truth
    (runs x parameters, units of parameter_errors: scale factors in ppm) and the reported 1σ
    (same shape), and the Cramér-Rao bound (None unless asked for)."""
    names: list
    errors: np.ndarray
    sigmas: np.ndarray
    crlb: np.ndarray | None
    workers: int


def preload() -> None:
    """Import in this process what a run imports (the estimator, scipy's optimize, special, sparse
    and spatial parts, the simulated world) before the pool forks its workers, so that they
    inherit the modules instead of each importing them: a run's first call in a fresh process
    took 1.04 s of CPU against 0.33 s for the next ones (issue 27 item 5: the share of the
    machine's ceiling).  tests/test_montecarlo_pool.py checks that a run after it imports nothing
    of station, sim_devices or scipy."""
    import scipy.optimize  # noqa: F401
    import scipy.sparse.linalg  # noqa: F401
    import scipy.special  # noqa: F401
    import scipy.spatial.transform  # noqa: F401

    import sim_devices.bench  # noqa: F401
    import sim_devices.truth  # noqa: F401
    from station.estimate import lsq, noise_groups, summaries, zhang2010  # noqa: F401
    from station.model import LIBRARY  # noqa: F401
    from station.model.calibration import parameter_errors  # noqa: F401
    from station.simulate import dryrun  # noqa: F401


# the settings of a study whose effects are instances (a plugin's: a class the registry made, which
# pickles by no importable name), held here for the pool's forked workers, which inherit it: their
# jobs carry None in its place (study)
_INHERITED: list = []


def _settings_of(settings):
    return settings if settings is not None else _INHERITED[0]


def _numbered_run(numbered):
    i, (scheme, settings, seed) = numbered
    return i, one_run((scheme, _settings_of(settings), seed))


def _bound_job(args) -> np.ndarray:
    scheme, settings = args
    return expected_cramer_rao(scheme, _settings_of(settings))


def picklable(settings: Settings) -> bool:
    """Whether the settings can be sent to another interpreter (a Dask worker): effects by id."""
    return all(isinstance(e, str) for e in settings.effects)


# the simulated bench's geometries the bound of a study is averaged over (each static's heading,
# each rotation axis' heading and roll: drawn anew in every run, unknown to the estimator);
# station design's predictions are averaged over the same ones (station/design/designer.py)
GEOMETRY_SEEDS = (0, 1, 2, 3)


def expected_cramer_rao(scheme: Scheme, settings: Settings, seeds=GEOMETRY_SEEDS) -> np.ndarray:
    """The Cramér-Rao bound (1σ, cramer_rao's units) expected over the bench's random geometry:
    the root of the mean over ``seeds`` of each geometry's variance -- what the spread of runs
    that each draw their own geometry is compared with.  One geometry is one draw: a static's
    heading decides which horizontal direction of the gyro bias its Earth rate hides, and the
    gyro biases' bound moved by up to 40 % from draw to draw (docs/design.md, thirteenth
    session)."""
    return np.sqrt(np.mean([cramer_rao(scheme, settings, seed=s) ** 2 for s in seeds], axis=0))


def study(scheme: Scheme, settings: Settings, runs: int, first_seed: int = 1000,
          workers: int | None = None, bound: bool = False,
          progress: Callable[[int, int], None] | None = None, executor=None) -> Study:
    """``runs`` dry runs (seeds first_seed, first_seed + 1, ...) on ``workers`` processes (default:
    every usable core), one BLAS thread each; with ``bound`` the Cramér-Rao bound is computed in
    the same pool, submitted first so that it never runs alone at the end.  ``progress(done,
    runs)`` is called in this process as runs finish (in any order; the results keep the seeds'
    order).  ``executor``: a concurrent.futures.Executor to run them on instead of the local pool
    (a Dask cluster's: ``station montecarlo --scheduler``); ``workers`` then only says how many
    it computes with."""
    from station.simulate import dryrun
    from station.model.calibration import parameter_errors

    dryrun.check_chamber(scheme, settings.chamber)
    truth_cal = dryrun.truth_calibration(make_truth(settings))
    names = [(e[0], e[4]) for e in parameter_errors(truth_cal, truth_cal)]
    names += [(p.name, p.unit) for e in _effects(settings) for p in e.params]
    jobs = [(scheme, settings, first_seed + i) for i in range(runs)]
    workers = max(1, min(workers or usable_cores(), runs + bound))
    rows: list = [None] * runs
    crlb = None
    if progress:
        progress(0, runs)
    if executor is not None:
        rows, crlb = _on_executor(executor, jobs, scheme, settings, bound, progress)
    elif workers == 1:
        from threadpoolctl import threadpool_limits

        with threadpool_limits(limits=1, user_api="blas"):
            for i, job in enumerate(jobs):
                rows[i] = one_run(job)
                if progress:
                    progress(i + 1, runs)
            crlb = expected_cramer_rao(scheme, settings) if bound else None
    else:
        preload()                       # once here, not once in every worker after the fork
        sent = settings
        if not picklable(settings):
            # a plugin's instances: inherited by the forked workers, not pickled to them
            _INHERITED[:] = [settings]
            sent = None
            jobs = [(scheme, None, seed) for _, _, seed in jobs]
        pool = multiprocessing.get_context("fork").Pool(workers, initializer=_worker_start)
        try:
            pending_bound = pool.apply_async(_bound_job, ((scheme, sent),)) if bound else None
            for done, (i, row) in enumerate(pool.imap_unordered(_numbered_run, enumerate(jobs)), 1):
                rows[i] = row
                if progress:
                    progress(done, runs)
            crlb = pending_bound.get() if pending_bound is not None else None
            pool.close()
        finally:
            # after Ctrl-C (the parent's alone) or a failed run the workers are ended at once
            pool.terminate()
            pool.join()
            _INHERITED.clear()
    return Study(names, np.array([r[0] for r in rows]), np.array([r[1] for r in rows]), crlb, workers)


def _on_executor(executor, jobs, scheme, settings, bound, progress) -> tuple[list, np.ndarray | None]:
    """The runs (and the bound, submitted first) on ``executor``; what is not finished is
    cancelled on the way out (a failed run, Ctrl-C)."""
    from concurrent.futures import as_completed

    rows: list = [None] * len(jobs)
    pending_bound = executor.submit(_bound_job, (scheme, settings)) if bound else None
    futures = [executor.submit(_numbered_run, (i, job)) for i, job in enumerate(jobs)]
    try:
        for done, fut in enumerate(as_completed(futures), 1):
            i, row = fut.result()
            rows[i] = row
            if progress:
                progress(done, len(jobs))
        return rows, pending_bound.result() if pending_bound is not None else None
    finally:
        for fut in futures + ([pending_bound] if pending_bound is not None else []):
            fut.cancel()


def run(scheme: Scheme, settings: Settings, runs: int, first_seed: int = 1000,
        workers: int | None = None):
    """((name, unit) per parameter, errors runs x parameters, reported 1σ runs x parameters)."""
    result = study(scheme, settings, runs, first_seed, workers)
    return result.names, result.errors, result.sigmas
