"""What a Dask worker does for one capture of a batch: the library functions the single-capture
commands (and station.api) call, with every error caught and returned as one line, so that one
bad capture never stops the others.

``run(job)`` is the task: it fingerprints the capture, skips it when an earlier batch already
made its output from the same capture with the same options (the output still there, its bytes
unchanged: ``job.previous``), and otherwise computes and writes the output, returning an
:class:`Outcome` (plain data: it travels back to the client).  Statuses: ``done``; ``poor fit``
(the file is written, its fit fails or did not converge: the single command's exit status 3);
``failed`` (bad input or an error: nothing written, ``message`` says why in one line);
``skipped`` (done before).

The capture is read in the worker's own process (``$STATION_READ_IN_PROCESS``: the worker's
cores are busy with other captures, a forked reader would only compete), with one BLAS thread.
"""
from __future__ import annotations

import hashlib
import json
import os
import socket
import time
from dataclasses import dataclass, field
from pathlib import Path

DONE, POOR_FIT, FAILED, SKIPPED = "done", "poor fit", "failed", "skipped"


@dataclass
class Job:
    command: str                  # estimate | diagnose | report | export
    source: str                   # the capture (a calibration file for export)
    output: str                   # the file to write (export: the exporter's path)
    options: dict
    calibrations: tuple = ()      # report, export: the calibration, first one that exists
    previous: dict | None = None  # this item's record in the state file of an earlier batch


@dataclass
class Outcome:
    source: str
    status: str
    message: str = ""
    outputs: list = field(default_factory=list)
    output_sha256: str | None = None
    fingerprint: str | None = None
    verdict: str | None = None     # estimate: the fit's verdict (passes, fails, ...)
    calibration: str | None = None  # estimate: the calibration file written (filed by the client)
    imu_serial: str | None = None   # estimate: the serial the file states (where the client files it)
    cpu_s: float = 0.0             # this worker process's CPU time for the item (user + sys)
    wall_s: float = 0.0
    worker: str = ""


def fingerprint(source: str) -> str:
    """A digest of what a capture is made of, cheap enough to take for every capture of a batch:
    the manifest's bytes and the name, size and modification time of every other file in the
    bundle (not the outputs a batch writes beside it).  A calibration file: its bytes."""
    path = Path(source)
    h = hashlib.sha256()
    if path.is_file():
        h.update(path.read_bytes())
        return h.hexdigest()
    h.update((path / "manifest.yaml").read_bytes())
    for f in sorted(path.iterdir()):
        if f.suffix == ".csv" and f.is_file():
            st = f.stat()
            h.update(f"{f.name}\0{st.st_size}\0{st.st_mtime_ns}\n".encode())
    return h.hexdigest()


def outputs_digest(paths) -> str | None:
    """sha256 over the files written (None if one is missing)."""
    h = hashlib.sha256()
    for p in paths:
        try:
            h.update(hashlib.sha256(Path(p).read_bytes()).digest())
        except OSError:
            return None
    return h.hexdigest()


def _one_line(e: BaseException) -> str:
    text = " ".join(str(e).split())
    return text or type(e).__name__


_BLAS_LIMIT = None

# glibc mallopt parameters (malloc.h)
M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3
MMAP_THRESHOLD_BYTES = 32 * 1024 * 1024      # glibc's own ceiling for its dynamic threshold (64-bit)
TRIM_THRESHOLD_BYTES = 2 * MMAP_THRESHOLD_BYTES


def _keep_freed_memory() -> None:
    """A Dask nanny starts its worker with MALLOC_TRIM_THRESHOLD_=65536 (its default, against
    fragmentation), which also fixes glibc's mmap threshold: every array over 128 kB of a
    capture's columns is then mapped and unmapped each time, and its pages faulted in again --
    measured 157,000 page faults and 0.30 s of system time per capture against 800 and 0.01 s,
    0.5 s of user time either way (docs/fleet.md).  Here glibc is given the thresholds its own
    dynamic rule ends at (arrays up to 32 MB from the heap, kept when freed, reused by the next
    capture).  Linux/glibc only; elsewhere nothing is done."""
    try:
        import ctypes

        libc = ctypes.CDLL(None)
        libc.mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES)
        libc.mallopt(M_TRIM_THRESHOLD, TRIM_THRESHOLD_BYTES)
    except (OSError, AttributeError):
        pass


