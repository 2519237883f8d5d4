"""Side studies of a run, for its charts: the θi stability sweep (fewer rays), the estimator
variants at a few ray counts (speed vs accuracy), the models' albedo ρ(θ) tables, and the
Mikkelsen Fig. 6 curves of ``microsim report``.

Each study traces with its own seed offset (independent of the main run) and raises
``KeyboardInterrupt`` if a simulation was cut short (``tracing.complete``): a partial side
study never feeds a report.
"""

from __future__ import annotations

import math
import warnings

import numpy as np

from ... import analytic as an
from ...analysis.report import albedo_stderr
from ...analysis.verdict_record import as_verdicts
from ...analysis.verdicts import verdicts_for_result
from ...analytic.anisotropic import AnisotropicNDF
from ...checkpoints import checkpoint
from ...sim import Bins, simulate
from ...sim.compare import attach_models, default_models
from ...sim.predict import Facets
from ...stats import energy_set
from . import tracing
from .planning import Effort, RunPlan

__all__ = [
    "SWEEP_SEED",
    "SPEED_SEED",
    "models_for",
    "attach",
    "noise_floor",
    "estimator_warnings",
    "stability",
    "speed_runs",
    "albedo_models",
    "fig6_curves",
]

SWEEP_SEED, SPEED_SEED = 7919, 104729
"""Seed offsets of the side studies (added to the run's seed): independent of the main run."""


def models_for(plan: RunPlan, seed: int | None = None, realisations: int | None = None):
    """The default model set; for a random scene ``ts-facets`` and the realised m pool every
    realisation the simulation averaged over (``compare.default_models``): the main run's
    (default), or ``realisations`` surfaces from ``seed`` (a side study's)."""
    sc = plan.scene
    seed = plan.seed if seed is None else seed
    n = plan.realisations if realisations is None else realisations
    single, reals = tracing.surface_source(sc, seed, plan.effort.scale_for(sc.surface.kind), n)
    surfaces = single if reals is None else [reals[0](s) for s in reals[1]]
    return default_models(surfaces, sc.ior, ndf=sc.ndf())


def attach(result, specs):
    """``attach_models``: a new Result with the models; quadrature bins that miss their
    tolerance (predict's RuntimeWarning) are recorded in its ``meta["model_warnings"]`` for the
    report instead of stderr."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", RuntimeWarning)
        out = attach_models(result, specs)
    return out.with_meta(model_warnings=sorted({str(w.message) for w in caught}))


def _energy_rel_rms(sim, ref, omega) -> float:
    """Energy-weighted relative RMS of ``sim`` against a reference ``ref`` over the bins
    carrying 90 % of ref's energy (the verdicts' rel_rms with the roles of sim and model
    swapped: here the reference is the noise-free one)."""
    e = np.nan_to_num(ref * omega).ravel()
    keep = energy_set(e) & (ref.ravel() > 0)
    r, s = ref.ravel()[keep], np.nan_to_num(sim.ravel()[keep])
    return float(np.sqrt(np.sum(e[keep] * ((s - r) / r) ** 2) / np.sum(e[keep])))


def noise_floor(result) -> np.ndarray:
    """(T,) relative RMS error a perfect model would show from the simulation's own noise:
    √(Σ_E sim·Ω (se/sim)² / Σ_E sim·Ω) over the energy set E (90 % of the energy)."""
    omega = result.bins.projected_solid_angle().ravel()
    out = []
    for sim, se in zip(result.brdf, result.stderr):
        sim, se = np.nan_to_num(sim.ravel()), np.nan_to_num(se.ravel())
        e = sim * omega
        k = energy_set(e) & (sim > 0)
        out.append(
            np.sqrt(np.sum(e[k] * (se[k] / sim[k]) ** 2) / np.sum(e[k])) if k.any() else np.nan
        )
    return np.array(out)


def estimator_warnings(plan: RunPlan, sweep) -> list[str]:
    """Estimator warnings for the stability chart: unresolved rays, lobes narrower than a bin,
    incidences where the sweep's own noise is not far below the 5 % failure line."""
    out = []
    for t, floor in zip(sweep.theta_i, noise_floor(sweep)):
        if not floor < 0.01:
            out.append(
                f"θi = {t:g}°: the sweep's own noise alone gives a relative error of "
                f"≈ {floor:.1%} ({int(sweep.rays[0])} rays): smaller model errors are not "
                f"resolved there"
            )
    for t, u in zip(sweep.theta_i, sweep.ledger["unresolved"]):
        if u > 0:
            out.append(
                f"θi = {t:g}°: {u:.2%} of the rays were unresolved (wrap cap or "
                f"back-facing hits); their energy is missing from the estimate"
            )
    bin_w = 90.0 / sweep.bins.n_theta
    ndf = plan.scene.ndf()
    if isinstance(ndf, AnisotropicNDF):  # the lobe is narrowest along the smooth axis
        ndf = ndf.isotropic_at(min(ndf.alpha_x, ndf.alpha_y))
    if ndf is None and plan.scene.surface.kind == "flat":
        out.append(
            f"the reflection lobe of a flat surface is a delta: narrower than any bin "
            f"({bin_w:g}° wide); relative errors are bin averages of a spike"
        )
    elif ndf is not None:
        lobe = 2.0 * math.degrees(float(ndf.tilt_quantile_rad(0.5)))  # median lobe half-width
        if lobe < bin_w:
            out.append(
                f"the reflection lobe (median half-width ≈ {lobe:.2g}°, twice the median "
                f"facet tilt) is narrower than a {bin_w:g}° bin: bin averages smear it"
            )
    return out


