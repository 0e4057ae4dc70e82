"""station's Python API: what the command line does, for notebooks and scripts (docs/api.md).

Plain functions over plain objects, each the same code path as its command:

    import station
    est = station.estimate("captures/run1")                 # station estimate
    est.verdict["result"], est.parameters["accel_scale_x"]  # value, sigma, unit
    est.save("cal.yaml")
    t, f, w = station.apply("cal.yaml", t, accel, gyro)     # station apply, numpy arrays
    frame = station.apply_frame("cal.yaml", df)             # the same on a pandas DataFrame

Stable from version 0.1 (names and arguments below; new keyword arguments may be added): the
functions in ``__all__`` and the attributes of :class:`Estimate` and :class:`Parameter`.  Bad
input raises :class:`station.UserError` with the one-line message the CLI prints (exit 2 there).
Units: accelerometer m/s^2, gyro deg/s, time s, temperature deg C; compensated outputs are in
frame p (the accelerometers' orthogonalised frame, docs/calibration-file.md).  The fitting
functions run with one BLAS thread (STATION_BLAS_THREADS for more) and restore the caller's
setting when they return (station/core/blas.py).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from station.core.blas import limited
from station.core.errors import UserError

__all__ = ["Applied", "EffectInfo", "Estimate", "Exported", "Comparison", "Compiled", "History", "MonteCarlo", "NoiseFiles", "Parameter", "Report",
           "UserError", "apply", "apply_file", "apply_frame", "characterise_noise", "diagnose", "diff", "drift", "effect",
           "effects",
           "estimate", "export", "history", "import_csv", "import_imucal", "import_rosbag", "load_calibration", "montecarlo",
           "noise", "plan", "read_capture", "report", "schemes", "simulate"]


@dataclass(frozen=True)
class Parameter:
    """One estimated parameter in its reported unit (ppm-free: scale factors as numbers near 1)."""
    value: float
    sigma: float | None         # 1-sigma; None where the fit gives none
    unit: str


@dataclass
class Estimate:
    """The result of :func:`estimate`: the calibration, its fit and where it came from."""
    calibration: object         # station.model.calibration.Calibration (the forward model's numbers)
    provenance: dict            # capture path and digest, method, IMU model and serial, scheme
    capture: object             # station.io.capture.Capture (samples not loaded)

    @property
    def parameters(self) -> dict[str, Parameter]:
        """Every written parameter (the ones the capture determines), base and effects."""
        sigma = self.calibration.sigma
        dropped = set(self.calibration.fit.get("not_determined", []))
        return {name: Parameter(float(value), sigma.get(name), unit)
                for name, value, unit in self.calibration.parameters() if name not in dropped}

    @property
    def held(self) -> dict[str, Parameter]:
        """The added effects' parameters the capture does not reveal (not written: the file's
        fit.not_determined): held by their priors, 0 +/- their typical size, in the fit; their
        posterior (value, 1-sigma as fitted, unit), for study only: the calibration does not use it."""
        return {name: Parameter(value, sigma, unit) for name, value, unit, sigma in self.calibration.held}

    @property
    def verdict(self) -> dict:
        """result (passes / fails / not converged / noise overestimated / untested), reason, reduced_chi2 ..."""
        return dict(self.calibration.fit.get("verdict", {}))

    @property
    def fit(self) -> dict:
        """Everything the fit says: chi2, dof, the noise model, the pose check, notes (the file's ``fit``)."""
        return self.calibration.fit

    @property
    def usable(self) -> bool:
        """False when the fit fails or did not converge (the CLI then exits 3)."""
        from station.estimate.verdict import fit_fails

        return not fit_fails(self.calibration)

    @property
    def notes(self) -> list[str]:
        return list(self.calibration.fit.get("notes", []))

    def document(self) -> dict:
        """The calibration file's content (station-calibration/1) as a dict."""
        from station.io.calfile import to_document

        return to_document(self.calibration, self.provenance)

    def save(self, path) -> Path:
        """Write the calibration file, atomically: an existing file at ``path`` is replaced whole
        (a symbolic link there is replaced, its target never written), as ``station estimate -o``."""
        from station.io.calfile import write_calfile

        return write_calfile(Path(path), self.calibration, self.provenance)


def _mc_library() -> dict:
    from station.model import LIBRARY

    return LIBRARY


def _registry(plugins=(), effects_dirs=(), config=None):
    """Where effects come from, as the commands' --config, --effects-dir and --plugin: the library,
    installed entry points, $STATION_EFFECTS_PATH, the effects section of the configuration
    ``config`` names (else $STATION_CONFIG, else station.yaml in the user's own configuration
    folder; never a ./station.yaml merely found in the working directory: loading a plugin runs
    its code), then the folders ``effects_dirs`` and the files ``plugins`` (loaded, not added)."""
    from station.io.config_paths import plugin_config
    from station.model.registry import EffectRegistry

    reg = EffectRegistry()
    config_path = plugin_config(None if config is None else str(config))
    if config_path is not None:
        from station.bench.config import load_config      # the bench only when there is a file to read

        cfg = load_config(str(config_path))
        reg.add_all(cfg.effects.plugins, cfg.effects.folders)
    reg.add_all(list(plugins), list(effects_dirs))
    return reg


def _effect_ids(registry, add) -> list[str]:
    from station.model.registry import effect_ids

    return effect_ids(registry, add)


def _path(capture) -> Path:
    return Path(getattr(capture, "path", capture))


def _whole(name: str, value, least: int) -> None:
    """An argument that must be a whole number >= ``least`` (the CLI's option checks it so)."""
    if not isinstance(value, (int, np.integer)) or isinstance(value, bool) or value < least:
        raise UserError(f"{name}: a whole number >= {least}, not {value!r}")


def _floats(name: str, value) -> np.ndarray:
    """An array argument as floats; text or objects that are not numbers a UserError naming it."""
    try:
        return np.asarray(value, float)
    except (ValueError, TypeError) as e:
        raise UserError(f"apply: {name}: not numbers ({str(e).splitlines()[0][:80]})") from None


def simulate(scheme: str = "optimal9", output=None, *, seed: int = 1, truth=None, dwell_s: float | None = None,
             rate_dps: float | None = None, rotation_s: float | None = None) -> Path:
    """``station run --sim`` without the estimate: record ``scheme`` (a built-in name or a YAML
    file) on the simulated bench into a new capture bundle at ``output`` (default
    captures/<scheme>-sim-<seed>); ``truth``: a truth YAML file (default: the seed's); returns
    the bundle's path (its simulated truth in sim_truth.yaml)."""
    from station.io.scheme import load_scheme
    from station.simulate import dryrun

    _whole("seed", seed, 0)            # numpy's SeedSequence takes a whole number from 0 (as --seed)
    overrides = {k: v for k, v in (("dwell_s", dwell_s), ("rate_dps", rate_dps), ("rotation_s", rotation_s))
                 if v is not None}
    plan = load_scheme(scheme, overrides)
    out = Path(output) if output is not None else Path("captures") / f"{plan.name}-sim-{seed}"
    return dryrun.record_scheme(plan, dryrun.load_truth(None if truth is None else str(truth), seed), seed, out)


def read_capture(path, *, samples: bool = True):
    """A capture bundle (station-capture/1): manifest, segments and (``samples``) their samples
    (``segment.data.t``, ``.accel``, ``.gyro``, ``.temp`` in the capture's units)."""
    from station.io.capture import read_capture as _read

    return _read(Path(path), load_data=samples)


@limited
def estimate(capture, *, method: str = "auto", add=(), plugins=(), effects_dirs=(),
             turn_sigma_deg: float | None = None, max_missing_fraction: float = 0.01,
             max_gap_s: float = 1.0, config=None) -> Estimate:
    """``station estimate``: calibrate from a capture (a path or :func:`read_capture`'s result).

    ``add``: effects to add to the model (library ids, or plugin specs ``FILE.py:CLASS``);
    ``plugins``/``effects_dirs``: plugin files and folders to load first (as ``--plugin``,
    ``--effects-dir``); ``config``: a station.yaml whose effects section names plugins (as
    ``--config``; default $STATION_CONFIG or the user's own); ``turn_sigma_deg``: the hand turns'
    1-sigma per turn (None: estimated).  The verdict is in :attr:`Estimate.verdict` (a failing
    fit is returned, not raised)."""
    from station.estimate import estimate_capture   # scipy and the file writer: while the capture is read

    if not (0 <= max_missing_fraction < 1 and max_gap_s > 0):
        raise UserError("--max-missing-fraction must be within [0, 1) and --max-gap-s > 0")
    if turn_sigma_deg is not None and not (0 <= turn_sigma_deg < 90):
        raise UserError(f"--turn-sigma-deg {turn_sigma_deg}: must be within [0, 90) degrees")
    registry = _registry(plugins, effects_dirs, config)
    cal, capture_read, provenance = estimate_capture(
        _path(capture), method, _effect_ids(registry, add), registry, max_missing_fraction=max_missing_fraction,
        max_gap_s=max_gap_s, turn_sigma_deg=turn_sigma_deg)
    return Estimate(cal, provenance, capture_read)


@limited
def diagnose(capture, *, add=(), plugins=(), effects_dirs=(), config=None, calibration=None, force: bool = False,
             auto: bool = False):
    """``station diagnose`` (without the page): the least-squares fit of the capture with the
    effects ``add`` (and, with ``calibration``, that file's effects; of another IMU serial only
    with ``force``), compared with its measurements.  ``auto``: add the most significant
    candidate that passes the checks, refit, repeat (``--auto``).  Returns
    station.diagnose.core.Diagnosis of the model it ends with: ``verdict`` (words),
    ``reduced_chi2``, ``p_value``, ``segments`` (residuals per segment), ``candidates`` (missing
    effects ranked by the score test), ``failures`` (where it fails), ``effects`` (the model's);
    and ``steps`` (each effect ``auto`` added: ``.added``, ``.before``, ``.after``,
    ``.predicted_drop``, ``.actual_drop``, ``.estimate``), ``first`` (the diagnosis of the model
    as fitted, before any step), ``warnings`` (lines the command prints)."""
    from station.diagnose import DIAGNOSIS_MODULES, segment_check
    from station.estimate import summarise_while_importing

    cap = read_capture(_path(capture), samples=False)        # the manifest: samples below
    # each segment read, checked and summarised (in a child, while the fit is imported here)
    summarise_while_importing(cap, segment_check(cap), modules=DIAGNOSIS_MODULES)
    from station.diagnose import pipeline

    registry = _registry(plugins, effects_dirs, config)
    ids, warnings = _model_effects(cap, registry, add, calibration, force)
    first, steps, final, _ = pipeline.run(cap, ids, registry=registry, auto=auto)
    final.steps, final.first, final.warnings = steps, first, warnings
    return final


def _model_effects(capture, registry, add, calibration, force) -> tuple[list, list]:
    """(the effect ids of the model to diagnose: the calibration file's, then ``add``; warnings)."""
    from station.io.calfile import read_calfile

    effects, warnings = [], []
    if calibration is not None:
        doc = read_calfile(calibration)
        warning = _check_serial(doc, calibration, capture.imu.serial, force, f"capture {capture.path}")
        if warning:
            warnings.append(warning)
        effects += [e for e in doc.get("effects", []) if e not in ("base_triads", "inter_triad")]
    return _effect_ids(registry, list(effects) + list(add)), warnings


def load_calibration(path) -> dict:
    """A calibration file, checked (station-calibration/1): ``parameters`` {name: {value, unit,
    sigma}}, ``verdict``, ``fit``, ``compensation`` (what :func:`apply` uses)."""
    from station.io.calfile import read_calfile

    return read_calfile(Path(path))


def apply(calibration, t, accel, gyro, temp=None, *, plugins=(), effects_dirs=(), config=None):
    """``station apply`` on arrays: raw IMU samples (t (N,) s; accel, gyro (N, 3) in the
    calibration's units) -> (t, specific force m/s^2, rate deg/s), compensated, frame p.
    ``calibration``: a file path, or :func:`load_calibration`'s or :meth:`Estimate.document`'s dict."""
    from station.io.calfile import read_calfile

    doc = calibration if isinstance(calibration, dict) else read_calfile(Path(calibration))
    where = "calibration" if isinstance(calibration, dict) else str(calibration)
    t = _floats("t", t).reshape(-1)
    accel, gyro = _floats("accel", accel), _floats("gyro", gyro)
    if accel.shape != (len(t), 3) or gyro.shape != (len(t), 3):
        raise UserError(f"apply: accel and gyro must be ({len(t)}, 3) like t, got {accel.shape} and {gyro.shape}")
    temp = None if temp is None else _floats("temp", temp).reshape(-1)
    return _compensate(doc, where, None, t, accel, gyro, temp, (plugins, effects_dirs, config), [])


def _compensate(doc, where, source, t, accel, gyro, temp, registry_args, messages):
    """What ``station apply`` computes, for :func:`apply` (arrays: ``source`` None) and
    :func:`apply_file` (``source`` the input file): the checks, the compensation with every
    effect of the calibration, and the lines the command prints (into ``messages``)."""
    from station.io.calfile import compensation_effects, not_compensated
    from station.model.compensate import LEGACY_EFFECTS, compensate, compensate_with_effects

    _check_gyro_output(doc, where)
    comp = doc["compensation"]
    if "effects" in comp:
        effects = compensation_effects(doc, _registry(*registry_args), where)
        # parameters the capture did not determine: compensated at their nominal 0, which is no
        # correction; an effect none of whose parameters is determined is left out (nor are its
        # inputs, a temperature column or rates of change, needed)
        held = {eid: (names, whole) for eid, names, whole in not_compensated(doc)}
        effects = [(e, x) for e, x in effects if not held.get(e.id, ((), False))[1]]
        needs = {need: [e.id for e, _ in effects if need in e.needs] for need in ("temperature", "time")}
        if needs["temperature"] and temp is None:
            if source is None:
                raise UserError(f"apply: {', '.join(needs['temperature'])} need the temperature (temp, deg C)")
            raise UserError(f"{source}: no temp column, which the compensation of "
                            f"{', '.join(needs['temperature'])} needs (deg C)")
        if needs["time"] and len(t) < 3:
            raise UserError(f"{source or 'apply'}: {len(t)} samples; the compensation of "
                            f"{', '.join(needs['time'])} needs rates of change (at least 3 samples)")
        t, f, w = compensate_with_effects(comp, effects, t, accel, gyro, temp)
        for e, _ in effects:
            inputs = ", ".join(e.needs)
            part = held.get(e.id, ((), False))[0]
            messages.append(f"compensated: {e.id} ({getattr(e, '_station_source', 'library')})"
                            + (f", using {inputs}" if inputs else "")
                            + (f"; not compensated: {', '.join(part)} (not determined by the capture: its "
                               "nominal 0 is used)" if part else ""))
        for eid, (names, whole) in held.items():
            if whole:
                messages.append(f"not compensated: {eid} (not determined by the capture: {', '.join(names)}; "
                                "the effect is left out)")
    else:                               # a file written before compensation.effects
        f, w = compensate(comp, t, accel, gyro, temp)
        skipped = [e for e in doc.get("effects", []) if e not in LEGACY_EFFECTS]
        if skipped:
            messages.append(f"note: this calibration file predates compensation.effects: not compensated: "
                            f"{', '.join(skipped)} (estimate again to compensate them)")
    if doc.get("gyro_pass_through"):
        messages.append(f"note: {where} calibrates the accelerometers only: the gyro columns are "
                        "passed through untouched (converted to deg/s only)")
    verdict = doc.get("verdict") or {}
    if verdict.get("result") in ("fails", "not converged"):
        messages.append(f"warning: {where}: its fit "
                        f"{verdict['result'].replace('not converged', 'did not converge')} "
                        f"({verdict.get('reason', '')})")
    return t, f, w


def _check_gyro_output(doc, where) -> None:
    if doc.get("gyro_pass_through") and (doc.get("imu") or {}).get("gyro_unit") == "raw":
        raise UserError(f"{where}: calibrates the accelerometers only, and the gyro output is in "
                        "raw counts: apply has no scale to write the gyros in deg/s (calibrate the gyros: "
                        "rotations with encoder angles, or hand turns between statics)")


def _check_serial(doc: dict, calibration, serial, force: bool, what: str) -> str | None:
    """Refuse (UserError) a calibration ``doc`` made for another IMU than ``serial`` unless
    ``force``; with ``force``, the warning to show (None when the serials agree or one is
    unknown)."""
    made_for = (doc.get("provenance") or {}).get("imu_serial") or (doc.get("imu") or {}).get("serial")
    if serial is None or made_for is None or str(made_for) == str(serial):
        return None
    if force:
        return (f"warning: {calibration} was made for IMU serial {made_for}, {what} comes from serial "
                f"{serial}: used anyway (--force)")
    raise UserError(f"{calibration}: field 'provenance.imu_serial': made for IMU serial {made_for}, "
                    f"but {what} comes from serial {serial}: refused (--force uses it anyway)")


@dataclass
class Applied:
    """What :func:`apply_file` did: the file written, its sample count, and the lines the command
    prints on stderr (each effect compensated and the inputs it used, notes, warnings)."""
    output: Path
    samples: int
    messages: list


def apply_file(calibration, input, output, *, serial: str | None = None, force: bool = False, plugins=(),
               effects_dirs=(), config=None) -> Applied:
    """``station apply CAL IN.csv -o OUT.csv``: compensate the raw samples of a CSV
    (t,ax,ay,az,gx,gy,gz[,temp] in the raw units) into OUT.csv (t,ax,ay,az,gx,gy,gz in m/s^2 and
    deg/s, frame p).  Refuses a calibration made for another IMU serial (``serial``, or that of
    the capture IN.csv lies in) unless ``force``.  An output given as a symbolic link is written
    through it."""
    from station.core.errors import cannot_write
    from station.io.calfile import read_calfile
    from station.io.capture import MANIFEST, read_capture as _read, read_segment_csv

    doc = read_calfile(calibration)
    if serial is None:         # the serial of the capture the input lies in, if it lies in one
        folder = Path(input).parent
        if (folder / MANIFEST).is_file():
            serial = _read(folder, load_data=False).imu.serial
    messages = []
    warning = _check_serial(doc, calibration, serial, force, str(input))
    if warning:
        messages.append(warning)
    _check_gyro_output(doc, str(calibration))
    data = read_segment_csv(Path(input))
    t, f, w = _compensate(doc, str(calibration), str(input), data.t, data.accel, data.gyro, data.temp,
                          (plugins, effects_dirs, config), messages)
    table = np.column_stack([t, f, w])
    from station.core.user_files import output_path

    output_path(output, "the compensated samples")
    try:
        with open(output, "w") as fh:
            fh.write("t,ax,ay,az,gx,gy,gz\n")
            np.savetxt(fh, table, delimiter=",", fmt=["%.9f"] + ["%.12g"] * 6)
    except OSError as e:
        raise cannot_write(output, e) from None
    return Applied(Path(output), len(table), messages)


COLUMNS = ("t", "ax", "ay", "az", "gx", "gy", "gz")


def apply_frame(calibration, frame, *, plugins=(), effects_dirs=(), config=None):
    """:func:`apply` on a pandas DataFrame with columns t, ax, ay, az, gx, gy, gz (and temp when
    an effect needs it): a new DataFrame with the same columns, compensated (m/s^2, deg/s).  A
    column that is not numbers is a UserError naming it."""
    import pandas as pd

    missing = [c for c in COLUMNS if c not in frame.columns]
    if missing:
        raise UserError(f"apply_frame: the frame has no column {', '.join(missing)} (needs {', '.join(COLUMNS)})")

    def numbers(*names):
        try:
            return frame[list(names)].to_numpy(float)
        except (ValueError, TypeError) as e:
            bad = next((n for n in names if not pd.api.types.is_numeric_dtype(frame[n])), names[0])
            raise UserError(f"apply_frame: column {bad!r} is not numbers ({str(e).splitlines()[0][:80]})") from None

    temp = numbers("temp")[:, 0] if "temp" in frame.columns else None
    t, f, w = apply(calibration, numbers("t")[:, 0], numbers("ax", "ay", "az"), numbers("gx", "gy", "gz"), temp,
                    plugins=plugins, effects_dirs=effects_dirs, config=config)
    return pd.DataFrame(np.column_stack([t, f, w]), columns=list(COLUMNS), index=frame.index[:len(t)])


def import_csv(path, output, *, gravity_mps2: float = 9.80665, **options):
    """``station import csv``: a continuous log into a capture bundle at ``output``; returns the
    import report (``.path``, ``.lines``: what the CLI prints).  ``options``: read_delimited's
    (preset, columns {role: column}, delimiter, header, accel_unit, gyro_unit, accel_nominal,
    gyro_nominal, time_unit, rate_hz, gyro_path) and write_capture's (latitude_deg,
    sections_path, window_s, min_static_s, rate_threshold_dps, init_rest_s, min_poses, model,
    serial, faces, placement_deg)."""
    from station.io.importers import delimited, recording

    read_keys = ("preset", "columns", "delimiter", "header", "accel_unit", "gyro_unit", "accel_nominal",
                 "gyro_nominal", "time_unit", "rate_hz", "gyro_path")
    unknown = set(options) - set(read_keys) - set(_WRITE_KEYS)
    if unknown:
        raise UserError(f"import_csv: unknown option {', '.join(sorted(unknown))}")
    rec = delimited.read_delimited(path, **{k: v for k, v in options.items() if k in read_keys})
    return recording.write_capture(rec, output, gravity_mps2=gravity_mps2,
                                   **{k: v for k, v in options.items() if k in _WRITE_KEYS})


_WRITE_KEYS = ("latitude_deg", "sections_path", "window_s", "min_static_s", "rate_threshold_dps", "init_rest_s",
               "min_poses", "model", "serial", "faces", "placement_deg")


def import_rosbag(path, output, *, topic: str | None = None, stamps: str = "header",
                  gravity_mps2: float = 9.80665, rate_hz: float | None = None, **options):
    """``station import rosbag``: sensor_msgs/Imu from a ROS 1/2 bag or MCAP file into a capture
    (``rate_hz``: re-time the messages evenly, as ``--rate-hz``)."""
    from station.io.importers import recording, rosbag

    unknown = set(options) - set(_WRITE_KEYS)
    if unknown:
        raise UserError(f"import_rosbag: unknown option {', '.join(sorted(unknown))}")
    rec = rosbag.read_rosbag(path, topic=topic, stamps=stamps, rate_hz=rate_hz)
    return recording.write_capture(rec, output, gravity_mps2=gravity_mps2, **options)


def import_imucal(path, output, *, rate_hz: float, **options) -> Path:
    """``station import imucal``: an imucal Ferraris session into a capture; returns its path.
    ``options``: sections_path, fmt, gravity_mps2, accel_unit, gyro_unit, model, serial, turn_deg."""
    from station.io.importers import imucal

    return imucal.import_imucal(path, output, rate_hz=rate_hz, **options)


class Exported(list):
    """:func:`export`'s result: the files written (a list of paths), with ``convention`` (the
    format's convention, one paragraph) and ``notes`` (what the export says about the source:
    units, what the format cannot hold)."""
    convention: str = ""
    notes: list = []


def export(calibration, to: str, output=None, *, noise=None, force: bool = False) -> Exported:
    """``station export --to``: a calibration file in another tool's format (imucal, imu_tk,
    kalibr, ros, c, json); returns the files written.  ``output``: a file, or a folder (the
    default name inside it); default: next to the calibration, named CAL-FORMAT with the
    format's ending.  ``noise``: a NOISE.yaml from :func:`characterise_noise` when the
    calibration holds no noise figures (Kalibr needs them); of another IMU serial only with
    ``force``."""
    from station.io.calfile import read_calfile
    from station.io.exporters import FORMATS, source_from_document
    from station.io.noise_file import noise_serial, read_noise_block

    if to not in FORMATS:
        raise UserError(f"export: unknown format {to!r}: use one of {', '.join(FORMATS)}")
    fmt = FORMATS[to]
    path = Path(calibration)
    source = source_from_document(read_calfile(path), path)
    if noise is not None:
        source.noise, source.noise_origin = read_noise_block(noise), str(noise)
        other = noise_serial(noise)
        if other and source.imu_serial and other != source.imu_serial and not force:
            raise UserError(f"{noise}: noise of IMU {other!r}, calibration of IMU {source.imu_serial!r} "
                            "(--force to combine them anyway)")
    name = f"{path.stem}-{to}{fmt.SUFFIX}"
    target = Path(output) if output is not None else path.with_name(name)
    if output is not None and (target.is_dir() or str(output).endswith(("/", "\\"))):
        target = target / name            # a folder: the default name inside it
    written = Exported(Path(p) for p in fmt.write(source, target))
    written.convention = fmt.CONVENTION
    written.notes = list(source.header_lines()[1:])
    return written


@limited
def noise(capture, *, segment: str | None = None, calibration=None):
    """``station noise`` on a capture: the Allan deviation of its longest static (or ``segment``)
    and the noise terms read from it (station.estimate.noise.NoiseResult: per axis the white
    noise, bias instability, random walk, with their intervals)."""
    from station.estimate import noise as _noise

    doc = None
    if calibration is not None:
        doc = calibration if isinstance(calibration, dict) else load_calibration(calibration)
    return _noise.from_capture(read_capture(_path(capture), samples=False), segment, doc)


@dataclass
class NoiseFiles:
    """What :func:`characterise_noise` found and wrote: ``result`` (station.estimate.noise.
    NoiseResult: per axis the white noise, bias instability, random walk), ``block`` (the figures
    as written, with Kalibr's four numbers under ``kalibr``), ``figures`` (the file they were
    written into), ``plot`` (the Allan deviation plot), ``warnings`` (lines the command prints)."""
    result: object
    block: dict
    figures: Path
    plot: Path
    warnings: list


@limited
def characterise_noise(source, *, calibration=None, segment: str | None = None, topic: str | None = None,
                       rate_hz: float | None = None, accel_unit: str = "m/s^2", gyro_unit: str = "deg/s",
                       plot=None, force: bool = False) -> NoiseFiles:
    """``station noise``: the overlapping Allan deviation of a still IMU and its noise terms,
    written down.  ``source``: a capture bundle (its longest static segment, or ``segment``), a
    CSV t,ax,ay,az,gx,gy,gz (``rate_hz``, ``accel_unit``, ``gyro_unit``), or a ROS bag (ROS 1
    .bag, ROS 2 folder, .mcap; ``topic``).  The figures go into ``calibration`` (default: the
    capture's calibration.yaml when it exists; of another IMU serial only with ``force``), else
    NOISE.yaml beside the recording (a CSV's or bag's named after it); the plot to ``plot``
    (default allan.png beside the figures; .svg for SVG)."""
    from types import SimpleNamespace

    from station.core.errors import cannot_write
    from station.diagnose.figures import allan_figure
    from station.estimate import noise as _noise
    from station.io.calfile import read_calfile
    from station.io.capture import read_segment_csv
    from station.io.noise_file import write_into_calibration, write_noise_file

    src = Path(source)
    cal = None if calibration is None else str(calibration)
    cal_doc = read_calfile(cal) if cal else None
    model = serial = None
    warnings = []
    bag = (src.suffix in (".bag", ".mcap", ".db3")
           or (src.is_dir() and (src / "metadata.yaml").is_file() and not (src / "manifest.yaml").exists()))
    if bag:          # a still IMU recorded as a ROS bag (allan_variance_ros's use): its whole length
        from station.io.importers.rosbag import read_rosbag

        if segment:
            raise UserError("--segment applies to a capture bundle, not to a bag")
        rec = read_rosbag(src, topic=topic)
        here = src.parent
        result = _noise.from_samples(src, SimpleNamespace(t=rec.t, accel=rec.accel, gyro=rec.gyro), rate_hz,
                                     rec.accel_unit, rec.gyro_unit, cal_doc)
    elif src.is_dir() or src.name == "manifest.yaml":
        capture = read_capture(src, samples=False)     # from_capture reads the static segments
        here = capture.path
        default_cal = here / "calibration.yaml"
        if cal_doc is None and default_cal.exists():
            cal, cal_doc = str(default_cal), read_calfile(default_cal)
        result = _noise.from_capture(capture, segment, cal_doc)
        model, serial = capture.imu.model, capture.imu.serial
        cal_serial = ((cal_doc or {}).get("provenance") or {}).get("imu_serial")
        if serial and cal_serial and serial != cal_serial and not force:
            raise UserError(f"{cal}: calibration of IMU {cal_serial!r}, recording of IMU {serial!r}: "
                            "the noise belongs to the IMU recorded (--force to write it anyway)")
        used = capture.segment(result.segment)
        if used.data.gaps:
            warnings.append("warning: the recording has gaps; the Allan deviation assumes even sampling")
        if used.status == "incomplete":
            warnings.append(f"warning: segment {used.name} is incomplete (the recording stopped): its "
                            f"{len(used.data.t)} samples before it stopped are characterised")
    else:
        if segment:
            raise UserError("--segment applies to a capture bundle, not to a CSV file")
        data = read_segment_csv(src, sample_rate_hz=rate_hz)
        here = src.parent
        result = _noise.from_samples(src, data, rate_hz, accel_unit, gyro_unit, cal_doc)
    block = result.block()
    # a capture holds one noise file and plot; a CSV's are named after it (two recordings in one
    # folder do not overwrite each other's)
    stem = f"{src.stem}-" if bag or not (src.is_dir() or src.name == "manifest.yaml") else ""
    if cal:
        target = write_into_calibration(cal, block)
    else:
        target = write_noise_file(here / f"{stem}noise.yaml", block, model, serial)
    png = Path(plot) if plot else Path(target).with_name(f"{stem}allan.png")
    try:
        allan_figure(result, png)
    except OSError as e:
        raise cannot_write(png, e) from None
    return NoiseFiles(result, block, Path(target), png, warnings)


@dataclass
class Report:
    """:func:`report`'s result: the page written and the warnings the command prints."""
    path: Path
    warnings: list


@limited
def report(capture, *, calibration=None, output=None, force: bool = False, auto: bool = True) -> Report:
    """``station report``: one self-contained HTML page about a capture and its calibration
    (``calibration``, default the capture's calibration.yaml if it exists; of another IMU serial
    only with ``force``): capture, IMU, scheme, dates; parameters +- 1 sigma; the fit verdict;
    residuals before and after each added effect (``auto``: the add-and-refit loop); candidates;
    noise.  ``output``: default CAPTURE/report.html."""
    from station.diagnose.report import report_input, write_page
    from station.io.calfile import read_calfile

    cap = read_capture(_path(capture), samples=False)     # the manifest: samples as needed
    cal_path = Path(calibration) if calibration is not None else cap.path / "calibration.yaml"
    cal_doc = read_calfile(cal_path) if (calibration is not None or cal_path.exists()) else None
    warnings = []
    if cal_doc is not None:
        warning = _check_serial(cal_doc, cal_path, cap.imu.serial, force, f"capture {cap.path}")
        if warning:
            warnings.append(warning)
    # the effects as diagnose builds them (station.diagnose.pipeline.run: the same diagnosis)
    registry = _registry()
    effects = _effect_ids(registry, [e for e in (cal_doc or {}).get("effects", [])
                                     if e not in ("base_triads", "inter_triad")])
    inp = report_input(cap, cal_doc, cal_path if cal_doc else None, effects=effects, auto=auto, registry=registry)
    target = Path(output) if output is not None else cap.path / "report.html"
    write_page(target, inp)
    return Report(target, warnings)


@dataclass(frozen=True)
class EffectInfo:
    """An effect the model can add: ``id`` (for ``add=``), ``title``, ``source`` (library, a
    plugin file, a package); from :func:`effect` also its physics, ``term`` in the measurement
    equation, what excites it, typical sizes, its signature when missing, its parameters
    ((name, unit) pairs) and what its compensation needs."""
    id: str
    title: str
    source: str
    physics: str = ""
    term: str = ""
    excited_by: str = ""
    magnitudes: str = ""
    signature: str = ""
    parameters: tuple = ()
    needs: tuple = ()


def effects(*, plugins=(), effects_dirs=(), config=None) -> list[EffectInfo]:
    """``station effects``: every effect the model can add (library, installed packages'
    entry points, plugins), sorted by id."""
    reg = _registry(plugins, effects_dirs, config)
    return [EffectInfo(eid, reg.classes[eid].title, reg.source(eid)) for eid in reg.ids()]


def effect(name: str, *, plugins=(), effects_dirs=(), config=None) -> EffectInfo:
    """``station effects NAME``: one effect explained (UserError for an unknown name)."""
    reg = _registry(plugins, effects_dirs, config)
    e = reg.create(name)
    params = getattr(e, "all_params", None) or e.params
    return EffectInfo(e.id, e.title, reg.source(e.id), e.physics, e.term, e.excited_by, e.magnitudes, e.signature,
                      tuple((p.name, p.unit) for p in params or ()), tuple(e.needs))


@dataclass
class MonteCarlo:
    """:func:`montecarlo`'s result: ``scheme`` (its name), ``runs``, ``method``, ``settings``
    (the noise and table figures simulated, with their units in the names), ``workers`` (the
    processes used), and ``parameters``: per parameter a dict with ``name``, ``unit``, ``std``
    (of the error against the simulated truth), ``crlb`` (the Cramér-Rao bound), ``mean_sigma``
    (the mean reported 1-sigma; None when the method reports none) and ``mean_error`` (scale
    factors relative); ``crlb`` None for a parameter the noiseless capture does not reveal.
    ``not_revealed``: {name: the runs whose capture did not reveal it} of the effects' parameters
    held by their priors and not written.  Such a parameter revealed in some runs has a row over
    every run (the error of the value each calibration compensates with: its nominal 0 where held,
    not the revealing runs alone, which are selected on the outcome), ``revealed_runs`` (how many
    revealed it) and no ``mean_sigma`` (the held runs write none); held in every run, none."""
    scheme: str
    runs: int
    method: str
    settings: dict
    workers: int
    parameters: list
    effects: tuple = ()
    not_revealed: dict = field(default_factory=dict)


def montecarlo(scheme: str = "optimal9", runs: int = 100, *, seed: int = 1000, accel_noise_ug: float = 100.0,
               gyro_noise_dph: float = 0.03, table_angle_arcsec: float = 2.0, accel_disturbance_ug: float = 50.0,
               method: str = "lsq", effects=(), progress=None, executor=None, workers=None,
               config=None, plugins=(), effects_dirs=()) -> MonteCarlo:
    """``station montecarlo``: ``runs`` dry runs of ``scheme`` (seeds ``seed``, ``seed`` + 1, ...)
    estimated with ``method`` (lsq or zhang2010) on every usable core, against the Cramér-Rao
    bound.  Noise densities: accelerometer µg/√Hz, gyro °/h/√Hz; ``table_angle_arcsec``: 1-sigma
    table angle error; ``accel_disturbance_ug``: 1-sigma white acceleration disturbance.
    ``effects``: library effects fitted too (lsq only; the simulated IMU has none of them, so
    their parameters' errors are against zero; one that its convention fixes is in no run's
    calibration and left out): ids or plugins as :func:`estimate` takes them (``plugins``,
    ``effects_dirs``, ``config``: the same registry; an unlisted effect, station/model/unlisted.py,
    by its id).  The dry runs ramp at the configured table's ``rate_accel_dps2`` (``config``: as
    ``station run --sim`` does).  ``progress(done, total)`` is called as runs finish.  ``executor``:
    a concurrent.futures executor to run them on (a Dask client's: ``station montecarlo
    --scheduler``) with ``workers`` its workers (default: a process pool on every usable core)."""
    import warnings

    from station.io.scheme import load_scheme
    from station.simulate import montecarlo as _mc

    _whole("runs", runs, 2)
    _whole("seed", seed, 0)
    effects = tuple(dict.fromkeys(effects or ()))
    instances = []
    if effects:
        if method != "lsq":
            raise UserError("--add needs --method lsq (the 2010 method fits the base model only)")
        # the registry estimate and design use (library, plugins, unlisted effects): one model
        registry = _registry(plugins, effects_dirs, config)
        instances = [registry.create(e) for e in _effect_ids(registry, effects)]
        effects = tuple(e.id for e in instances)
    plan = load_scheme(scheme)
    from station.bench.config import load_config
    from station.simulate.dryrun import table_ramp_accel, warmup_seconds

    cfg = load_config(config)
    if executor is not None and not all(e.id in _mc_library() for e in instances):
        raise UserError("--scheduler: a plugin's effect cannot be sent to the Dask workers (they do not load your "
                        "files); run its Monte Carlo on this machine's cores (without --scheduler)")
    settings = _mc.Settings(accel_noise_ug=accel_noise_ug, gyro_noise_dph=gyro_noise_dph,
                            table_angle_arcsec=table_angle_arcsec, accel_disturbance_ug=accel_disturbance_ug,
                            method=method, effects=_mc.effect_settings(instances),
                            chamber=cfg.chamber if plan.chamber_steps else None,
                            ramp_accel_dps2=table_ramp_accel(cfg.table), warmup=cfg.warmup)
    # (a warm-up it cannot wait: one line, before any run); said in the result's settings
    warm_s = warmup_seconds(cfg.warmup, _mc.make_truth(settings).temperature)
    result = _mc.study(plan, settings, runs, first_seed=seed, bound=True, progress=progress, executor=executor,
                       workers=workers)
    errors, sigmas = result.errors, result.sigmas
    # an effect parameter a run's capture does not reveal (held by its prior, not written: no
    # error, 1σ inf) is compensated there at its nominal 0, and the simulated IMU has none of the
    # effects: that run's error is 0.  Its row is over every run, of the value each calibration
    # compensates with (written, or the nominal where held): over the revealing runs only it was
    # selected on the outcome (a prior the data contradict is released by the value's size:
    # lsq._contradicted_priors).  Its mean 1σ is None: the held runs write none, and the revealing
    # runs' alone would be compared with a spread they are not the runs of (issue 28, nineteenth
    # session)
    held = np.isinf(sigmas) & np.isnan(errors)
    revealed = len(errors) - held.sum(axis=0)
    errors = np.where(held, 0.0, errors)
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)        # (a column of NaN: left out below)
        std = errors.std(axis=0, ddof=1)
        mean_error = errors.mean(axis=0)
        sigmas = np.where(held, np.nan, sigmas)
        mean_sigma = np.nanmean(sigmas, axis=0) if np.isfinite(sigmas).any() else np.full(len(std), np.nan)
    mean_sigma = np.where(held.any(axis=0), np.nan, mean_sigma)
    rows = [{"name": n, "unit": u, "std": float(sd), "crlb": float(c) if np.isfinite(c) else None,
             "mean_sigma": None if not np.isfinite(ms) else float(ms), "mean_error": float(me),
             **({"revealed_runs": int(k)} if k < runs else {})}
            for (n, u), sd, c, ms, me, k in zip(result.names, std, result.crlb, mean_sigma, mean_error, revealed)
            if np.isfinite(sd) and k > 0]
    not_revealed = {n: int(k) for (n, _), k in zip(result.names, held.sum(axis=0)) if k}
    return MonteCarlo(plan.name, runs, method, {"accel_noise_ug_rthz": accel_noise_ug,
                                                "gyro_noise_dph_rthz": gyro_noise_dph,
                                                "table_angle_arcsec": table_angle_arcsec,
                                                "accel_disturbance_ug": accel_disturbance_ug,
                                                # the configured warm-up waited on the simulated IMU
                                                # before every run's first segment (0: none)
                                                "warmup_s": float(warm_s)},
                      result.workers, rows, effects, not_revealed)


