"""Where effects come from: the library, Python files, installed packages.

An effect is a subclass of ``station.model.effect.Effect`` with a unique ``id``.  Besides the
library's (station/model/*.py), a user can bring their own:

* ``path/to/file.py:ClassName`` (or ``path/to/file.py`` for every Effect subclass in it),
  given to ``--add`` / ``--plugin`` or listed under ``effects.plugins`` in station.yaml;
* a folder of such files (every ``*.py`` in it), ``--effects-dir DIR``, ``STATION_EFFECTS_PATH``
  (folders or files separated by the OS path separator) or ``effects.folders`` in station.yaml;
* an installed package's entry point in the group ``station.effects``
  (``[project.entry-points."station.effects"] my_effect = "my_pkg.effects:MyEffect"``).

Loading a plugin runs its code: station loads only what the user names on the command line, in a
configuration they named (--config, $STATION_CONFIG) or their own (the user's configuration folder)
or in the environment, never a path written in a capture or calibration file, nor a ./station.yaml
merely found in the working directory (station.cli.plugins, station.bench.config.plugin_config).
"""
from __future__ import annotations

import importlib
import importlib.util
import inspect
import os
import re
import sys
from pathlib import Path

from station.core.errors import UserError
from station.model.effect import Effect, Param
from station.model.raw_counts import in_capture_units

ENTRY_POINT_GROUP = "station.effects"
ENV_PATH = "STATION_EFFECTS_PATH"
_ID = re.compile(r"^[A-Za-z_][A-Za-z0-9_]{0,63}$")


def _library() -> dict:
    from station.model import LIBRARY

    return dict(LIBRARY)


def is_spec(text: str) -> bool:
    """Whether an --add value names a plugin (a file or module) rather than an effect id."""
    return ":" in text or text.endswith(".py") or os.sep in text