def _worker_setup() -> None:
    """Once per worker process: read captures in process, one BLAS thread for every BLAS library
    (the other captures fill the other cores; a Dask nanny also sets OPENBLAS_NUM_THREADS=1
    before the worker starts), freed memory kept for the next capture."""
    global _BLAS_LIMIT
    if _BLAS_LIMIT is None:
        os.environ.setdefault("STATION_READ_IN_PROCESS", "1")
        _keep_freed_memory()
        # numpy's and scipy's BLAS loaded first, so that the limit holds for both (threadpoolctl
        # limits only the libraries loaded; a worker the user started without OPENBLAS_NUM_THREADS=1
        # would run scipy's with a thread per core): once here, not per task (station.api.estimate
        # enters and leaves threadpoolctl on every call, ~1 ms: the task calls estimate_capture itself)
        import numpy  # noqa: F401
        import scipy.linalg  # noqa: F401
        from threadpoolctl import threadpool_limits

        from station.core.blas import blas_threads      # 1 unless $STATION_BLAS_THREADS says more

        _BLAS_LIMIT = threadpool_limits(limits=blas_threads(), user_api="blas")


def run(job: Job) -> Outcome:
    """The task: one capture, never raising (an error is the outcome's message)."""
    from station.core.errors import UserError

    started_cpu, started = time.process_time(), time.perf_counter()
    out = Outcome(job.source, FAILED, worker=f"{socket.gethostname()}:{os.getpid()}")
    try:
        _worker_setup()
        out.fingerprint = fingerprint(job.source)
        prev = job.previous
        if prev and prev.get("fingerprint") == out.fingerprint and prev.get("outputs") \
                and outputs_digest(prev["outputs"]) == prev.get("output_sha256"):
            out.status, out.outputs, out.output_sha256 = SKIPPED, prev["outputs"], prev["output_sha256"]
            out.verdict, out.message = prev.get("verdict"), "done by an earlier batch"
        else:
            COMMANDS[job.command](job, out)
            out.output_sha256 = outputs_digest(out.outputs)
    except UserError as e:
        out.status, out.message = FAILED, _one_line(e)
    except FileNotFoundError as e:
        out.status, out.message = FAILED, f"{e.filename or job.source}: no such file or folder"
    except OSError as e:
        out.status, out.message = FAILED, f"{e.filename or job.source}: {e.strerror or _one_line(e)}"
    except Exception as e:                     # noqa: BLE001 - a defect: said, the batch goes on
        out.status, out.message = FAILED, f"{type(e).__name__}: {_one_line(e)}"[:400]
    out.cpu_s, out.wall_s = time.process_time() - started_cpu, time.perf_counter() - started
    return out


def _registry(options):
    from station.model.registry import effect_ids, registry_for

    reg = registry_for(options.get("plugins", ()), options.get("effects_dirs", ()))[0]
    return reg, effect_ids(reg, options.get("add", ()))


#: (registry, effect ids) by what they were built from, in this worker process (_effects)
_EFFECTS: dict = {}


def _config_stamp() -> tuple | None:
    """The configuration whose ``effects`` section the registry loads, as station.api finds it
    ($STATION_CONFIG, else the user's own station.yaml), with its size, modification time and
    inode: a worker kept between batches (a cluster of the user's) sees the file edited."""
    from station.io.config_paths import plugin_config

    path = plugin_config(None)
    if path is None:
        return None
    try:
        st = path.stat()
    except OSError:
        return (str(path), None)
    return (str(path), st.st_size, st.st_mtime_ns, st.st_ino)


def _folders_changed(registry) -> bool:
    """Whether a plugin folder the registry loaded has other ``*.py`` files, or files modified,
    since (names and modification times in ns, station.model.registry.folder_files): a plugin
    file dropped into a folder between two batches is then seen by a worker that is kept."""
    from station.model.registry import folder_files

    return any(folder_files(folder) != files for folder, files in registry.folders)


def _effects(options: dict) -> tuple:
    """(registry, effect ids) for a job's options, as ``station.api.estimate`` builds them (the
    library, installed entry points, $STATION_EFFECTS_PATH, the configuration's effects section,
    ``--plugin`` files, ``--add``), built once per worker process for a batch's options and kept
    while the configuration file and the plugin folders' files are unchanged (the folders the
    registry loaded, wherever they were named: --effects-dir, $STATION_EFFECTS_PATH, the
    configuration's effects.folders; _folders_changed).  Built for every capture, they cost 0.12 ms of CPU
    per task with no configuration, 3.9 ms with ``--add EFFECT`` (the installed packages' entry
    points scanned) and 7.9 ms with that and a station.yaml (parsed and validated): up to 2 % of
    a capture's 0.35 s (docs/fleet.md, Fifteenth session); kept, 0.01-0.02 ms (0.013 ms of CPU
    measured after this change without a plugin folder, 0.031 ms with one folder of two plugin
    files: the glob and a stat per file).  A plugin file's code is loaded once
    per process either way (station.model.registry keeps its module); a build that fails is not
    kept (the next capture says the same)."""
    from station import api

    key = (tuple(options.get("plugins", ())), tuple(options.get("effects_dirs", ())), tuple(options.get("add", ())),
           os.environ.get("STATION_EFFECTS_PATH", ""), _config_stamp())
    found = _EFFECTS.get(key)
    if found is not None and _folders_changed(found[0]):
        found = None                # a plugin folder's files changed: built again
    if found is None:
        registry = api._registry(options.get("plugins", ()), options.get("effects_dirs", ()))
        found = (registry, api._effect_ids(registry, options.get("add", ())))
        if len(_EFFECTS) >= 8:              # a worker serving many batches' options
            _EFFECTS.clear()
        _EFFECTS[key] = found
    return found


