"""Estimation: from a capture bundle to a calibration."""
from __future__ import annotations

import hashlib
from pathlib import Path

from station.calibration import Calibration
from station.capture import Capture, read_capture

METHODS = ("zhang2010",)


def capture_digest(capture: Capture) -> str:
    """sha256 over the manifest and every complete segment file, in manifest order."""
    h = hashlib.sha256()
    h.update((capture.path / "manifest.yaml").read_bytes())
    for seg in capture.complete():
        h.update((capture.path / seg.file).read_bytes())
    return h.hexdigest()


def estimate_capture(path, method: str = "zhang2010") -> tuple[Calibration, Capture, dict]:
    """Read a capture, estimate, and return the calibration, the capture and its provenance."""
    from station.estimate import zhang2010

    capture = read_capture(path)
    cal = zhang2010.estimate(capture)
    provenance = {
        "capture": str(Path(capture.path).resolve()),
        "capture_sha256": capture_digest(capture),
        "method": method,
        "imu_model": capture.imu.model,
        "imu_serial": capture.imu.serial,
        "scheme": capture.scheme,
    }
    return cal, capture, provenance
