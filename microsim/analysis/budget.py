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

import numpy as np

from microsim.errors import UsageError
from microsim.stats import energy_set

__all__ = ["MIN_AUTO", "MAX_AUTO", "AUTO_TARGET", "error_budget", "realisations_needed"]

MIN_AUTO = 8
MAX_AUTO = 32
AUTO_TARGET = 0.01
MARGIN = 1.25


def _ew(x: np.ndarray, w: np.ndarray) -> float:
    return float(np.sqrt(np.sum(w * x**2) / np.sum(w)))


def error_budget(result) -> list[dict]:
    """Per incidence: {"theta_i", "phi_i", "realisations", "ray", "tile", "total", "energy"} — the
    energy-weighted relative standard errors of the mean BRDF from ray noise, from tile scatter
    and in total, and the relative standard error of its energy over E (module docstring).
    ``tile``/``energy`` are None with fewer than 2 realisations (no scatter to measure)."""
    omega = result.bins.projected_solid_angle()
    per = result.brdf_realisations
    se_ray = result.stderr_ray if result.stderr_ray is not None else result.stderr
    out = []
    for t, theta in enumerate(result.theta_i):
        f = result.brdf[t]
        ok = np.isfinite(f) & (f > 0) & np.isfinite(se_ray[t])
        E = energy_set(np.where(ok, f * omega, 0.0)).reshape(f.shape)
        row = {"theta_i": float(theta), "phi_i": float(result.phi_i[t]), "realisations": 1}
        row.update({"ray": None, "tile": None})
        row.update({"total": None, "energy": None})
        if not E.any():
            out.append(row)
            continue
        w, fe = (f * omega)[E], f[E]
        row["ray"] = _ew(se_ray[t][E] / fe, w)
        row["total"] = row["ray"]
        if per is not None:
            F = per[result.realisations_traced(t), t]
            R = len(F)
            if R >= 2:
                s2 = np.var(F[:, E], axis=0, ddof=1)
                tile2 = np.maximum(s2 / R - se_ray[t][E] ** 2, 0.0)
                energies = np.sum(F[:, E] * omega[E], axis=1)
                row.update(
                    realisations=R,
                    tile=_ew(np.sqrt(tile2) / fe, w),
                    total=_ew(np.sqrt(s2 / R) / fe, w),
                    energy=float(energies.std(ddof=1) / np.sqrt(R) / energies.mean()),
                )
        out.append(row)
    return out


def realisations_needed(budget, target: float = AUTO_TARGET) -> int:
    """Realisations for the tile scatter of every incidence in ``budget`` (``error_budget``) to
    reach ``target`` (relative, e.g. 0.01), at least ``MIN_AUTO``, at most ``MAX_AUTO``."""
    if not (isinstance(target, (int, float)) and 0.0 < target < 1.0):
        raise UsageError(f"target must be a relative error in (0, 1), got {target!r}")
    need = MIN_AUTO
    for row in budget:
        if row["tile"] is None:
            continue
        need = max(need, math.ceil(MARGIN * row["realisations"] * (row["tile"] / target) ** 2))
    return min(need, MAX_AUTO)
