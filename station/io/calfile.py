"""Calibration files (``format: station-calibration/1``): write, read, validate.

The file is YAML, for people and programs alike.  ``parameters`` lists every estimated
parameter with its unit; ``compensation`` is all a program needs to correct raw samples.
"""
from __future__ import annotations

import datetime as _dt
import math
import os
import re
import secrets
import stat
import time
from pathlib import Path

import numpy as np
import yaml

import station
from station.core import yaml_text
from station.model.calibration import Calibration
from station.core.errors import UserError, cannot_write
from station.core.units import ACCEL_UNITS, GYRO_UNITS, accel_to_mps2_factor, gyro_to_dps_factor

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


MAX_BYTES = 16 * 2**20          # a calibration file is a few kB; refuse anything above 16 MB
MAX_VALUE = 1e12                # no compensation coefficient is anywhere near this
GYRO_PASS_THROUGH = "not calibrated: passed through (unit conversion only)"
GYRO_PARAMETERS = tuple(f"gyro_{kind}_{a}" for kind in ("scale", "bias") for a in "xyz")
SCALE_UNITS = ("1", "raw/(m/s^2)", "raw/(deg/s)")     # the units a scale factor is written in
MAX_CONDITION = 1e12            # a compensation matrix less well conditioned is singular


def gyro_calibrated(cal: Calibration) -> bool:
    return cal.fit.get("gyro_calibrated", True) is not False


def _correlation(cal: Calibration, written: list) -> dict:
    names, matrix = list(cal.correlation[0]), np.asarray(cal.correlation[1])
    keep = [i for i, n in enumerate(names) if n in written]
    return {"names": [names[i] for i in keep],
            "matrix": np.nan_to_num(matrix[np.ix_(keep, keep)]).round(4).tolist()}


def to_document(cal: Calibration, provenance: dict) -> dict:
    dropped = set(cal.fit.get("not_determined", []))
    written = [(n, v, u) for n, v, u in cal.parameters() if n not in dropped]
    if gyro_calibrated(cal):
        gyro = {"gyro_matrix": _floats(cal.gyro_matrix), "gyro_bias": _floats(cal.gyro_bias)}
    else:
        gyro = {"gyro": GYRO_PASS_THROUGH}
    extra = {key: _floats(value) for key, value in cal.compensation_extra.items()
             if gyro_calibrated(cal) or not key.startswith("gyro_")}
    return {
        "format": FORMAT,
        "convention": CONVENTION,
        "imu": {"accel_unit": cal.accel_unit, "gyro_unit": cal.gyro_unit,
                **{key: provenance[f"imu_{key}"] for key in ("model", "serial", "firmware")
                   if provenance.get(f"imu_{key}") is not None}},
        "verdict": cal.fit.get("verdict", {"result": "untested", "reason": "not judged"}),
        "effects": list(cal.effects),
        "parameters": {name: _parameter(value, unit, cal.sigma.get(name)) for name, value, unit in written},
        "compensation": {
            **extra,
            "accel_matrix": _floats(cal.accel_matrix),
            "accel_bias": _floats(cal.accel_bias),
            **gyro,
            "raw_units": {"accel": cal.accel_unit, "gyro": cal.gyro_unit},
            "output_units": {"accel": "m/s^2", "gyro": "deg/s"},
            "effects": [_plain(e) for e in cal.effect_compensation],
        },
        "fit": cal.fit,
        **({"correlation": _correlation(cal, [n for n, _, _ in written])}
           if cal.correlation is not None else {}),
        "provenance": {
            "software": f"station {station.__version__}",
            "date_utc": _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
            **provenance,
        },
    }


def write_calfile(path, cal: Calibration, provenance: dict) -> Path:
    """Write atomically: a new temporary file with a random name in the target's folder, opened
    with O_CREAT|O_EXCL|O_NOFOLLOW (never through a link, never over an existing file), fsynced,
    renamed over ``path`` (a symbolic link at ``path`` is replaced, its target never written);
    the temporary file is removed on every path out."""
    path = Path(path)
    text = dump_text(to_document(cal, provenance))
    write_new_file(path, text.encode("utf-8"), what="calibration file")
    return path


