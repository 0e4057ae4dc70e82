"""Estimation: from a capture bundle to a calibration."""
from __future__ import annotations

import hashlib
from pathlib import Path

from station.model.calibration import Calibration
from station.io.capture import Capture, read_capture

METHODS = ("auto", "lsq", "zhang2010", "fourier", "fourier-high")
# "auto": fourier when any complete rotation segment has no angle_deg (no encoder) and is not a
# hand turn between statics, lsq otherwise (hand turns of unknown angle are terms of its model).  "lsq" is the weighted least-squares fit of the full measurement model, started
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
    """The method "auto" stands for: fourier if any complete rotation lacks angle_deg and is
    not a hand turn (a steady rotation about a shaft); lsq otherwise (hand turns between statics
    enter its model: station/estimate/hand_rotation.py)."""
    from station.estimate.hand_rotation import is_hand

    if any(seg.angle_deg is None and not is_hand(seg) for seg in capture.complete("rotation")):
        return "fourier"
    return "lsq"


def estimate_with(capture: Capture, method: str = "auto", effects=()) -> tuple[Calibration, str]:
    """Estimate from a capture already read; returns the calibration and the method used.

    ``effects``: ids of station.model.EFFECTS to add to the model (least squares only)."""
    from station.core.errors import UserError
    from station.model import EFFECTS

    if method not in METHODS:
        raise UserError(f"unknown estimation method {method!r}: use one of {', '.join(METHODS)}")
    if method == "auto":
        method = choose_method(capture)
    unknown = [e for e in effects if e not in EFFECTS]
    if unknown:
        raise UserError(f"unknown effect {unknown[0]!r}: the library has {', '.join(sorted(EFFECTS))} "
                        "(station effects lists them)")
    if effects and method != "lsq":
        raise UserError(f"--add needs the least-squares method (lsq); this capture uses {method}")
    if method == "lsq":
        from station.estimate import lsq

        return lsq.estimate(capture, [EFFECTS[e]() for e in effects]), method
    if method == "zhang2010":
        from station.estimate import zhang2010

        return zhang2010.estimate(capture), method
    from station.estimate import fourier

    return fourier.estimate(capture, "high" if method == "fourier-high" else "low"), method


def estimate_capture(path, method: str = "auto", effects=()) -> tuple[Calibration, Capture, dict]:
    """Read a capture, estimate, and return the calibration, the capture and its provenance."""
    capture = read_capture(path)
    cal, method = estimate_with(capture, method, effects)
    provenance = {
        "capture": str(Path(capture.path).resolve()),
        "capture_sha256": capture_digest(capture),
        "method": method,
        "imu_model": capture.imu.model,
        "imu_serial": capture.imu.serial,
        "scheme": capture.scheme,
    }
    return cal, capture, provenance
