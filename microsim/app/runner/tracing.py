"""Tracing a planned scene: the main run, a ``rays = "auto"`` run and the side studies' runs
(``simulate_scene``), and the run's description in ``meta.json``.

Random surfaces are averaged over the plan's realisations (``RunPlan.realisations``: the
scene's count, or the count the pilot of a ``realisations = "auto"`` scene chose, see
``choose_realisations``); realisation r is built with seed ``seed + r``. Callers reach
``simulate_scene`` through this module (``tracing.simulate_scene``) so that one replacement
(tests) covers every run.
"""

from __future__ import annotations

from dataclasses import asdict, replace

import numpy as np

from ...analysis.budget import error_budget, realisations_needed
from ...sim import Estimator, Execution, Experiment, estimate
from ...sim.auto import AutoRecord, simulate_auto
from .planning import AUTO_TARGET, RunPlan, tally_settings

__all__ = [
    "surface_source",
    "scene_surface",
    "simulate_scene",
    "complete",
    "simulate_auto_scene",
    "auto_summary",
    "run_meta",
    "remaining_rays",
    "pilot_continues",
    "choose_realisations",
    "realisations_record",
]


def surface_source(scene, seed: int, scale: float, n: int):
    """(surface, realisations) arguments of ``simulate`` for ``n`` realisations of the scene."""
    if n == 1:
        return scene.build_surface(seed=seed, scale=scale), None
    return None, (lambda s: scene.build_surface(seed=s, scale=scale), [seed + r for r in range(n)])


def scene_surface(plan: RunPlan, seed: int):
    """The plan's surface realisation ``seed`` at the effort's scale."""
    sc = plan.scene
    return sc.build_surface(seed=seed, scale=plan.effort.scale_for(sc.surface.kind))


def simulate_scene(
    plan: RunPlan,
    theta_i,
    rays,
    seed,
    bins,
    progress=None,
    resume=None,
    origins="stratified",
    realisations=True,
    bounces=1,
    surface=None,
    phi_i=None,
    cluster=None,
    transmission=None,
):
    """``estimate`` the plan's scene at ``theta_i`` (degrees; ``phi_i`` one azimuth per θi,
    None: the scene's first φi at every θi — the side studies) with ``rays`` per incidence over
    ``realisations`` surfaces: True = the plan's, False = one (seed ``seed``), or a count;
    ``bounces``: scattering orders traced (``simulate``; the side studies trace one).
    ``surface``: that one realisation already built (``scene_surface``), so that repeated
    runs on it reuse its tracer instead of building surface and BVH again. ``cluster``: a
    ``dask.distributed.Client`` whose workers trace (``sim.cluster``), or None.
    ``transmission``: refract at a dielectric interface (``simulate``); None: the scene's
    ``transmission`` (the side studies trace reflection alone: False)."""
    sc = plan.scene
    scale = plan.effort.scale_for(sc.surface.kind)
    n = plan.realisations if realisations is True else max(1, int(realisations))
    if surface is not None and n != 1:
        raise ValueError("simulate_scene: a prebuilt surface is one realisation")
    surface, reals = (surface, None) if surface is not None else surface_source(sc, seed, scale, n)
    factory, seeds = reals if reals is not None else (None, None)
    return estimate(
        Experiment(
            surface,
            sc.material,
            tuple(theta_i),
            plan.phi_i[0] if phi_i is None else tuple(phi_i),
            bins=bins,
            bounces=bounces,
            surface_factory=factory,
            seeds=seeds,
            transmission=sc.transmission if transmission is None else transmission,
        ),
        Estimator(rays, seed, origins=origins),
        Execution(plan.threads, progress=progress, cluster=cluster),
        resume=resume,
    )


def complete(result):
    """A side study's ``Result``, or ``KeyboardInterrupt`` when it was cut short: ``simulate``
    returns partial tallies on Ctrl-C, and a side study must never feed a report from them."""
    if result.is_partial:
        raise KeyboardInterrupt
    return result


def simulate_auto_scene(plan: RunPlan, log):
    """``simulate_auto`` to ``AUTO_TARGET`` on the scene's surface, at most ``plan.rays`` rays
    per incidence; one progress line per batch through ``log`` (None: silent)."""
    sc = plan.scene
    surface = scene_surface(plan, plan.seed)
    theta_i, phi_i = plan.incidences
    return simulate_auto(
        surface,
        sc.ior,
        list(theta_i),
        phi_i=list(phi_i),
        target=AUTO_TARGET,
        bins=plan.bins,
        seed=plan.seed,
        threads=plan.threads,
        max_rays=plan.rays,
        progress=log,
    )


