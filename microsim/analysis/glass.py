"""Rough glass: what a run through a dielectric interface says (``glass_study``, the
``"glass"`` study of a scene with ``[material] transmission``; docs/dielectric.md).

Per incidence, from the air and from inside the medium:

* the fractions of the incident flux reflected (R) and transmitted (T), all orders and at
  order 1 (single scattering), from the paths' ledger. The roulette gives every path weight 1,
  so each fraction is a proportion of paths: its standard error is the binomial √(p(1 − p)/N)
  (conservative for stratified origins);
* per model, Walter et al. 2007's single-scattering BSDF with separable and height-correlated
  Smith G on the surface's microfacet distribution (``GLASS_MODELS``): its R and T by quadrature
  (``analytic.dielectric.dielectric_albedo``) — 1 − R − T is the energy single scattering
  loses, which the traced orders ≥ 2 hold;
* of every order, Heitz et al. 2016's dielectric random walk and Kulla & Conty 2017's
  compensation (``MULTIPLE_MODELS``): their R and T against the traced ones;
* verdicts of the models' BRDF and BTDF against order 1, bin by bin (``verdicts.verdict``,
  the same statistics as every verdict): where Walter's assumptions hold (single scattering,
  Smith's uncorrelated masking) they agree, and where they depart the verdict says by how
  much. A lobe no traced light leaves by (total internal reflection), or with too few
  events in every bin, has no verdict.

Bins: both lobes on the run's grid, θo from the pole of the side the light leaves by, Δφ of
the direction itself (``sim.dielectric``). A model is evaluated there by flipping z: the
incidence to the canonical upper side, the outgoing direction to the side its lobe leaves by.
"""

from __future__ import annotations

import re
from dataclasses import replace
from typing import Callable

import numpy as np

from microsim.analytic.dielectric import WalterDielectric, dielectric_albedo
from microsim.analytic.energy_compensation import DielectricAlbedoTable, KullaContyDielectric
from microsim.analytic.masking import Smith
from microsim.analytic.random_walk import WalkNDF, dielectric_walk_bin_averages
from microsim.bins import Bins
from microsim.errors import UsageError
from microsim.sim.predict import bin_average
from microsim.vectors import spherical_deg

from .study_records import GlassIncidence, GlassStudy
from .verdicts import Measured, Prediction, Significance, verdict

__all__ = [
    "GLASS_MODELS",
    "LOBES",
    "MULTIPLE_MODELS",
    "glass_models",
    "canonical_incidence",
    "lobe_function",
    "lobe_measured",
    "lobe_values",
    "multiple_models",
    "glass_study",
]

LOBES = ("reflected", "transmitted")
GLASS_MODELS = {
    "walter-smith": (False, "as-reflection"),
    "walter-smith-corr": (True, "as-reflection"),
    "walter-smith-corr-beta": (True, "height-correlated"),
}
"""Walter et al. 2007's single-scattering BSDF by its Smith G: name → (height-correlated,
the G of transmission: ``WalterDielectric.crossing``). The first two are what renderers ship
(the reflection's G2 also across the interface); the third takes Heitz 2014's
height-correlated G for directions on opposite sides."""


def glass_models(ndf, eta: float) -> dict:
    """Name → ``WalterDielectric`` on ``ndf`` at index ``eta`` (``GLASS_MODELS``)."""
    return {
        name: WalterDielectric(ndf, Smith(correlated=corr), eta, crossing)
        for name, (corr, crossing) in GLASS_MODELS.items()
    }


def _flip(w: np.ndarray, flip: bool) -> np.ndarray:
    return w * np.array([1.0, 1.0, -1.0]) if flip else w


def lobe_function(model, inside: bool, lobe: str) -> Callable:
    """f(wi, wo) of ``model`` on canonical upper-side directions: the incidence flipped to
    the medium's side when lit from ``inside``, the outgoing direction to the side ``lobe``
    leaves by."""
    out_below = inside != (lobe == "transmitted")
    return lambda wi, wo: model.f(_flip(wi, inside), _flip(wo, out_below))


def lobe_values(model, result, t: int, lobe: str, rtol: float = 1e-3) -> np.ndarray:
    """``model``'s bin averages (Θ, Φ) sr⁻¹ of ``lobe`` at incidence ``t`` of ``result``."""
    theta, inside = canonical_incidence(float(result.theta_i[t]))
    phi = float(result.phi_i[t])
    fn = lobe_function(model, inside, lobe)
    return bin_average(
        spherical_deg(theta, phi), result.bins, fn, phi, rtol, symmetric=model.symmetric
    ).values


def canonical_incidence(theta_i: float) -> tuple[float, bool]:
    """(θ from the pole of the incidence's side, lit from inside the medium)."""
    return (180.0 - theta_i, True) if theta_i > 90.0 else (theta_i, False)


def lobe_measured(result, t: int, lobe: str) -> Measured:
    """The order-1 ``lobe`` ("reflected" or "transmitted") of incidence ``t`` of a run
    through a dielectric interface, as a verdict's ``Measured``: its events per bin from the
    raw tallies (slot 0 of its side), its realisations when there are several."""
    k = LOBES.index(lobe)
    values = (result.brdf_orders, result.btdf_orders)[k]
    stderr = (result.stderr_orders, result.stderr_btdf_orders)[k]
    per_real = (result.brdf_realisations_orders, result.btdf_realisations_orders)[k]
    nbin = result.bins.shape[0] * result.bins.shape[1]
    start = k * values.shape[0] * nbin
    counts = np.asarray(result.tallies["count"]).sum(axis=0)[t, start : start + nbin]
    return Measured.of(
        result,
        t,
        brdf=values[0, t],
        stderr=stderr[0, t],
        counts=counts.reshape(result.bins.shape),
        realisations=None if per_real is None else per_real[0, :, t],
    )


