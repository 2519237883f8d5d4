"""Smith shadowing–masking G (Smith 1967; Heitz 2014; docs/design.md, "Shadowing and Fresnel");
the V-groove G (Mikkelsen 2009, eq. 25) and the ``shadowing``-string functions are in ``masking``.

Directions are unit (..., 3) arrays pointing away from the surface, macro normal n = +z; every
function takes its directions first, ``(wi, wo, h, ...)`` or ``(w, h, ...)``, then the NDF.
Every G here is dimensionless in [0, 1], finite everywhere (also h = n and θ = 90°), and 0 for
a direction at or below the horizon (the macro surface itself blocks it) or on the back of the
facet (χ⁺(w·h) = 0).

Both families satisfy the projected-area identity ∫ G1(w, h)(w·h)⁺ D(h) dω_h = cos θ_w: Smith by
construction of Λ, the V-groove because a groove pairs h with its mirror image (−h_x, −h_y, h_z)
and for such a pair min(w·h, 2h_z w_z)⁺ + min(w·h', 2h_z w_z)⁺ = 2 h_z w_z (w·h + w·h' = 2h_z w_z),
so the identity holds for every centrally symmetric D, in particular every isotropic one.

The Smith functions are thin wrappers: every distribution owns its Λ, G1 and G2
(``microsim.analytic.ndf.NDF``; the numerical Λ of those without a closed form is in ``smith``).
"""

from __future__ import annotations

import numpy as np

__all__ = ["smith_lambda", "smith_g1", "smith_g2"]


# --- Smith: thin wrappers over the distribution's own Λ, G1 and G2 ----------------------------
def _tilt_breakpoints(ndf) -> np.ndarray:
    """θ_h panels of the quadratures over a distribution: ``ndf.tilt_breakpoints_rad()``."""
    return ndf.tilt_breakpoints_rad()


def smith_lambda(w, ndf, method: str = "auto"):
    """Smith Λ(w) (dimensionless, ≥ 0; inf at θ_w = 90°) for upper-hemisphere unit w:
    ``ndf.smith_lambda(w, method)`` (``method``: "auto", "closed" or "numerical")."""
    return ndf.smith_lambda(w, method)


def smith_g1(w, h, ndf):
    """Smith masking G1(w, h) = χ⁺(w·h)/(1 + Λ(w)) (Smith 1967; Heitz 2014; docs/design.md,
    "Shadowing and Fresnel"): ``ndf.G1(w, h)``."""
    return ndf.G1(w, h)


def smith_g2(wi, wo, h, ndf, correlated: bool = False):
    """Smith shadowing–masking: separable G1(wi)G1(wo), or height-correlated
    χ⁺(wi·h)χ⁺(wo·h)/(1 + Λ(wi) + Λ(wo)) when ``correlated``: ``ndf.G2(wi, wo, h, correlated)``."""
    return ndf.G2(wi, wo, h, correlated)
