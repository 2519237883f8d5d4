"""The answer of an anisotropic scene: how far each Smith G variant is from the simulation, and
how far the isotropic stand-in renderers use is from the exact anisotropic Λ.

Input: a ``Result`` holding the default models of an anisotropic Gaussian field
(``sim.compare.default_models``: ``ts-beckmann-nominal-smith-corr`` — the exact Λ, height-
correlated —, ``ts-beckmann-nominal-smith`` — exact Λ, separable — and ``GEOMEAN_MODEL`` — the
Λ of α = √(αx αy), MaterialX) and its verdicts. Per incidence (θi at the scene's φi):

* against the simulation: each variant's energy-weighted relative RMS error and energy deviation
  Σ_E Ω (f̄ − m)/Σ_E Ω m with its standard error, and its verdict, as the verdicts report them;
* stand-in against exact: Σ_E Ω (m_stand-in − m_exact)/Σ_E Ω m_exact and the energy-weighted
  relative RMS of (m_stand-in − m_exact)/m_exact over the exact model's energy set E (90 % of
  its Σ m Ω; ``stats.energy_set``) — model against model, no noise.
"""

from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np

from microsim.stats import energy_set

from .verdicts import verdict_kind

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


def anisotropy_summary(result, verdicts: Sequence[Mapping]) -> dict | None:
    """JSON-able summary (module docstring), or None when ``result`` lacks the variants."""
    names = list(VARIANTS.values())
    if not all(n in result.models for n in names):
        return None
    omega = result.bins.projected_solid_angle()
    exact, stand_in = names[0], names[2]
    rows = []
    for t, th in enumerate(result.theta_i):
        by = {v["model"]: v for v in verdicts if float(v["theta_i"]) == float(th)}
        dev, rms = _model_vs_model(
            np.asarray(result.models[stand_in][t]), np.asarray(result.models[exact][t]), omega
        )
        rows.append(
            {
                "theta_i": float(th),
                "phi_i": float(result.phi_i[t]),
                "stand_in_vs_exact": {"energy_dev": dev, "rel_rms": rms},
                "against_simulation": {
                    label: {
                        "rel_rms": by[name]["rel_rms"],
                        "energy_dev": by[name]["energy_dev"],
                        "energy_dev_se": by[name].get("energy_dev_se"),
                        "verdict": verdict_kind(by[name]),
                    }
                    for label, name in VARIANTS.items()
                    if name in by
                },
            }
        )
    return {"variants": dict(VARIANTS), "incidences": rows}
