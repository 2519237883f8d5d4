"""Tracing a planned scene: the main run, a ``rays = "auto"`` run and the side studies' runs
(``simulate_scene``), and the run's description in ``meta.json``.

Random surfaces are averaged over the scene's realisations; realisation r is built with seed
``seed + r``. Callers reach ``simulate_scene`` through this module (``tracing.simulate_scene``)
so that one replacement (tests) covers every run.
"""

from __future__ import annotations

from dataclasses import asdict

import numpy as np

from ..sim import simulate
from ..sim.auto import simulate_auto
from .planning import AUTO_TARGET, RunPlan

__all__ = [
    "surface_source",
    "simulate_scene",
    "complete",
    "simulate_auto_scene",
    "auto_summary",
    "run_meta",
    "remaining_rays",
]


def surface_source(scene, seed: int, scale: float):
    """(surface, realisations) arguments of ``simulate`` for the scene."""
    n = scene.simulation.realisations
    if n == 1:
        return scene.build_surface(seed=seed, scale=scale), None
    return None, (lambda s: scene.build_surface(seed=s, scale=scale), [seed + r for r in range(n)])


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
):
    """``simulate`` the plan's scene at ``theta_i`` (degrees) with ``rays`` per incidence;
    ``realisations=False``: one surface (seed ``seed``) whatever the scene's realisations."""
    sc = plan.scene
    scale = plan.effort.scale_for(sc.surface.kind)
    if realisations:
        surface, reals = surface_source(sc, seed, scale)
    else:
        surface, reals = sc.build_surface(seed=seed, scale=scale), None
    factory, seeds = reals if reals is not None else (None, None)
    return simulate(
        surface,
        sc.ior,
        list(theta_i),
        rays=rays,
        bins=bins,
        seed=seed,
        threads=plan.threads,
        surface_factory=factory,
        seeds=seeds,
        progress=progress,
        origins=origins,
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
    surface = sc.build_surface(seed=plan.seed, scale=plan.effort.scale_for(sc.surface.kind))
    return simulate_auto(
        surface,
        sc.ior,
        list(plan.theta_i),
        target=AUTO_TARGET,
        bins=plan.bins,
        seed=plan.seed,
        threads=plan.threads,
        max_rays=plan.rays,
        progress=log,
    )


def auto_summary(result) -> dict | None:
    """Rays, seconds, achieved rse and convergence per incidence of an auto run (or None)."""
    auto = result.meta.get("auto")
    if not auto:
        return None
    keys = ("theta_i", "rays", "seconds", "rse", "converged", "batches")
    return {
        "target": auto["target"],
        "seconds": float(result.meta.get("seconds", 0.0)),
        "incidences": [{k: d[k] for k in keys} for d in auto["incidences"]],
    }


def run_meta(plan: RunPlan) -> dict:
    """``meta["run"]``: the settings a ``--resume`` must match (``planning``) and the effort."""
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
        "realisations": sc.simulation.realisations,
        "surface_scale": plan.effort.scale_for(sc.surface.kind),
        "effort": asdict(plan.effort),
    }


def remaining_rays(plan: RunPlan) -> np.ndarray:
    """(R, T) rays each (realisation, incidence) still has to trace."""
    n = plan.scene.simulation.realisations
    per_real = np.array([plan.rays // n + (r < plan.rays % n) for r in range(n)], dtype=np.int64)
    todo = np.repeat(per_real[:, None], len(plan.theta_i), axis=1)
    prev = plan.previous
    if prev is not None and prev.tallies is not None and "rays" in prev.tallies:
        todo = todo - np.asarray(prev.tallies["rays"], dtype=np.int64).reshape(todo.shape)
    return np.maximum(todo, 0)
