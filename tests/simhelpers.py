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
