"""Wave optics on the explicit surfaces: scalar Kirchhoff (tangent-plane) scattering by a
periodic heightfield tile, far field on the tile's reciprocal lattice (``kirchhoff``), and the
order powers as the bin-averaged BRDF ``Result`` (``brdf``).

Layer: "wave", between sim and analysis (imports core, analytic and sim.bins/paths/result)."""

from .brdf import bin_orders, kirchhoff_brdf
from .kirchhoff import Orders, direct_orders, kirchhoff_orders, obliquity, order_directions

__all__ = [
    "kirchhoff_brdf",
    "bin_orders",
    "Orders",
    "kirchhoff_orders",
    "direct_orders",
    "order_directions",
    "obliquity",
]
