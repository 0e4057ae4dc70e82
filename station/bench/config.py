"""The station configuration: ``station.yaml`` < environment < command-line flags.

Loaded with ``yaml.safe_load``; every problem is ONE ``UserError`` naming the file and the field
(``station.yaml: field 'table.limits[1].max_rate_dps': must be > 0, got -3``).  ``EXAMPLE`` is the
commented file ``station init`` writes; docs/sequencer.md describes every key.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field, fields, replace
from pathlib import Path

import numpy as np
import yaml

from drivers.transport import SerialSettings

from station.core.chamber import KINDS as CHAMBER_KINDS, ChamberConfig
from station.core.errors import UserError
from station.core import yaml_text

# where configuration files are looked for (station.io.config_paths: what `estimate` needs of them,
# without this module)
from station.io.config_paths import (DEFAULT_FILE, ENV_FILE, implicit_plugins, plugin_config,  # noqa: F401
                                     user_config_dir)
#: environment variables that override the file (flags override them)
ENV_KEYS = {"STATION_IMU_PORT": ("imu", "port"), "STATION_TABLE_PORT": ("table", "port"),
            "STATION_IMU_PROTOCOL": ("imu", "protocol"), "STATION_TABLE_PROTOCOL": ("table", "protocol")}
#: conventional axis directions at zero (east-north-up), outer -> inner, by number of axes
DEFAULT_AXES_ENU = {1: [[0, 0, 1]], 2: [[0, 0, 1], [1, 0, 0]], 3: [[0, 0, 1], [1, 0, 0], [0, 1, 0]]}
AXIS_NAMES = {"+x": (1, 0, 0), "-x": (-1, 0, 0), "+y": (0, 1, 0), "-y": (0, -1, 0),
              "+z": (0, 0, 1), "-z": (0, 0, -1)}


@dataclass(frozen=True)
class AxisConfig:
    """Limits of one table axis.  The sequencer never commands beyond them."""

    max_rate_dps: float = 300.0        # rate demands
    max_accel_dps2: float = 300.0
    move_rate_dps: float = 60.0        # position moves
    move_accel_dps2: float = 60.0
    rate_accel_dps2: float = 50.0      # ramps to and from a rotation rate
    angle_min_deg: float | None = None  # both None: a continuous axis
    angle_max_deg: float | None = None

    @property
    def angle_limits(self):
        return None if self.angle_min_deg is None else (self.angle_min_deg, self.angle_max_deg)


# the least sleep between the driver's reads of the table while it waits (s): with the twins at
# speed 100 a sleep of 0.1 ms (10 ms of their time) let station run's table polling starve its own
# IMU reader (one process, one GIL): the twins' lossless clock waited for the reader and the IMU's
# watchdog ended the run ("no valid frame for 2 s", CI of the twenty-first session); a real
# controller's exchange takes milliseconds anyway
MIN_POLL_INTERVAL_S = 1e-3


@dataclass(frozen=True)
class TableConfig:
    port: str | None = None
    protocol: str = "acutrol"
    serial: SerialSettings = field(default_factory=SerialSettings)
    axes: int = 3
    axes_enu: tuple = ()                  # per axis, ENU at zero; () -> DEFAULT_AXES_ENU[axes]
    mounting: tuple = ("+x", "+y", "+z")  # platform directions of the IMU's case x, y, z
    limits: tuple = (AxisConfig(),)       # one for every axis, or one per axis
    load_position_deg: tuple = ()         # where the operator (re)mounts the IMU; () -> zeros
    position_tolerance_deg: float = 0.002
    rate_tolerance_dps: float = 0.01
    # the driver's waits (a move's, a rate's settle, a stop) sleep this long after each read of the
    # table (wall s): arrival is settle_polls reads in a row within the tolerances (drivers.table.TableSettings)
    poll_interval_s: float = 0.01         # >= MIN_POLL_INTERVAL_S
    angle_error_arcsec: float = 2.0       # 1-sigma of the table's angles (into the capture)
    imu_offset_m: tuple | None = None     # IMU reference point from the axes' intersection
    # the table's geometry (docs/method-lsq.md, "The table's geometry"): whether the axes meet at
    # one point (then the IMU's offset from it is one vector in the IMU frame for every rotation
    # while the IMU stays mounted), and the 1-sigma of the rotation axes' elevation (levelling and
    # the axes' squareness; None: not known, the fit leaves gravity along each axis free)
    axes_intersect: bool = True
    level_arcsec: float | None = None

    def axis_list(self) -> list:
        return [list(a) for a in (self.axes_enu or DEFAULT_AXES_ENU[self.axes])]

    def axis_limits(self) -> tuple:
        return self.limits * self.axes if len(self.limits) == 1 else tuple(self.limits)

    def mounting_matrix(self) -> np.ndarray:
        """Case -> platform coordinates: column j is the platform direction of case axis j."""
        return np.column_stack([AXIS_NAMES[m] for m in self.mounting]).astype(float)


@dataclass(frozen=True)
class ImuConfig:
    port: str | None = None
    protocol: str = "vectornav"
    serial: SerialSettings = field(default_factory=SerialSettings)
    rate_hz: float = 100.0
    csv_units: str = ""
    frame_timeout_s: float = 2.0
    lot: str | None = None          # the production lot, into the capture's imu.lot and the calibration's provenance
    # several IMUs in one run (``imus:``) only: a label (the output folder when the IMU tells no
    # serial number), how it sits on the platform (None: table.mounting) and its reference
    # point from the axes' intersection (None: table.imu_offset_m)
    name: str | None = None
    mounting: tuple | None = None
    offset_m: tuple | None = None

    def mounting_matrix(self, table: "TableConfig") -> np.ndarray:
        """Case -> platform coordinates of this IMU (column j: the platform direction of case axis j)."""
        return np.column_stack([AXIS_NAMES[m] for m in (self.mounting or table.mounting)]).astype(float)


@dataclass(frozen=True)
class SiteConfig:
    latitude_deg: float = 45.0
    height_m: float = 0.0
    gravity_mps2: float | None = None     # None: WGS-84 normal gravity at latitude and height

    @property
    def gravity(self) -> float:
        return self.gravity_mps2 if self.gravity_mps2 is not None else normal_gravity(
            self.latitude_deg, self.height_m)


@dataclass(frozen=True)
class WarmupConfig:
    duration_s: float = 0.0               # at least this long (IMU time)
    max_s: float | None = None            # at most (with a temperature criterion)
    temp_slope_c_per_h: float | None = None   # until |dT/dt| over window_s is below this
    window_s: float = 300.0


@dataclass(frozen=True)
class RunConfig:
    settle_s: float = 5.0                 # IMU samples discarded after every move and ramp
    operator: bool = True                 # someone can remount the IMU (False: unattended)
    operator_s: float = 120.0             # time allowed for an operator step, in estimates
    output_dir: str = "captures"
    # data-loss limits per segment: above either, the segment is bad and recorded again
    max_missing_fraction: float = 0.01    # share of the frames lost
    max_gap_s: float = 1.0                # longest stretch without a frame, s (device time)
    rerecord_attempts: int = 2            # bad recordings of one segment tolerated before the run stops


@dataclass(frozen=True)
class EffectsConfig:
    plugins: tuple = ()                   # effect plugins: path/file.py:ClassName (relative: to the file)
    folders: tuple = ()                   # folders whose *.py files hold effect plugins


@dataclass(frozen=True)
class Config:
    imu: ImuConfig = field(default_factory=ImuConfig)
    table: TableConfig = field(default_factory=TableConfig)
    site: SiteConfig = field(default_factory=SiteConfig)
    warmup: WarmupConfig = field(default_factory=WarmupConfig)
    run: RunConfig = field(default_factory=RunConfig)
    effects: EffectsConfig = field(default_factory=EffectsConfig)
    source: str = "defaults"
    imus: tuple = ()                      # several IMUs in one run (``imus:``); then imu is imus[0]
    chamber: ChamberConfig | None = None  # a temperature chamber (``chamber:``), None: none

    @property
    def imu_list(self) -> tuple:
        """The IMUs of a run: the ``imus:`` list, or the one ``imu:``."""
        return self.imus or (self.imu,)

    def with_overrides(self, section: str, **values) -> "Config":
        """A copy with ``values`` (None ones skipped) set in ``section``."""
        values = {k: v for k, v in values.items() if v is not None}
        if not values:
            return self
        return replace(self, **{section: replace(getattr(self, section), **values)})

    def to_dict(self) -> dict:
        """Plain data (the snapshot kept in a capture for --resume), defaults resolved."""
        doc = _plain(self)
        doc["table"]["axes_enu"] = self.table.axis_list()
        doc["table"]["load_position_deg"] = list(self.table.load_position_deg or [0.0] * self.table.axes)
        doc["table"]["geometry"] = {k: doc["table"].pop(k) for k in GEOMETRY_KEYS}
        if self.imus:
            del doc["imu"]
            doc["imus"] = [{k: v for k, v in item.items() if v is not None} for item in doc["imus"]]
        else:
            del doc["imus"]
            for key in MULTI_IMU_KEYS:
                doc["imu"].pop(key, None)
        if self.chamber is None:
            del doc["chamber"]
        else:                               # one settle rule, as the file gave it
            doc["chamber"].pop("settle_slope_c_per_min" if self.chamber.soak_s is not None else "soak_s")
        return doc


def normal_gravity(latitude_deg: float, height_m: float = 0.0) -> float:
    """WGS-84 normal gravity (Somigliana) with the second-order free-air correction, m/s^2."""
    a, f, gm, omega = 6378137.0, 1 / 298.257223563, 3.986004418e14, 7.292115e-5
    ge, k, e2 = 9.7803253359, 0.00193185265241, 0.00669437999013
    s2 = math.sin(math.radians(latitude_deg)) ** 2
    gamma = ge * (1 + k * s2) / math.sqrt(1 - e2 * s2)
    b = a * (1 - f)
    m = omega**2 * a**2 * b / gm
    return gamma * (1 - 2 / a * (1 + f + m - 2 * f * s2) * height_m + 3 * height_m**2 / a**2)


# ------------------------------------------------------------------------------------ loading

def find_config(path: str | None) -> Path | None:
    """The file to read for the bench: ``path``, else $STATION_CONFIG, else ./station.yaml if it
    exists.  (Not for plugins: see plugin_config.)"""
    if path:
        return Path(path)
    if os.environ.get(ENV_FILE):
        return Path(os.environ[ENV_FILE])
    return Path(DEFAULT_FILE) if Path(DEFAULT_FILE).is_file() else None


def load_config(path: str | None = None, *, env: dict | None = None) -> Config:
    """The configuration from the file (if any) and the environment; flags come on top."""
    file = find_config(path)
    config = Config()
    if file is not None:
        from station.core.user_files import read_user_text

        text = read_user_text(file, "the configuration")         # (a FIFO is refused, not read: it hung)
        try:
            doc = yaml_text.safe_load(text)
        except (yaml.YAMLError, ValueError) as e:      # ValueError: a timestamp in month 13
            mark = getattr(e, "problem_mark", None)
            where = f" (line {mark.line + 1})" if mark is not None else ""
            raise UserError(f"{file}: not valid YAML{where}: {getattr(e, 'problem', e)}") from None
        config = parse_config(doc, str(file))
    env = os.environ if env is None else env
    for var, (section, key) in ENV_KEYS.items():
        if env.get(var):
            config = config.with_overrides(section, **{key: env[var]})
    return config


def parse_config(doc, source: str) -> Config:
    if doc is None:
        doc = {}
    if not isinstance(doc, dict):
        raise UserError(f"{source}: a configuration must be a YAML mapping")
    v = _Validator(source)
    version = doc.get("version", 1)
    if version != 1:
        raise v.fail("version", f"must be 1, got {version!r}")
    v.known(doc, "", ("version", "imu", "imus", "table", "site", "warmup", "run", "effects", "chamber"))
    imu_checks = {"port": v.text, "protocol": v.text, "serial": v.serial, "rate_hz": v.positive,
                  "csv_units": v.text_or_empty, "frame_timeout_s": v.positive, "lot": v.text}
    imu = v.section(doc, "imu", ImuConfig, imu_checks)
    imus = _imus(doc, v, imu_checks)
    if imus:
        imu = imus[0]
    doc, geometry = _geometry(doc, v)
    table = v.section(doc, "table", TableConfig, {
        "port": v.text, "protocol": v.text, "serial": v.serial, "axes": v.axes_count,
        "axes_enu": v.vectors, "mounting": v.mounting, "limits": v.limits,
        "load_position_deg": v.numbers, "position_tolerance_deg": v.positive,
        "rate_tolerance_dps": v.positive, "poll_interval_s": v.non_negative, "angle_error_arcsec": v.non_negative,
        "imu_offset_m": v.vector, "geometry": None})
    if table.poll_interval_s < MIN_POLL_INTERVAL_S:
        raise v.fail("table.poll_interval_s", f"must be at least {MIN_POLL_INTERVAL_S:g} s (the driver polling "
                     f"faster starves the IMU's reader in the same process), got {table.poll_interval_s!r}")
    site = v.section(doc, "site", SiteConfig, {
        "latitude_deg": v.latitude, "height_m": v.number, "gravity_mps2": v.gravity})
    warmup = v.section(doc, "warmup", WarmupConfig, {
        "duration_s": v.non_negative, "max_s": v.positive, "temp_slope_c_per_h": v.positive,
        "window_s": v.positive})
    run = v.section(doc, "run", RunConfig, {
        "settle_s": v.non_negative, "operator": v.boolean, "operator_s": v.non_negative,
        "output_dir": v.text, "max_missing_fraction": v.fraction, "max_gap_s": v.positive,
        "rerecord_attempts": v.count})
    effects = v.section(doc, "effects", EffectsConfig, {
        "plugins": lambda value, where: v.paths(value, where, source),
        "folders": lambda value, where: v.paths(value, where, source)})
    table = _check_table(replace(table, **geometry), v)
    for i, entry in enumerate(imus):
        if entry.offset_m is not None and not table.axes_intersect:
            raise v.fail(f"imus[{i}].offset_m", "is the IMU's offset from the axes' intersection: with "
                                                "geometry.axes_intersect false there is none (leave it out)")
    if warmup.temp_slope_c_per_h is not None and warmup.max_s is None:
        raise v.fail("warmup.max_s", "needed with temp_slope_c_per_h (the longest warm-up)")
    if warmup.temp_slope_c_per_h is not None and warmup.window_s < 2.0:
        raise v.fail("warmup.window_s", f"must be at least 2 s, got {warmup.window_s:g}: the temperature is read "
                                        "once a second and its slope fitted to three readings at least")
    return Config(imu=imu, table=table, site=site, warmup=warmup, run=run, effects=effects, source=source,
                  imus=imus, chamber=_chamber(doc, v))


CHAMBER_KEYS = ("kind", "range_c", "ramp_c_per_min", "ambient_c", "soak_s", "settle_slope_c_per_min",
                "settle_window_s", "settle_max_s", "imu_time_constant_s", "agree_c")


def _chamber(doc: dict, v: "_Validator") -> ChamberConfig | None:
    """The ``chamber:`` section (None without one), checked field by field in one line each."""
    if doc.get("chamber") is None:
        return None

    def kind(value, where):
        if value not in CHAMBER_KINDS:
            raise v.fail(where, f"must be one of {', '.join(CHAMBER_KINDS)} (manual: the operator sets "
                                f"the chamber when asked), got {repr(value)[:40]}")
        return value

    def span(value, where):
        if not isinstance(value, list) or len(value) != 2:
            raise v.fail(where, f"must be [min, max] in degrees C, got {repr(value)[:40]}")
        lo, hi = (v.number(x, f"{where}[{i}]") for i, x in enumerate(value))
        if not -100.0 <= lo < hi <= 200.0:
            raise v.fail(where, f"must be [min, max] with -100 <= min < max <= 200 degrees C, got {value!r}")
        return (lo, hi)

    def celsius(value, where):
        x = v.number(value, where)
        if not -100.0 <= x <= 200.0:
            raise v.fail(where, f"must be within -100..200 degrees C, got {value!r}")
        return x

    c = v.section(doc, "chamber", ChamberConfig, {
        "kind": kind, "range_c": span, "ramp_c_per_min": v.positive, "ambient_c": celsius,
        "soak_s": v.non_negative, "settle_slope_c_per_min": v.positive, "settle_window_s": v.positive,
        "settle_max_s": v.positive, "imu_time_constant_s": v.positive, "agree_c": v.positive})
    given = doc["chamber"] if isinstance(doc["chamber"], dict) else {}
    if "soak_s" in given and "settle_slope_c_per_min" in given:
        raise v.fail("chamber.soak_s", "give either soak_s (a fixed soak) or settle_slope_c_per_min "
                                       "(until the IMU's temperature settles), not both")
    if "range_c" not in given:
        raise v.fail("chamber.range_c", "needed: the setpoints the chamber can hold, [min, max] in degrees C")
    return c


GEOMETRY_KEYS = ("axes_intersect", "level_arcsec")


MULTI_IMU_KEYS = ("name", "mounting", "offset_m")
MAX_IMUS = 32


def _imus(doc: dict, v: "_Validator", checks: dict) -> tuple:
    """The ``imus:`` list (several IMUs in one run), each entry as ``imu:`` plus name, mounting
    and offset_m; () without one."""
    value = doc.get("imus")
    if value is None:
        return ()
    if doc.get("imu") is not None:
        raise v.fail("imus", "give either imu: (one IMU) or imus: (a list of IMUs), not both")
    if not isinstance(value, list) or not value:
        raise v.fail("imus", "must be a list of IMUs (each a mapping: port, protocol, serial, mounting, ...)")
    if len(value) > MAX_IMUS:
        raise v.fail("imus", f"at most {MAX_IMUS} IMUs in one run, got {len(value)}")
    checks = {**checks, "name": v.name, "mounting": v.mounting, "offset_m": v.vector}
    out = []
    for i, item in enumerate(value):
        if not isinstance(item, dict):
            raise v.fail(f"imus[{i}]", f"must be a mapping, got {type(item).__name__}")
        out.append(_imu_entry(item, f"imus[{i}]", v, checks))
    for key in ("port", "name"):
        seen = {}
        for i, imu in enumerate(out):
            x = getattr(imu, key)
            if x is not None and x in seen:
                raise v.fail(f"imus[{i}].{key}", f"{x!r} is also imus[{seen[x]}].{key}: each IMU has its own")
            seen.setdefault(x, i)
    return tuple(out)


def _imu_entry(item: dict, where: str, v: "_Validator", checks: dict) -> ImuConfig:
    v.known(item, f"{where}.", tuple(checks))
    return ImuConfig(**{k: checks[k](val, f"{where}.{k}") for k, val in item.items() if val is not None})


def _geometry(doc: dict, v: "_Validator") -> tuple[dict, dict]:
    """(the document without ``table.geometry``, that mapping's values as TableConfig fields)."""
    table = doc.get("table")
    if not isinstance(table, dict) or table.get("geometry") is None:
        return doc, {}
    value, where = table["geometry"], "table.geometry"
    if not isinstance(value, dict):
        raise v.fail(where, f"must be a mapping (axes_intersect, level_arcsec), got {type(value).__name__}")
    v.known(value, f"{where}.", GEOMETRY_KEYS)
    out = {}
    if value.get("axes_intersect") is not None:
        out["axes_intersect"] = v.boolean(value["axes_intersect"], f"{where}.axes_intersect")
    if value.get("level_arcsec") is not None:
        level = v.positive(value["level_arcsec"], f"{where}.level_arcsec")
        if level > 3600.0:
            raise v.fail(f"{where}.level_arcsec", f"must be at most 3600 (1 deg), got {value['level_arcsec']!r}")
        out["level_arcsec"] = level
    return {**doc, "table": {k: x for k, x in table.items() if k != "geometry"}}, out


def _check_table(table: TableConfig, v: "_Validator") -> TableConfig:
    n = len(table.axes_enu) if table.axes_enu else table.axes
    if table.axes_enu and not 1 <= n <= 3:
        raise v.fail("table.axes_enu", f"a table has 1 to 3 axes, got {n}")
    table = replace(table, axes=n)
    if table.imu_offset_m is not None and not table.axes_intersect:
        raise v.fail("table.imu_offset_m", "is the IMU's offset from the axes' intersection: with "
                                           "geometry.axes_intersect false there is none (leave it out: the fit "
                                           "takes an offset across each axis)")
    if len(table.limits) not in (1, n):
        raise v.fail("table.limits", f"one entry for every axis or one per axis ({n}), got {len(table.limits)}")
    if table.load_position_deg and len(table.load_position_deg) != n:
        raise v.fail("table.load_position_deg", f"one angle per axis ({n}), got {len(table.load_position_deg)}")
    for i, lim in enumerate(table.axis_limits()):
        where = f"table.limits[{i if len(table.limits) > 1 else 0}]"
        if lim.move_rate_dps > lim.max_rate_dps or lim.move_accel_dps2 > lim.max_accel_dps2 \
                or lim.rate_accel_dps2 > lim.max_accel_dps2:
            raise v.fail(where, "move_rate_dps, move_accel_dps2 and rate_accel_dps2 must not exceed "
                                "max_rate_dps and max_accel_dps2")
        if (lim.angle_min_deg is None) != (lim.angle_max_deg is None):
            raise v.fail(where, "angle_min_deg and angle_max_deg go together")
        if lim.angle_min_deg is not None and not 0 < lim.angle_max_deg - lim.angle_min_deg < 360:
            raise v.fail(where, "angle_max_deg - angle_min_deg must be within (0, 360) "
                                "(leave both out for a continuous axis)")
        if table.load_position_deg and lim.angle_limits is not None:
            p = table.load_position_deg[i]
            if not lim.angle_min_deg <= p <= lim.angle_max_deg:
                raise v.fail(f"table.load_position_deg[{i}]", f"{p} is outside the axis's angle limits")
    return table


class _Validator:
    """Typed values from the YAML document; failures name the file and the field."""

    def __init__(self, source: str):
        self.source = source

    def fail(self, where: str, message: str) -> UserError:
        # a key from the file may hold anything: control characters escaped, the message one line
        where = where if where.isprintable() else repr(where)[1:-1]
        return UserError(f"{self.source}: field '{where}': {message}")

    def known(self, mapping: dict, prefix: str, keys) -> None:
        for key in mapping:
            if key not in keys:
                raise self.fail(f"{prefix}{key}", f"unknown key (known: {', '.join(keys)})")

    def section(self, doc: dict, name: str, cls, checks: dict, prefix: str = ""):
        mapping = doc.get(name)
        if mapping is None:
            return cls()
        where = f"{prefix}{name}"
        if not isinstance(mapping, dict):
            raise self.fail(where, f"must be a mapping, got {type(mapping).__name__}")
        self.known(mapping, f"{where}.", tuple(checks))
        values = {k: checks[k](val, f"{where}.{k}") for k, val in mapping.items() if val is not None}
        return cls(**values)

    # -------------------------------------------------------------- value checks
    def number(self, value, where):
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise self.fail(where, f"must be a finite number, got {value!r}")
        return float(value)

    def positive(self, value, where):
        x = self.number(value, where)
        if x <= 0:
            raise self.fail(where, f"must be > 0, got {value!r}")
        return x

    def non_negative(self, value, where):
        x = self.number(value, where)
        if x < 0:
            raise self.fail(where, f"must be >= 0, got {value!r}")
        return x

    def fraction(self, value, where):
        x = self.number(value, where)
        if not 0 <= x < 1:
            raise self.fail(where, f"must be a fraction within [0, 1), got {value!r}")
        return x

    def count(self, value, where):
        if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= 100:
            raise self.fail(where, f"must be a whole number from 0 to 100, got {value!r}")
        return value

    def latitude(self, value, where):
        x = self.number(value, where)
        if not -90 <= x <= 90:
            raise self.fail(where, f"must be within [-90, 90], got {value!r}")
        return x

    def gravity(self, value, where):
        x = self.number(value, where)
        if not 9.7 < x < 9.9:
            raise self.fail(where, f"must be a local gravity on Earth (9.7-9.9 m/s^2), got {value!r}")
        return x

    def boolean(self, value, where):
        if not isinstance(value, bool):
            raise self.fail(where, f"must be true or false, got {value!r}")
        return value

    def text(self, value, where):
        if isinstance(value, bool) or not isinstance(value, (str, int)) or str(value) == "":
            raise self.fail(where, f"must be text, got {value!r}")
        return str(value)

    def name(self, value, where):
        """A label that names a folder: letters, digits, '-', '_' and '.' (not only dots)."""
        text = self.text(value, where)
        if len(text) > 64 or not all(c.isalnum() or c in "-_." for c in text) or set(text) == {"."}:
            raise self.fail(where, f"must be 1-64 letters, digits, '-', '_' or '.' (it names a folder), "
                                   f"got {value!r}")
        return text

    def text_or_empty(self, value, where):
        if not isinstance(value, str):
            raise self.fail(where, f"must be text, got {value!r}")
        return value

    def axes_count(self, value, where):
        if isinstance(value, bool) or value not in (1, 2, 3):
            raise self.fail(where, f"must be 1, 2 or 3, got {value!r}")
        return int(value)

    def numbers(self, value, where):
        if not isinstance(value, list):
            raise self.fail(where, f"must be a list of numbers, got {value!r}")
        return tuple(self.number(x, f"{where}[{i}]") for i, x in enumerate(value))

    def paths(self, value, where, source):
        """A list of paths; relative ones are taken from the configuration file's folder."""
        if not isinstance(value, list) or not all(isinstance(x, str) and x for x in value):
            raise self.fail(where, "must be a list of paths")
        base = Path(source).parent if source not in ("defaults", "") else Path(".")
        return tuple(x if Path(x.split(":")[0]).is_absolute() else str(base / x) for x in value)

    def vector(self, value, where):
        out = self.numbers(value, where)
        if len(out) != 3:
            raise self.fail(where, f"must be a list of 3 numbers, got {value!r}")
        return out

    def vectors(self, value, where):
        if not isinstance(value, list) or not value:
            raise self.fail(where, f"must be a list of axis directions [e, n, u], got {value!r}")
        out = []
        for i, item in enumerate(value):
            vec = np.array(self.vector(item, f"{where}[{i}]"))
            if np.linalg.norm(vec) == 0:
                raise self.fail(f"{where}[{i}]", "must not be the zero vector")
            out.append(tuple(float(x) for x in vec / np.linalg.norm(vec)))
        return tuple(out)

    def mounting(self, value, where):
        if not isinstance(value, list) or len(value) != 3 or not all(
                isinstance(x, str) and x.strip().lower() in AXIS_NAMES for x in value):
            raise self.fail(where, "must be the platform directions of the IMU's x, y and z axes, "
                                   f"each one of {', '.join(AXIS_NAMES)}, e.g. [+x, +y, +z]; got {value!r}")
        names = tuple(x.strip().lower() for x in value)
        m = np.column_stack([AXIS_NAMES[x] for x in names])
        if round(float(np.linalg.det(m))) != 1:
            raise self.fail(where, f"{list(value)} is not a right-handed mounting (x cross y must be z)")
        return names

    def serial(self, value, where):
        """The drivers' own SerialSettings, which check the values (parity, sizes, timeouts)."""
        try:
            s = self.section({"serial": value}, "serial", SerialSettings, {
                "baudrate": self.positive, "bytesize": self.number, "parity": self.text,
                "stopbits": self.number, "rtscts": self.boolean, "xonxoff": self.boolean,
                "timeout_s": self.positive, "write_timeout_s": self.positive}, prefix=where[: -len("serial")])
        except ValueError as e:
            raise self.fail(where, str(e)) from None
        return replace(s, baudrate=int(s.baudrate), bytesize=int(s.bytesize))

    def limits(self, value, where):
        checks = {f.name: (self.positive if f.name.endswith(("dps", "dps2")) else self.number)
                  for f in fields(AxisConfig)}
        items = value if isinstance(value, list) else [value]
        if not items:
            raise self.fail(where, "must not be empty")
        return tuple(self._axis(item, f"{where}[{i}]", checks) for i, item in enumerate(items))

    def _axis(self, item, where, checks):
        if not isinstance(item, dict):
            raise self.fail(where, f"must be a mapping, got {type(item).__name__}")
        self.known(item, f"{where}.", tuple(checks))
        return AxisConfig(**{k: checks[k](v, f"{where}.{k}") for k, v in item.items() if v is not None})


def _plain(value):
    if hasattr(value, "__dataclass_fields__"):
        return {f.name: _plain(getattr(value, f.name)) for f in fields(value)}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


def from_dict(doc: dict, source: str) -> Config:
    """A Config back from ``Config.to_dict()`` (a capture's snapshot)."""
    doc = {k: v for k, v in doc.items() if k != "source"}
    return parse_config({"version": 1, **doc}, source)


EXAMPLE = """\
# station configuration (station init wrote this file; docs/sequencer.md describes every key).
# Flags override it: --port, --table-port, --imu-protocol, --table-protocol; so do the
# environment variables STATION_IMU_PORT, STATION_TABLE_PORT, STATION_IMU_PROTOCOL,
# STATION_TABLE_PROTOCOL.  Units are in the names.
version: 1

imu:
  port: /dev/ttyUSB0          # device path or pyserial URL (socket://host:port, spy://...)
  protocol: vectornav         # vectornav | xsens | csv
  rate_hz: 100                # vectornav: 800 / N
  # csv_units: t=ms,accel=g,gyro=rad/s   # csv only (default t=s,accel=m/s^2,gyro=deg/s)
  frame_timeout_s: 2.0
  # lot: 2026-W48             # the production lot: filed with each calibration (station fleet --lot)
  serial: {baudrate: 115200, bytesize: 8, parity: N, stopbits: 1, rtscts: false, xonxoff: false, timeout_s: 1.0}

# Several IMUs on the table in one run (docs/fleet.md): instead of imu:, a list
# imus:
#   - {port: /dev/ttyUSB0, protocol: vectornav}
#   - {port: /dev/ttyUSB2, protocol: vectornav, name: left, mounting: [-x, -y, +z], offset_m: [0.1, 0, 0]}

table:
  port: /dev/ttyUSB1
  protocol: acutrol           # acutrol | aerosmith
  serial: {baudrate: 115200, timeout_s: 1.0}
  axes: 3
  # Each axis's direction in east-north-up when every axis is at zero, outer -> inner.
  # The platform's own axes are east, north, up at zero.  Default for 3 axes:
  axes_enu: [[0, 0, 1], [1, 0, 0], [0, 1, 0]]
  # How the IMU sits on the platform: the platform directions of the IMU's x, y and z axes.
  mounting: [+x, +y, +z]
  # Limits, one entry for every axis or one per axis (outer first).  Never exceeded.
  limits:
    - {max_rate_dps: 300, max_accel_dps2: 300, move_rate_dps: 60, move_accel_dps2: 60,
       rate_accel_dps2: 50}
    # an axis with cables: add angle_min_deg: -170, angle_max_deg: 170
  load_position_deg: [0, 0, 0]   # where the table waits while the operator remounts the IMU
  position_tolerance_deg: 0.002
  rate_tolerance_dps: 0.01
  poll_interval_s: 0.01          # how often the driver reads the table while it waits for arrival
  angle_error_arcsec: 2.0        # 1-sigma of the table's angles (recorded in the capture)
  # imu_offset_m: [0, 0, 0]      # IMU reference point from the axes' intersection, if known
  # The table's geometry (recorded in every capture; docs/method-lsq.md "The table's geometry"):
  # axes_intersect: the axes meet at one point, so the IMU's offset from it is one vector for
  # every rotation while the IMU stays mounted (false: each axis turns about its own line).
  # level_arcsec: 1-sigma of the rotation axes' elevation (levelling, squareness of the axes);
  # given, the fit knows gravity along each axis and one rate reveals the size effect's
  # cross positions from diagonal axes.
  geometry: {axes_intersect: true}
  #   level_arcsec: 5

site:
  latitude_deg: 45.0
  height_m: 0.0
  # gravity_mps2: 9.80620      # measured local gravity; default: WGS-84 normal gravity

warmup:
  duration_s: 0                # at least this long before the first segment
  # temp_slope_c_per_h: 0.5    # ...and until the IMU temperature changes less than this
  # max_s: 14400               # but never longer
  window_s: 300                # the temperature slope is fitted over this window

# A temperature chamber around the table (docs/sequencer.md "chamber"): schemes may then set it
# (chamber_c: 45 on a segment) and station design places segments at its setpoints.
# chamber:
#   kind: manual               # the operator sets the chamber when asked and presses Enter
#   range_c: [20, 60]          # the setpoints it can hold, degC
#   ramp_c_per_min: 2.0        # how fast its air follows a new setpoint
#   ambient_c: 25              # the room: the chamber's air before the first setpoint
#   soak_s: 600                # a fixed soak after the ramp; or, instead, until the IMU settles:
#   # settle_slope_c_per_min: 0.02   # the IMU's own temperature slope below this
#   # settle_window_s: 120           # ...over this window
#   # settle_max_s: 3600             # ...but never longer after the ramp
#   imu_time_constant_s: 600   # the IMU's lag behind the air, for the time estimates of plan and design
#   agree_c: 5.0               # IMU temperature vs setpoint beyond this: a finding in the capture

run:
  settle_s: 5.0                # discarded after every move and every ramp
  operator: true               # false: unattended, never ask for a remount
  operator_s: 120              # time allowed for an operator step in duration estimates
  output_dir: captures
  max_missing_fraction: 0.01   # a segment that lost more of its frames is recorded again
  max_gap_s: 1.0               # ...or that went longer without a frame (IMU stall), s
  rerecord_attempts: 2         # then the run stops (resume later with --resume)
"""
