"""Issue 28, nineteenth session: can the recorded ramps' own residuals tell a host whose latency
drifts along the session from one whose windows are independent?  A bound, from first principles
and sharing no code with the product: n windows in recording order, each window's timing error
an independent part (standard deviation --independent-ms: the host's placement scatter, ~3.8 ms
on tests/test_ramp_placement_scatter.py's host) plus an AR(1) part (--drift-ms, --rho between
neighbours); the fit takes their common part (the time offset), so the residuals are the errors
less their mean.  For each statistic its threshold is set at the --alpha point of its own null
distribution (no drift, simulated), and its power is the share of drifting sessions beyond it:

  lag-1       the product's check (before the nineteenth session: lag-1 correlation > 2.33 / sqrt n)
  REML LR     the likelihood ratio of an independent + AR(1) covariance (rho profiled over a grid)
              against independent windows, from the residuals' restricted likelihood
  oracle LR   the same with rho known (the most powerful test of that alternative for this rho:
              no statistic of the residuals does better against it)

and the offset's z spread (its error over its 1-sigma) with the windows taken as independent,
and with the 1-sigma inflated by the REML estimate's effective number of windows (n / 1'C1 n).

    python benchmarks/ramp_drift_power.py [--windows 24] [--drift-ms 2] [--rho 0.9] [--sessions 400]
"""
from __future__ import annotations

import argparse

import numpy as np

RHOS = (0.3, 0.5, 0.7, 0.8, 0.9, 0.95)
PHIS = np.linspace(0.0, 0.95, 20)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--windows", type=int, default=24)
    ap.add_argument("--independent-ms", type=float, default=3.8)
    ap.add_argument("--drift-ms", type=float, default=2.0)
    ap.add_argument("--rho", type=float, default=0.9)
    ap.add_argument("--sessions", type=int, default=400)
    ap.add_argument("--alpha", type=float, default=0.01)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    n = args.windows
    rng = np.random.default_rng(args.seed)
    lags = np.abs(np.subtract.outer(np.arange(n), np.arange(n)))
    # an orthonormal basis of the residuals' space (orthogonal to the common part)
    Q = np.linalg.qr(np.column_stack([np.ones(n), np.eye(n)[:, :n - 1]]))[0][:, 1:]
    m = n - 1
    shapes = {}
    for rho in RHOS:
        for phi in PHIS[1:]:
            C = (1 - phi) * np.eye(n) + phi * rho ** lags
            V = Q.T @ C @ Q
            shapes[rho, phi] = (np.linalg.inv(V), np.linalg.slogdet(V)[1], np.ones(n) @ C @ np.ones(n) / n)

    def session(drift_ms):
        d = np.empty(n)
        d[0] = rng.normal(0.0, drift_ms)
        for i in range(1, n):
            d[i] = args.rho * d[i - 1] + np.sqrt(1 - args.rho ** 2) * rng.normal(0.0, drift_ms)
        return rng.normal(0.0, args.independent_ms, n) + d

    def statistics(e):
        y = Q.T @ e
        null = -0.5 * m * np.log(y @ y / m)
        best, best_oracle, factor = null, null, 1.0
        for (rho, phi), (Vi, logdet, f) in shapes.items():
            ll = -0.5 * (m * np.log(y @ Vi @ y / m) + logdet)
            if ll > best:
                best, factor = ll, f
            if rho == args.rho or (args.rho not in RHOS and rho == 0.9):
                best_oracle = max(best_oracle, ll)
        r = e - e.mean()
        lag1 = float(r[:-1] @ r[1:] / (r @ r))
        var_mean = (r @ r / m) / n
        z = e.mean() / np.sqrt(var_mean)
        return lag1, 2 * (best - null), 2 * (best_oracle - null), z, z / np.sqrt(factor)

    null = np.array([statistics(session(0.0)) for _ in range(args.sessions)])
    drift = np.array([statistics(session(args.drift_ms)) for _ in range(args.sessions)])
    q = 100 * (1 - args.alpha)
    print(f"{n} windows, independent {args.independent_ms} ms, drift {args.drift_ms} ms at rho {args.rho}, "
          f"{args.sessions} sessions each; thresholds at the null's {q:g} % point")
    for j, name in enumerate(["lag-1", "REML LR", "oracle LR"]):
        thr = np.percentile(null[:, j], q)
        fixed = f" (the product's 2.33/sqrt n = {2.33 / np.sqrt(n):.2f}: fires in {np.mean(null[:, 0] > 2.33 / np.sqrt(n)):.3f} "\
                f"without drift, {np.mean(drift[:, 0] > 2.33 / np.sqrt(n)):.3f} with)" if j == 0 else ""
        print(f"  {name:10s} power {np.mean(drift[:, j] > thr):.3f}{fixed}")
    for label, rows in (("no drift", null), ("drift", drift)):
        print(f"  {label:9s} offset z sd: windows independent {np.std(rows[:, 3]):.2f}, "
              f"inflated by the REML effective number {np.std(rows[:, 4]):.2f}")


if __name__ == "__main__":
    main()
