"""Simulated captures with hidden effects, shared by the diagnostics tests."""
import numpy as np

from station.io.scheme import load_scheme
from station.simulate import dryrun


def hide(truth, **hidden):
    """Set truth fields given as ``section__field=value`` (lists become arrays); returns truth."""
    for path, value in hidden.items():
        obj = truth
        *parents, leaf = path.split("__")
        for p in parents:
            obj = getattr(obj, p)
        setattr(obj, leaf, np.asarray(value, float) if isinstance(value, list) else value)
    return truth


def mems_capture(seed=3, scheme="optimal9", overrides=None, out=None, **hidden):
    """A MEMS IMU (sim_devices.truth.mems_truth(0)) with hidden effects through a scheme: in memory,
    or recorded as a bundle into ``out``.  Returns (truth, capture or its path)."""
    from sim_devices.truth import mems_truth

    truth = hide(mems_truth(0), **hidden)
    scheme = load_scheme(scheme, overrides or {"rate_dps": 100.0, "rotation_s": 36.0})
    if out is not None:
        return truth, dryrun.record_scheme(scheme, truth, seed, out)
    return truth, dryrun.simulate_capture(scheme, truth, seed)


NINE_STATICS = """\
  - {static: pos01, up_body: [1, 0, 0]}
  - {static: pos02, up_body: [-1, 0, 0]}
  - {static: pos03, up_body: [0, 1, 0]}
  - {static: pos04, up_body: [0, -1, 0]}
  - {static: pos05, up_body: [0, 0, 1]}
  - {static: pos06, up_body: [0, 0, -1]}
  - {static: pos07, up_body: [1, 1, 0]}
  - {static: pos08, up_body: [1, 0, 1]}
  - {static: pos09, up_body: [0, 1, 1]}
"""
THREE_ROTATIONS = """\
  - {rotation: rotx, axis_body: [1, 0, 0]}
  - {rotation: roty, axis_body: [0, 1, 0]}
  - {rotation: rotz, axis_body: [0, 0, 1]}
"""


def scheme_yaml(name, dwell_s, rotations=True, title=None):
    """A small scheme's YAML: nine static attitudes (six faces and three diagonals), then one
    rotation about each body axis (10 deg/s for 36 s) unless ``rotations`` is False."""
    head = f"name: {name}\n" + (f"title: {title}\n" if title else "")
    head += f"defaults: {{dwell_s: {dwell_s}, rate_dps: 10.0, rotation_s: 36.0}}\nsegments:\n"
    return head + NINE_STATICS + (THREE_ROTATIONS if rotations else "")


# The simulator's accelerometer cross-coupling (C_ij a_i F_j) is the library's accel_cross_axis;
# the tests of what diagnose does with an effect OUTSIDE the library take it out of the library.
CROSS_AXIS = "accel_cross_axis"


def registry_without(*ids):
    """An EffectRegistry of the library's effects but ``ids``."""
    from station.model.registry import EffectRegistry

    reg = EffectRegistry()
    for eid in ids:
        reg.classes.pop(eid)
        reg.sources.pop(eid)
    return reg


def library_without(monkeypatch, *ids):
    """Every EffectRegistry made from now on in this test (the CLI's too) lacks ``ids``."""
    from station.model import LIBRARY, registry

    monkeypatch.setattr(registry, "_library", lambda: {k: v for k, v in LIBRARY.items() if k not in ids})
