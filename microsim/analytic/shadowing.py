"""Shadowing–masking functions G: V-groove (Mikkelsen 2009, eq. 25) and Smith (Smith 1967;
Heitz 2014; docs/design.md, "Shadowing and Fresnel").

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

from microsim import checks as _checks
from microsim import vectors
from microsim.errors import UsageError

__all__ = [
    "vgroove_g",
    "vgroove_g1",
    "smith_lambda",
    "smith_g1",
    "smith_g2",
    "shadowing_g",
    "SHADOWING_KINDS",
]

SHADOWING_KINDS = ("vgroove", "smith", "smith-correlated", "none")
"""Allowed values of the ``shadowing`` argument."""


# --- V-groove (Blinn / Cook–Torrance) ---------------------------------------------------------
def _vgroove_g1(cos_w, w_dot_h, cos_h):
    """min(1, 2(n·h)(n·w)/(w·h)) χ⁺(w·h) χ⁺(n·w) from the three cosines (Mikkelsen 2009, eq. 25)."""
    ok = (w_dot_h > 0.0) & (cos_w > 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = 2.0 * cos_h * cos_w / w_dot_h
    return np.where(ok, np.clip(ratio, 0.0, 1.0), 0.0)


def vgroove_g1(w, h):
    """One-sided V-groove masking min(1, 2(n·h)(n·w)/(w·h)) χ⁺(w·h) (Mikkelsen 2009, eq. 25)."""
    w = _checks.directions("w", w)
    h = _checks.directions("h", h)
    _checks.broadcast({"w": w, "h": h})
    return _vgroove_g1(w[..., 2], vectors.dot(w, h), h[..., 2])


def vgroove_g(wi, wo, h):
    """V-groove shadowing–masking min(1, 2(n·h)(n·wo)/(wo·h), 2(n·h)(n·wi)/(wi·h)) with χ⁺
    conditions (Mikkelsen 2009, eq. 25, Blinn 1977); 0 where wi·h ≤ 0 or wo·h ≤ 0."""
    wi = _checks.directions("wi", wi)
    wo = _checks.directions("wo", wo)
    h = _checks.directions("h", h)
    _checks.broadcast({"wi": wi, "wo": wo, "h": h})
    hz = h[..., 2]
    return np.minimum(
        _vgroove_g1(wi[..., 2], vectors.dot(wi, h), hz),
        _vgroove_g1(wo[..., 2], vectors.dot(wo, h), hz),
    )


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


def _smith_g2(ndf, wi, wo, wih, woh, correlated: bool):
    """Smith G2 on validated unit arrays from the precomputed wi·h, wo·h."""
    return ndf.smith_g2_dots(wi, wo, wih, woh, correlated)


def smith_g2(wi, wo, h, ndf, correlated: bool = False):
    """Smith shadowing–masking: separable G1(wi)G1(wo), or height-correlated
    χ⁺(wi·h)χ⁺(wo·h)/(1 + Λ(wi) + Λ(wo)) when ``correlated``: ``ndf.G2(wi, wo, h, correlated)``."""
    return ndf.G2(wi, wo, h, correlated)


def _check_kind(kind) -> str:
    if kind not in SHADOWING_KINDS:
        raise UsageError(
            f"shadowing must be one of {', '.join(map(repr, SHADOWING_KINDS))}, got {kind!r}"
        )
    return kind


def _shadowing(kind: str, ndf, wi, wo, cos_h, wih, woh):
    """G for validated unit arrays from h_z and the precomputed wi·h, wo·h (used by the BRDFs)."""
    if kind == "vgroove":
        return np.minimum(_vgroove_g1(wi[..., 2], wih, cos_h), _vgroove_g1(wo[..., 2], woh, cos_h))
    if kind == "none":
        return ((wih > 0.0) & (woh > 0.0)).astype(np.float64)
    return _smith_g2(ndf, wi, wo, wih, woh, correlated=(kind == "smith-correlated"))


def shadowing_g(wi, wo, h, ndf, shadowing: str):
    """G(wi, wo, h) of the model named by ``shadowing``: "vgroove" (Mikkelsen 2009, eq. 25),
    "smith" (separable), "smith-correlated" (height-correlated) or "none" (χ⁺(wi·h)χ⁺(wo·h)
    only); ``ndf`` is used by the Smith models only."""
    kind = _check_kind(shadowing)
    wi = _checks.directions("wi", wi)
    wo = _checks.directions("wo", wo)
    h = _checks.directions("h", h)
    _checks.broadcast({"wi": wi, "wo": wo, "h": h})
    return _shadowing(kind, ndf, wi, wo, h[..., 2], vectors.dot(wi, h), vectors.dot(wo, h))
