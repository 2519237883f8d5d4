"""Anisotropic Beckmann and GGX normal distributions with an in-plane rotation, their exact
Smith Λ, and the isotropic stand-in renderers use.

Frame: the NDF's own axes are the surface's x and y axes rotated by ``rotation`` degrees
(counter-clockwise about n = +z); a direction w of the surface frame has w' = R(−rotation) w
there. Slopes of a facet h are (x̃, ỹ) = (−h'x/h'z, −h'y/h'z), and with the stretched slope
radius ρ² = x̃²/αx² + ỹ²/αy² (Heitz 2014; the αx, αy of pbrt-v4 and Mitsuba 3):

    Beckmann  D(h) = exp(−ρ²) / (π αx αy cos⁴θ_h)
    GGX       D(h) = 1 / (π αx αy cos⁴θ_h (1 + ρ²)²)

both normalised as every microsim NDF, ∫ D(h) cos θ_h dω = 1 (Mikkelsen 2009, eq. 14), and
equal to ``Beckmann(m = α)`` / ``GGX(α)`` when αx = αy = α. The slope distribution is the
isotropic one with unit roughness stretched by (αx, αy), so samples of D(h) cos θ_h are the
stretched samples of the unit one (``sample``).

Tilt distribution (``cdf_theta_rad``, ``tilt_pdf_rad``, the isotropic NDFs' interface): a
stretched slope is (αx ρ cos φ, αy ρ sin φ) with the unit slope radius ρ independent of the
uniform φ, so tan²θ_h = ρ² α(φ)², α(φ)² = αx² cos²φ + αy² sin²φ, and

    P(θ_h ≤ θ) = ⟨F(tan²θ / α(φ)²)⟩_φ,   F the CDF of ρ² (Beckmann 1 − e^{−x}, GGX x/(1 + x)),

whose θ-derivative has the profile above as the density of ρ². The azimuth average is the
trapezoid rule over the period (exponentially accurate for this smooth periodic integrand).

Smith Λ (Heitz 2014): the isotropic Λ of the same family with α replaced by the roughness the
direction sees,

    α(φ'_w) = √(αx² cos²φ'_w + αy² sin²φ'_w),   a = 1/(α(φ'_w) tan θ_w).

Derivation (re-derived here): Smith's Λ(w) depends on the slope distribution only through the
1-D distribution of the slope component along w's azimuth, s = x̃ cos φ'_w + ỹ sin φ'_w. For a
distribution stretched from a unit isotropic one, s = αx u cos φ'_w + αy v sin φ'_w with (u, v)
unit-isotropic, which is distributed as α(φ'_w) times the unit 1-D marginal; Λ of the
isotropic family at roughness α(φ'_w) follows. tests/test_anisotropic.py checks it against the
projected-area identity by quadrature. Renderers often use Λ with α = √(αx αy)
instead (MaterialX; ``isotropic_equivalent``): equal at φ'_w where α(φ'_w)² = αx αy only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from microsim import checks as _checks
from microsim import vectors
from microsim.errors import UsageError

from .ndf import (
    GGX,
    NDF,
    Beckmann,
    _check_lambda_method,
    _cos_array,
    _sin2,
    _tilt_rad,
    _unit_interval,
    beckmann_lambda,
    ggx_lambda,
)

__all__ = ["AnisotropicBeckmann", "AnisotropicGGX"]

AZIMUTH_NODES = 512
"""Trapezoid nodes over the period of the azimuth averages of the tilt distribution."""


class AnisotropicNDF(NDF):
    """The stretched (αx, αy, rotation) family of the ``NDF`` protocol: shared frame, slopes,
    projected roughness, Λ and visible normals; subclasses set the family (``_profile``,
    ``_rho2_cdf``, ``_rho_quantile``, ``_lambda``, ``isotropic_at``)."""

    isotropic = False
    has_closed_smith = True
    has_visible_sampler = True
    alpha_x: float
    alpha_y: float
    rotation: float

    def _check(self) -> None:
        object.__setattr__(self, "alpha_x", _checks.positive("alpha_x", self.alpha_x))
        object.__setattr__(self, "alpha_y", _checks.positive("alpha_y", self.alpha_y))
        object.__setattr__(self, "rotation", _checks.finite("rotation", self.rotation))

    def params(self) -> dict:
        return {"alpha_x": self.alpha_x, "alpha_y": self.alpha_y, "rotation": self.rotation}

    def _to_local(self, w: np.ndarray) -> np.ndarray:
        """``w`` (..., 3) in the NDF's frame: rotated by −``rotation`` about z."""
        c, s = np.cos(np.radians(self.rotation)), np.sin(np.radians(self.rotation))
        x, y = w[..., 0], w[..., 1]
        return np.stack([c * x + s * y, -s * x + c * y, w[..., 2]], axis=-1)

    def _from_local(self, w: np.ndarray) -> np.ndarray:
        c, s = np.cos(np.radians(self.rotation)), np.sin(np.radians(self.rotation))
        x, y = w[..., 0], w[..., 1]
        return np.stack([c * x - s * y, s * x + c * y, w[..., 2]], axis=-1)

    def _rho2(self, h: np.ndarray):
        """(ρ², cos θ_h) of unit half vectors in the surface frame (ρ² = 0 where h_z ≤ 0)."""
        hl = self._to_local(h)
        hz = hl[..., 2]
        safe = np.where(hz > 0.0, hz, 1.0)
        rho2 = (hl[..., 0] / (self.alpha_x * safe)) ** 2 + (hl[..., 1] / (self.alpha_y * safe)) ** 2
        return rho2, hz

    def D(self, h):
        """D(h) in sr⁻¹ for unit half vectors (..., 3) in the surface frame; 0 for h_z ≤ 0."""
        h = _checks.directions("h", h)
        rho2, hz = self._rho2(h)
        with np.errstate(over="ignore", invalid="ignore"):
            d = self._profile(rho2) / (np.pi * self.alpha_x * self.alpha_y * hz**4)
        return np.where(hz > 0.0, d, 0.0)

    def D_cos(self, cos_theta):
        """Azimuthal average of D at cos θ_h in sr⁻¹ (trapezoid rule over ``AZIMUTH_NODES``
        facet azimuths); 0 for cos θ_h ≤ 0."""
        c = np.minimum(_cos_array(cos_theta), 1.0)
        pos = c > 0.0
        cs = np.where(pos, c, 1.0)[..., None]
        phi = 2.0 * np.pi * np.arange(AZIMUTH_NODES) / AZIMUTH_NODES
        s = np.sqrt(_sin2(cs))
        h = np.stack(np.broadcast_arrays(s * np.cos(phi), s * np.sin(phi), cs), axis=-1)
        return np.where(pos, self.D(h).mean(axis=-1), 0.0)

    def _stretch2(self, theta):
        """(tan²θ / α(φ)², 1 / α(φ)²) on the azimuth nodes (last axis) for tilts θ (radians),
        with α(φ)² = αx² cos²φ + αy² sin²φ (module docstring)."""
        phi = 2.0 * np.pi * np.arange(AZIMUTH_NODES) / AZIMUTH_NODES
        inv_a2 = 1.0 / (self.alpha_x**2 * np.cos(phi) ** 2 + self.alpha_y**2 * np.sin(phi) ** 2)
        t2 = np.tan(np.clip(theta, 0.0, 0.5 * np.pi))[..., None] ** 2
        return t2 * inv_a2, inv_a2

    def cdf_theta_rad(self, theta):
        """P(θ_h ≤ θ) of the tilt under D(h) cos θ_h, θ in radians in [0, π/2] (UsageError
        outside): the azimuth average of the CDF of ρ² (module docstring)."""
        x, _ = self._stretch2(_tilt_rad("theta", theta))
        with np.errstate(divide="ignore", over="ignore"):
            return self._rho2_cdf(x).mean(axis=-1)

    def tilt_pdf_rad(self, theta):
        """Density of the tilt θ_h in radians⁻¹ at θ in radians in [0, π/2], the θ-derivative of
        ``cdf_theta_rad``: 2 tanθ / cos²θ · ⟨profile(tan²θ / α²) / α²⟩_φ, equal to
        ∫ D(θ, φ_h) cos θ sin θ dφ_h."""
        theta = _tilt_rad("theta", theta)
        x, inv_a2 = self._stretch2(theta)
        c = np.cos(np.clip(theta, 0.0, 0.5 * np.pi))
        with np.errstate(over="ignore"):
            mean = (self._profile(x) * inv_a2).mean(axis=-1)
            return 2.0 * np.sqrt(np.maximum(1.0 - c * c, 0.0)) / c**3 * mean

    def tilt_quantile_rad(self, u):
        """θ_h (radians) with ``cdf_theta_rad(θ_h)`` = u ∈ [0, 1], by bisection to ~1e-16 rad."""
        u = _unit_interval(u)
        lo, hi = np.zeros_like(u), np.full_like(u, 0.5 * np.pi)
        for _ in range(54):
            mid = 0.5 * (lo + hi)
            below = self.cdf_theta_rad(mid) < u
            lo, hi = np.where(below, mid, lo), np.where(below, hi, mid)
        return 0.5 * (lo + hi)

    def pdf(self, h):
        """Solid-angle density D(h) cos θ_h of ``sample`` (sr⁻¹)."""
        h = _checks.directions("h", h)
        return self.D(h) * np.maximum(h[..., 2], 0.0)

    def sample(self, u1, u2):
        """Unit half vectors h ~ D(h) cos θ_h from uniforms in [0, 1): the unit-roughness
        slope radius ρ from ``u1`` (``_rho_quantile``), φ = 2π u2, slopes stretched by
        (αx, αy), rotated into the surface frame."""
        _checks.broadcast({}, {"u1": u1, "u2": u2})
        u1, u2 = np.broadcast_arrays(np.asarray(u1, float), np.asarray(u2, float))
        rho = self._rho_quantile(np.clip(u1, 0.0, 1.0))
        phi = 2.0 * np.pi * u2
        sx, sy = self.alpha_x * rho * np.cos(phi), self.alpha_y * rho * np.sin(phi)
        h = vectors.normalize(np.stack([-sx, -sy, np.ones_like(sx)], axis=-1))
        return self._from_local(h)

    def projected_alpha(self, w):
        """α(φ'_w) = √(αx² cos²φ'_w + αy² sin²φ'_w): the roughness direction ``w`` sees."""
        wl = self._to_local(np.asarray(w, dtype=np.float64))
        r2 = wl[..., 0] ** 2 + wl[..., 1] ** 2
        safe = np.where(r2 > 0.0, r2, 1.0)
        a2 = (self.alpha_x**2 * wl[..., 0] ** 2 + self.alpha_y**2 * wl[..., 1] ** 2) / safe
        return np.sqrt(np.where(r2 > 0.0, a2, self.alpha_x * self.alpha_y))

    def smith_lambda_w(self, w):
        """Exact Smith Λ(w) (module docstring) for unit w of the upper hemisphere; +inf at
        θ_w = 90°, 0 at the normal."""
        w = np.asarray(w, dtype=np.float64)
        return self._lambda(np.clip(w[..., 2], 0.0, 1.0), self.projected_alpha(w))

    def smith_lambda_cos(self, cos_theta):
        """Not defined: an anisotropic Λ depends on the azimuth too (``smith_lambda(w)``)."""
        raise UsageError(
            f"{type(self).__name__}'s Smith Λ depends on the azimuth: use smith_lambda(w)"
        )

    def _smith_lambda(self, w, method: str = "auto"):
        """Λ(w) for unit w (no validation) by the closed form; inf at cos θ_w ≤ 0."""
        _check_lambda_method(method)
        if method == "numerical":
            raise UsageError(
                f"method='numerical' is not available for {type(self).__name__} (its Λ is "
                f"exact in closed form; use 'auto' or 'closed')"
            )
        return np.where(w[..., 2] > 0.0, self.smith_lambda_w(w), np.inf)

    def _sample_visible(self, v, u1, u2):
        """Visible normals m ~ D_v(m) = ⟨v, m⟩⁺ D(m) / ((1 + Λ(v)) cos θ_v) for unit view
        directions v (N, 3) and uniforms u1, u2 (N,): by the stretch to unit roughness —
        v' = normalize(αx v'x, αy v'y, v'z) in the NDF's frame, m' sampled from the unit
        isotropic NDF seen from v' (its ``sample_visible``: Heitz 2018 for GGX, Heitz &
        d'Eon 2014 for Beckmann), m = normalize(αx m'x, αy m'y, m'z) — valid
        because slopes scale by (αx, αy) under the stretch (as pbrt-v4's ``Sample_wm``), and
        ⟨v, m⟩ is a linear form in the slopes that the stretch carries to ⟨v', m'⟩. That holds
        for views below the horizon too (not straight down), where the normaliser is
        Λ(−v)|v_z| (``random_walk.visible_projected_area``): what a ray going up after a
        bounce sees in the random walk. Density (upper hemisphere): ``pdf_visible``."""
        vl = self._to_local(v)
        stretched = vectors.normalize(
            np.stack([self.alpha_x * vl[..., 0], self.alpha_y * vl[..., 1], vl[..., 2]], -1)
        )
        m = self.isotropic_at(1.0)._sample_visible(stretched, u1, u2)
        ml = vectors.normalize(
            np.stack([self.alpha_x * m[..., 0], self.alpha_y * m[..., 1], m[..., 2]], -1)
        )
        return self._from_local(ml)

    def isotropic_equivalent(self):
        """The isotropic NDF of the same family with α = √(αx αy) (the stand-in MaterialX
        uses for the anisotropic Smith G)."""
        return self.isotropic_at(float(np.sqrt(self.alpha_x * self.alpha_y)))