def write_new_file(path: Path, data: bytes, *, what: str = "file") -> None:
    """Replace ``path`` with ``data`` atomically through a random-named temporary file in the
    same folder (O_EXCL|O_NOFOLLOW), removed on every path out (also KeyboardInterrupt).  The
    temporary's name carries the writer's pid (``.NAME.PID_RANDOM.tmp``): one left by a writer
    killed mid-write is removed by the next write of ``path`` (remove_stale_temporaries)."""
    from station.core.user_files import output_path

    output_path(path, f"the {what}")
    remove_stale_temporaries(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}_{secrets.token_hex(8)}.tmp")
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)
    created = False
    try:
        fd = os.open(tmp, flags, 0o644)
        created = True
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
        created = False
    except OSError as e:
        raise cannot_write(path, e, what) from None
    finally:
        if created:
            try:
                os.unlink(tmp)
            except OSError:
                pass


STALE_TEMPORARY_S = 3600.0      # a temporary of a live writer older than this is stale too (pid reused)


def remove_stale_temporaries(path: Path) -> list[str]:
    """Remove the temporaries of ``path`` that killed writers left (write_new_file's
    ``.NAME.PID_RANDOM.tmp``, and an older version's ``.NAME.RANDOM.tmp``), only when they are
    ours (that name exactly, a regular file, never a link, of this user) and stale: their pid is
    no running process, or older than STALE_TEMPORARY_S.  Returns the names removed; a failure
    to remove one is no error (the write goes on)."""
    path = Path(path)
    pattern = re.compile(re.escape(f".{path.name}.") + r"(?:(?P<pid>[0-9]{1,10})_)?[0-9a-f]{16}\.tmp")
    removed = []
    try:
        entries = list(os.scandir(path.parent if str(path.parent) else "."))
    except OSError:
        return removed
    now = time.time()
    for entry in entries:
        m = pattern.fullmatch(entry.name)
        if not m:
            continue
        try:
            info = entry.stat(follow_symlinks=False)
            if not stat.S_ISREG(info.st_mode) or (hasattr(os, "getuid") and info.st_uid != os.getuid()):
                continue
            old = now - info.st_mtime > STALE_TEMPORARY_S
            if old or (m.group("pid") is not None and not _running(int(m.group("pid")))):
                os.unlink(entry.path)
                removed.append(entry.name)
        except OSError:
            continue
    return removed


def _running(pid: int) -> bool:
    """Whether a process ``pid`` exists (True when that cannot be told: the file is then kept)."""
    if pid == os.getpid():
        return True
    if os.name == "nt" or pid <= 0:         # (os.kill(pid, 0) would end a process on Windows)
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:                         # EPERM: another user's process: it exists
        return True
    return True


def _matrix(doc: dict, key: str, shape, path) -> np.ndarray:
    where = f"{path}: field 'compensation.{key}'"
    try:
        a = np.array(doc[key], dtype=float)
    except KeyError:
        raise UserError(f"{where}: missing") from None
    except (TypeError, ValueError):
        raise UserError(f"{where}: must be numbers") from None
    if a.shape != shape or not np.all(np.isfinite(a)) or np.any(np.abs(a) > MAX_VALUE):
        raise UserError(f"{where}: must be {'x'.join(map(str, shape)) or 'a'} finite number"
                        f"{'s' if shape else ''} of at most {MAX_VALUE:g} in size")
    return a


class _Dumper(yaml.SafeDumper):
    """safe_dump without anchors and aliases (the reader refuses them)."""

    def ignore_aliases(self, data):
        return True


_CDumper = None
if getattr(yaml, "__with_libyaml__", False):
    class _CDumper(yaml.CSafeDumper):
        """The same through libyaml's C emitter (4x faster: 2 ms against 8.5 ms for a calibration
        file)."""

        def ignore_aliases(self, data):
            return True


