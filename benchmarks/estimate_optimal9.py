"""Wall time and peak memory of `station estimate` on a full optimal9 dry-run capture, and the
least-squares fit alone: its CPU seconds, residual evaluations and ms per evaluation, paired in
this process with the per-segment residual and Jacobian it replaced (tests/lsq_reference.py);
and one Jacobian at the solution: complex step (the fit's) against forward differences of the
same model (what it replaced, and the fallback for unsafe plugins), timed in alternation, and
the largest difference of each from central differences (per column, relative to its norm).

Records the capture once per sample rate, then times the command (a fresh process each time,
reading the files included).  Usage:
    python benchmarks/estimate_optimal9.py [--rates 100 1000] [--repeat 3] [--effects]

BLAS is held to one thread in this process (the fit's CPU time would otherwise count the
threads OpenBLAS spins on a shared machine); `station estimate` runs as a user would run it.
"""
import os

ORIGINAL_ENV = set(os.environ)
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import copy  # noqa: E402
import resource  # noqa: E402
import shutil  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from station.estimate import lsq  # noqa: E402
from station.estimate.summaries import summarise  # noqa: E402
from station.io.capture import read_capture  # noqa: E402
from station.model import LIBRARY  # noqa: E402
from station.simulate import dryrun  # noqa: E402
from station.io.scheme import load_scheme  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from lsq_reference import PerSegmentModel  # noqa: E402


USER_ENV = {k: v for k, v in os.environ.items() if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")}
USER_ENV.update({k: os.environ[k] for k in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")
                 if k in ORIGINAL_ENV})


class CountedReference(PerSegmentModel):
    """The previous formulation, its residual evaluations counted like lsq.Model's."""

    def residuals(self, x):
        self.evaluations = getattr(self, "evaluations", 0) + 1
        return super().residuals(x)


def fit_figures(s, effects, model_class, repeat):
    """(median CPU s, residual evaluations, the result) of lsq.fit with the given model class."""
    saved, lsq.Model = lsq.Model, model_class
    try:
        times = []
        for _ in range(repeat):
            chosen = [LIBRARY[e]() for e in effects]
            t0 = time.process_time()
            result = lsq.fit(copy.deepcopy(s), chosen)
            times.append(time.process_time() - t0)
    finally:
        lsq.Model = saved
    return float(np.median(times)), result.model.evaluations, result


def jacobian_figures(s, effects, x, pairs=15):
    """(median ms per Jacobian by complex step, by forward differences, the largest difference
    of each from central differences relative to the column's norm), the two timed alternately
    on the same model at x."""
    model = lsq.Model(copy.deepcopy(s), [LIBRARY[e]() for e in effects])
    times = {"complex step": [], "forward differences": []}
    J = {}
    for _ in range(pairs):
        for method in times:
            model._unsafe = [] if method == "complex step" else ["benchmark"]
            model._last_jacobian = None
            t0 = time.process_time()
            J[method] = model.jacobian(x)
            times[method].append(time.process_time() - t0)
    # central differences are exact only to their truncation (large steps) and rounding (small
    # ones, and columns whose rows cancel large numbers): each column is compared with the
    # closest of five steps, 1e-1 to 1e-5 of the parameter's size (a term linear in its parameter is exact at the largest), for both methods
    errors = {m: np.full(len(x), np.inf) for m in times}
    for relative in (1e-1, 1e-2, 1e-3, 1e-4, 1e-5):
        h = relative * model._sizes(x)
        central = np.empty_like(J["complex step"])
        for c in range(len(x)):
            xp, xm = x.copy(), x.copy()
            xp[c] += h[c]
            xm[c] -= h[c]
            central[:, c] = (model.residuals(xp) - model.residuals(xm)) / (2 * h[c])
        norms = np.maximum(np.linalg.norm(central, axis=0), 1e-300)
        for m in times:
            errors[m] = np.minimum(errors[m], np.max(np.abs(J[m] - central), axis=0) / norms)
    return [1e3 * float(np.median(times[m])) for m in times] + [float(np.max(errors[m])) for m in times]


def compare_fits(cap, repeat, effects):
    s = summarise(read_capture(cap))
    label = f" + {len(effects)} effects" if effects else ""
    new = fit_figures(s, effects, lsq.Model, repeat)
    old = fit_figures(s, effects, CountedReference, max(1, repeat // 2))
    for name, (t, n, _) in (("per-segment (before)", old), ("vectorised", new)):
        print(f"  fit{label}, {name:20s}: {t:.3f} s CPU, {n} residual evaluations, {1e3 * t / n:.2f} ms each")
    a, b = new[2], old[2]
    dz = np.max(np.abs(a.x - b.x)[(b.covariance_columns if b.covariance_columns is not None else slice(None))]
                / np.sqrt(np.maximum(np.diag(b.covariance), 1e-300)))   # (a large model: its calibration's columns)
    print(f"  fit{label}: vectorised / before = {new[0] / old[0]:.3f} in CPU time; the two solutions differ "
          f"by at most {dz:.1e} sigma, chi2 {a.chi2:.3f} vs {b.chi2:.3f}")
    cs, fd, cs_err, fd_err = jacobian_figures(s, effects, a.x)
    print(f"  Jacobian{label} at the solution ({a.model.layout.size} columns, {len(a.model._groups)} groups): "
          f"complex step {cs:.2f} ms, forward differences {fd:.2f} ms (complex / forward {cs / fd:.2f}); "
          f"largest difference from central differences (closest of 5 steps), of a column's norm: complex step {cs_err:.1e}, "
          f"forward differences {fd_err:.1e}")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--rates", type=float, nargs="+", default=[100.0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--effects", action="store_true", help="also fit with every library effect added")
    a = ap.parse_args()
    station = shutil.which("station") or sys.exit("install the project first (pip install -e .)")
    scheme = load_scheme("optimal9")
    for rate in a.rates:
        with tempfile.TemporaryDirectory() as tmp:
            truth = dryrun.load_truth(None, 1)
            truth.sample_rate_hz = rate
            cap = dryrun.record_scheme(scheme, truth, 1, Path(tmp) / "cap")
            samples = int(scheme.duration_s * rate)
            walls = []
            for _ in range(a.repeat):
                t0 = time.perf_counter()
                subprocess.run([station, "estimate", str(cap), "-o", str(Path(tmp) / "cal.yaml")],
                               check=True, capture_output=True, env=USER_ENV)
                walls.append(time.perf_counter() - t0)
            peak_mb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
            print(f"optimal9 at {rate:g} Hz ({samples} samples): station estimate median "
                  f"{sorted(walls)[len(walls) // 2]:.3f} s, best {min(walls):.3f} s wall (of {a.repeat}), "
                  f"peak RSS {peak_mb:.0f} MB (goal at 100 Hz: under 0.5 s)")
            compare_fits(cap, max(a.repeat, 3), ())
            if a.effects:
                compare_fits(cap, max(a.repeat, 3), sorted(LIBRARY))


if __name__ == "__main__":
    main()
