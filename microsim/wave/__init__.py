"""Wave optics on the explicit surfaces: scalar Kirchhoff (tangent-plane) scattering by a
periodic heightfield tile, far field on the tile's reciprocal lattice (``kirchhoff``).

Layer: "wave", between sim and analysis (imports core and analytic only)."""

from .kirchhoff import Orders, direct_orders, kirchhoff_orders, obliquity, order_directions

__all__ = ["Orders", "kirchhoff_orders", "direct_orders", "order_directions", "obliquity"]
