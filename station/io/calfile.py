"""Calibration files (``format: station-calibration/1``): write, read, validate.

The file is YAML, for people and programs alike.  ``parameters`` lists every estimated
parameter with its unit; ``compensation`` is all a program needs to correct raw samples.
"""
from __future__ import annotations

import datetime as _dt
import math
import os
from pathlib import Path

import numpy as np
import yaml

import station
from station.model.calibration import Calibration
from station.core.errors import UserError

FORMAT = "station-calibration/1"

CONVENTION = {
    "frame": ("p, the platform frame defined by the accelerometers: x along the x accelerometer's "
              "sensing axis, y in the plane of the x and y sensing axes, z completing a "
              "right-handed frame"),
    "forward_model": ("accel_raw = K_a T_a f_p + b_a ; gyro_raw = K_g T_g R_po w_p + b_g "
                      "(Zhang et al. 2010, eqs. 1-6); K diagonal scale factors, T lower-triangular "
                      "unit-row sensing directions, R_po the inter-triad rotation ~ I + [theta x]; "
                      "f_p, w_p in the IMU's declared unit (m/s^2 and deg/s when the unit is raw)"),
    "misalignment": ("accel (yz, zy, zx) = (asin T[1,0], -asin T[2,0], asin T[2,1]); gyro the same; "
                     "inter_triad = rotation vector of R_po"),
    "compensation": ("f_p = accel_matrix (accel_raw - accel_bias) in m/s^2 ; "
                     "w_p = gyro_matrix (gyro_raw - gyro_bias) in deg/s ; raw in the capture's units"),
}


def _floats(a) -> list:
    return np.asarray(a, dtype=float).round(15).tolist()


def _plain(value):
    """numpy values -> plain YAML numbers and lists."""
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [_plain(v) for v in value]
    if isinstance(value, (np.floating, float)):
        return float(value)
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, np.bool_):
        return bool(value)
    return value


def _parameter(value: float, unit: str, sigma: float | None) -> dict:
    out = {"value": value, "unit": unit}
    if sigma is not None and math.isfinite(sigma):
        out["sigma"] = sigma
    return out


def to_document(cal: Calibration, provenance: dict) -> dict:
    return {
        "format": FORMAT,
        "convention": CONVENTION,
        "imu": {"accel_unit": cal.accel_unit, "gyro_unit": cal.gyro_unit},
        "effects": list(cal.effects),
        "parameters": {name: _parameter(value, unit, cal.sigma.get(name))
                       for name, value, unit in cal.parameters()},
        "compensation": {
            **{key: _floats(value) for key, value in cal.compensation_extra.items()},
            "accel_matrix": _floats(cal.accel_matrix),
            "accel_bias": _floats(cal.accel_bias),
            "gyro_matrix": _floats(cal.gyro_matrix),
            "gyro_bias": _floats(cal.gyro_bias),
            "raw_units": {"accel": cal.accel_unit, "gyro": cal.gyro_unit},
            "output_units": {"accel": "m/s^2", "gyro": "deg/s"},
            "effects": [_plain(e) for e in cal.effect_compensation],
        },
        "fit": cal.fit,
        **({"correlation": {"names": list(cal.correlation[0]),
                            "matrix": np.nan_to_num(np.asarray(cal.correlation[1])).round(4).tolist()}}
           if cal.correlation is not None else {}),
        "provenance": {
            "software": f"station {station.__version__}",
            "date_utc": _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
            **provenance,
        },
    }


def write_calfile(path, cal: Calibration, provenance: dict) -> Path:
    path = Path(path)
    text = yaml.safe_dump(to_document(cal, provenance), sort_keys=False, width=100)
    tmp = path.with_name(path.name + ".tmp")
    try:
        with open(tmp, "w") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except OSError as e:
        raise UserError(f"{path}: cannot write calibration file: {e.strerror}") from None
    return path


def _matrix(doc: dict, key: str, shape, path) -> np.ndarray:
    where = f"{path}: field 'compensation.{key}'"
    try:
        a = np.array(doc[key], dtype=float)
    except KeyError:
        raise UserError(f"{where}: missing") from None
    except (TypeError, ValueError):
        raise UserError(f"{where}: must be numbers") from None
    if a.shape != shape or not np.all(np.isfinite(a)):
        raise UserError(f"{where}: must be {'x'.join(map(str, shape)) or 'a'} finite number"
                        f"{'s' if shape else ''}")
    return a