def _estimate(job: Job, out: Outcome) -> None:
    """As ``station estimate CAPTURE -o OUTPUT`` (station.api.estimate: estimate_capture with
    the effects of the options, the file written), the effects built once per worker (_effects);
    the options were checked where the batch was started (station.cli.batch)."""
    from station.api import Estimate
    from station.estimate import estimate_capture

    o = job.options
    registry, ids = _effects(o)
    cal, capture, provenance = estimate_capture(
        Path(job.source), o.get("method", "auto"), ids, registry,
        max_missing_fraction=o.get("max_missing_fraction", 0.01), max_gap_s=o.get("max_gap_s", 1.0),
        turn_sigma_deg=o.get("turn_sigma_deg"))
    est = Estimate(cal, provenance, capture)
    est.save(job.output)
    serial = provenance.get("imu_serial")
    out.imu_serial = serial if isinstance(serial, str) else None
    verdict = est.verdict
    out.outputs, out.calibration = [job.output], job.output
    out.verdict = verdict.get("result", "untested")
    out.status = DONE if est.usable else POOR_FIT
    out.message = f"fit {out.verdict}: {verdict.get('reason', '')}".strip()


def _diagnose(job: Job, out: Outcome) -> None:
    """As ``station diagnose CAPTURE [--add E] [--auto] --json`` (the JSON into the output file):
    the same diagnosis (station.diagnose.pipeline.run)."""
    from station.diagnose import pipeline, segment_check
    from station.diagnose.as_json import to_json
    from station.estimate.summaries import summarise
    from station.io.calfile import write_new_file
    from station.io.capture import read_capture

    reg, ids = _registry(job.options)
    capture = read_capture(Path(job.source), load_data=False)
    summarise(capture, check_segment=segment_check(capture))
    _, steps, final, _ = pipeline.run(capture, ids, registry=reg, auto=bool(job.options.get("auto")))
    doc = to_json(final, steps)
    write_new_file(Path(job.output), (json.dumps(doc, indent=1) + "\n").encode(), what="diagnosis")
    out.outputs, out.status = [job.output], DONE
    out.verdict = final.verdict
    out.message = final.verdict


def _calibration(job: Job, required: bool):
    for c in job.calibrations:
        if Path(c).is_file():
            return Path(c)
    if required:
        from station.core.errors import UserError

        raise UserError(f"{job.calibrations[-1] if job.calibrations else job.source}: no calibration file "
                        "(station batch estimate writes it)")
    return None


def _report(job: Job, out: Outcome) -> None:
    """As ``station report CAPTURE -o OUTPUT [--no-auto]`` (the calibration: see Job.calibrations)."""
    from station.diagnose.report import report_input, write_page
    from station.io.calfile import read_calfile
    from station.io.capture import read_capture

    capture = read_capture(Path(job.source), load_data=False)
    cal_path = _calibration(job, required=False)
    cal_doc = read_calfile(cal_path) if cal_path else None
    effects = [e for e in (cal_doc or {}).get("effects", []) if e not in ("base_triads", "inter_triad")]
    inp = report_input(capture, cal_doc, cal_path, effects=effects, auto=not job.options.get("no_auto"))
    write_page(Path(job.output), inp)
    out.outputs, out.status = [job.output], DONE
    out.verdict = inp.verdict
    out.message = f"report of {cal_path or 'the capture (no calibration)'}"


def _export(job: Job, out: Outcome) -> None:
    """As ``station export CAL --to FORMAT -o OUTPUT``: station.api.export."""
    from station import api

    cal = _calibration(job, required=True)
    out.outputs = [str(p) for p in api.export(cal, job.options["to"], job.output)]
    out.status, out.message = DONE, f"{job.options['to']} from {cal}"


COMMANDS = {"estimate": _estimate, "diagnose": _diagnose, "report": _report, "export": _export}
