"""Estimation: from a capture bundle to a calibration."""
from __future__ import annotations

import hashlib
from pathlib import Path

from station.model.calibration import Calibration
from station.io.capture import Capture, read_capture

METHODS = ("auto", "lsq", "zhang2010", "fourier", "fourier-high")
# "auto": fourier when any complete rotation segment has no angle_deg (no encoder), lsq
# otherwise.  "lsq" is the weighted least-squares fit of the full measurement model, started
# from the 2010 algebraic solution ("zhang2010", which is also available alone).  "fourier" is
# the Fourier method's low-grade variant (Earth rate neglected),
# "fourier-high" its high-grade variant (Earth rate along each shaft estimated; only |Omega_E|).


def capture_digest(capture: Capture) -> str:
    """sha256 over the manifest and every complete segment file, in manifest order."""
    h = hashlib.sha256()
    h.update((capture.path / "manifest.yaml").read_bytes())
    for seg in capture.complete():
        h.update((capture.path / seg.file).read_bytes())
    return h.hexdigest()


def choose_method(capture: Capture) -> str:
    """The method "auto" stands for: fourier if any complete rotation lacks angle_deg."""
    if any(seg.angle_deg is None for seg in capture.complete("rotation")):
        return "fourier"
    return "lsq"


def estimate_with(capture: Capture, method: str = "auto", effects=(), registry=None) -> tuple[Calibration, str]:
    """Estimate from a capture already read; returns the calibration and the method used.

    ``effects``: ids of effects to add to the model (least squares only), created by ``registry``
    (station.model.registry.EffectRegistry: the library, entry points, loaded plugins)."""
    from station.core.errors import UserError
    from station.model.registry import EffectRegistry

    if method not in METHODS:
        raise UserError(f"unknown estimation method {method!r}: use one of {', '.join(METHODS)}")
    if method == "auto":
        method = choose_method(capture)
    registry = registry if registry is not None else EffectRegistry()
    instances = [registry.create(e) for e in effects]
    if effects and method != "lsq":
        raise UserError(f"--add needs the least-squares method (lsq); this capture uses {method}")
    if method == "lsq":
        from station.estimate import lsq

        return lsq.estimate(capture, instances), method
    if method == "zhang2010":
        from station.estimate import zhang2010

        return zhang2010.estimate(capture), method
    from station.estimate import fourier

    return fourier.estimate(capture, "high" if method == "fourier-high" else "low"), method


def estimate_capture(path, method: str = "auto", effects=(), registry=None) -> tuple[Calibration, Capture, dict]:
    """Read a capture, estimate, and return the calibration, the capture and its provenance."""
    capture = read_capture(path)
    cal, method = estimate_with(capture, method, effects, registry)
    provenance = {
        "capture": str(Path(capture.path).resolve()),
        "capture_sha256": capture_digest(capture),
        "method": method,
        "imu_model": capture.imu.model,
        "imu_serial": capture.imu.serial,
        "scheme": capture.scheme,
    }
    return cal, capture, provenance
