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
frame p (the accelerometers' orthogonalised frame, docs/calibration-file.md).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from station.core.errors import UserError

__all__ = ["Estimate", "Parameter", "UserError", "apply", "apply_frame", "diagnose", "estimate", "export",
           "import_csv", "import_imucal", "import_rosbag", "load_calibration", "noise", "read_capture", "simulate"]


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
        return {name: Parameter(float(value), sigma.get(name), unit)
                for name, value, unit in self.calibration.parameters()}

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
        """Write the calibration file (refuses to overwrite an existing one: choose a new path)."""
        from station.io.calfile import write_calfile

        return write_calfile(Path(path), self.calibration, self.provenance)


def _registry(plugins=(), effects_dirs=()):
    """The library, entry points, $STATION_EFFECTS_PATH and the plugins named (loaded, not added)."""
    from station.model.registry import registry_for

    return registry_for(plugins, effects_dirs)[0]


def _effect_ids(registry, add) -> list[str]:
    from station.model.registry import effect_ids

    return effect_ids(registry, add)


def _path(capture) -> Path:
    return Path(getattr(capture, "path", capture))


def simulate(scheme: str = "optimal9", output=None, *, seed: int = 1, truth=None, dwell_s: float | None = None,
             rate_dps: float | None = None, rotation_s: float | None = None) -> Path:
    """``station run --sim`` without the estimate: record ``scheme`` (a built-in name or a YAML
    file) on the simulated bench into a new capture bundle at ``output`` (default
    captures/<scheme>-sim-<seed>); ``truth``: a truth YAML file (default: the seed's); returns
    the bundle's path (its simulated truth in sim_truth.yaml)."""
    from station.io.scheme import load_scheme
    from station.simulate import dryrun

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


def estimate(capture, *, method: str = "auto", add=(), plugins=(), effects_dirs=(),
             turn_sigma_deg: float | None = None, max_missing_fraction: float = 0.01,
             max_gap_s: float = 1.0) -> Estimate:
    """``station estimate``: calibrate from a capture (a path or :func:`read_capture`'s result).

    ``add``: effects to add to the model (library ids, or plugin specs ``FILE.py:CLASS``);
    ``plugins``/``effects_dirs``: plugin files and folders to load first (as ``--plugin``,
    ``--effects-dir``); ``turn_sigma_deg``: the hand turns' 1-sigma per turn (None: estimated).
    The verdict is in :attr:`Estimate.verdict` (a failing fit is returned, not raised)."""
    from station.estimate import estimate_capture

    registry = _registry(plugins, effects_dirs)
    cal, capture_read, provenance = estimate_capture(
        _path(capture), method, _effect_ids(registry, add), registry, max_missing_fraction=max_missing_fraction,
        max_gap_s=max_gap_s, turn_sigma_deg=turn_sigma_deg)
    return Estimate(cal, provenance, capture_read)


def diagnose(capture, *, add=(), plugins=(), effects_dirs=()):
    """``station diagnose`` (without the page): the least-squares fit of the capture with the
    effects ``add``, compared with its measurements.  Returns station.diagnose.core.Diagnosis:
    ``verdict`` (words), ``reduced_chi2``, ``p_value``, ``segments`` (residuals per segment),
    ``candidates`` (missing effects ranked by the score test), ``failures`` (where it fails)."""
    from station.diagnose.core import diagnose as _diagnose
    from station.estimate import lsq
    from station.estimate.summaries import summarise

    registry = _registry(plugins, effects_dirs)
    ids = _effect_ids(registry, add)
    s = summarise(read_capture(_path(capture), samples=False))
    return _diagnose(lsq.fit(s, [registry.create(e) for e in ids]), registry=registry)


def load_calibration(path) -> dict:
    """A calibration file, checked (station-calibration/1): ``parameters`` {name: {value, unit,
    sigma}}, ``verdict``, ``fit``, ``compensation`` (what :func:`apply` uses)."""
    from station.io.calfile import read_calfile

    return read_calfile(Path(path))


def apply(calibration, t, accel, gyro, temp=None, *, plugins=(), effects_dirs=()):
    """``station apply`` on arrays: raw IMU samples (t (N,) s; accel, gyro (N, 3) in the
    calibration's units) -> (t, specific force m/s^2, rate deg/s), compensated, frame p.
    ``calibration``: a file path, or :func:`load_calibration`'s or :meth:`Estimate.document`'s dict."""
    from station.io.calfile import compensation_effects, read_calfile
    from station.model.compensate import compensate, compensate_with_effects

    doc = calibration if isinstance(calibration, dict) else read_calfile(Path(calibration))
    where = "calibration" if isinstance(calibration, dict) else str(calibration)
    t = np.asarray(t, float).reshape(-1)
    accel, gyro = np.asarray(accel, float), np.asarray(gyro, float)
    if accel.shape != (len(t), 3) or gyro.shape != (len(t), 3):
        raise UserError(f"apply: accel and gyro must be ({len(t)}, 3) like t, got {accel.shape} and {gyro.shape}")
    temp = None if temp is None else np.asarray(temp, float).reshape(-1)
    comp = doc["compensation"]
    if "effects" not in comp:
        f, w = compensate(comp, t, accel, gyro, temp)
        return t, f, w
    effects = compensation_effects(doc, _registry(plugins, effects_dirs), where)
    needs = [e.id for e, _ in effects if "temperature" in e.needs]
    if needs and temp is None:
        raise UserError(f"apply: {', '.join(needs)} need the temperature (temp, deg C)")
    return compensate_with_effects(comp, effects, t, accel, gyro, temp)


COLUMNS = ("t", "ax", "ay", "az", "gx", "gy", "gz")


def apply_frame(calibration, frame, *, plugins=(), effects_dirs=()):
    """:func:`apply` on a pandas DataFrame with columns t, ax, ay, az, gx, gy, gz (and temp when
    an effect needs it): a new DataFrame with the same columns, compensated (m/s^2, deg/s)."""
    import pandas as pd

    missing = [c for c in COLUMNS if c not in frame.columns]
    if missing:
        raise UserError(f"apply_frame: the frame has no column {', '.join(missing)} (needs {', '.join(COLUMNS)})")
    temp = frame["temp"].to_numpy(float) if "temp" in frame.columns else None
    t, f, w = apply(calibration, frame["t"].to_numpy(float), frame[["ax", "ay", "az"]].to_numpy(float),
                    frame[["gx", "gy", "gz"]].to_numpy(float), temp, plugins=plugins, effects_dirs=effects_dirs)
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
                  gravity_mps2: float = 9.80665, **options):
    """``station import rosbag``: sensor_msgs/Imu from a ROS 1/2 bag or MCAP file into a capture."""
    from station.io.importers import recording, rosbag

    unknown = set(options) - set(_WRITE_KEYS)
    if unknown:
        raise UserError(f"import_rosbag: unknown option {', '.join(sorted(unknown))}")
    rec = rosbag.read_rosbag(path, topic=topic, stamps=stamps)
    return recording.write_capture(rec, output, gravity_mps2=gravity_mps2, **options)