@dataclass
class History:
    """:func:`history`'s result: ``store`` (where its index is: a folder, or the PostgreSQL
    database's URL without its password), ``filed`` ((entry, new) for each file
    given to ``add``: new False when it, or a calibration of the same capture and model, was
    filed before), ``serials`` ((serial, count) of every IMU in the store), ``entries`` (the
    calibrations of ``serial``, oldest first: each ``.id``, ``.serial``, ``.date_utc``,
    ``.scheme``, ``.method``, ``.verdict``, ``.path``, ``.imu_model``, ``.lot``)."""
    store: str
    filed: list
    serials: list
    entries: list


def history(serial: str | None = None, *, store=None, add=(), lot: str | None = None,
            imu_model: str | None = None) -> History:
    """``station history [SERIAL] [--add CAL [--lot L] [--imu-model M]]``: the calibration history
    (``store``: a folder or a ``postgresql://`` URL; default $STATION_STORE, $STATION_HISTORY_DIR
    or the user's data directory: docs/fleet.md), the calibrations ``add`` filed into it first,
    with the IMU's ``lot`` and ``imu_model`` when given.  Filing runs no policy: what you give is
    filed (the commands file only real IMUs')."""
    from station.io.history import Store

    if (lot or imu_model) and not add:
        raise UserError("--lot and --imu-model go with --add CAL.yaml (they are filed with a calibration)")
    with Store(store) as st:
        filed = [st.file(cal, lot=lot, imu_model=imu_model) for cal in add]
        return History(st.where, filed, st.serials(), st.list(serial) if serial is not None else [])


