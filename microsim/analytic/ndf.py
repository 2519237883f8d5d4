"""Microfacet normal distributions (NDFs).

Convention (Mikkelsen eq. 14): an NDF D(h) is normalised so that ∫ D(h) (h·n) dω_h = 1 over the
upper hemisphere, n = +z. ``pdf(h) = D(h) (h·n)`` is then a probability density in solid angle,
and ``sample(u1, u2)`` draws unit half vectors h from it by inverting the CDF of the tilt
θ_h (density 2π D(θ) cosθ sinθ) and taking φ_h = 2π u2.

All isotropic NDFs implement two things: the radial profile ``D_cos(cos θ_h)`` and the tilt
quantile ``tilt_quantile(u)`` (inverse CDF of θ_h). Everything else follows in this base class.
"""
from __future__ import annotations

import numpy as np

from . import _checks

__all__ = ["NDF"]


class NDF:
    """Base class of an isotropic microfacet normal distribution.

    Subclasses set ``name`` and implement ``D_cos``, ``tilt_quantile`` and ``params``.
    Those with a closed-form Smith Λ set ``has_closed_smith = True`` and implement
    ``smith_lambda_cos``; for the others the shadowing module integrates the
    projected-area identity numerically.
    """

    name: str = "ndf"
    isotropic: bool = True
    has_closed_smith: bool = False

    # --- to implement -------------------------------------------------------------------
    def params(self) -> dict:
        """Parameters as a name → value dict (for reports and meta.json)."""
        raise NotImplementedError

    def D_cos(self, cos_theta):
        """D as a function of cos θ_h (sr⁻¹); 0 for cos θ_h ≤ 0; finite at cos θ_h = 1 and 0."""
        raise NotImplementedError

    def tilt_quantile(self, u):
        """θ_h (radians) at cumulative probability u ∈ [0, 1] of the tilt density 2πD cosθ sinθ."""
        raise NotImplementedError

    def smith_lambda_cos(self, cos_theta):
        """Smith Λ(w) as a function of cos θ_w (only when ``has_closed_smith``)."""
        raise NotImplementedError

    # --- derived ------------------------------------------------------------------------
    def D(self, h):
        """D(h) in sr⁻¹ for unit half vectors h of shape (..., 3); 0 below the horizon."""
        h = _checks.directions("h", h)
        return self.D_cos(h[..., 2])

    def pdf(self, h):
        """Solid-angle density of sampled half vectors, D(h)(h·n) (Mikkelsen eq. 14)."""
        h = _checks.directions("h", h)
        c = h[..., 2]
        return self.D_cos(c) * np.maximum(c, 0.0)

    def tilt_pdf(self, theta):
        """Density of the tilt angle θ_h in radians⁻¹: 2π D(θ) cos θ sin θ."""
        theta = np.asarray(theta, dtype=np.float64)
        return 2.0 * np.pi * self.D_cos(np.cos(theta)) * np.cos(theta) * np.sin(theta)

    def sample(self, u1, u2):
        """Unit half vectors h ~ pdf from uniform numbers u1, u2 ∈ [0, 1) (inverse CDF)."""
        u1, u2 = np.broadcast_arrays(np.asarray(u1, float), np.asarray(u2, float))
        theta = self.tilt_quantile(u1)
        return _checks.spherical(theta, 2.0 * np.pi * u2)

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self.params().items())
        return f"{type(self).__name__}({args})"
