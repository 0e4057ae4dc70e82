"""The effect-plugin options shared by estimate, diagnose, apply and effects."""
from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:      # the registry is imported when a command uses it, not to build the parser
    from station.model.registry import EffectRegistry


def add_arguments(p) -> None:
    p.add_argument("--plugin", action="append", default=[], metavar="FILE.py:CLASS",
                   help="load an effect plugin (a file, FILE.py:CLASS, or module:CLASS); repeatable")
    p.add_argument("--effects-dir", action="append", default=[], metavar="DIR",
                   help="load every effect plugin in DIR/*.py; repeatable")


def options(args) -> dict:
    """The plugin options as the API takes them (station.api: plugins, effects_dirs, config); a
    note when a ./station.yaml found in the working directory names plugins, which are not loaded
    (loading one runs its code)."""
    from station.io.config_paths import implicit_plugins

    if implicit_plugins(getattr(args, "config", None)):
        from station.cli.output import err

        err.print("note: ./station.yaml names effect plugins: not loaded (a configuration found in the "
                  "working directory runs no code; give --config station.yaml to load them)",
                  markup=False, soft_wrap=True)
    return {"plugins": list(getattr(args, "plugin", [])), "effects_dirs": list(getattr(args, "effects_dir", [])),
            "config": getattr(args, "config", None)}


def registry(args) -> EffectRegistry:
    """The registry the API builds from the same options (station.api._registry): library +
    installed entry points + $STATION_EFFECTS_PATH + the effects section of a configuration the
    user named (--config, $STATION_CONFIG) or of their own + --effects-dir + --plugin."""
    from station.api import _registry

    return _registry(**options(args))


def effect_ids(reg: EffectRegistry, values) -> list[str]:
    """--add values: effect ids, or plugin specs whose effects are loaded and added."""
    from station.model.registry import effect_ids as ids_of

    return ids_of(reg, values)
