"""The table's geometry as a capture states it, in the terms the least-squares fit needs.

A capture of ``station run`` records in its manifest ``table.geometry: {axes_intersect,
level_arcsec}`` and, per rotation segment, the IMU's ``mounting`` on the platform and the
``axis_elevation_deg`` of ``axis_body`` above the horizontal (docs/capture.md).  From them:

* which rotations turn about one mounting offset: the IMU's reference point from the point
  where the table's axes meet is ONE vector in the IMU frame for every rotation while the IMU
  stays mounted (axes that intersect); a remount moves it (one vector per mounting); on a table
  whose axes do not intersect each axis turns about its own line, so every rotation axis (per
  mounting) has its own offset, of which only the part across the axis matters (two numbers);
* what the table says about gravity along each rotation axis: with the axes' elevation known to
  ``level_arcsec`` (1 sigma), kappa = g sin(elevation) is known, and the fit takes it as a prior
  (docs/method-lsq.md, "The table's geometry": without it, gravity along an axis and the
  centripetal acceleration along it cannot be told apart at one rate).

A capture that does not state the geometry (older captures, imports, dry runs) keeps what the
fit did before: one offset vector for every rotation, gravity along each axis free.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from station.core import units
from station.core.errors import UserError

# Two recorded elevations of rotations about one body axis are one axis setting (one axis group,
# one gravity angle in the fit) when they differ by no more than this.  Gravity turns by g*delta
# across or along the axis when the elevation does: 1 arcsec is 4.8e-6 g (4.8 ug), below what
# any table's axes are levelled to (level_arcsec: arcseconds at best) -- a smaller difference is
# how the number was written (a tool printing 89.99999 for 90: 0.036 arcsec), not another
# setting.  The estimator's groups (summaries), the elevation the fit's level prior takes
# (from_capture) and station design --from's groups (design.sequential.capture_groups) share it.
SAME_ELEVATION_ARCSEC = 1.0


def same_elevation(a: float | None, b: float | None) -> bool:
    """Two recorded elevations (deg) of one axis group: equal to SAME_ELEVATION_ARCSEC; one not
    recorded (None) is level (0), as station design --from reads it (sequential.capture_scheme),
    so that the design's axis groups are the estimator's (a capture without elevations: one
    group per axis, as before)."""
    return abs((0.0 if a is None else a) - (0.0 if b is None else b)) * 3600.0 <= SAME_ELEVATION_ARCSEC


@dataclass(frozen=True)
class TableGeometry:
    stated: bool                    # the manifest has table.geometry
    axes_intersect: bool            # True also when not stated (the fit's behaviour before)
    level_sigma_rad: float | None   # 1-sigma of the rotation axes' elevation (None: not known)
    mounting: dict                  # rotation name -> the IMU's mounting on the platform (None: not recorded)
    elevation_deg: dict             # axis group -> the recorded elevation of its axis_body (known ones only)

    def offset_sets(self, rotations) -> tuple[list, list]:
        """(per rotation: the index of the mounting offset it turns about, per offset: the axis
        group it is seen about alone (only its part across that axis matters: two numbers) or
        None (a 3-vector)).  Unstated: one vector for every rotation, as before."""
        keys, sets, groups = {}, [], []
        for r in rotations:
            if not self.stated:
                key = None
            else:
                mounting = self.mounting.get(r.name)
                key = mounting if self.axes_intersect else (mounting, r.group)
            if key not in keys:
                keys[key] = len(keys)
                groups.append(set())
            sets.append(keys[key])
            groups[keys[key]].add(r.group)
        if not self.stated:
            return sets, [None] * len(groups)
        return sets, [next(iter(g)) if len(g) == 1 else None for g in groups]

    def describe(self, rotations) -> str:
        """One line for the fit's notes ("" when the capture states no geometry)."""
        if not self.stated or not rotations:
            return ""
        n = len(self.offset_sets(rotations)[1])
        what = (f"the table's axes intersect: one mounting offset vector per mounting ({n})" if self.axes_intersect
                else f"the table's axes do not intersect: a mounting offset across each rotation axis ({n})")
        level = ("; gravity along each axis from its recorded elevation "
                 f"(+/- {self.level_sigma_rad / units.ARCSEC_RAD:g} arcsec)"
                 if self.level_sigma_rad and self.elevation_deg else "")
        return f"table geometry: {what}{level}"


def unstated() -> TableGeometry:
    """The geometry of a capture that does not state one: as the fit was before."""
    return TableGeometry(False, True, None, {}, {})


def read(capture, rotations) -> TableGeometry:
    """The geometry of ``capture`` for its rotation summaries (``rotations``, in order)."""
    table = capture.extra.get("table") if isinstance(capture.extra.get("table"), dict) else {}
    doc = table.get("geometry")
    if doc is None:
        return unstated()
    where = f"{capture.path}/manifest.yaml: field 'table.geometry"
    if not isinstance(doc, dict):
        raise UserError(f"{where}': must be a mapping (axes_intersect, level_arcsec)")
    intersect = doc.get("axes_intersect", True)
    if not isinstance(intersect, bool):
        raise UserError(f"{where}.axes_intersect': must be true or false, got {intersect!r}")
    level = doc.get("level_arcsec")
    if level is not None:
        if isinstance(level, bool) or not isinstance(level, (int, float)) or not 0 < level <= 3600:
            raise UserError(f"{where}.level_arcsec': must be a number of arcsec in (0, 3600], got {level!r}")
        level = float(level) * units.ARCSEC_RAD
    segments = {s.name: s for s in capture.segments}
    mounting, found = {}, {}
    for r in rotations:
        seg = segments.get(r.name)
        m = seg.extra.get("mounting") if seg is not None else None
        mounting[r.name] = tuple(str(x) for x in m) if isinstance(m, (list, tuple)) else None
        e = seg.extra.get("axis_elevation_deg") if seg is not None else None
        ok = isinstance(e, (int, float)) and not isinstance(e, bool) and np.isfinite(e)
        found.setdefault(r.group, []).append(float(e) if ok else None)
    # one recorded elevation for every rotation about the axis (to SAME_ELEVATION_ARCSEC: the
    # first one recorded stands for the group), else nothing known about it
    elevations = {k: v[0] for k, v in found.items()
                  if None not in v and all(same_elevation(v[0], x) for x in v)}
    return TableGeometry(True, intersect, level, mounting, elevations)
