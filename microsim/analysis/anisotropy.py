"""The answer of an anisotropic scene: how far each Smith G variant is from the simulation, and
how far the isotropic stand-in renderers use is from the exact anisotropic Λ.

Input: a ``Result`` holding the default models of an anisotropic Gaussian field
(``sim.compare.default_models``: ``ts-beckmann-nominal-smith-corr`` — the exact Λ, height-
correlated —, ``ts-beckmann-nominal-smith`` — exact Λ, separable — and ``GEOMEAN_MODEL`` — the
Λ of α = √(αx αy), MaterialX) and its verdicts. Per incidence (θi, φi):

* against the simulation: each variant's energy-weighted relative RMS error and energy deviation
  Σ_E Ω (f̄ − m)/Σ_E Ω m with its standard error, and its verdict, as the verdicts report them;
* stand-in against exact: Σ_E Ω (m_stand-in − m_exact)/Σ_E Ω m_exact and the energy-weighted
  relative RMS of (m_stand-in − m_exact)/m_exact over the exact model's energy set E (90 % of
  its Σ m Ω; ``stats.energy_set``) — model against model, no noise;
* for a run traced with ``bounces`` > 1, the energy each variant misses: the simulated
  reflected energy of all orders E_sim = Σ_o Σ_B f̄_B,o Ω_B (fraction of the incident power,
  ± its standard error, ``multiple.order_energies``) against the variant's single-scattering
  energy E_m = Σ_B m_B Ω_B over the hemisphere, missed = (E_sim − E_m)/E_sim with standard
  error √((se(E_sim) E_m/E_sim²)² + (ε E_m/E_sim)²), ε the model's relative quadrature
  tolerance (the verdicts' ``model_rtol``); and the simulated orders ≥ 2, the part no
  single-scattering model can carry, beside the energy of orders ≥ 2 that the random walk on
  the anisotropic Smith microsurface (Heitz et al. 2016) predicts — what the Smith model says
  its own single-scattering form misses.
"""

from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np

from microsim.stats import energy_set

from . import incidence
from .multiple import order_energies
from .study_records import (
    AnisotropyIncidence,
    AnisotropyStudy,
    MissedEnergy,
    OrderComparison,
    OrderEnergy,
)
from .verdicts import Significance, as_verdicts

__all__ = ["VARIANTS", "anisotropy_summary"]

VARIANTS = {
    "exact Λ, height-correlated": "ts-beckmann-nominal-smith-corr",
    "exact Λ, separable": "ts-beckmann-nominal-smith",
    "α = √(αx αy) Λ (MaterialX)": "ts-beckmann-nominal-smith-corr-geomean",
}
"""Label → model name of the Smith G variants the summary compares."""


def _model_vs_model(a: np.ndarray, b: np.ndarray, omega: np.ndarray) -> tuple[float, float]:
    """(energy deviation Σ_E Ω(a − b)/Σ_E Ω b, energy-weighted rel. RMS of (a − b)/b) over
    the energy set E of b."""
    w = np.where(np.isfinite(b) & (b > 0), b * omega, 0.0)
    E = energy_set(w).reshape(b.shape)
    dev = float(np.sum(omega[E] * (a[E] - b[E])) / np.sum(omega[E] * b[E]))
    rel = (a[E] - b[E]) / b[E]
    rms = float(np.sqrt(np.sum(w[E] * rel**2) / np.sum(w[E])))
    return dev, rms


def _walk_at(comparison: Mapping | None, here: tuple[float, float]) -> Mapping | None:
    """The random walk's orders-≥ 2 entry of ``comparison`` at incidence ``here``, or None."""
    if comparison is None:
        return None
    for inc in OrderComparison.from_json(comparison).incidences:
        if (inc.theta_i, inc.phi_i) == here:
            return inc.models.get("random-walk")
    return None


def _missed(energies: OrderEnergy, result, t: int, omega: np.ndarray, rtol: Mapping, walk):
    """The energy each variant misses at incidence t (``MissedEnergy``; module docstring);
    ``rtol``: model name → its relative quadrature tolerance; ``walk``: the random walk's
    ``ModelEnergy`` at t, or None."""
    e_sim, se_sim = energies.reflected, energies.reflected_se
    models = {}
    for label, name in VARIANTS.items():
        e_m = float(np.sum(np.asarray(result.models[name][t]) * omega))
        models[label] = {
            "energy": e_m,
            "missed": (e_sim - e_m) / e_sim,
            "missed_se": float(np.hypot(se_sim * e_m / e_sim**2, rtol[name] * e_m / e_sim)),
        }
    return MissedEnergy(
        reflected=e_sim,
        reflected_se=se_sim,
        multiple=energies.multiple,
        multiple_se=energies.multiple_se,
        models=models,
        walk_multiple=None if walk is None else walk.energy,
        walk_multiple_se=None if walk is None else walk.energy_se,
    )


def anisotropy_summary(
    result, verdicts: Sequence[Mapping], comparison: Mapping | None = None
) -> AnisotropyStudy | None:
    """The summary (module docstring; an ``AnisotropyStudy``, also its JSON dict), or None
    when ``result`` lacks the variants.
    ``comparison``: the run's order comparison (``multiple.order_comparison``), whose random
    walk on the anisotropic Smith microsurface gives the orders ≥ 2 the Smith model itself
    predicts (``MissedEnergy.walk_multiple``)."""
    names = list(VARIANTS.values())
    if not all(n in result.models for n in names):
        return None
    omega = result.bins.projected_solid_angle()
    exact, stand_in = names[0], names[2]
    orders = None
    if getattr(result, "brdf_orders", None) is not None and result.brdf_orders.shape[0] >= 2:
        orders = order_energies(result)
    rows = []
    for t, th in enumerate(result.theta_i):
        here = (float(th), float(result.phi_i[t]))
        by = {v.model: v for v in as_verdicts(verdicts) if incidence.key(v) == here}
        dev, rms = _model_vs_model(
            np.asarray(result.models[stand_in][t]), np.asarray(result.models[exact][t]), omega
        )
        missed = None
        if orders is not None:
            rtol = {n: by[n].model_rtol if n in by else Significance().model_rtol for n in names}
            missed = _missed(orders[t], result, t, omega, rtol, _walk_at(comparison, here))
        rows.append(
            AnisotropyIncidence(
                theta_i=float(th),
                phi_i=float(result.phi_i[t]),
                stand_in_vs_exact={"energy_dev": dev, "rel_rms": rms},
                against_simulation={
                    label: {
                        "rel_rms": by[name].rel_rms,
                        "energy_dev": by[name].energy_dev,
                        "energy_dev_se": by[name].energy_dev_se,
                        "verdict": by[name].kind,
                    }
                    for label, name in VARIANTS.items()
                    if name in by
                },
                missed=missed,
            )
        )
    return AnisotropyStudy(variants=dict(VARIANTS), incidences=rows)
