"""Compiled plans kept in the user's cache folder, so that `station schemes` and `station plan`
do not solve the table's inverse kinematics again for a scheme and table they have compiled
before (issue 26: `station schemes` spent ~1.2 s of CPU in ~1,250 batched Gauss-Newton runs to
list seven schemes).

A plan is a pure function of the scheme (after its overrides), the configuration, the code that
compiles it and the numeric libraries; the key is the SHA-256 of all of them:

* the scheme and the configuration as pickled objects (every field, the configuration's source
  too: a different file never shares an entry),
* the bytes of every module the compilation runs (``CODE``) and the versions of Python and
  numpy (another numpy may round an angle differently).

So a cached plan is the very plan the compiler returns (the same floats: pickled, not printed),
and an edited scheme, configuration or compiler misses.  A compilation that fails (a scheme the
table cannot run) is kept as its message and raised again as the same ``UserError``.

The folder is platformdirs' ``user_cache_dir("station")/plans`` ($XDG_CACHE_HOME/station/plans
or ~/.cache/station/plans on Linux), or ``$STATION_CACHE_DIR/plans``;
``STATION_CACHE_DIR=off`` (or ``none``, ``0``) turns the cache off.  It is only ever written by
this module (one file per key, written to a temporary file and renamed: a reader never sees half
a file), pruned to the newest ``KEEP`` entries, and read with an unpickler that builds only the
plan's own classes (``_ALLOWED``), so a damaged or foreign file is a miss, never code run.  Any
error reading or writing it (a read-only home, a full disk) is a miss too: the plan is compiled
as without a cache.
"""
from __future__ import annotations

import hashlib
import io
import os
import pickle
import sys
from pathlib import Path

from station.core.errors import UserError

KEEP = 256                      # entries kept (~10 KB each)
_MAGIC = b"station-plan/1\n"
# the modules whose code a compilation runs (relative to the station package)
CODE = ("bench/compile.py", "bench/compile_cache.py", "bench/gimbal.py", "bench/plan.py", "bench/config.py",
        "io/scheme.py", "model/geometry.py")
_ALLOWED = {("station.bench.plan", n) for n in ("Plan", "Checkpoint", "Dwell", "HandRotation", "HandStatic",
                                               "MoveTo", "Operator", "Rotate", "Settle", "WarmUp")} | {
    ("station.io.scheme", "RotationSpec"), ("station.io.scheme", "StaticSpec"),
    ("numpy", "dtype"), ("numpy", "ndarray"), ("numpy._core.multiarray", "scalar"),
    ("numpy._core.multiarray", "_reconstruct"), ("numpy.core.multiarray", "scalar"),
    ("numpy.core.multiarray", "_reconstruct"), ("copyreg", "_reconstructor"), ("builtins", "object")}
_code_digest: bytes | None = None


def cache_dir() -> Path | None:
    """The folder of the cached plans, or None when the cache is off."""
    env = os.environ.get("STATION_CACHE_DIR")
    if env is not None and env.strip().lower() in ("off", "none", "0", ""):
        return None
    if env:
        return Path(env) / "plans"
    import platformdirs

    return Path(platformdirs.user_cache_dir("station", appauthor=False)) / "plans"


def _code() -> bytes:
    global _code_digest
    if _code_digest is None:
        import numpy

        h = hashlib.sha256(f"{sys.version}|numpy {numpy.__version__}".encode())
        root = Path(__file__).resolve().parent.parent
        for rel in CODE:
            h.update(rel.encode() + b"\0" + (root / rel).read_bytes())
        _code_digest = h.digest()
    return _code_digest


def key(scheme, config) -> str:
    h = hashlib.sha256(_code())
    h.update(pickle.dumps((scheme, config), protocol=5))
    return h.hexdigest()


class _Unpickler(pickle.Unpickler):
    def find_class(self, module, name):
        if (module, name) not in _ALLOWED:
            raise pickle.UnpicklingError(f"{module}.{name} is not part of a plan")
        return super().find_class(module, name)


def _load(path: Path):
    data = path.read_bytes()
    if not data.startswith(_MAGIC):
        raise ValueError("not a cached plan")
    kind, value = _Unpickler(io.BytesIO(data[len(_MAGIC):])).load()
    if kind not in ("plan", "error"):
        raise ValueError("not a cached plan")
    return kind, value


def _store(folder: Path, path: Path, outcome) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    tmp = folder / f".{path.name}.{os.getpid()}.tmp"
    try:
        tmp.write_bytes(_MAGIC + pickle.dumps(outcome, protocol=5))
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    entries = sorted(folder.glob("*.plan"), key=lambda p: p.stat().st_mtime)
    for old in entries[:-KEEP]:
        old.unlink(missing_ok=True)


def cached_plan(scheme, config):
    """The cached outcome of compiling ``scheme`` for ``config`` (("plan", Plan) or ("error",
    message)), or None (a miss: never compiled by this code, the cache off, damaged, unreadable)."""
    folder = cache_dir()
    if folder is None:
        return None
    try:
        return _load(folder / f"{key(scheme, config)}.plan")
    except Exception:                   # noqa: BLE001 - a miss (absent, damaged, foreign, unreadable)
        return None


def compile_cached(scheme, config, hit=None):
    """``compile_scheme(scheme, config)``, from the cache when this scheme and configuration were
    compiled by this code before (``hit``: what ``cached_plan`` returned, when asked already).
    The compiler (and with it the model package, ~60 ms) is imported on a miss only."""
    if hit is None:
        hit = cached_plan(scheme, config)
    if hit is not None:
        kind, value = hit
        if kind == "error":
            raise UserError(value)
        return value
    folder = cache_dir()
    path = None
    if folder is not None:
        try:
            path = folder / f"{key(scheme, config)}.plan"
        except Exception:               # noqa: BLE001 - an unpicklable scheme: compiled, not kept
            path = None
    from station.bench.compile import compile_scheme

    try:
        outcome = ("plan", compile_scheme(scheme, config))
    except UserError as e:
        outcome = ("error", str(e))
    if path is not None:
        try:
            _store(folder, path, outcome)
        except (OSError, pickle.PicklingError):
            pass
    if outcome[0] == "error":
        raise UserError(outcome[1])
    return outcome[1]
