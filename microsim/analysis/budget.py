"""Error budget of a simulated ensemble BRDF: ray noise against tile-to-tile scatter, and how
many realisations a target precision asks for (``realisations = "auto"``).

A random scene's BRDF f̄_B (bin B) is the mean of R realisations f_r, each traced with its own
rays. Its variance per bin has two parts (Result.stderr_ray, Result.brdf_realisations):

* ray noise of the mean, se_ray_B² (from the rays' Fresnel weights: shrinks with more rays);
* tile scatter of the mean, τ_B²/R with τ_B² = s_B² − R·se_ray_B² (s_B the sample standard
  deviation of the f_r; a realisation's ray noise is ≈ R·se_ray_B² since each traced 1/R of
  the rays): shrinks only with more realisations. Estimated per bin, clipped at 0.

Each is summarised as an energy-weighted relative RMS over the energy set E of f̄ (the fewest
bins carrying ``ENERGY_FRACTION`` of Σ f̄Ω, ``microsim.stats.energy_set``):
EW(x) = √(Σ_E f̄Ω (x_B/f̄_B)² / Σ_E f̄Ω). ``tile`` is the realisation scatter of the
energy-weighted BRDF that ``realisations = "auto"`` brings below its target; ``energy`` is the
standard error of the mean's total energy over E from the scatter of the R tile energies (what
the verdicts' energy test resolves).

The rule (``realisations_needed``): R ≥ ``MIN_AUTO`` (Student t tests on R − 1 degrees of
freedom lose little power from about 8 realisations: the two-sided t₇ quantile at 10⁻⁴ is 1.9×
the normal one, t₃'s is 7×) and tile ≤ target, i.e. R ≥ ``MARGIN`` · R_now · (tile_now/target)²,
rounded up, at most ``MAX_AUTO``. τ²/R is estimated from the pilot's R_now realisations; the
margin covers that estimate's own scatter, so that the chosen run lands below the target.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from microsim.errors import UsageError
from microsim.stats import energy_set

from .json_record import JsonRecord

__all__ = [
    "MIN_AUTO",
    "MAX_AUTO",
    "AUTO_TARGET",
    "BudgetRow",
    "error_budget",
    "realisations_needed",
]

MIN_AUTO = 8
MAX_AUTO = 32
AUTO_TARGET = 0.01
MARGIN = 1.25


def _ew(x: np.ndarray, w: np.ndarray) -> float:
    return float(np.sqrt(np.sum(w * x**2) / np.sum(w)))


@dataclass(frozen=True, eq=False)
class BudgetRow(JsonRecord):
    """The error budget of one incidence (module docstring): the energy-weighted relative
    standard errors of the mean BRDF from ray noise (``ray``), from tile scatter (``tile``)
    and in total, and the relative standard error of its energy over E (``energy``); each None
    without an energy set, ``tile`` and ``energy`` also with fewer than 2 realisations."""

    theta_i: float
    phi_i: float
    realisations: int = 1
    ray: float | None = None
    tile: float | None = None
    total: float | None = None
    energy: float | None = None


def error_budget(result) -> list[BudgetRow]:
    """Per incidence its ``BudgetRow`` (module docstring)."""
    omega = result.bins.projected_solid_angle()
    per = result.brdf_realisations
    se_ray = result.stderr_ray if result.stderr_ray is not None else result.stderr
    out = []
    for t, theta in enumerate(result.theta_i):
        at = dict(theta_i=float(theta), phi_i=float(result.phi_i[t]))
        f = result.brdf[t]
        ok = np.isfinite(f) & (f > 0) & np.isfinite(se_ray[t])
        E = energy_set(np.where(ok, f * omega, 0.0)).reshape(f.shape)
        if not E.any():
            out.append(BudgetRow(**at))
            continue
        w, fe = (f * omega)[E], f[E]
        ray = _ew(se_ray[t][E] / fe, w)
        F = per[result.realisations_traced(t), t] if per is not None else None
        if F is None or len(F) < 2:
            out.append(BudgetRow(**at, ray=ray, total=ray))
            continue
        R = len(F)
        s2 = np.var(F[:, E], axis=0, ddof=1)
        tile2 = np.maximum(s2 / R - se_ray[t][E] ** 2, 0.0)
        energies = np.sum(F[:, E] * omega[E], axis=1)
        out.append(
            BudgetRow(
                **at,
                realisations=R,
                ray=ray,
                tile=_ew(np.sqrt(tile2) / fe, w),
                total=_ew(np.sqrt(s2 / R) / fe, w),
                energy=float(energies.std(ddof=1) / np.sqrt(R) / energies.mean()),
            )
        )
    return out


def realisations_needed(budget, target: float = AUTO_TARGET) -> int:
    """Realisations for the tile scatter of every incidence in ``budget`` (``error_budget``, or
    its dicts) to reach ``target`` (relative, e.g. 0.01), at least ``MIN_AUTO``, at most
    ``MAX_AUTO``."""
    if not (isinstance(target, (int, float)) and 0.0 < target < 1.0):
        raise UsageError(f"target must be a relative error in (0, 1), got {target!r}")
    need = MIN_AUTO
    for row in map(BudgetRow.from_json, budget):
        if row.tile is None:
            continue
        need = max(need, math.ceil(MARGIN * row.realisations * (row.tile / target) ** 2))
    return min(need, MAX_AUTO)