def read_calfile(path) -> dict:
    """Load and validate a calibration file; compensation arrays come back as numpy arrays."""
    path = Path(path)
    try:
        doc = yaml.safe_load(path.read_text())
    except OSError as e:
        raise UserError(f"{path}: cannot read calibration file: {e.strerror}") from None
    except yaml.YAMLError as e:
        raise UserError(f"{path}: not valid YAML: {str(e).splitlines()[0]}") from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise UserError(f"{path}: field 'format': not a station calibration file (expected {FORMAT})")
    comp = doc.get("compensation")
    if not isinstance(comp, dict):
        raise UserError(f"{path}: field 'compensation': missing or not a mapping")
    extra = {}
    if "accel_lever_arm_m" in comp:
        extra["accel_lever_arm_m"] = _matrix(comp, "accel_lever_arm_m", (3, 3), path)
    if "temperature_reference_c" in comp:
        extra["temperature_reference_c"] = float(_matrix(comp, "temperature_reference_c", (), path))
        for key in ("accel_bias_tempco_raw_per_c", "gyro_bias_tempco_raw_per_c"):
            extra[key] = _matrix(comp, key, (3,), path)
    doc["compensation"] = {
        **comp,
        **extra,
        "accel_matrix": _matrix(comp, "accel_matrix", (3, 3), path),
        "accel_bias": _matrix(comp, "accel_bias", (3,), path),
        "gyro_matrix": _matrix(comp, "gyro_matrix", (3, 3), path),
        "gyro_bias": _matrix(comp, "gyro_bias", (3,), path),
    }
    if "effects" in comp:
        doc["compensation"]["effects"] = _effect_entries(comp["effects"], path)
    params = doc.get("parameters")
    if not isinstance(params, dict):
        raise UserError(f"{path}: field 'parameters': missing or not a mapping")
    for name, p in params.items():
        if not (isinstance(p, dict) and isinstance(p.get("value"), (int, float))
                and not isinstance(p.get("value"), bool) and math.isfinite(p["value"])
                and isinstance(p.get("unit"), str)
                and (p.get("sigma") is None or (isinstance(p["sigma"], (int, float))
                                                and not isinstance(p["sigma"], bool)))):
            raise UserError(f"{path}: field 'parameters.{name}': needs a finite 'value', a 'unit' "
                            "and, if given, a numeric 'sigma'")
    return doc


def _effect_entries(entries, path) -> list:
    """Validate ``compensation.effects``: a list of {id, source, state, parameters}."""
    if not isinstance(entries, list):
        raise UserError(f"{path}: field 'compensation.effects': must be a list")
    out = []
    for k, e in enumerate(entries):
        where = f"{path}: field 'compensation.effects[{k}]"
        if not isinstance(e, dict) or not isinstance(e.get("id"), str):
            raise UserError(f"{where}.id': needs an effect id")
        params = e.get("parameters", {})
        if not isinstance(params, dict) or not all(
                isinstance(n, str) and isinstance(v, (int, float)) and not isinstance(v, bool)
                and math.isfinite(v) for n, v in params.items()):
            raise UserError(f"{where}.parameters': must map names to finite numbers")
        state = e.get("state", {})
        if not isinstance(state, dict):
            raise UserError(f"{where}.state': must be a mapping")
        source = e.get("source", "library")
        if not isinstance(source, str):
            raise UserError(f"{where}.source': must be text")
        out.append({"id": e["id"], "source": source, "state": state, "parameters": dict(params)})
    return out


def compensation_effects(doc: dict, registry, path="calibration") -> list:
    """(Effect, x internal) for every effect of a calibration read by read_calfile, created from
    ``registry`` (station.model.registry): the library, installed plugins and those the user
    loaded.  A plugin effect the registry lacks is refused with the way to load it; station never
    runs code named in a calibration file."""
    out = []
    for k, entry in enumerate(doc["compensation"].get("effects", [])):
        eid, source = entry["id"], entry["source"]
        if eid not in registry:
            how = (f"load it with --plugin {source}" if source != "library"
                   else "it is not in this version's library")
            raise UserError(f"{path}: effect {eid!r} ({source}) is not "
                            f"available: {how}")
        effect = registry.create(eid)
        try:
            effect.restore(entry["state"])
            params = effect.params
        except Exception as e:
            raise UserError(f"{path}: field 'compensation.effects[{k}].state': "
                            f"effect {eid!r} cannot use it: {type(e).__name__}: {e}") from None
        missing = [p.name for p in params if p.name not in entry["parameters"]]
        if missing:
            raise UserError(f"{path}: field 'compensation.effects[{k}]"
                            f".parameters': missing {', '.join(missing)}")
        x = np.array([entry["parameters"][p.name] / p.scale for p in params], dtype=float)
        out.append((effect, x))
    return out
