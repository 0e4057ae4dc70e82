"""How many residual evaluations and Jacobians the least-squares fits take, and their CPU, on the
fits that crept (issue 27; docs/performance.md "Fourteenth session").  Counts, not times, are
the figures to compare across trees and machines: `lsq.Model.residuals` and `lsq.Model.jacobian`
are counted in this process, and every `lsq._lm` solve is listed (evaluations, status, chi2;
status 0 = stopped at the limit, not converged).  BLAS is limited to one thread, as the CLI
limits it (station/cli/app.py), before numpy is imported.

Cases (each a fresh process of this script; `--case NAME` runs one in this process):
  montecarlo   tests/test_lsq_partial_arcs.py's tilted Monte Carlo (seeds 4 and 1, axes at 30 and
               60 deg, 300 deg/s over 120 deg): two fits, eight solves
  imucal       imucal's annotated session (tests/data/imucal, raw counts, 204.8 Hz) imported and
               estimated: the fit `diagnose` also makes (36 parameters, 54 rows)
  xsens        imu_tk's own Xsens log (its bin/test_data: --imu-tk-data DIR or
               $STATION_IMU_TK_DATA) imported with `--preset imu_tk --gravity-mps2 9.81744` and
               estimated; skipped, and said, without it

Usage: PYTHONPATH=$PWD python benchmarks/solver_evaluations.py [--imu-tk-data DIR] [--case NAME]
Compare two trees by running it with PYTHONPATH set to each (the counts are exact; run the trees
side by side for the CPU)."""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import argparse  # noqa: E402
import json  # noqa: E402
import contextlib  # noqa: E402
import io  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
IMUCAL = ROOT / "tests" / "data" / "imucal" / "annotated_session.csv"


def counted():
    """Count the fits' residual evaluations and Jacobians; list every LM solve."""
    from station.estimate import lsq

    stats = {"residuals": 0, "jacobians": 0, "solves": []}
    residuals, jacobian, lm = lsq.Model.residuals, lsq.Model.jacobian, lsq._lm

    def res(self, x):
        stats["residuals"] += 1
        return residuals(self, x)

    def jac(self, x):
        stats["jacobians"] += 1
        return jacobian(self, x)

    def solve(model, start, evaluations=lsq.MAX_EVALUATIONS):
        r = lm(model, start, evaluations)
        stats["solves"].append([int(r.nfev), int(r.status), round(2 * float(r.cost), 6)])
        return r

    if hasattr(lsq, "_LMSolve"):
        # every dense solve is an _LMSolve finished (_lm's too); replacing _lm would turn
        # _minimise's trials off (a replaced _lm is solved whole from every start)
        finish = lsq._LMSolve.finish

        def finished(self):
            r = finish(self)
            stats["solves"].append([int(r.nfev), int(r.status), round(2 * float(r.cost), 6)])
            return r

        lsq.Model.residuals, lsq.Model.jacobian, lsq._LMSolve.finish = res, jac, finished
        return stats
    lsq.Model.residuals, lsq.Model.jacobian, lsq._lm = res, jac, solve
    return stats


def montecarlo(_args, _tmp):
    sys.path.insert(0, str(ROOT / "tests"))
    from test_lsq_partial_arcs import default_truth, tilted_turns

    from station.estimate import lsq
    from station.simulate import dryrun

    for elevation_deg, seed in ((30, 4), (60, 1)):
        lsq.fit(lsq.summarise(dryrun.simulate_capture(tilted_turns(elevation_deg, 300, 120), default_truth(seed), seed)))


def imucal(_args, tmp):
    from station.estimate import estimate_capture
    from station.io.importers import imucal as importer

    estimate_capture(importer.import_imucal(IMUCAL, tmp / "imucal", rate_hz=204.8))


def xsens(args, tmp):
    data = Path(args.imu_tk_data or os.environ.get("STATION_IMU_TK_DATA") or "")
    if not (data / "xsens_acc.mat").is_file():
        return "skipped: imu_tk's bin/test_data not given (--imu-tk-data DIR or $STATION_IMU_TK_DATA)"
    from station.estimate import estimate_capture

    from station import cli

    out = tmp / "xsens"
    with contextlib.redirect_stdout(io.StringIO()):
        status = cli.main(["import", "csv", str(data / "xsens_acc.mat"), "--preset", "imu_tk", "--gyro-file",
                 str(data / "xsens_gyro.mat"), "--gravity-mps2", "9.81744", "-o", str(out)])
    if status != 0:
        raise SystemExit("the import failed")
    stats = counted.last
    stats.update(residuals=0, jacobians=0, solves=[])      # the estimate's fits only
    estimate_capture(out)


CASES = {"montecarlo": montecarlo, "imucal": imucal, "xsens": xsens}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--case", choices=sorted(CASES))
    ap.add_argument("--imu-tk-data", help="imu_tk's bin/test_data (xsens_acc.mat, xsens_gyro.mat)")
    args = ap.parse_args()
    if args.case is None:
        for name in CASES:
            cmd = [sys.executable, __file__, "--case", name]
            if args.imu_tk_data:
                cmd += ["--imu-tk-data", args.imu_tk_data]
            subprocess.run(cmd, check=True)
        return 0
    stats = counted.last = counted()
    with tempfile.TemporaryDirectory() as tmp:
        t = time.process_time()
        skipped = CASES[args.case](args, Path(tmp))
        cpu = time.process_time() - t
    if skipped:
        print(f"{args.case}: {skipped}")
        return 0
    from station.estimate.lsq import MAX_EVALUATIONS

    # (a solve given fewer evaluations on purpose, lsq._axes_first's 10, is not counted; nor is a
    # start _minimise tried and did not finish: its trial's evaluations are in the residuals)
    limit = sum(1 for n, status, _ in stats["solves"] if status == 0 and n >= MAX_EVALUATIONS)
    print(f"{args.case}: {stats['residuals']} residual evaluations, {stats['jacobians']} Jacobians, CPU {cpu:.2f} s, "
          f"{len(stats['solves'])} solves ({limit} stopped at the limit of {MAX_EVALUATIONS})")
    print("  solves [evaluations, status, chi2]: " + json.dumps(stats["solves"]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
