"""The fit's dense solve done by another solver, for tests that force a solver's outcome
(tests/test_verdicts.py, tests/test_verdict_thresholds.py): ``numpy_lm`` is the numpy LM with
scipy.optimize.least_squares's signature, ``dense_solve_through(solve)`` replaces lsq._lm by
``solve(fun, x0, jac=..., **kw)`` with the fit's tolerances."""
from station.estimate import lsq, solver


def numpy_lm(fun, x0, *args, jac=None, **kw):
    """The fit's dense solver (solver.least_squares, the numpy LM) with scipy's signature."""
    return solver.least_squares(fun, x0, jac if jac is not None else args[0],
                                **{k: kw[k] for k in ("xtol", "ftol", "gtol", "max_nfev") if k in kw})


def dense_solve_through(solve):
    """lsq's dense solve (lsq._lm) done by ``solve(fun, x0, jac=..., **kw)``, scipy's signature:
    these tests patched lsq.least_squares, which the solver27-b branch replaced by the numpy LM
    (solver.LevenbergMarquardt, watched in lsq._lm), so they failed with an AttributeError."""
    return lambda model, start, evaluations=lsq.MAX_EVALUATIONS: solve(
        model.residuals, start, jac=model.jacobian, max_nfev=evaluations, xtol=1e-10, ftol=1e-10, gtol=1e-10)
