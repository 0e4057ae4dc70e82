"""What a scheme will reveal on the configured table, computed, not listed: the least-squares
fit of a simulated capture of the scheme as the compiler plans it on this table.

The capture is recorded on the simulated bench (the simulator's default IMU, or a truth file),
with the table's geometry as station.yaml states it (``table.geometry``, ``table.imu_offset_m``),
and each segment's mounting and axis elevation as the compiled plan has them (a remount moves the
mounting offset).  It is fitted with the effects asked for, as ``station estimate --add`` would;
a parameter is revealed when the fit determines it by the fit's own test (not in the Jacobian's
null space, and its 1-sigma below its typical size: lsq._blind_effect_parameters), with the
1-sigma this IMU's noise gives.  Parameters that an effect's convention fixes (the size effect's
own-axis positions with the mounting offset unknown) are said to be so.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np


@dataclass(frozen=True)
class Revealed:
    name: str
    unit: str
    status: str            # "revealed", "not revealed", "convention"
    sigma: float | None    # 1-sigma in ``unit`` (None: fixed by convention)


def reveals(scheme, config, plan=None, effect_ids=("accel_lever_arm",), seed: int = 0,
            truth_path: str | None = None) -> tuple[list[Revealed], list[str]]:
    """(the effects' parameters and the base calibration's, each revealed or not, in order; the
    fit's notes)."""
    from station.estimate import lsq
    from station.estimate.summaries import summarise
    from station.model import EFFECTS
    from station.simulate import dryrun

    truth = dryrun.load_truth(truth_path, seed)
    t = config.table
    if t.imu_offset_m is not None:
        truth.bench.lever_arm_m = np.asarray(t.imu_offset_m, float)
    geometry = {"axes_intersect": bool(t.axes_intersect)}
    if t.level_arcsec is not None:
        geometry["level_arcsec"] = float(t.level_arcsec)
    elevation = {}
    if plan is not None and not plan.manual:
        # the elevations the compiler chose (an unattended table turns some axes at another one)
        elevation = {s.spec.name: float(s.elevation_deg) for s in plan.steps
                     if type(s).__name__ == "Rotate" and getattr(s, "spec", None) is not None}
        scheme = replace(scheme, segments=[replace(spec, axis_elevation_deg=elevation[spec.name])
                                           if spec.name in elevation else spec for spec in scheme.segments])
    capture = dryrun.simulate_capture(scheme, truth, seed, geometry if scheme.table else None,
                                      chamber=getattr(config, "chamber", None), warmup=getattr(config, "warmup", None))
    if t.imu_offset_m is not None:
        capture.extra["mounting"] = {"offset_m": [float(x) for x in t.imu_offset_m]}
    for seg in capture.segments:
        if plan is not None and seg.name in plan.mounting_of:
            seg.extra["mounting"] = [str(m) for m in plan.mounting_of[seg.name]]
    effects = [EFFECTS[e]() for e in effect_ids]
    result = lsq.fit(summarise(capture), effects)
    model, rows = result.model, []
    names, index, factors, units_ = lsq._reported_index(result, "m/s^2", "deg/s")
    cov = result.covariance_of(index) * np.outer(factors, factors)
    sigma = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    aliased = {int(c) for c in result.rank_deficient}
    blind = set(model.unobservable) | {n for n, c in zip(names, index) if int(c) in aliased}
    for i, name in enumerate(names):
        rows.append(Revealed(name, units_[i], "not revealed" if name in blind else "revealed", float(sigma[i])))
    for e in model.effects:
        if e.id == "accel_lever_arm":
            free = set(e.free)
            for i in range(3):
                if (i, i) not in free:
                    a = "xyz"[i]
                    rows.append(Revealed(f"accel_position_{a}_{a}", "mm", "convention", None))
    notes = []
    for e in model.effects:
        notes += list(e.notes())
    if model.geometry.describe(model.s.rotations):
        notes.append(model.geometry.describe(model.s.rotations))
    return rows, notes