def import_imucal(path, output, *, rate_hz: float, **options) -> Path:
    """``station import imucal``: an imucal Ferraris session into a capture; returns its path.
    ``options``: sections_path, fmt, gravity_mps2, accel_unit, gyro_unit, model, serial, turn_deg."""
    from station.io.importers import imucal

    return imucal.import_imucal(path, output, rate_hz=rate_hz, **options)


def export(calibration, to: str, output) -> list[Path]:
    """``station export --to``: a calibration file in another tool's format (imucal, imu_tk,
    kalibr, ros, c, json); returns the files written."""
    from station.io.calfile import read_calfile
    from station.io.exporters import FORMATS, source_from_document

    if to not in FORMATS:
        raise UserError(f"export: unknown format {to!r}: use one of {', '.join(FORMATS)}")
    path = Path(calibration)
    return [Path(p) for p in FORMATS[to].write(source_from_document(read_calfile(path), path), Path(output))]


def noise(capture, *, segment: str | None = None, calibration=None):
    """``station noise`` on a capture: the Allan deviation of its longest static (or ``segment``)
    and the noise terms read from it (station.estimate.noise.NoiseResult: per axis the white
    noise, bias instability, random walk, with their intervals)."""
    from station.estimate import noise as _noise

    doc = None
    if calibration is not None:
        doc = calibration if isinstance(calibration, dict) else load_calibration(calibration)
    return _noise.from_capture(read_capture(_path(capture), samples=False), segment, doc)