def _plain_text(s: str) -> bool:
    """A string both emitters write alike: not empty, printable characters of the Basic
    Multilingual Plane and newlines only.  Fuzzed (tests/test_calfile_emitter.py): the two
    emitters differ on empty keys, control characters, U+0085/U+2028/U+2029/U+FEFF and
    characters beyond U+FFFF, which the pure-Python emitter writes unescaped and libyaml escapes."""
    return bool(s) and all(" " <= c < "\x7f" or "\xa0" <= c < "\ud800" or "\ue000" <= c < "\ufeff"
                           or "\uff00" <= c < "\ufffe" or c == "\n" for c in s)


def _c_safe(node) -> bool:
    """Whether every string in the document (keys and values) is one both emitters write alike."""
    stack = [node]
    while stack:
        x = stack.pop()
        if isinstance(x, str):
            if not _plain_text(x):
                return False
        elif isinstance(x, dict):
            stack.extend(x.keys())
            stack.extend(x.values())
        elif isinstance(x, (list, tuple)):
            stack.extend(x)
    return True


def dump_text(doc: dict) -> str:
    """The calibration file's text: libyaml's C emitter when it is installed and gives what the
    pure-Python emitter gives (a mapping whose strings are all plain text), the pure-Python
    emitter otherwise; the same bytes either way."""
    dumper = _CDumper if _CDumper is not None and isinstance(doc, dict) and _c_safe(doc) else _Dumper
    return yaml.dump(doc, Dumper=dumper, sort_keys=False, width=100, allow_unicode=True)


def _read_bytes(path: Path) -> bytes:
    """The file's bytes: a regular file (not a FIFO, device or folder) of at most MAX_BYTES."""
    try:
        info = os.stat(path)
        if not stat.S_ISREG(info.st_mode):
            raise UserError(f"{path}: not a regular file (a FIFO, device or folder): cannot read "
                            "calibration file")
        if info.st_size > MAX_BYTES:
            raise UserError(f"{path}: {info.st_size} bytes: too large for a calibration file "
                            f"(at most {MAX_BYTES} bytes)")
        with open(path, "rb") as f:
            return f.read(MAX_BYTES + 1)
    except OSError as e:
        raise UserError(f"{path}: cannot read calibration file: {e.strerror}") from None


def _scalar_mapping(doc: dict, key: str, path) -> dict:
    value = doc.get(key)
    if value is None:
        return {}
    if not isinstance(value, dict) or not all(
            isinstance(k, str) and (v is None or isinstance(v, (str, int, float, bool)))
            for k, v in value.items()):
        raise UserError(f"{path}: field '{key}': must be a mapping of names to text or numbers")
    return value


