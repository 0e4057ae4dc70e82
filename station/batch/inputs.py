"""What a batch runs on: captures named by path, by glob, by a folder of captures, or by a
history query; and where each one's output goes (beside the capture, or into ``-o DIR``).

The names are expanded where the batch is started; the workers read the captures from the
paths given (docs/fleet.md: a path every worker reaches -- local disk for a local cluster, a
shared filesystem mounted at the same path for a remote one)."""
from __future__ import annotations

import glob
import hashlib
import os
from dataclasses import dataclass
from pathlib import Path

from station.core.errors import UserError

MANIFEST = "manifest.yaml"
GLOB_CHARACTERS = set("*?[")

# the file each command writes beside the capture, and its ending in -o DIR (after the stem)
OUTPUT_NAMES = {"estimate": ("calibration.yaml", ".calibration.yaml"),
                "diagnose": ("diagnosis.json", ".diagnosis.json"),
                "report": ("report.html", ".report.html")}


@dataclass(frozen=True)
class Item:
    """One unit of a batch: the capture (or, for export, a calibration file), the file(s) to
    write, and the calibration the report or export uses (the first of ``calibrations`` that
    exists where the worker looks)."""
    source: str
    output: str
    calibrations: tuple = ()


def expand(names, *, allow_files: bool = False) -> list[str]:
    """Paths in the order given, globs expanded (sorted), a folder that is not a capture replaced
    by the captures directly inside it; each path once.  ``allow_files``: a calibration file
    (.yaml) is an input too (export)."""
    found: list[str] = []
    for name in names:
        if GLOB_CHARACTERS & set(name) and not Path(name).exists():
            matches = sorted(glob.glob(name, recursive=True))
            if not matches:
                raise UserError(f"{name}: no capture matches this pattern")
            found += [m for m in matches if _usable(Path(m), allow_files)]
            continue
        path = Path(name)
        if path.is_dir() and not (path / MANIFEST).is_file():
            inside = sorted(str(p.parent) for p in path.glob(f"*/{MANIFEST}"))
            if not inside:
                raise UserError(f"{name}: neither a capture (no {MANIFEST}) nor a folder of captures")
            found += inside
            continue
        found.append(name)         # a capture, or a path only the workers reach: they say if not
    seen, unique = set(), []
    for name in found:
        key = str(Path(name).resolve()) if Path(name).exists() else name
        if key not in seen:
            seen.add(key)
            unique.append(name)
    return unique


def _usable(path: Path, allow_files: bool) -> bool:
    return (path / MANIFEST).is_file() or (allow_files and path.is_file() and path.suffix in (".yaml", ".yml"))


def from_history(queries, store=None) -> list[str]:
    """The captures the history's calibrations were made from: ``queries`` are IMU serials, or
    ``all`` (every serial in the store); each calibration's provenance names its capture."""
    from station.io.calfile import read_calfile
    from station.io.history import Store

    st = Store(store)
    serials = []
    for q in queries:
        serials += [s for s, _ in st.serials()] if q == "all" else [q]
    captures = []
    for serial in serials:
        entries = st.list(serial)
        if not entries:
            raise UserError(f"--history-query {serial}: no calibration of this IMU serial in {st.root}")
        for entry in entries:
            if entry.problem:           # its file is not the calibration filed: not read as it
                raise UserError(f"--history-query {serial}: calibration #{entry.id}: {entry.problem}")
            capture = (read_calfile(entry.path).get("provenance") or {}).get("capture")
            if isinstance(capture, str) and capture not in captures:
                captures.append(capture)
    if not captures:
        raise UserError(f"--history-query {' '.join(queries)}: the calibrations name no capture")
    return captures


def stems(sources) -> dict:
    """A file-name stem per source for -o DIR: the capture's folder name (a calibration file's
    stem), made unique with a digest of its path where two share a name."""
    def base(s):
        p = Path(s)
        return p.stem if p.suffix in (".yaml", ".yml") else p.name or "capture"

    count: dict = {}
    for s in sources:
        count[base(s)] = count.get(base(s), 0) + 1
    out = {}
    for s in sources:
        b = base(s)
        out[s] = b if count[b] == 1 else f"{b}-{hashlib.sha256(str(Path(s).resolve()).encode()).hexdigest()[:8]}"
    return out


def plan(command: str, sources, out_dir=None, export_format: str | None = None) -> list[Item]:
    """The items of a batch: each source with its output path and, for report and export, where
    its calibration is looked for (the batch estimate's output in the same -o DIR, then the
    capture's own calibration.yaml); every path absolute (a path relative to the working folder
    means this machine's: a worker elsewhere has another working folder)."""
    names = stems(sources)
    out = Path(out_dir) if out_dir else None
    if out is not None:
        from station.core.user_files import output_path

        output_path(out, "the output folder")
        try:
            out.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            raise UserError(f"-o {out}: cannot make the output folder: {e.strerror}") from None
    items = []
    for s in sources:
        p, stem = Path(s), names[s]
        is_cal = p.suffix in (".yaml", ".yml")
        cals = ()
        if command in ("report", "export"):
            if is_cal:
                cals = (str(p),)
            else:
                cals = ((str(out / f"{stem}{OUTPUT_NAMES['estimate'][1]}"),) if out else ()) + \
                       (str(p / OUTPUT_NAMES["estimate"][0]),)
        if command == "export":
            from station.io.exporters import FORMATS

            name = f"{stem if (out or is_cal) else 'calibration'}-{export_format}{FORMATS[export_format].SUFFIX}"
            target = (out / name) if out else (p.with_name(name) if is_cal else p / name)
        else:
            beside, ending = OUTPUT_NAMES[command]
            target = (out / f"{stem}{ending}") if out else p / beside
        # absolute: a worker elsewhere has another working folder (the paths must be the same there)
        items.append(Item(os.path.abspath(s), os.path.abspath(target), tuple(os.path.abspath(c) for c in cals)))
    return items
