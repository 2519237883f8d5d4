"""Scattering orders of a run traced with ``bounces`` > 1 (scene ``[simulation] bounces``): how
much light single scattering misses, and the order-resolved comparison with Heitz et al.'s
random walk, Kulla–Conty and Mikkelsen eq. 28 (``analysis.multiple``).

The verdicts of the run keep judging order 1 (``Result.brdf``), as without bounces. The
walk needs a Smith microsurface NDF: for Gaussian/ABC heightfields Beckmann at the realised
slope of the traced tiles (the ``ts-beckmann-realised-*`` models' m; the anisotropic Beckmann
at the realised αx, αy for anisotropic fields), for V-grooves the scene's NDF when it is
Beckmann or GGX; otherwise only the order energies are reported.
"""

from __future__ import annotations

from ...analysis.multiple import needs_more_bounces, order_comparison
from ...analysis.study_records import OrdersStudy
from ...analytic.random_walk import WALK_NDFS, WalkNDF
from ...checkpoints import checkpoint
from ...errors import UsageError

__all__ = ["WALK_PATHS", "walk_ndf", "orders_study"]

WALK_PATHS = {False: 1_000_000, True: 200_000}
"""Random-walk paths per θi: full runs, ``--quick``."""


def walk_ndf(plan, specs):
    """The Smith microsurface NDF of the scene for the walk (module docstring), or None."""
    for s in specs:
        if s.name.startswith("ts-beckmann-realised"):
            return s.model.ndf
    ndf = plan.scene.ndf()
    try:
        return WalkNDF.of(ndf).ndf
    except UsageError:
        return None


def orders_study(plan, result, specs) -> OrdersStudy | None:
    """The ``"orders"`` study of verdicts.json (``OrdersStudy``) of a run with ``bounces`` > 1
    that reflects only (None otherwise; a dielectric interface's orders are in its "glass"
    study): ``needs_more_bounces`` per θi and the ``order_comparison`` (None, with a
    note saying why, when the scene's NDF has no walk)."""
    if getattr(result, "brdf_orders", None) is None or result.brdf_orders.shape[0] < 2:
        return None
    if result.btdf_orders is not None:  # a dielectric interface: the "glass" study's orders
        return None
    checkpoint("side-studies")
    ndf = walk_ndf(plan, specs)
    comparison, note = None, None
    if ndf is None:
        note = (
            f"the random walk needs a {' or '.join(WALK_NDFS)} "
            f"microsurface; this scene's NDF is {type(plan.scene.ndf()).__name__}: order "
            f"energies only"
        )
    else:
        try:
            comparison = order_comparison(
                result,
                plan.scene.ior,
                ndf,
                walk_paths=WALK_PATHS[bool(plan.quick)],
                seed=plan.seed,
            )
        except UsageError as e:  # e.g. no multiply scattered light at some θi to compare
            note = f"no order-resolved comparison: {e}"
    return OrdersStudy(
        bounces=plan.scene.simulation.bounces,
        needs=needs_more_bounces(result),
        comparison=comparison,
        note=note,
    )
