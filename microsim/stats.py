"""Statistics shared by the estimator, the verdicts and the reports.

``sidak`` (Šidák 1967) keeps a family of n tests at level α; ``energy_set`` picks the bins
that carry a share (``ENERGY_FRACTION``, 90 %) of the reflected energy, over which relative
errors are weighted; ``MIN_EVENTS`` is the number of single-bounce events a bin needs before
its standard error is trusted in a test (below it the paired-strata estimate is too noisy;
docs/design.md, "Verdicts"). ``chi2_sf``, ``t_sf``, ``t_isf`` and ``norm_isf`` are the tail
probabilities and quantiles the tests use, from ``scipy.special`` (``scipy.stats`` gives the
same numbers but takes ~1 s to import, which every ``microsim.testing`` check would pay).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy import special

from microsim.errors import UsageError

__all__ = [
    "sidak",
    "energy_set",
    "ENERGY_FRACTION",
    "MIN_EVENTS",
    "chi2_sf",
    "t_sf",
    "t_isf",
    "norm_sf",
    "norm_isf",
    "StratifiedMean",
    "stratified_mean",
]

ENERGY_FRACTION = 0.9
"""Share of the reflected energy carried by the bins relative errors are taken over."""
MIN_EVENTS = 25
"""Single-bounce events a bin needs to enter a statistical test."""


def sidak(alpha: float, n: int) -> float:
    """Per-test level 1 − (1 − α)^(1/n) keeping the family-wise error of n independent tests at
    α (Šidák 1967); α in (0, 1), n an integer ≥ 1."""
    if (
        isinstance(alpha, bool)
        or not isinstance(alpha, (int, float, np.floating))
        or not 0.0 < float(alpha) < 1.0
    ):
        raise UsageError(f"alpha must lie in (0, 1), got {alpha!r}")
    if isinstance(n, bool) or int(n) != n or n < 1:
        raise UsageError(f"n must be an integer >= 1, got {n!r}")
    return float(-np.expm1(np.log1p(-float(alpha)) / int(n)))


def energy_set(energy: np.ndarray, fraction: float = ENERGY_FRACTION) -> np.ndarray:
    """Boolean mask of the fewest entries of ``energy`` (≥ 0, flat), taken in decreasing order,
    whose sum reaches ``fraction`` of the total (ties broken by position)."""
    e = np.asarray(energy, dtype=np.float64).ravel()
    mask = np.zeros(e.shape, dtype=bool)
    total = e.sum()
    if e.size == 0 or not total > 0:
        return mask
    order = np.argsort(-e, kind="stable")
    n = int(np.searchsorted(np.cumsum(e[order]), fraction * total * (1.0 - 1e-12))) + 1
    mask[order[: min(n, e.size)]] = True
    return mask


def chi2_sf(x, dof):
    """P(χ²_dof ≥ x) (``scipy.stats.chi2.sf``)."""
    return special.chdtrc(dof, x)


def t_sf(x, dof):
    """P(T_dof ≥ x), Student's t (``scipy.stats.t.sf``)."""
    return special.stdtr(dof, -np.asarray(x, dtype=np.float64))


def norm_sf(x):
    """P(Z ≥ x) for a standard normal Z (``scipy.stats.norm.sf``)."""
    return special.ndtr(-np.asarray(x, dtype=np.float64))


def t_isf(q, dof):
    """x with P(T_dof ≥ x) = q (``scipy.stats.t.isf``)."""
    return -special.stdtrit(dof, q)


def norm_isf(q):
    """x with P(Z ≥ x) = q for a standard normal Z (``scipy.stats.norm.isf``)."""
    return -special.ndtri(q)


class StratifiedMean(NamedTuple):
    """``stratified_mean``'s answer: ``mean`` and ``var`` (the variance of that mean) along the
    realisation axis, and ``dof``, the degrees of freedom of ``var``."""

    mean: np.ndarray
    var: np.ndarray
    dof: int


def stratified_mean(values, strata) -> StratifiedMean:
    """Mean over realisations drawn one stratum each (or several) of K equal-probability
    strata, and its variance (Cochran 1977: stratified sampling, and the collapsed-strata
    estimate where a stratum holds one unit).

    ``values`` (R, ...): one row per realisation; ``strata`` (R,): the stratum of each. The
    mean is that of the stratum means μ_k (equal weights 1/K). With ≥ 2 realisations in every
    stratum, var = Σ_k s_k²/n_k / K² (s_k the within-stratum standard deviation), dof the
    Welch–Satterthwaite value of that sum (at most R − K); with one in some stratum the strata,
    in order, are collapsed into adjacent pairs (the last group a triple when K is odd),
    var = Σ_G |G|/(|G| − 1) Σ_(k∈G) (μ_k − μ̄_G)² / K², dof = K − number of groups: it counts
    the difference between neighbouring strata as noise, so it is conservative where the mean
    varies smoothly from stratum to stratum. K ≥ 2 needed."""
    values = np.asarray(values, dtype=np.float64)
    strata = np.asarray(strata)
    if strata.shape != values.shape[:1]:
        raise UsageError(f"strata must have shape ({len(values)},), got {strata.shape}")
    keys = np.unique(strata)
    K = len(keys)
    if K < 2:
        raise UsageError(f"strata must hold at least 2 distinct strata, got {K}")
    rows = [values[strata == k] for k in keys]
    mu = np.stack([r.mean(axis=0) for r in rows])
    mean = mu.mean(axis=0)
    n = np.array([len(r) for r in rows])
    if n.min() >= 2:
        part = np.stack([r.var(axis=0, ddof=1) / len(r) for r in rows])
        var = part.sum(axis=0) / K**2
        nu = (n - 1).reshape((K,) + (1,) * (part.ndim - 1))
        with np.errstate(invalid="ignore", divide="ignore"):
            ws = np.atleast_1d(part.sum(axis=0) ** 2 / np.sum(part**2 / nu, axis=0))
        ws = ws[np.isfinite(ws)]  # bins without scatter constrain nothing
        dof = int(max(1, np.floor(ws.min()))) if ws.size else int(n.sum() - K)
        return StratifiedMean(mean, var, dof)
    groups = [list(range(i, min(i + 2, K))) for i in range(0, K - K % 2, 2)]
    if K % 2:
        groups[-1].append(K - 1)
    var = np.zeros_like(mean)
    for g in groups:
        mg = mu[g]
        var = var + len(g) / (len(g) - 1) * ((mg - mg.mean(axis=0)) ** 2).sum(axis=0)
    return StratifiedMean(mean, var / K**2, K - len(groups))
