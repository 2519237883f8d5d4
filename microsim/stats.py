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