def read_calfile(path) -> dict:
    """Load and validate a calibration file; compensation arrays come back as numpy arrays.

    UserError (one line, naming the file and field) for: not a regular file, more than
    MAX_BYTES, not UTF-8, not YAML, YAML aliases, wrong types.  A calibration without the gyro
    (``compensation.gyro: not calibrated...``) comes back with ``gyro_pass_through: True`` and
    a unit-conversion-only gyro_matrix, zero gyro_bias (and zero gyro temperature coefficients)."""
    path = Path(path)
    raw = _read_bytes(path)
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as e:
        raise UserError(f"{path}: not UTF-8 text (byte {e.start}): not a calibration file") from None
    try:
        doc = yaml_text.safe_load(text, allow_aliases=False)
    except yaml.MarkedYAMLError as e:
        line = f"line {e.problem_mark.line + 1}: " if e.problem_mark is not None else ""
        raise UserError(f"{path}: {line}not valid YAML: {e.problem}") from None
    except (yaml.YAMLError, ValueError, RecursionError) as e:
        raise UserError(f"{path}: not valid YAML: {str(e).splitlines()[0] if str(e) else type(e).__name__}") from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise UserError(f"{path}: field 'format': not a station calibration file (expected {FORMAT})")
    effects = doc.get("effects", [])
    if not isinstance(effects, list) or not all(isinstance(e, str) for e in effects):
        raise UserError(f"{path}: field 'effects': must be a list of effect names")
    imu = _scalar_mapping(doc, "imu", path)
    for key in ("accel_unit", "gyro_unit"):
        if key in imu and imu[key] not in (ACCEL_UNITS if key == "accel_unit" else GYRO_UNITS):
            raise UserError(f"{path}: field 'imu.{key}': unknown unit {str(imu[key])[:40]!r}")
    _scalar_mapping(doc, "provenance", path)
    verdict = doc.get("verdict")
    if verdict is not None and not isinstance(verdict, dict):
        raise UserError(f"{path}: field 'verdict': must be a mapping")
    comp = doc.get("compensation")
    if not isinstance(comp, dict):
        raise UserError(f"{path}: field 'compensation': missing or not a mapping")
    extra = {}
    pass_through = comp.get("gyro") == GYRO_PASS_THROUGH
    if pass_through:
        factor = gyro_to_dps_factor(imu.get("gyro_unit", "deg/s")) or 1.0
        extra["gyro_matrix"] = factor * np.eye(3)
        extra["gyro_bias"] = np.zeros(3)
    elif "gyro" in comp:
        raise UserError(f"{path}: field 'compensation.gyro': must be {GYRO_PASS_THROUGH!r} or absent")
    if "accel_lever_arm_m" in comp:
        extra["accel_lever_arm_m"] = _matrix(comp, "accel_lever_arm_m", (3, 3), path)
    if "temperature_reference_c" in comp:
        extra["temperature_reference_c"] = float(_matrix(comp, "temperature_reference_c", (), path))
        for key in ("accel_bias_tempco_raw_per_c", "gyro_bias_tempco_raw_per_c"):
            if key == "gyro_bias_tempco_raw_per_c" and pass_through:
                extra[key] = np.zeros(3)
                continue
            extra[key] = _matrix(comp, key, (3,), path)
    doc["compensation"] = {
        **comp,
        "accel_matrix": _matrix(comp, "accel_matrix", (3, 3), path),
        "accel_bias": _matrix(comp, "accel_bias", (3,), path),
        **({} if pass_through else {"gyro_matrix": _matrix(comp, "gyro_matrix", (3, 3), path),
                                    "gyro_bias": _matrix(comp, "gyro_bias", (3,), path)}),
        **extra,
    }
    for key in ("accel_matrix", "gyro_matrix"):     # apply inverts them (the forward model)
        m = doc["compensation"][key]
        if not np.linalg.cond(m) < MAX_CONDITION:
            raise UserError(f"{path}: field 'compensation.{key}': singular (an all-zero row or column, "
                            "or rows that depend on each other): no sensor's compensation")
    if "effects" in comp:
        doc["compensation"]["effects"] = _effect_entries(comp["effects"], path)
    doc["gyro_pass_through"] = pass_through
    params = doc.get("parameters")
    if not isinstance(params, dict) or not all(isinstance(k, str) for k in params):
        raise UserError(f"{path}: field 'parameters': missing or not a mapping")
    for name, p in params.items():
        if not (isinstance(p, dict) and isinstance(p.get("value"), (int, float))
                and not isinstance(p.get("value"), bool) and math.isfinite(p["value"])
                and isinstance(p.get("unit"), str)
                and (p.get("sigma") is None or (isinstance(p["sigma"], (int, float))
                                                and not isinstance(p["sigma"], bool)
                                                and math.isfinite(p["sigma"]) and p["sigma"] >= 0))):
            shown = name[:60] if name[:60].isprintable() else repr(name[:60])[1:-1]   # one line
            raise UserError(f"{path}: field 'parameters.{shown}': needs a finite 'value', a 'unit' "
                            "and, if given, a finite 'sigma' >= 0")
        if "_scale_" in name and p["unit"] in SCALE_UNITS and p["value"] == 0:
            shown = name[:60] if name[:60].isprintable() else repr(name[:60])[1:-1]
            raise UserError(f"{path}: field 'parameters.{shown}.value': a scale factor of 0 (a sensor that reads "
                            "nothing of what it senses): not a calibration")
    if not pass_through:            # a gyro compensation stands on the gyro parameters it came from
        missing = [n for n in GYRO_PARAMETERS if n not in params]
        if missing:
            raise UserError(f"{path}: field 'parameters': no {', '.join(missing)}, yet "
                            "'compensation.gyro_matrix' is given: the gyro parameters were removed, the gyro "
                            f"compensation cannot be trusted (an accelerometer-only file has compensation.gyro: "
                            f"{GYRO_PASS_THROUGH!r})")
    _scales_agree(doc, imu, params, pass_through, path)
    _not_determined_agrees(doc, params, path)
    return doc


