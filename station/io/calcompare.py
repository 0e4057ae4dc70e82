"""Two calibrations compared parameter by parameter: the change in the parameter's unit (and in
ppm for scale factors) and in combined standard deviations, sqrt(sigma_a^2 + sigma_b^2), the two
calibrations' errors taken as independent."""
from __future__ import annotations

import math
from dataclasses import dataclass

FLAG_SIGMA = 3.0
SCALE_UNITS = ("1", "raw/(m/s^2)", "raw/(deg/s)")


@dataclass
class Change:
    name: str
    unit: str
    before: float
    after: float
    change: float                 # after - before, unit
    change_ppm: float | None      # scale factors: relative change, ppm
    combined_sigma: float | None  # unit
    z: float | None               # change / combined sigma
    flagged: bool                 # |z| > FLAG_SIGMA


def changes(doc_a: dict, doc_b: dict) -> tuple[list[Change], list[str], list[str]]:
    """(changes of the parameters both have, names only in a, names only in b)."""
    pa, pb = doc_a.get("parameters") or {}, doc_b.get("parameters") or {}
    out = []
    for name, a in pa.items():
        b = pb.get(name)
        if b is None or a.get("unit") != b.get("unit"):
            continue
        d = b["value"] - a["value"]
        sa, sb = a.get("sigma"), b.get("sigma")
        combined = math.hypot(sa, sb) if sa is not None and sb is not None else None
        combined = combined if combined is not None and math.isfinite(combined) and combined > 0 else None
        z = d / combined if combined else None
        ppm = d / a["value"] * 1e6 if a["unit"] in SCALE_UNITS and a["value"] else None
        out.append(Change(name, a["unit"], a["value"], b["value"], d, ppm, combined, z,
                          z is not None and abs(z) > FLAG_SIGMA))
    only_a = [n for n in pa if n not in pb]
    only_b = [n for n in pb if n not in pa]
    return out, only_a, only_b