def stability(plan: RunPlan):
    """θi sweep with fewer rays: (sweep Result with models, its verdicts)."""
    e = plan.effort
    bins = Bins(*e.sweep_bins) if e.sweep_bins else plan.bins
    checkpoint("side-studies")
    n, seed = plan.side_realisations, plan.seed + SWEEP_SEED
    sweep = tracing.complete(
        tracing.simulate_scene(
            plan, e.sweep_theta, max(e.sweep_rays, n), seed, bins, realisations=n
        )
    )
    # the sweep's own surfaces: ts-facets must describe the facets it traced
    specs = [
        m for m in models_for(plan, seed, n) if e.sweep_facets or not isinstance(m.rule, Facets)
    ]
    sweep = attach(sweep, specs)
    return sweep, verdicts_for_result(sweep)


def speed_runs(plan: RunPlan, result, shown, verdicts):
    """Estimator variants at a few ray counts: (name → (wall times s, relative RMS errors),
    θi of the runs, label of the reference). One surface realisation serves every run (its
    tracer is built once and reused): the times are tracing times, without the scene build.

    Reference (noise-free): the prescribed model that agrees best (lowest rel_rms) at the
    incidence nearest 30° (at the first φi); without one, the main run (whose own noise then
    floors the error)."""
    t_index = int(np.argmin(np.abs(np.asarray(plan.theta_i) - 30.0)))
    theta = plan.theta_i[t_index]
    ok = [
        v
        for v in as_verdicts(verdicts)
        if v.agrees
        and not v.fitted
        and abs(v.theta_i - theta) < 1e-9
        and v.phi_i == plan.phi_i[0]
        and v.rel_rms is not None
    ]
    best = min(ok, key=lambda v: v.rel_rms).model if ok else None
    ref = shown[best][t_index] if best else result.brdf[t_index]
    label = f"{best} (agrees)" if best else "the main run"
    omega = result.bins.projected_solid_angle()
    runs = {}
    surface = tracing.scene_surface(plan, plan.seed + SPEED_SEED)
    for origins in ("stratified", "independent"):
        times, errs = [], []
        for n in plan.effort.speed_rays:
            checkpoint("side-studies")
            r = tracing.complete(
                tracing.simulate_scene(
                    plan,
                    [theta],
                    n,
                    plan.seed + SPEED_SEED,
                    result.bins,
                    origins=origins,
                    realisations=False,
                    surface=surface,
                )
            )
            times.append(r.info.seconds - r.info.seconds_scene_build)
            errs.append(_energy_rel_rms(r.brdf[0], ref, omega))
        runs[origins] = (times, errs)
    return runs, theta, label


def albedo_models(plan: RunPlan, theta_grid):
    """Model ρ(θ) for each Torrance–Sparrow shadowing variant: name → (θ grid, ρ). None for
    anisotropic surfaces (their albedo depends on the incidence azimuth as well; the albedo
    tables are isotropic): the energy chart then shows the simulation alone."""
    ndf = plan.scene.ndf()
    cos = np.cos(np.radians(theta_grid))
    if plan.scene.anisotropic:
        return {}
    if ndf is None:
        return {"Fresnel (flat mirror)": (theta_grid, an.fresnel(cos, plan.scene.ior))}
    n_t, n_g, n_p = plan.effort.albedo_nodes
    return {
        f"TS {kind}": (
            theta_grid,
            an.AlbedoTable.of(
                ndf, kind, plan.scene.ior, n_theta=n_t, n_grazing=n_g, n_gl_phi=n_p
            ).rho(cos),
        )
        for kind in ("vgroove", "smith", "smith-correlated")
    }


def fig6_curves(scenes, effort: Effort, threads: int) -> list[dict]:
    """Mikkelsen Fig. 6(c)(d) data: the catalogue's vMF V-groove surfaces (κ = 17, 1024) with
    methanol and aluminium: simulated 1 − ρ(θ) (single-bounce albedo, Mikkelsen 2009, eq. 27)
    against the model's (V-groove G) and the Fresnel transmittance."""
    vmf = [s for s in scenes if s.surface.kind == "vgrooves" and s.surface.params["ndf"] == "vmf"]
    grid = np.linspace(0.0, 89.9, 180)
    cos = np.cos(np.radians(grid))
    curves = []
    for sc in sorted(vmf, key=lambda s: s.surface.params["kappa"]):
        surface = sc.build_surface(scale=effort.scale_for("vgrooves"))
        for material in ("methanol", "aluminium"):
            ior = an.resolve_material(material)
            checkpoint("side-studies")
            res = tracing.complete(
                simulate(
                    surface,
                    ior,
                    list(effort.fig6_theta),
                    rays=effort.fig6_rays,
                    bins=Bins(9, 5),
                    seed=sc.simulation.seed,
                    threads=threads,
                )
            )
            n_t, n_g, n_p = effort.albedo_nodes
            table = an.AlbedoTable.of(
                sc.ndf(), "vgroove", ior, n_theta=n_t, n_grazing=n_g, n_gl_phi=n_p
            )
            curves.append(
                {
                    "label": f"{material} κ={sc.surface.params['kappa']:g}",
                    "material": material,
                    "theta": grid,
                    "one_minus_rho_model": 1.0 - table.rho(cos),
                    "fresnel_T": an.fresnel_transmittance(cos, ior),
                    "sim_theta": res.theta_i,
                    "sim_one_minus_rho": 1.0 - res.ledger["single_fresnel"],
                    "sim_err": albedo_stderr(res),
                }
            )
    return curves
