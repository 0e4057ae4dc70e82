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


def registry(args) -> EffectRegistry:
    """Library + installed entry points + $STATION_EFFECTS_PATH + the effects section of a
    configuration the user named (--config, $STATION_CONFIG) or of their own (the user's
    configuration folder) + --effects-dir + --plugin.  A ./station.yaml found in the working
    directory is not read for plugins: loading one runs its code (a note says so)."""
    from station.bench.config import implicit_plugins, load_config, plugin_config
    from station.cli.output import err
    from station.model.registry import EffectRegistry

    reg = EffectRegistry()
    config_path = plugin_config(getattr(args, "config", None))
    if config_path is not None:
        config = load_config(str(config_path))
        reg.add_all(config.effects.plugins, config.effects.folders)
    elif implicit_plugins(getattr(args, "config", None)):
        err.print("note: ./station.yaml names effect plugins: not loaded (a configuration found in the "
                  "working directory runs no code; give --config station.yaml to load them)",
                  markup=False, soft_wrap=True)
    reg.add_all(getattr(args, "plugin", []), getattr(args, "effects_dir", []))
    return reg


def effect_ids(reg: EffectRegistry, values) -> list[str]:
    """--add values: effect ids, or plugin specs whose effects are loaded and added."""
    from station.model.registry import effect_ids as ids_of

    return ids_of(reg, values)