def rebuild_history(*, store=None):
    """``station history --rebuild``: a new index of the calibration store built from the
    calibration files in its folder (after the index was lost or damaged: a zero-byte
    ``index.sqlite`` is refused, not read as an empty history).  Returns a ``Rebuilt``:
    ``.where`` (the index), ``.filed`` (the entries), ``.skipped`` ((file, why) pairs: links,
    files outside the store, files that are not calibrations, duplicates) and ``.kept_aside``
    (the old SQLite index, renamed ``index.sqlite.before-rebuild-UTC``)."""
    from station.io.history import Store

    with Store(store) as st:
        return st.rebuild()


@dataclass
class Comparison:
    """:func:`diff`'s result: ``a``, ``b`` (the files compared), their documents ``doc_a``,
    ``doc_b``, ``changes`` (per parameter in both: ``.name``, ``.before``, ``.after``,
    ``.change`` in its unit, ``.change_ppm`` for scale factors, ``.unit``, ``.z`` = change over
    sqrt(sigma_A^2 + sigma_B^2), None without both sigmas, ``.flagged`` over 3 sigma),
    ``only_a``, ``only_b`` (parameter names), ``warnings`` (a fit that does not pass)."""
    a: Path
    b: Path
    doc_a: dict
    doc_b: dict
    changes: list
    only_a: list
    only_b: list
    warnings: list


