"""The tails of the distributions the verdicts read, in the standard library's arithmetic: so
that a fit's verdict imports no scipy (scipy.special's import alone was ~0.17 s of CPU, most of
it scipy's array-API layer: issue 27; scipy.stats 0.5 s).

- ``chi2_sf(dof, x)`` / ``chi2_cdf(dof, x)``: P(χ²_dof > x) and P(χ²_dof < x), the regularised
  incomplete gamma function Q(dof/2, x/2) / P(dof/2, x/2) by its power series (x < a + 1) or its
  continued fraction (modified Lentz), each to a relative 1e-15 of its terms (Numerical Recipes
  §6.2; what scipy.special.chdtrc / chdtr compute, tests/test_distributions.py compares);
- ``norm_ppf(p)``: the standard normal quantile (statistics.NormalDist, Wichura's AS 241);
- ``binom_sf(k, n, p)``: P(K >= k) for K ~ Binomial(n, p), the sum of its terms from k (in
  logarithms: any n); what scipy.special.betainc(k, n - k + 1, p) gives for whole k and n.
"""
from __future__ import annotations

import math
from statistics import NormalDist

TINY = 1e-300
EPS = 1e-16


def _log_prefactor(a: float, x: float) -> float:
    """log(x^a e^-x / Gamma(a))."""
    return a * math.log(x) - x - math.lgamma(a)


def _lower_series(a: float, x: float) -> float:
    """P(a, x) by its series, x < a + 1."""
    term = total = 1.0 / a
    ap = a
    for _ in range(100000):
        ap += 1.0
        term *= x / ap
        total += term
        if abs(term) < abs(total) * EPS:
            break
    return total * math.exp(_log_prefactor(a, x))


def _upper_fraction(a: float, x: float) -> float:
    """Q(a, x) by its continued fraction (modified Lentz), x >= a + 1."""
    b = x + 1.0 - a
    c = 1.0 / TINY
    d = 1.0 / b
    h = d
    for i in range(1, 100000):
        an = -i * (i - a)
        b += 2.0
        d = an * d + b
        if abs(d) < TINY:
            d = TINY
        c = b + an / c
        if abs(c) < TINY:
            c = TINY
        d = 1.0 / d
        delta = d * c
        h *= delta
        if abs(delta - 1.0) < EPS:
            break
    return math.exp(_log_prefactor(a, x)) * h


def _gamma_pq(a: float, x: float) -> tuple[float, float]:
    if not (a > 0) or math.isnan(x):
        return math.nan, math.nan
    if x <= 0:
        return 0.0, 1.0
    if math.isinf(x):
        return 1.0, 0.0
    if x < a + 1.0:
        p = _lower_series(a, x)
        return p, 1.0 - p
    q = _upper_fraction(a, x)
    return 1.0 - q, q


def chi2_sf(dof: float, x: float) -> float:
    """P(χ²_dof > x)."""
    return _gamma_pq(0.5 * float(dof), 0.5 * float(x))[1]


def chi2_cdf(dof: float, x: float) -> float:
    """P(χ²_dof < x)."""
    return _gamma_pq(0.5 * float(dof), 0.5 * float(x))[0]


def norm_ppf(p: float) -> float:
    """The standard normal quantile: P(Z < norm_ppf(p)) = p."""
    if p <= 0.0:
        return -math.inf
    if p >= 1.0:
        return math.inf
    return NormalDist().inv_cdf(p)


def binom_sf(k: int, n: int, p: float) -> float:
    """P(K >= k), K ~ Binomial(n, p), 0 < p < 1."""
    if k <= 0:
        return 1.0
    if k > n:
        return 0.0
    log_p, log_q = math.log(p), math.log1p(-p)
    base = math.lgamma(n + 1)
    total = 0.0
    for j in range(k, n + 1):
        term = math.exp(base - math.lgamma(j + 1) - math.lgamma(n - j + 1) + j * log_p + (n - j) * log_q)
        total += term
        if j > n * p and term < total * 1e-17:      # past the mode the terms only fall
            break
    return min(total, 1.0)


P_FAIL = 1e-3               # the verdict's (station.estimate.verdict.P_FAIL, REDUCED_CHI2_FAIL)
REDUCED_CHI2_FAIL = 1.5


def chi2_verdict(chi2: float, dof: float, p_fail: float, reduced_fail: float) -> dict:
    """station.estimate.verdict.chi2_verdict's rule with its thresholds given (P_FAIL,
    REDUCED_CHI2_FAIL): here so that lsq may ask it without an import cycle (lsq._newcomer_released).
    The thresholds are always given (no defaults: a caller that left one out would get a default
    that equals it, a change the verdict's mutation check could not see)."""
    reduced = chi2 / dof
    p_value = chi2_sf(dof, chi2)        # P(chi2_dof > chi2) (distributions.py: scipy costs 0.17-0.5 s to import)
    p_below = chi2_cdf(dof, chi2)       # P(chi2_dof < chi2)
    fails = p_value < p_fail and reduced > reduced_fail
    overestimated = p_below < p_fail and reduced < 1.0 / reduced_fail
    result = "fails" if fails else "noise overestimated" if overestimated else "passes"
    return {"result": result, "reduced_chi2": float(reduced), "p_value": p_value, "p_below": p_below}
