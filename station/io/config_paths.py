"""Where station's configuration files are looked for (``station.yaml``): the user's own
configuration folder, the file whose ``effects`` section may load plugins, and whether a
./station.yaml passed over names plugins.  Apart from station.bench.config (which reads the
file) so that `station estimate` finds a configuration without importing the bench, the drivers
and pyserial (issue 27: ~9 ms of its start)."""
from __future__ import annotations

import os
from pathlib import Path

from station.core import yaml_text

DEFAULT_FILE = "station.yaml"
ENV_FILE = "STATION_CONFIG"


def user_config_dir() -> Path:
    """The user's own configuration folder for station: platformdirs' user_config_dir
    ($XDG_CONFIG_HOME/station or ~/.config/station on Linux, ~/Library/Application
    Support/station on macOS, %LOCALAPPDATA%\\station on Windows; docs/architecture.md says
    why platformdirs)."""
    import platformdirs

    return Path(platformdirs.user_config_dir("station", appauthor=False))


def plugin_config(path: str | None) -> Path | None:
    """The configuration whose ``effects`` section may load plugins (run their code): one the user
    named, ``path`` (--config) or $STATION_CONFIG, else station.yaml in the user's own
    configuration folder (user_config_dir) if it exists.  Never a ./station.yaml found in the
    working directory: a capture or a download can ship one (issue 26)."""
    if path:
        return Path(path)
    if os.environ.get(ENV_FILE):
        return Path(os.environ[ENV_FILE])
    own = user_config_dir() / DEFAULT_FILE
    return own if own.is_file() else None


def implicit_plugins(path: str | None) -> bool:
    """Whether a ./station.yaml that plugin_config passes over (found, not named) lists plugins."""
    if path or os.environ.get(ENV_FILE) or not Path(DEFAULT_FILE).is_file():
        return False
    try:
        from station.io.capture import read_regular_file

        doc = yaml_text.safe_load(read_regular_file(DEFAULT_FILE, limit=2**20))
    except Exception:       # noqa: BLE001 - only to say it is passed over; never read for more
        return False
    return isinstance(doc, dict) and isinstance(doc.get("effects"), dict) and any(doc["effects"].values())