def diff(a, b, *, store=None) -> Comparison:
    """``station diff A B``: two calibrations (files, or ids ``#N`` of the history in
    ``store``) compared parameter by parameter, in their units and in combined sigma."""
    from station.io.calcompare import changes
    from station.io.calfile import read_calfile
    from station.io.history import Store, verdict_of

    with Store(store) as st:
        pa, pb = st.resolve(str(a)), st.resolve(str(b))
    da, db = read_calfile(pa), read_calfile(pb)
    rows, only_a, only_b = changes(da, db)
    warnings = []
    for label, doc in (("A", da), ("B", db)):
        verdict = verdict_of(doc)
        if not verdict.startswith("passes"):
            warnings.append(f"warning: {label}'s fit does not pass ({verdict.split(': ')[0]}): its numbers are not a "
                            "calibration to compare against")
    return Comparison(pa, pb, da, db, rows, only_a, only_b, warnings)


def drift(serial: str, output, *, store=None) -> tuple[Path, list]:
    """``station history SERIAL --drift PNG``: every parameter of the IMU's filed calibrations
    against the date, +- 1 sigma, those whose fit does not pass drawn apart; returns (the plot,
    the entries drawn apart as "#N verdict")."""
    from station.core.errors import cannot_write
    from station.diagnose.figures import drift_figure, drift_status
    from station.io.calfile import read_calfile
    from station.io.history import Store

    with Store(store) as st:
        entries = st.list(serial) if isinstance(serial, str) else []
        where = st.where
    if not entries:
        raise UserError(f"no calibration of IMU {serial!r} in {where} (station history lists the serials)")
    unverified = [f"#{e.id} not drawn: {e.problem}" for e in entries if e.problem]
    entries = [e for e in entries if not e.problem]
    if not entries:
        raise UserError(f"IMU {serial!r} in {where}: no calibration whose file is the one filed ({'; '.join(unverified)})")
    png = Path(output)
    rows: dict = {}
    for e in entries:
        doc = read_calfile(e.path)
        status = drift_status(e.verdict)
        for name, p in doc["parameters"].items():
            rows.setdefault(name, []).append((e.date_utc, p["value"], p.get("sigma"), p["unit"], status))
    marked = [f"#{e.id} {e.verdict.split(':')[0]}" for e in entries if drift_status(e.verdict) != "passes"] + unverified
    rows = {k: v for k, v in rows.items() if len(v) == len(entries)}
    try:
        drift_figure(rows, png, f"IMU {serial}: {len(entries)} calibrations, value ± 1σ")
    except OSError as e:
        raise cannot_write(png, e) from None
    except ValueError as e:
        raise UserError(f"{png}: cannot plot the drift: {e}") from None
    return png, marked