def _not_determined_agrees(doc, params, path) -> None:
    """``fit`` a mapping, its ``not_determined`` a list of names; a parameter named there is not
    written under ``parameters`` (to_document leaves it out) and, if an added effect's, its entry
    in ``compensation.effects`` lists it in its own not_determined (at the nominal 0): a file that
    says a parameter is not determined and gives it a value says two things about it (review of
    issue 28).  Files written before not_determined have none: nothing to check."""
    entries = doc["compensation"].get("effects", [])
    written = [n for entry in entries for n in entry.get("not_determined", []) if n in params]
    if written:
        raise UserError(f"{path}: field 'parameters': {', '.join(written)[:200]} not determined (its "
                        "compensation entry's not_determined), yet written: not one calibration")
    fit = doc.get("fit")
    if fit is None:
        return
    if not isinstance(fit, dict):
        raise UserError(f"{path}: field 'fit': must be a mapping")
    for key in ("settled", "stopped_short"):      # how the solver stopped (lsq.to_calibration)
        if key in fit and not isinstance(fit[key], bool):
            raise UserError(f"{path}: field 'fit.{key}': must be true or false")
    if fit.get("settled") is True and (fit.get("converged") is True or fit.get("stopped_short") is True):
        # settled: stopped where it crept, not at a minimum (lsq._last_phase): neither converged nor
        # stopped short by its tolerances (review of settle27: such a file was read)
        raise UserError(f"{path}: field 'fit.settled': true beside "
                        + ("converged" if fit.get("converged") is True else "stopped_short")
                        + " true: a fit that settled did not converge: not one calibration")
    held = fit.get("not_determined", [])
    if not isinstance(held, list) or not all(isinstance(n, str) for n in held):
        raise UserError(f"{path}: field 'fit.not_determined': must be a list of parameter names")
    written = [n for n in held if n in params]
    if written:
        raise UserError(f"{path}: field 'parameters': {', '.join(written)[:200]} not determined "
                        "(fit.not_determined), yet written: not one calibration")
    for k, entry in enumerate(entries):
        used = [n for n in held if n in entry["parameters"] and n not in entry.get("not_determined", [])]
        if used:
            raise UserError(f"{path}: field 'compensation.effects[{k}].parameters': {', '.join(used)[:200]} "
                            "not determined (fit.not_determined), yet compensated at the value given "
                            "(not in the entry's not_determined): not one calibration")
    # the held parameters the data pull on (lsq.held_pulls): {name: pull in sigma} of parameters
    # held by their prior, so named in fit.not_determined and not written (review of held28)
    for where, block in (("fit", fit), ("verdict", doc.get("verdict") or {})):
        pulled = block.get("held_contradicted")
        if pulled is None:
            continue
        if not isinstance(pulled, dict) or not all(
                isinstance(n, str) and isinstance(w, (int, float)) and not isinstance(w, bool) and math.isfinite(w)
                for n, w in pulled.items()):
            raise UserError(f"{path}: field '{where}.held_contradicted': must be a mapping of held parameter "
                            "names to their pull in sigma (finite numbers)")
        stray = [n for n in pulled if n not in held]
        if stray:
            raise UserError(f"{path}: field '{where}.held_contradicted': {', '.join(stray)[:200]} not held by its "
                            "prior (not in fit.not_determined), yet said to be: not one calibration")


