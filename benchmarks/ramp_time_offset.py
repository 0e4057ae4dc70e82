"""Issue 28 item 3, fifteenth session: is the time offset's 1σ honest when turns with their ramp
recorded reveal it?  Over N seeds the simulated bench records six faces, steady ± pairs about x,
y and z and ramp pairs (up about x, down about (0, 1, 1)) at 100 deg/s with the IMU's stamps
``--offset-ms`` behind the table's clock; the estimator (lsq, time_offset added) gives the offset
± 1σ.  Printed: the mean and the standard deviation of z = (estimate - truth) / 1σ, sum z^2
against chi2(N)'s 0.1 % and 99.9 % points, and the same statistic for the 1σ halved and doubled
(a 1σ too large fails like one too small).

    PYTHONPATH=$PWD python benchmarks/ramp_time_offset.py --seeds 100 --offset-ms 5
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from scipy.stats import chi2

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=100)
    ap.add_argument("--offset-ms", type=float, default=5.0)
    args = ap.parse_args()
    from test_ramp_segments import _fit, _ramp_capture

    z, sig = [], []
    t0 = time.process_time()
    for seed in range(args.seeds):
        _, capture = _ramp_capture(None, args.offset_ms * 1e-3, 1000 + seed)
        _, value, sigma = _fit(capture)
        z.append((value - args.offset_ms) / sigma)
        sig.append(sigma)
    cpu = time.process_time() - t0
    z = np.array(z)
    n = len(z)
    lo, hi = chi2.ppf(0.001, n), chi2.ppf(0.999, n)
    print(f"{n} seeds, offset {args.offset_ms:g} ms: 1σ {np.mean(sig) * 1e3:.2f} us (mean), mean z {z.mean():+.3f}, "
          f"std z {z.std(ddof=1):.3f}, max |z| {np.abs(z).max():.2f}; {cpu:.1f} s CPU")
    for factor in (1.0, 0.5, 2.0):
        s = float(np.sum((z / factor) ** 2))
        verdict = "within" if lo < s < hi else "OUTSIDE"
        print(f"  1σ x {factor:g}: sum z^2 = {s:.1f}, chi2({n}) 0.1-99.9 % [{lo:.1f}, {hi:.1f}]: {verdict}")


if __name__ == "__main__":
    main()
