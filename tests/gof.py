"""Goodness-of-fit helpers shared by the sampler tests (docs/design.md, "Tests").

Pearson χ² of observed counts against expected counts, with cells whose expected count is
below ``min_expected`` pooled into one, and Šidák's correction for running several tests at
one family-wise significance.
"""
from __future__ import annotations

import numpy as np
from scipy import stats

from microsim.stats import sidak  # noqa: F401  (re-exported for the tests)


def pearson_chi2(observed, expected, min_expected: float = 5.0):
    """Return (statistic, dof, p-value) of Pearson's χ² test.

    ``expected`` must sum to the same total as ``observed`` (the caller integrates the pdf over
    each cell and multiplies by the sample count; any probability outside the cells belongs in
    one extra cell). Cells with expected count < ``min_expected`` are pooled into one cell.
    """
    obs = np.asarray(observed, dtype=np.float64).ravel()
    exp = np.asarray(expected, dtype=np.float64).ravel()
    if obs.shape != exp.shape:
        raise ValueError("observed and expected must have the same number of cells")
    small = exp < min_expected
    if small.any():
        obs = np.append(obs[~small], obs[small].sum())
        exp = np.append(exp[~small], exp[small].sum())
        if exp[-1] == 0:
            if obs[-1] > 0:   # samples where the pdf says none can be: certain failure
                return np.inf, max(len(exp) - 2, 1), 0.0
            obs, exp = obs[:-1], exp[:-1]
    stat = float(np.sum((obs - exp) ** 2 / exp))
    dof = len(exp) - 1
    return stat, dof, float(stats.chi2.sf(stat, dof))
