"""Wave optics on the explicit surfaces: scalar Kirchhoff (tangent-plane) scattering by a
periodic heightfield tile, far field on the tile's reciprocal lattice, on the smooth
interpolant of the heights or on the ray tracer's triangle mesh (``kirchhoff``) and the order
powers as the bin-averaged BRDF ``Result`` (``brdf``). The solver's timing for
``microsim bench`` is ``microsim.app.wave_bench``.

Layer: "wave", between sim and analysis (imports core, analytic and sim.paths/result)."""

from .brdf import bin_orders, kirchhoff_brdf
from .kirchhoff import (
    Orders,
    direct_orders,
    incident_direction,
    kirchhoff_orders,
    mesh_direct_orders,
    obliquity,
    order_directions,
    reflectance,
    triangle_rule,
)

__all__ = [
    "kirchhoff_brdf",
    "bin_orders",
    "Orders",
    "kirchhoff_orders",
    "direct_orders",
    "order_directions",
    "obliquity",
    "mesh_direct_orders",
    "triangle_rule",
    "incident_direction",
    "reflectance",
]