MULTIPLE_MODELS = ("random-walk", "kulla-conty")
"""The models of every scattering order a glass study sets against the traced R and T:
Heitz et al. 2016's dielectric random walk (Monte Carlo) and Kulla & Conty 2017's
compensation added to ``walter-smith-corr-beta`` (the walk's first order)."""


def multiple_models(ndf, eta: float, theta_i, walk_paths: int, seed: int) -> list[dict]:
    """Per incidence ``theta_i`` (degrees, as traced), name → [R, T, se R, se T] of
    ``MULTIPLE_MODELS`` on ``ndf`` (the walk needs a Beckmann or GGX distribution: without
    one, none)."""
    try:
        WalkNDF.of(ndf)
    except UsageError:
        return [{} for _ in theta_i]
    walk = dielectric_walk_bin_averages(
        list(theta_i), Bins(1, 2), ndf, eta, n_paths=walk_paths, orders=1, seed=seed
    )
    single = glass_models(ndf, eta)["walter-smith-corr-beta"]
    compensation = KullaContyDielectric(eta=eta, table=DielectricAlbedoTable.from_model(single))
    out = []
    for a, t in enumerate(theta_i):
        r_ss, t_ss = dielectric_albedo(single, float(t))
        r_ms, t_ms = compensation.albedo(float(t))
        out.append(
            {
                "random-walk": [float(walk.R[a]), float(walk.T[a])]
                + [float(walk.R_stderr[a]), float(walk.T_stderr[a])],
                "kulla-conty": [float(r_ss + r_ms), float(t_ss + t_ms), 0.0, 0.0],
            }
        )
    return out


def glass_study(
    above,
    inside,
    ndf,
    eta: float,
    inside_dir: str,
    walk_paths: int = 200_000,
    seed: int = 0,
    predictions: dict | None = None,
) -> GlassStudy:
    """The ``GlassStudy`` of the runs ``above`` (lit from the air) and ``inside`` (from the
    medium) of one scene through a dielectric interface of index ``eta``, its models on the
    microfacet distribution ``ndf`` (module docstring; None: no models, the energies only),
    the random walk with ``walk_paths`` paths per incidence from ``seed``; ``inside_dir``
    names the folder the inside run is saved in. The verdicts of one study form
    one family (their false-alarm rate is shared, ``Significance.n_tests``). ``predictions``:
    a dict that receives every model's bin averages, (θi as traced, lobe, model name) →
    (Θ, Φ) sr⁻¹ (``glass_report.glass_chart`` draws them)."""
    models = glass_models(ndf, eta) if ndf is not None else {}
    runs = [(r, t) for r in (above, inside) for t in range(len(r.theta_i))]
    significance = Significance(n_tests=max(1, len(runs) * len(LOBES) * len(models)))
    angles = [float(r.theta_i[t]) for r, t in runs]
    multiple = multiple_models(ndf, eta, angles, walk_paths, seed) if ndf is not None else None
    rows = []
    for k, (result, t) in enumerate(runs):
        row = _incidence(result, t, models, significance, predictions)
        rows.append(row if multiple is None else replace(row, multiple=multiple[k]))
    text = re.sub(r"(\d\.\d{3})\d+", r"\1", repr(ndf))  # the parameters to 4 digits
    return GlassStudy(eta=float(eta), ndf=text, inside=inside_dir, incidences=rows)


def _incidence(result, t: int, models: dict, significance, predictions) -> GlassIncidence:
    theta, inside = canonical_incidence(float(result.theta_i[t]))
    n, L = int(result.rays[t]), result.ledger
    escaped = L["escaped_energy"][t]
    transmitted = L["transmitted_energy"][t]
    verdicts = []
    for lobe in LOBES:
        measured = lobe_measured(result, t, lobe)
        if not measured.counts.any():  # no light leaves this way (total internal reflection)
            continue
        for name, model in models.items():
            values = lobe_values(model, result, t, lobe)
            if predictions is not None:
                predictions[(float(result.theta_i[t]), lobe, name)] = values
            prediction = Prediction(
                values,
                name=f"{name} ({lobe})",
                params=model.params(),
                ensemble=True,
            )
            v = verdict(measured, prediction, significance)
            if v.n_bins:  # else too few events in every bin to judge
                verdicts.append(v)
    albedo = {
        name: [float(v) for v in dielectric_albedo(model, float(result.theta_i[t]))]
        for name, model in models.items()
    }
    return GlassIncidence(
        side="medium" if inside else "air",
        theta=theta,
        theta_i=float(result.theta_i[t]),
        **_fractions("reflected", escaped, n),
        **_fractions("transmitted", transmitted, n),
        **_fractions("single_reflected", L["escaped_1_energy"][t], n),
        **_fractions("single_transmitted", L["transmitted_1_energy"][t], n),
        **_fractions("single", L["escaped_1_energy"][t] + L["transmitted_1_energy"][t], n),
        tir=float(L["tir_1"][t]),
        models=albedo,
        verdicts=verdicts,
    )


def _fractions(name: str, p: float, n: int) -> dict:
    """``name`` → the proportion ``p`` of ``n`` paths, ``name_se`` → its binomial error."""
    return {name: float(p), f"{name}_se": float(np.sqrt(max(p * (1.0 - p), 0.0) / n))}