@dataclass(frozen=True, repr=False)
class AnisotropicBeckmann(AnisotropicNDF):
    """Anisotropic Beckmann NDF (module docstring): roughness ``alpha_x``, ``alpha_y`` > 0 along
    its axes, ``rotation`` of its x axis in degrees. Equals ``Beckmann(m=α)`` when αx = αy = α
    (for a Gaussian heightfield the per-axis slope variances are αx²/2, αy²/2)."""

    alpha_x: float
    alpha_y: float
    rotation: float = 0.0
    name = "beckmann-anisotropic"

    def __post_init__(self):
        self._check()

    @staticmethod
    def _profile(rho2):
        return np.exp(-rho2)

    @staticmethod
    def _rho2_cdf(x):
        return -np.expm1(-x)

    @staticmethod
    def _rho_quantile(u):
        with np.errstate(divide="ignore"):
            return np.sqrt(-np.log1p(-u))

    @staticmethod
    def _lambda(cos_w, alpha):
        return beckmann_lambda(cos_w, alpha)

    @staticmethod
    def isotropic_at(alpha):
        """The isotropic Beckmann NDF of roughness ``alpha`` (m = α)."""
        return Beckmann(alpha)


@dataclass(frozen=True, repr=False)
class AnisotropicGGX(AnisotropicNDF):
    """Anisotropic GGX (Trowbridge–Reitz) NDF (module docstring): ``alpha_x``, ``alpha_y`` > 0,
    ``rotation`` in degrees; equals ``GGX(α)`` when αx = αy = α."""

    alpha_x: float
    alpha_y: float
    rotation: float = 0.0
    name = "ggx-anisotropic"

    def __post_init__(self):
        self._check()

    @staticmethod
    def _profile(rho2):
        return 1.0 / (1.0 + rho2) ** 2

    @staticmethod
    def _rho2_cdf(x):
        return 1.0 / (1.0 + 1.0 / x)

    @staticmethod
    def _rho_quantile(u):
        with np.errstate(divide="ignore"):
            return np.sqrt(u / (1.0 - u))

    @staticmethod
    def _lambda(cos_w, alpha):
        return ggx_lambda(cos_w, alpha)

    @staticmethod
    def isotropic_at(alpha):
        """The isotropic GGX NDF of roughness ``alpha``."""
        return GGX(alpha)