@dataclass
class Compiled:
    """:func:`plan`'s result: ``scheme`` (the scheme as loaded: ``.name``, ``.title``,
    ``.segments``, ``.duration_s`` of recording), ``config`` (the configuration it was compiled
    for: ``.table``, ``.run``, ``.source``), and ``plan`` (the table's steps: ``.steps``, each
    with ``.describe()`` and ``.estimate_s``; ``.notes``; ``.duration_s`` of device time;
    ``.manual`` for a scheme done by hand)."""
    scheme: object
    config: object
    plan: object


def _bench_config(config=None, *, port=None, imu_protocol=None, table_port=None, table_protocol=None,
                  unattended: bool = False):
    """station.yaml (``config``; default $STATION_CONFIG, ./station.yaml, the built-in) with the
    commands' overrides."""
    from station.bench.config import load_config

    cfg = load_config(None if config is None else str(config))
    cfg = cfg.with_overrides("imu", port=port, protocol=imu_protocol)
    cfg = cfg.with_overrides("table", port=table_port, protocol=table_protocol)
    if unattended:
        cfg = cfg.with_overrides("run", operator=False)
    return cfg


def plan(scheme: str = "optimal9", *, config=None, unattended: bool = False, dwell_s: float | None = None,
         rate_dps: float | None = None, rotation_s: float | None = None) -> Compiled:
    """``station plan``: a scheme (a built-in name or a YAML file) compiled for the table of
    ``config`` (a station.yaml; default $STATION_CONFIG, ./station.yaml, the built-in), without
    hardware: the moves, dwells, rotations and operator steps, and their device time.
    ``unattended``: no remount steps (run.operator false)."""
    from station.bench.compile_cache import compile_cached
    from station.io.scheme import load_scheme

    cfg = _bench_config(config, unattended=unattended)
    overrides = {k: v for k, v in (("dwell_s", dwell_s), ("rate_dps", rate_dps), ("rotation_s", rotation_s))
                 if v is not None}
    sch = load_scheme(scheme, overrides)
    try:
        compiled = compile_cached(sch, cfg)     # kept in the user's cache folder (station/bench/compile_cache.py)
    except UserError as e:
        rotations = [seg for seg in sch.segments if getattr(seg, "kind", "") == "rotation"]
        if rotations and all(not getattr(seg, "encoder", True) for seg in rotations):
            raise UserError(f"scheme {sch.name} is not a table scheme: its rotations have no encoder (a "
                            "shaft, a screwdriver or a hand turns the IMU; `station run --scheme "
                            f"{sch.name} --sim` simulates it); on this table: {e}") from None
        raise
    return Compiled(sch, cfg, compiled)