def _scales_agree(doc, imu, params, pass_through, path) -> None:
    """The compensation matrices and the scale factors the file states are one calibration.

    The model (station/model/calibration.py) writes accel_matrix = f inv(diag(s) T) and
    gyro_matrix = f R_po^T inv(diag(s) T), T's rows unit sensing directions, R_po a rotation, f
    the raw unit's factor to m/s^2 or deg/s (1 for raw): so row i of inv(matrix) / f has length
    |s_i| for both.  A file edited by hand on one side only (a matrix of 1e-308s that compensates
    into nothing, a scale changed, or set to 0, beside the matrix it came from) says two different
    things about one sensor: refused, naming both.  Tolerance: 1 ppm of the scale (the estimator's
    best 1σ is ~1 ppm for gyros; both sides are written from one float) plus what the matrices'
    rounding to 15 decimals (``_floats``) can move a row's length: 1e-15 per entry, relative
    1e-15 * sqrt(3) / |smallest entry's row| -- bounded here by 1e-13 / max|row|."""
    for sensor, unit_key, factor_of in (("accel", "accel_unit", accel_to_mps2_factor),
                                        ("gyro", "gyro_unit", gyro_to_dps_factor)):
        if sensor == "gyro" and pass_through:
            continue
        names = [f"{sensor}_scale_{a}" for a in "xyz"]
        if not any(n in params and params[n].get("unit") in SCALE_UNITS for n in names):
            continue
        m = doc["compensation"][f"{sensor}_matrix"]
        factor = factor_of(imu.get(unit_key, "m/s^2" if sensor == "accel" else "deg/s")) or 1.0
        with np.errstate(all="ignore"):         # (a matrix of 1e-308s inverts to 1e308s: inf, refused below)
            rows = np.linalg.norm(np.linalg.inv(m), axis=1) * factor
        for i, n in enumerate(names):
            if n not in params or params[n].get("unit") not in SCALE_UNITS:
                continue
            stated = abs(params[n]["value"])
            tol = 1e-6 + 1e-13 / max(float(np.max(np.abs(m[i]))), 1e-300)
            if not (abs(rows[i] - stated) <= tol * stated):
                raise UserError(f"{path}: field 'parameters.{n}.value': {params[n]['value']:.9g} disagrees with "
                                f"'compensation.{sensor}_matrix' (its scale on that axis: {rows[i]:.9g}): the file "
                                "was changed on one side only; not one calibration")


def _effect_entries(entries, path) -> list:
    """Validate ``compensation.effects``: a list of {id, source, state, parameters, and
    not_determined when the capture did not reveal some of them}.  A parameter not determined
    is written at its nominal, 0 (station.estimate.lsq.to_calibration): one listed with another
    value says two things about it and is refused.  Files written before not_determined (the
    eighteenth session) have none: every parameter is used as written."""
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
        held = e.get("not_determined", [])
        if not isinstance(held, list) or not all(isinstance(n, str) and n in params for n in held):
            raise UserError(f"{where}.not_determined': must list names of its parameters")
        given = [n for n in held if params[n] != 0]
        if given:
            raise UserError(f"{where}.parameters': {', '.join(given)} not determined (not_determined), yet "
                            "given a value other than its nominal 0: not one calibration")
        out.append({"id": e["id"], "source": source, "state": state, "parameters": dict(params),
                    **({"not_determined": list(held)} if held else {})})
    return out


def compensation_effects(doc: dict, registry, path="calibration") -> list:
    """(Effect, x internal) for every effect of a calibration read by read_calfile, created from
    ``registry`` (station.model.registry): the library, installed plugins and those the user
    loaded; a parameter the capture did not determine (its entry's ``not_determined``) is at its
    nominal 0 in x (not_compensated names them).  A plugin effect the registry lacks is refused with the way to load it; station never
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


def not_compensated(doc: dict) -> list:
    """(effect id, [parameter names], all of them) of every effect of a calibration read by
    read_calfile whose entry lists parameters the capture did not determine (compensated at their
    nominal 0: no correction for them); ``all`` True when none of the effect's parameters is
    determined (the effect is not compensated at all)."""
    out = []
    for entry in doc["compensation"].get("effects", []):
        held = list(entry.get("not_determined", []))
        if held:
            out.append((entry["id"], held, set(held) >= set(entry["parameters"])))
    return out