class EffectRegistry:
    """Effect classes by id, with where each came from (``library``, a file, a package)."""

    def __init__(self, entry_points: bool = True, environment: bool = True):
        """The library's effects, then the installed packages' entry points, then the effects of
        $STATION_EFFECTS_PATH.  The entry points are looked up when the registry is first asked
        for an effect, its ids, or to add a plugin (in that order still), not here: a command
        that uses no effect (``station estimate`` without ``--add``) neither imports
        importlib.metadata nor scans the installed distributions (~20 ms of its start)."""
        self.classes: dict[str, type] = {}
        self.sources: dict[str, str] = {}
        # the folders whose *.py were loaded (add), in order, each with the (name, modification
        # time in ns) of the files found there: what a kept registry is checked against
        self.folders: list[tuple[str, tuple]] = []
        for eid, cls in _library().items():
            self._register(cls, "library")
        self._entry_points_pending = entry_points
        if environment:
            for path in _env_paths():
                self.add(path)

    # --- queries ------------------------------------------------------------------------------
    def __contains__(self, eid) -> bool:
        self._load_entry_points()
        return eid in self.classes

    def ids(self) -> list[str]:
        self._load_entry_points()
        return sorted(self.classes)

    def source(self, eid: str) -> str:
        self._load_entry_points()
        return self.sources[eid]

    def create(self, eid: str) -> Effect:
        self._load_entry_points()
        if eid not in self.classes:
            raise UserError(f"unknown effect {eid!r}: known are {', '.join(self.ids())} (station effects "
                            "lists them; a plugin is added with --add path/file.py:ClassName)")
        try:
            effect = in_capture_units(self.classes[eid])()     # counts on a raw capture
            effect._station_source = self.sources[eid]
            return effect
        except Exception as e:      # a plugin's constructor
            raise UserError(f"effect {eid!r} ({self.sources[eid]}): cannot be created: "
                            f"{type(e).__name__}: {e}") from None

    # --- adding -------------------------------------------------------------------------------
    def add(self, spec: str) -> list[str]:
        """Load a plugin spec (file.py:Class, file.py, module:Class, or a folder); returns the ids."""
        self._load_entry_points()
        spec = str(spec)
        path_part, _, cls_name = spec.rpartition(":") if ":" in spec else (spec, "", "")
        if os.name == "nt" and len(path_part) == 1:     # C:\... without a class
            path_part, cls_name = spec, ""
        path = Path(path_part)
        if path.is_dir() and not cls_name:
            ids, files = [], sorted(path.glob("*.py"))
            self.folders.append((str(path), folder_files(path, files)))
            for f in files:
                ids += self._add_module(self._load_file(f), str(f), None)
            return ids
        if path_part.endswith(".py") or path.exists():
            module = self._load_file(path)
            return self._add_module(module, str(path), cls_name or None)
        if cls_name:                                     # an importable module
            try:
                module = importlib.import_module(path_part)
            except Exception as e:
                raise UserError(f"effect plugin {spec}: cannot import {path_part}: {type(e).__name__}: {e}") from None
            return self._add_module(module, path_part, cls_name)
        raise UserError(f"effect plugin {spec}: no such file (give path/file.py:ClassName)")

    def add_all(self, specs=(), folders=()) -> list[str]:
        ids = []
        for folder in folders:
            ids += self.add(folder)
        for spec in specs:
            ids += self.add(spec)
        return ids

    def _load_file(self, path: Path):
        if not path.is_file():
            raise UserError(f"effect plugin {path}: no such file")
        name = "station_effect_plugin_" + re.sub(r"\W", "_", str(path.resolve()))
        if name in sys.modules:                       # the same file named twice
            return sys.modules[name]
        spec = importlib.util.spec_from_file_location(name, path)
        if spec is None or spec.loader is None:
            raise UserError(f"effect plugin {path}: not a Python file")
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        try:
            spec.loader.exec_module(module)
        except SyntaxError as e:
            sys.modules.pop(name, None)
            raise UserError(f"effect plugin {path}: line {e.lineno}: syntax error: {e.msg}") from None
        except Exception as e:
            sys.modules.pop(name, None)
            raise UserError(f"effect plugin {path}: fails to load: {type(e).__name__}: {e}") from None
        return module

    def _add_module(self, module, where: str, cls_name: str | None) -> list[str]:
        if cls_name:
            cls = getattr(module, cls_name, None)
            if cls is None:
                raise UserError(f"effect plugin {where}: no class {cls_name!r} in it")
            classes = [cls]
        else:
            classes = [c for _, c in inspect.getmembers(module, inspect.isclass)
                       if issubclass(c, Effect) and c is not Effect and c.__module__ == module.__name__]
            if not classes:
                raise UserError(f"effect plugin {where}: defines no subclass of station.model.effect.Effect")
        ids = []
        for cls in classes:
            self._register(cls, f"{where}:{cls.__name__}")
            ids.append(cls.id)
        return ids

    def _register(self, cls, source: str) -> None:
        where = f"effect {getattr(cls, '__name__', cls)!s} ({source})"
        if not (inspect.isclass(cls) and issubclass(cls, Effect)):
            raise UserError(f"{where}: not a subclass of station.model.effect.Effect")
        eid = getattr(cls, "id", "")
        if not isinstance(eid, str) or not _ID.match(eid):
            raise UserError(f"{where}: its 'id' must be an identifier (letters, digits, _), got {eid!r}")
        if eid in self.classes and self.classes[eid] is not cls:
            raise UserError(f"{where}: id {eid!r} is taken by {self.sources[eid]}")
        try:
            params = cls().params
        except Exception as e:
            raise UserError(f"{where}: cannot be created: {type(e).__name__}: {e}") from None
        if not all(isinstance(p, Param) for p in params):
            raise UserError(f"{where}: 'params' must be station.model.effect.Param values")
        bad = [n for n in ("needs",) if not set(getattr(cls, n)) <= {"temperature", "time"}]
        if bad:
            raise UserError(f"{where}: 'needs' may name only 'temperature' and 'time'")
        self.classes[eid] = cls
        self.sources[eid] = source

    def _load_entry_points(self) -> None:
        if not self._entry_points_pending:
            return
        self._entry_points_pending = False
        from importlib import metadata

        try:
            eps = metadata.entry_points(group=ENTRY_POINT_GROUP)
        except Exception:           # a broken installed distribution must not stop station
            return
        for ep in eps:
            try:
                cls = ep.load()
            except Exception as e:
                raise UserError(f"effect entry point {ep.name} = {ep.value}: fails to load: "
                                f"{type(e).__name__}: {e}") from None
            self._register(cls, f"entry point {ep.value}")


def folder_files(folder, files=None) -> tuple | None:
    """((name, modification time in ns), ...) of a plugin folder's ``*.py`` files (``files``:
    as globbed already), sorted; None when the folder or a file cannot be read."""
    try:
        return tuple(sorted((f.name, f.stat().st_mtime_ns)
                            for f in (files if files is not None else Path(folder).glob("*.py"))))
    except OSError:
        return None


def _env_paths() -> list[str]:
    return [p for p in os.environ.get(ENV_PATH, "").split(os.pathsep) if p]


def effect_ids(reg: EffectRegistry, values) -> list[str]:
    """Effect ids, or plugin specs whose effects are loaded into ``reg``: the ids they name, in
    order, once each; an unknown id is the one-line "unknown effect" error."""
    ids = []
    for value in values:
        if is_spec(value):
            ids += reg.add(value)
        else:
            reg.create(value)          # raises the one-line "unknown effect" error
            ids.append(value)
    return list(dict.fromkeys(ids))


def registry_for(specs=(), folders=()) -> tuple[EffectRegistry, list[str]]:
    """The registry with the library, entry points, the environment's and the given plugins;
    ``specs`` may mix effect ids and plugin specs: returns the registry and the ids they name."""
    reg = EffectRegistry()
    for folder in folders:
        reg.add(folder)
    return reg, effect_ids(reg, specs)