def schemes(*, config=None) -> list[dict]:
    """``station schemes``: each built-in scheme with its statics and rotations, seconds of
    recording, and compiled for the table of ``config``: seconds of device time (None when it
    cannot run there: ``note`` says why) and operator steps.  A scheme compiled before for this
    table (by this code) is read from the user's cache folder (station/bench/compile_cache.py);
    the others are compiled in this process."""
    from station.bench.compile_cache import cached_plan
    from station.bench.config import load_config
    from station.io.scheme import builtin_names, load_scheme

    cfg = load_config(None if config is None else str(config))
    rows = {}
    for name in builtin_names():
        sch = load_scheme(name)
        rows[name] = (sch, cached_plan(sch, cfg))
    missing = [name for name, (_, hit) in rows.items() if hit is None]
    # compiled here, one after the other: with the closed-form inverse kinematics (issue 26) a
    # scheme compiles in ~25 ms, and forked children (one per scheme, each with its own memory of
    # solves) cost more than they saved: 549 -> 351 ms CPU, 0.98 -> 0.53 s wall for the cold
    # listing (7 interleaved pairs, docs/performance.md)
    computed = {name: _scheme_row(name, cfg, rows[name][0]) for name in missing}
    return [computed[name] if name in computed else _scheme_row(name, cfg, sch, hit)
            for name, (sch, hit) in rows.items()]


def _scheme_row(name, cfg, sch=None, hit=None) -> dict:
    from station.bench.compile_cache import compile_cached
    from station.io.scheme import load_scheme

    if sch is None:
        sch = load_scheme(name)
    statics = sum(s.kind == "static" for s in sch.segments)
    row = {"name": name, "title": sch.title, "statics": statics, "rotations": len(sch.segments) - statics,
           "recording_s": sch.duration_s, "run_s": None, "operator_steps": None, "note": None}
    try:
        compiled = compile_cached(sch, cfg, hit)
        row["run_s"] = compiled.duration_s
        row["operator_steps"] = sum(type(s).__name__ in ("Operator", "HandStatic", "HandRotation") for s in compiled)
    except UserError as e:
        row["note"] = f"{name}: {e}"
    return row