def auto_summary(result) -> dict | None:
    """Rays, seconds, achieved rse and convergence per incidence of an auto run (or None)."""
    auto = AutoRecord.of(result.info.auto)
    if auto is None:
        return None
    return {
        "target": auto.target,
        "seconds": float(result.info.seconds or 0.0),
        "incidences": [asdict(incidence) for incidence in auto.incidences],
    }


def run_meta(plan: RunPlan) -> dict:
    """``meta["run"]``: the settings a ``--resume`` must match (``planning``: the options and
    ``tally_settings``, what the scene's tallies depend on) and the effort."""
    sc = plan.scene
    rays = {"rays": "auto", "max_rays": plan.rays} if plan.auto else {"rays": plan.rays}
    return {
        "scene": sc.name,
        "scene_file": str(sc.path),
        "description": sc.description,
        **rays,
        "theta_i": list(plan.theta_i),
        "seed": plan.seed,
        "quick": plan.quick,
        "bins": [plan.bins.n_theta, plan.bins.n_phi],
        "realisations": plan.realisations,
        **tally_settings(sc),
        "surface_scale": plan.effort.scale_for(sc.surface.kind),
        "effort": asdict(plan.effort),
    }


def remaining_rays(plan: RunPlan, prev) -> np.ndarray:
    """(R, T) rays each (realisation, incidence) still has to trace when ``prev`` (a Result
    of the plan's first k ≤ R realisations, or None) is continued."""
    n = plan.realisations
    per_real = np.array([plan.rays // n + (r < plan.rays % n) for r in range(n)], dtype=np.int64)
    todo = np.repeat(per_real[:, None], len(plan.incidences[0]), axis=1)
    if prev is not None and prev.tallies is not None and "rays" in prev.tallies:
        done = np.asarray(prev.tallies["rays"], dtype=np.int64).reshape(-1, todo.shape[1])
        todo[: len(done)] -= done
    return np.maximum(todo, 0)


def pilot_continues(pilot_plan: RunPlan, plan: RunPlan) -> bool:
    """Whether the chosen plan can continue its pilot's tallies (``simulate``'s resume of a
    prefix of realisations): the pilot's rays divide evenly among its realisations, so each
    of them is exactly realisation r of the chosen run."""
    k = pilot_plan.realisations
    return pilot_plan.rays % k == 0 and plan.rays == (pilot_plan.rays // k) * plan.realisations


def choose_realisations(plan: RunPlan, pilot) -> RunPlan:
    """The plan of a ``realisations = "auto"`` scene after its pilot (``pilot``: the complete
    result of ``plan``, ``budget.MIN_AUTO`` realisations): as many realisations as bring every
    incidence's tile scatter below ``plan.realisation_target`` (``budget.realisations_needed``,
    at most ``plan.effort.max_realisations``), each traced with the pilot's rays per
    realisation. Realisations 0 … pilot−1 of the new plan are the pilot's (same surfaces, same
    ray streams): the runner continues the pilot's tallies (``pilot_continues``) rather than
    tracing them again, and the chosen run is exactly ``simulate`` with that count."""
    need = realisations_needed(error_budget(pilot), plan.realisation_target)
    n = max(plan.realisations, min(need, plan.effort.max_realisations))
    return replace(plan, realisations=n, rays=(plan.rays // plan.realisations) * n, previous=None)


def realisations_record(plan: RunPlan, pilot_plan: RunPlan, pilot, stage: str) -> dict:
    """``meta["run"]["realisations_auto"]``: the target, the pilot (realisations, rays per
    incidence, error budget, seconds, whether the chosen run continued its tallies), and the
    realisations and rays chosen (``stage`` "pilot" while the pilot is unfinished, then
    "final")."""
    return {
        "stage": stage,
        "target": plan.realisation_target,
        "max_realisations": plan.effort.max_realisations,
        "pilot_realisations": pilot_plan.realisations,
        "pilot_rays": pilot_plan.rays,
        "pilot_budget": error_budget(pilot) if pilot is not None else None,
        "pilot_seconds": pilot.meta.get("seconds") if pilot is not None else None,
        "pilot_continued": pilot is not None and pilot_continues(pilot_plan, plan),
        "realisations": plan.realisations,
        "rays": plan.rays,
    }
