"""Rough glass: the second half of a run through a dielectric interface (scene ``[material]
transmission``) and its study (``analysis.glass``; verdicts.json ``"glass"``, report "Rough
glass").

The main run lights the surface from the air at the scene's θi; this module traces the same
surface lit from inside the medium at the same angles from the inward pole (θi' = 180° − θi,
the same rays, seed, bins and realisations), saved beside the main result in ``INSIDE_DIR``.
The models use the microsurface distribution of the orders study (``orders.walk_ndf``: the
realised Beckmann of a heightfield's tiles, or the scene's distribution), else the scene's.
"""

from __future__ import annotations

from ...analysis.glass import glass_study
from ...analysis.study_records import GlassStudy
from ...checkpoints import checkpoint
from . import tracing
from .orders import WALK_PATHS, walk_ndf

__all__ = ["INSIDE_DIR", "trace_inside", "rough_glass"]

INSIDE_DIR = "inside"
"""The folder of a glass run's result lit from inside the medium (brdf.npz, meta.json)."""


def trace_inside(plan):
    """The scene lit from inside the medium (module docstring): a complete ``Result``, or
    ``KeyboardInterrupt`` when it was cut short (``tracing.complete``)."""
    checkpoint("side-studies")
    theta_i, phi_i = plan.incidences
    return tracing.complete(
        tracing.simulate_scene(
            plan,
            [180.0 - t for t in theta_i],
            plan.rays,
            plan.seed,
            plan.bins,
            bounces=plan.scene.simulation.bounces,
            phi_i=phi_i,
        )
    )


def rough_glass(plan, above, inside, specs) -> tuple[GlassStudy, dict]:
    """The ``"glass"`` study of the runs ``above`` and ``inside`` (``analysis.glass``), the
    random walk with ``orders.WALK_PATHS`` paths per incidence, and its models' bin averages
    (``glass_study``'s ``predictions``, for the chart)."""
    checkpoint("side-studies")
    ndf = walk_ndf(plan, specs) or plan.scene.ndf()
    eta = float(plan.scene.ior.real)
    paths, predictions = WALK_PATHS[bool(plan.quick)], {}
    study = glass_study(
        above, inside, ndf, eta, INSIDE_DIR, walk_paths=paths, seed=plan.seed,
        predictions=predictions,
    )  # fmt: skip
    return study, predictions
