"""Microfacet normal distributions (NDFs).

Convention (Mikkelsen 2009, eq. 14): an NDF D(h) is normalised so that ∫ D(h) (h·n) dω_h = 1
over the upper hemisphere, n = +z. ``pdf(h) = D(h) (h·n)`` is then a probability density in
solid angle, and ``sample(u1, u2)`` draws unit half vectors h from it by inverting the CDF of
the tilt θ_h (density 2π D(θ) cosθ sinθ) and taking φ_h = 2π u2.

All isotropic NDFs implement three things: the radial profile ``D_cos(cos θ_h)``, the tilt
CDF ``_cdf_theta(θ)`` and its inverse ``tilt_quantile_rad(u)``. Everything else follows in this
base class. Tilt angles are in radians, and every method taking or returning one says so
(``cdf_theta_rad``, ``tilt_pdf_rad``, ``tilt_quantile_rad``); tilts outside [0, π/2] — say, a
value in degrees — raise a UsageError.

Visible normals (``sample_visible``, the phase function of the random walk): facet normals m
from D_v(m) = ⟨v, m⟩⁺ D(m) / ∫⟨v, m⟩⁺ D dm, for views v on either side of the horizon.

* GGX: Heitz 2018 ("Sampling the GGX distribution of visible normals", JCGT 7(4)): stretch v by
  α, sample the projected visible hemisphere uniformly (disk, warped by s = (1 + v_z)/2), lift to
  the hemisphere, unstretch. For v below the horizon the warped region is the half disk minus the
  half ellipse of semi-axis |v_z| — exactly the projection of the hemisphere points facing v
  (checked: its inner boundary t₂ = |v_z|√(1 − t₁²) lifts to z = 0), so the method holds for
  every v but straight down (where nothing is visible and no ray arrives: Λ = 0 there).
* Beckmann: Heitz & d'Eon 2014 / Heitz 2014 slope sampling. In the stretched frame with v at
  polar angle θ and azimuth 0, the visible slope x̃ along v has density ∝ (a − x̃)⁺ e^{−x̃²},
  a = cot θ ∈ ℝ (negative for v below the horizon), and the transverse slope ỹ is N(0, 1/2).
  The CDF of x̃ is F(x) = a(1 + erf x)/2 + e^{−x²}/(2√π) (x ≤ a), written for x < 0 as
  F = e^{−x²}(a·erfcx(−x) + 1/√π)/2 so that ln F stays finite far in the tail; F(a) is the
  projected area. x̃ solves ln F(x̃) = ln(U F(a)) by safeguarded Newton iteration (ln F is
  concave: F is the CDF of a log-concave density), vectorised over paths, to |Δx| < 1e-12.
  Then the slope is rotated to v's azimuth, scaled by α, and m = (−x, −y, 1)/‖·‖. For a > 1e6
  (v within 1e-6/α rad of the normal) a is clipped to 1e6: a relative change of the density of
  O(1e-6).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import special

from microsim import checks as _checks
from microsim import vectors
from microsim.errors import UsageError

from . import smith

__all__ = [
    "NDF",
    "Beckmann",
    "GGX",
    "BlinnPhong",
    "VonMisesFisher",
    "ABC",
    "scene_distribution",
    "scene_distributions",
    "beckmann_lambda",
    "beckmann_lambda_walter2007",
    "ggx_lambda",
    "beckmann_to_phong",
    "phong_to_beckmann",
]


class NDF:
    """Base class of a microfacet distribution, and the protocol every distribution satisfies.

    Every distribution has a ``name`` (also its scene-file name where it has one), ``isotropic``,
    ``params()``, ``D(h)``, ``pdf(h)`` and ``sample(u1, u2)`` (of D(h)(h·n)), the tilt
    distribution (``D_cos``: the azimuthal average of D; ``cdf_theta_rad``, ``tilt_pdf_rad``,
    ``tilt_quantile_rad``), the Smith ``smith_lambda(w)``, ``G1(w, h)``, ``G2(wi, wo, h,
    correlated)`` and the visible-normal density ``pdf_visible(m, v)``. What only some have is
    declared, never probed for:

    * ``has_closed_smith``: Λ in closed form (``smith_lambda_cos``, isotropic); the others'
      Λ is integrated numerically from the projected-area identity (``smith``).
    * ``has_visible_sampler``: ``sample_visible(v, u1, u2)`` draws visible normals for views on
      either side of the horizon; without it that method raises a UsageError saying so.
    * ``scene_params``: {parameter: (lo, hi)} of a distribution a scene file may name (by
      ``name`` or one of ``scene_aliases``); declaring it registers the class
      (``scene_distribution``).

    Isotropic subclasses implement ``D_cos``, ``tilt_quantile_rad``, ``_cdf_theta`` and
    ``params`` (and ``smith_lambda_cos`` with ``has_closed_smith``); the rest follows here.
    """

    name: str = "ndf"
    isotropic: bool = True
    has_closed_smith: bool = False
    has_visible_sampler: bool = False
    scene_aliases: tuple = ()

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        if "scene_params" in cls.__dict__:
            _register(cls)

    # --- to implement -------------------------------------------------------------------
    def params(self) -> dict:
        """Parameters as a name → value dict (for reports and meta.json)."""
        raise NotImplementedError

    def D_cos(self, cos_theta):
        """D as a function of cos θ_h (sr⁻¹); 0 for cos θ_h ≤ 0; finite at cos θ_h = 1 and 0."""
        raise NotImplementedError

    def tilt_quantile_rad(self, u):
        """θ_h (radians) at cumulative probability u ∈ [0, 1] of the tilt density 2πD cosθ sinθ."""
        raise NotImplementedError

    def _cdf_theta(self, theta):
        """P(θ_h ≤ θ) for θ in radians, already checked to lie in [0, π/2] (up to rounding)."""
        raise NotImplementedError

    def smith_lambda_cos(self, cos_theta):
        """Smith Λ(w) as a function of cos θ_w (only when ``has_closed_smith``)."""
        raise UsageError(f"{type(self).__name__} has no closed-form Smith Λ(cos θ)")

    def _sample_visible(self, v, u1, u2):
        """``sample_visible`` on checked, clipped inputs (only when ``has_visible_sampler``)."""
        raise UsageError(
            f"{type(self).__name__} has no visible-normal sampler (has_visible_sampler is "
            f"False); those that have one: {', '.join(_visible_samplers())}"
        )

    # --- derived ------------------------------------------------------------------------
    def cdf_theta_rad(self, theta):
        """P(θ_h ≤ θ), θ in radians in [0, π/2] (UsageError outside, e.g. for degrees).
        Inverse: ``tilt_quantile_rad``."""
        return self._cdf_theta(_tilt_rad("theta", theta))

    def D(self, h):
        """D(h) in sr⁻¹ for unit half vectors h of shape (..., 3); 0 below the horizon."""
        h = _checks.directions("h", h)
        return self.D_cos(h[..., 2])

    def pdf(self, h):
        """Solid-angle density of sampled half vectors, D(h)(h·n) (Mikkelsen 2009, eq. 14)."""
        h = _checks.directions("h", h)
        c = h[..., 2]
        return self.D_cos(c) * np.maximum(c, 0.0)

    def tilt_pdf_rad(self, theta):
        """Density of the tilt angle θ_h in radians⁻¹ at θ in radians in [0, π/2]:
        2π D(θ) cos θ sin θ."""
        theta = _tilt_rad("theta", theta)
        return 2.0 * np.pi * self.D_cos(np.cos(theta)) * np.cos(theta) * np.sin(theta)

    def sample(self, u1, u2):
        """Unit half vectors h ~ pdf from uniform numbers u1, u2 ∈ [0, 1) (inverse CDF)."""
        _checks.broadcast({}, {"u1": u1, "u2": u2})
        u1, u2 = np.broadcast_arrays(np.asarray(u1, float), np.asarray(u2, float))
        theta = self.tilt_quantile_rad(u1)
        return vectors.spherical(theta, 2.0 * np.pi * u2)

    def tilt_breakpoints_rad(self) -> np.ndarray:
        """θ_h (radians) that split [0, π/2] into panels on which D is smooth and well resolved
        (for quadratures over the distribution): its tilt quantiles and a uniform grid."""
        u = np.concatenate(
            [
                np.linspace(0.0, 1.0, 65)[1:-1],
                np.logspace(-10, -2, 9),
                1.0 - np.logspace(-10, -2, 9),
            ]
        )
        q = np.asarray(self.tilt_quantile_rad(u), dtype=np.float64)
        return np.unique(np.concatenate([q[np.isfinite(q)], np.linspace(0, 0.5 * np.pi, 33)]))

    # --- Smith masking ------------------------------------------------------------------
    def smith_lambda(self, w, method: str = "auto"):
        """Smith Λ(w) (dimensionless, ≥ 0; inf at θ_w = 90°) for upper-hemisphere unit w.

        ``method``: "auto" (closed form when ``has_closed_smith``, else numerical), "closed",
        or "numerical" (projected-area identity, ``smith``; forced even when a closed form
        exists, for checking it); ``Beckmann`` also "walter2007" (``beckmann_lambda_walter2007``).
        """
        w = _checks.directions("w", w, upper=True)
        return self._smith_lambda(w, method)

    def _smith_lambda(self, w, method: str = "auto"):
        """Λ(w) for unit w (no validation); inf at cos θ_w ≤ 0."""
        self._check_lambda_method(method)
        c = w[..., 2]
        if self.has_closed_smith and method != "numerical":
            pos = c > 0.0
            lam = np.full(c.shape, np.inf)
            lam[pos] = self.smith_lambda_cos(c[pos])
            return lam
        return smith.numerical_lambda_cos(self, c)

    def _check_lambda_method(self, method) -> None:
        """UsageError unless ``method`` is one of "auto", "closed", "numerical" and this
        distribution has what it asks for."""
        _check_lambda_method(method)
        if method == "closed" and not self.has_closed_smith:
            raise UsageError(
                f"method='closed' needs an NDF with a closed-form Smith Λ; "
                f"{type(self).__name__} has none (use 'auto' or 'numerical')"
            )

    def G1(self, w, h, method: str = "auto"):
        """Smith masking G1(w, h) = χ⁺(w·h)/(1 + Λ(w)) (Smith 1967; Heitz 2014); ``method``
        as ``smith_lambda``'s."""
        w = _checks.directions("w", w)
        h = _checks.directions("h", h)
        _checks.broadcast({"w": w, "h": h})
        return _g1_from_lambda(self._smith_lambda(w, method), vectors.dot(w, h), w[..., 2])

    def G2(self, wi, wo, h, correlated: bool = False):
        """Smith shadowing–masking: separable G1(wi)G1(wo), or height-correlated
        χ⁺(wi·h)χ⁺(wo·h)/(1 + Λ(wi) + Λ(wo)) when ``correlated``."""
        wi = _checks.directions("wi", wi)
        wo = _checks.directions("wo", wo)
        h = _checks.directions("h", h)
        _checks.broadcast({"wi": wi, "wo": wo, "h": h})
        return self.smith_g2_dots(wi, wo, vectors.dot(wi, h), vectors.dot(wo, h), correlated)

    def smith_g2_dots(self, wi, wo, wih, woh, correlated: bool, method: str = "auto"):
        """``G2`` for validated unit wi, wo and their precomputed dot products with h; Λ by
        ``method`` (``smith_lambda``)."""
        lam_i, lam_o = self._smith_lambda(wi, method), self._smith_lambda(wo, method)
        if correlated:
            ok = (wih > 0.0) & (woh > 0.0) & (wi[..., 2] > 0.0) & (wo[..., 2] > 0.0)
            with np.errstate(invalid="ignore"):
                return np.where(ok, 1.0 / (1.0 + lam_i + lam_o), 0.0)
        return _g1_from_lambda(lam_i, wih, wi[..., 2]) * _g1_from_lambda(lam_o, woh, wo[..., 2])

    # --- visible normals ----------------------------------------------------------------
    def pdf_visible(self, m, v):
        """D_v(m) = ⟨v, m⟩⁺ D(m) / ((1 + Λ(v)) cos θ_v) in sr⁻¹ for views v of the upper
        hemisphere (the Smith visible-normal density, normalised by the projected-area
        identity)."""
        m = _checks.directions("m", m)
        v = _checks.directions("v", v, upper=True)
        vm = np.maximum(np.einsum("...i,...i->...", v, m), 0.0)
        return vm * self.D(m) / ((1.0 + self._smith_lambda(v)) * v[..., 2])

    def sample_visible(self, v, u1, u2):
        """Facet normals m ~ D_v(m) = ⟨v, m⟩⁺ D(m) / ∫⟨v, m'⟩⁺ D dm' for unit views v (N, 3)
        of either hemisphere (not straight down) and uniforms u1, u2 of shape (N,) (only with
        ``has_visible_sampler``, else UsageError)."""
        v = _checks.directions("v", v)
        if v.ndim != 2:
            raise UsageError(f"v must have shape (N, 3), got {v.shape}")
        u1 = np.clip(np.asarray(u1, dtype=np.float64), 1e-300, 1.0)
        u2 = np.clip(np.asarray(u2, dtype=np.float64), 0.0, 1.0)
        if u1.shape != (len(v),) or u2.shape != (len(v),):
            raise UsageError(
                f"v, u1 and u2 must have shapes (N, 3), (N,) and (N,), "
                f"got v {v.shape}, u1 {u1.shape}, u2 {u2.shape}"
            )
        return self._sample_visible(v, u1, np.clip(u2, 1e-16, 1 - 1e-16))

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self.params().items())
        return f"{type(self).__name__}({args})"


# --- the scene files' distributions -------------------------------------------------------------
_SCENE_CLASSES: dict = {}
_SCENE_ALIASES: dict = {}


def _register(cls) -> None:
    """Record a distribution class with ``scene_params`` under its ``name`` and aliases."""
    for key in (cls.name, *cls.scene_aliases):
        if key in _SCENE_CLASSES or key in _SCENE_ALIASES:
            raise ValueError(f"scene distribution name {key!r} registered twice")
    _SCENE_CLASSES[cls.name] = cls
    _SCENE_ALIASES.update({alias: cls.name for alias in cls.scene_aliases})


def scene_distributions() -> tuple:
    """Names a scene file may give a distribution (the registered classes' ``name``)."""
    return tuple(_SCENE_CLASSES)


def scene_distribution(name):
    """The distribution class a scene names (its ``name`` or an alias), else UsageError naming
    the allowed values."""
    cls = _SCENE_CLASSES.get(_SCENE_ALIASES.get(name, name)) if isinstance(name, str) else None
    if cls is None:
        raise UsageError(f"ndf must be one of {', '.join(_SCENE_CLASSES)}, got {name!r}")
    return cls


def _visible_samplers() -> list:
    """Names of the distribution classes that declare a visible-normal sampler."""
    out, todo = [], list(NDF.__subclasses__())
    while todo:
        cls = todo.pop(0)
        todo.extend(cls.__subclasses__())
        if cls.has_visible_sampler and not cls.__name__.startswith("_"):
            out.append(cls.__name__)
    return out


_LAMBDA_METHODS = ("auto", "closed", "numerical")


def _check_lambda_method(method) -> None:
    if method not in _LAMBDA_METHODS:
        raise UsageError(
            f"method must be one of 'auto', 'closed', 'numerical' (Beckmann also "
            f"{WALTER_2007!r}), got {method!r}"
        )


def _g1_from_lambda(lam, w_dot_h, cos_w):
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where((w_dot_h > 0.0) & (cos_w > 0.0), 1.0 / (1.0 + lam), 0.0)


# --- numerically careful building blocks -----------------------------------------------------
TILT_SLACK = 1e-9
"""Rounding allowed beyond [0, π/2] in a tilt angle (radians) before it is refused."""


def _tilt_rad(name: str, theta) -> np.ndarray:
    """Tilt angle(s) in radians as float64, or a UsageError naming ``name`` unless every value
    lies in [0, π/2] (± ``TILT_SLACK``); NaN passes through."""
    t = np.asarray(theta, dtype=np.float64)
    if np.any(t < -TILT_SLACK) or np.any(t > 0.5 * np.pi + TILT_SLACK):
        raise UsageError(
            f"{name} must be tilt angles in radians within [0, π/2], got values in "
            f"[{np.nanmin(t):.6g}, {np.nanmax(t):.6g}] (degrees? use np.radians)"
        )
    return t


def _unit_interval(u) -> np.ndarray:
    """Cumulative probabilities as float64 clipped to [0, 1]."""
    return np.clip(np.asarray(u, dtype=np.float64), 0.0, 1.0)


def _one_minus_cos(theta) -> np.ndarray:
    """x = 1 − cos θ = 2 sin²(θ/2), accurate for small θ; θ clipped to [0, π/2]."""
    t = np.clip(np.asarray(theta, dtype=np.float64), 0.0, 0.5 * np.pi)
    return 2.0 * np.sin(0.5 * t) ** 2


def _theta_from_x(x) -> np.ndarray:
    """θ = 2 arcsin √(x/2) from x = 1 − cos θ (accurate for small θ); x clipped to [0, 1]."""
    return np.minimum(2.0 * np.arcsin(np.sqrt(0.5 * np.clip(x, 0.0, 1.0))), 0.5 * np.pi)


def _sin2(c) -> np.ndarray:
    """sin²θ = (1 − c)(1 + c) from c = cos θ, without the cancellation of 1 − c²."""
    return (1.0 - c) * (1.0 + c)


def _expm1x(z) -> np.ndarray:
    """(e^z − 1)/z with its limit 1 at z = 0 (= ∫₀¹ e^{zt} dt)."""
    z = np.asarray(z, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.expm1(z) / z
    return np.where(z == 0.0, 1.0, r)


def _cos_array(cos_theta) -> np.ndarray:
    """cos θ as a float64 array (not clipped: D is 0 below the horizon)."""
    return np.asarray(cos_theta, dtype=np.float64)


# --- Beckmann -------------------------------------------------------------------------------
WALTER_2007 = "walter2007"
"""The Λ ``method`` of ``Beckmann`` that is Walter et al. 2007's rational G1 (eq. 27)."""


def beckmann_lambda_walter2007(cos_theta, m):
    """Beckmann Smith Λ = 1/G1 − 1 from the rational approximation of Walter et al. 2007,
    eq. 27: G1 = (3.535a + 2.181a²)/(1 + 2.276a + 2.577a²) for a < 1.6, else 1, a = 1/(m tan θ)
    ("< 0.35 %" from the exact G1; 0.31 % at a ≈ 1.34, and the rational form exceeds 1 by up
    to 6e-5 just below a = 1.6, where this Λ is slightly negative). Mitsuba 3 evaluates its
    Beckmann G1 so (``smith_g1`` in include/mitsuba/render/microfacet.h); cos θ in [0, 1]."""
    c = np.clip(np.asarray(cos_theta, dtype=np.float64), 0.0, 1.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        a = c / (m * np.sqrt(_sin2(c)))  # inf at c = 1
        g1 = (3.535 * a + 2.181 * a * a) / (1.0 + 2.276 * a + 2.577 * a * a)
        lam = 1.0 / g1 - 1.0  # inf at c = 0
    return np.where(a >= 1.6, 0.0, lam)


def beckmann_lambda(cos_theta, m):
    """Beckmann Smith Λ at cos θ (array, clipped to [0, 1]) for roughness ``m`` (scalar or an
    array broadcasting with it): ``Beckmann.smith_lambda_cos``'s formula."""
    c = np.clip(np.asarray(cos_theta, dtype=np.float64), 0.0, 1.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        a = c / (m * np.sqrt(_sin2(c)))  # inf at c = 1
        lam = 0.5 * np.exp(-a * a) * (1.0 / (a * np.sqrt(np.pi)) - special.erfcx(a))
    return np.where(c == 1.0, 0.0, lam)


def ggx_lambda(cos_theta, alpha):
    """GGX Smith Λ at cos θ (array, clipped to [0, 1]) for roughness ``alpha`` (scalar or an
    array broadcasting with it): ``GGX.smith_lambda_cos``'s formula."""
    c = np.clip(np.asarray(cos_theta, dtype=np.float64), 0.0, 1.0)
    q = alpha**2 * _sin2(c)
    with np.errstate(divide="ignore"):
        return q / (2.0 * c * (np.sqrt(c * c + q) + c))


@dataclass(frozen=True, repr=False)
class Beckmann(NDF):
    """Beckmann NDF, D = exp(−tan²θ/m²)/(π m² cos⁴θ) (Mikkelsen 2009, eq. 20); rms slope m > 0.

    For a Gaussian heightfield the per-axis slope variance is m²/2 (docs/design.md).
    """

    m: float
    name = "beckmann"
    has_closed_smith = True
    has_visible_sampler = True
    scene_params = {"m": (1e-6, 10.0)}

    def __post_init__(self):
        object.__setattr__(self, "m", _checks.positive("m", self.m))

    def params(self) -> dict:
        return {"m": self.m}

    @property
    def horizon_area(self) -> float:
        """lim Λ(θ) cos θ as θ → 90°: m/(2√π), the visible facets' projected area per unit
        macro area for a view at the horizon."""
        return self.m / (2.0 * _SQRT_PI)

    def D_cos(self, cos_theta):
        """D(cos θ) in sr⁻¹, evaluated as exp(−sin²/(c² m²) − 4 ln c)/(π m²); 0 for c ≤ 0."""
        c = _cos_array(cos_theta)
        pos = c > 0.0
        cs = np.where(pos, np.minimum(c, 1.0), 1.0)
        with np.errstate(divide="ignore", over="ignore"):
            expo = -_sin2(cs) / (cs * cs * self.m**2) - 4.0 * np.log(cs)
        return np.where(pos, np.exp(expo) / (np.pi * self.m**2), 0.0)

    def _cdf_theta(self, theta):
        """P(θ_h ≤ θ) = 1 − exp(−tan²θ/m²)."""
        t = np.clip(np.asarray(theta, dtype=np.float64), 0.0, 0.5 * np.pi)
        return -np.expm1(-((np.tan(t) / self.m) ** 2))

    def tilt_quantile_rad(self, u):
        """θ_h with tan²θ = −m² ln(1 − u); u = 1 gives π/2."""
        u = _unit_interval(u)
        with np.errstate(divide="ignore"):
            t = -np.log1p(-u)
        return np.arctan(self.m * np.sqrt(t))

    def smith_lambda_cos(self, cos_theta):
        """Smith Λ = [erf(a) − 1]/2 + e^{−a²}/(2a√π), a = 1/(m tan θ) (Smith 1967; Heitz 2014),
        cos θ in [0, 1].

        Evaluated as Λ = e^{−a²}(1/(a√π) − erfcx(a))/2, which avoids the cancellation of
        erf(a) − 1 (erfcx(a) = e^{a²} erfc(a)). Λ = 0 at θ = 0 and Λ = +inf at θ = 90°
        (a = 0), so that G1 = 1/(1 + Λ) = 0 there.
        """
        return beckmann_lambda(_cos_array(cos_theta), self.m)

    def _smith_lambda(self, w, method: str = "auto"):
        """Λ(w) for unit w; ``method`` may also be ``WALTER_2007`` ("walter2007": the rational
        G1 of ``beckmann_lambda_walter2007``, a renderer's approximation, for comparing with
        one); inf at cos θ_w ≤ 0."""
        if method != WALTER_2007:
            return super()._smith_lambda(w, method)
        c = w[..., 2]
        return np.where(c > 0.0, beckmann_lambda_walter2007(c, self.m), np.inf)

    def _sample_visible(self, v, u1, u2):
        """Heitz & d'Eon 2014 visible-slope inversion (module docstring, "Visible normals")."""
        return _beckmann_visible(v, self.m, u1, u2)


# --- GGX ------------------------------------------------------------------------------------
@dataclass(frozen=True, repr=False)
class GGX(NDF):
    """GGX / Trowbridge–Reitz NDF, D = α²/(π cos⁴θ (α² + tan²θ)²), α > 0 (docs/design.md).

    Evaluated as α²/(π (α² cos²θ + sin²θ)²), finite at θ = 90°.
    """

    alpha: float
    name = "ggx"
    has_closed_smith = True
    has_visible_sampler = True
    scene_params = {"alpha": (1e-6, 10.0)}

    def __post_init__(self):
        object.__setattr__(self, "alpha", _checks.positive("alpha", self.alpha))

    def params(self) -> dict:
        return {"alpha": self.alpha}

    @property
    def horizon_area(self) -> float:
        """lim Λ(θ) cos θ as θ → 90°: α/2 (as ``Beckmann.horizon_area``)."""
        return 0.5 * self.alpha

    def D_cos(self, cos_theta):
        """D(cos θ) in sr⁻¹; 0 for c ≤ 0."""
        c = np.minimum(_cos_array(cos_theta), 1.0)
        a2 = self.alpha**2
        d = a2 / (np.pi * (a2 * c * c + _sin2(c)) ** 2)
        return np.where(c > 0.0, d, 0.0)

    def _cdf_theta(self, theta):
        """P(θ_h ≤ θ) = tan²θ/(α² + tan²θ) = sin²θ/(α² cos²θ + sin²θ)."""
        t = np.clip(np.asarray(theta, dtype=np.float64), 0.0, 0.5 * np.pi)
        s2, c2 = np.sin(t) ** 2, np.cos(t) ** 2
        return s2 / (self.alpha**2 * c2 + s2)

    def tilt_quantile_rad(self, u):
        """θ_h with tan θ = α √(u/(1 − u)); u = 1 gives π/2."""
        u = _unit_interval(u)
        return np.arctan2(self.alpha * np.sqrt(u), np.sqrt(1.0 - u))

    def smith_lambda_cos(self, cos_theta):
        """Smith Λ = (−1 + √(1 + α² tan²θ))/2 (docs/design.md), cos θ in [0, 1].

        Evaluated as α² sin²/(2c(√(c² + α² sin²) + c)): no cancellation; +inf at θ = 90°.
        """
        return ggx_lambda(_cos_array(cos_theta), self.alpha)

    def _sample_visible(self, v, u1, u2):
        """Heitz 2018 (module docstring, "Visible normals")."""
        return _ggx_visible(v, self.alpha, u1, u2)


# --- visible normals of Beckmann and GGX ----------------------------------------------------
_A_MAX = 1e6  # largest |cot θ| used in Beckmann visible-slope sampling (module docstring)
_SQRT_PI = np.sqrt(np.pi)


def _beckmann_ln_f(a, x):
    """ln F(x), F(x) = a(1 + erf x)/2 + e^{−x²}/(2√π) = ∫_{−∞}^x (a − s) e^{−s²} ds/√π, x ≤ a;
    for x < 0 as −x² + ln((a erfcx(−x) + 1/√π)/2) (finite far in the tail)."""
    neg = x < 0
    xn = np.where(neg, x, -1.0)
    xp = np.where(neg, 1.0, x)
    with np.errstate(divide="ignore", invalid="ignore"):
        lneg = -xn * xn + np.log(0.5 * np.maximum(a * special.erfcx(-xn) + 1.0 / _SQRT_PI, 0.0))
        lpos = np.log(0.5 * a * (1.0 + special.erf(xp)) + np.exp(-xp * xp) / (2.0 * _SQRT_PI))
    return np.where(neg, lneg, lpos)


def _beckmann_slope_x(a, u):
    """x̃ ≤ a with F(x̃) = u F(a) (``_beckmann_ln_f``), vectorised over paths.

    Safeguarded Newton on the concave increasing g(x) = ln F(x) − ln(u F(a)) inside the bracket
    [min(a, 0) − 9, a] (F(lo)/F(a) < 1e-30 < u for every u the walk draws), with bisection
    whenever a step leaves the bracket; only unconverged entries are iterated.
    """
    a = np.asarray(a, dtype=np.float64)
    target = np.log(u) + _beckmann_ln_f(a, a)
    lo = np.minimum(a, 0.0) - 9.0
    hi = a.copy()
    # start: the root for a → +∞ (x = erfinv(2u − 1)) clipped into the bracket; for a < 0 near
    # the median of the limiting Gamma(2, 2|a|) law of a − x̃ (density ∝ r e^{−2|a| r}, r = a − x̃)
    x = np.where(
        a >= 0,
        np.clip(special.erfinv(2.0 * u - 1.0), lo, hi),
        a - 1.68 / (2.0 * np.abs(a) + 1.2),
    )
    act = np.arange(len(a))
    for _ in range(200):
        xa, aa = x[act], a[act]
        lf = _beckmann_ln_f(aa, xa)
        g = lf - target[act]
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            dg = (aa - xa) * np.exp(-xa * xa - lf) / _SQRT_PI  # d ln F/dx
            step = g / dg
            x_new = xa - step
        lo_a = np.where(g < 0, xa, lo[act])
        hi_a = np.where(g > 0, xa, hi[act])
        bad = ~np.isfinite(x_new) | (x_new < lo_a) | (x_new > hi_a)
        lo[act], hi[act] = lo_a, hi_a
        done = (g == 0) | (~bad & (np.abs(step) <= 1e-12 * np.maximum(1.0, np.abs(xa))))
        x[act] = np.where(g == 0, xa, np.where(bad, 0.5 * (lo_a + hi_a), x_new))
        act = act[~done]
        if len(act) == 0:
            break
    return np.minimum(x, a)


def slope_space_visible(v, alpha: float, u1, u2, slopes):
    """Visible normals by the slope-space method (Heitz & d'Eon 2014) for unit views v (N, 3):
    v stretched to unit roughness, a = cot θ of the stretched view (clipped to ±``_A_MAX``),
    ``slopes(a, u1, u2)`` → the unit-roughness visible slopes (x̃ along the view's azimuth, ỹ
    across), rotated to that azimuth, scaled by α, m = (−x, −y, 1)/‖·‖."""
    vs = np.stack([alpha * v[:, 0], alpha * v[:, 1], v[:, 2]], axis=1)
    vs /= np.linalg.norm(vs, axis=1, keepdims=True)
    rxy = np.hypot(vs[:, 0], vs[:, 1])
    with np.errstate(divide="ignore", invalid="ignore"):
        a = np.clip(vs[:, 2] / rxy, -_A_MAX, _A_MAX)  # cot θ of the stretched direction
    a = np.where(rxy > 0, a, np.sign(vs[:, 2]) * _A_MAX)
    x, y = slopes(a, u1, u2)
    safe = rxy > 0
    cphi = np.where(safe, vs[:, 0] / np.where(safe, rxy, 1.0), 1.0)
    sphi = np.where(safe, vs[:, 1] / np.where(safe, rxy, 1.0), 0.0)
    sx = alpha * (cphi * x - sphi * y)
    sy = alpha * (sphi * x + cphi * y)
    m = np.stack([-sx, -sy, np.ones_like(sx)], axis=1)
    return m / np.linalg.norm(m, axis=1, keepdims=True)


def _beckmann_slopes(a, u1, u2):
    """Unit-roughness Beckmann visible slopes: x̃ by inversion, ỹ ~ N(0, 1/2)."""
    return _beckmann_slope_x(a, u1), special.erfinv(2.0 * u2 - 1.0)


def _beckmann_visible(v, alpha, u1, u2):
    return slope_space_visible(v, alpha, u1, u2, _beckmann_slopes)


def _ggx_visible(v, alpha, u1, u2):
    vh = np.stack([alpha * v[:, 0], alpha * v[:, 1], v[:, 2]], axis=1)
    vh /= np.linalg.norm(vh, axis=1, keepdims=True)
    lensq = vh[:, 0] ** 2 + vh[:, 1] ** 2
    inv = np.where(lensq > 0, 1.0 / np.sqrt(np.where(lensq > 0, lensq, 1.0)), 0.0)
    t1v = np.stack(
        [np.where(lensq > 0, -vh[:, 1] * inv, 1.0), np.where(lensq > 0, vh[:, 0] * inv, 0.0)],
        axis=1,
    )
    T1 = np.stack([t1v[:, 0], t1v[:, 1], np.zeros(len(v))], axis=1)
    T2 = np.cross(vh, T1)
    r = np.sqrt(u1)
    phi = 2.0 * np.pi * u2
    t1 = r * np.cos(phi)
    t2 = r * np.sin(phi)
    s = 0.5 * (1.0 + vh[:, 2])
    w = np.sqrt(np.maximum(1.0 - t1 * t1, 0.0))
    t2 = (1.0 - s) * w + s * t2
    up = np.sqrt(np.maximum(1.0 - t1 * t1 - t2 * t2, 0.0))
    nh = t1[:, None] * T1 + t2[:, None] * T2 + up[:, None] * vh
    m = np.stack([alpha * nh[:, 0], alpha * nh[:, 1], np.maximum(nh[:, 2], 0.0)], axis=1)
    return m / np.linalg.norm(m, axis=1, keepdims=True)


# --- normalised Blinn–Phong -----------------------------------------------------------------
@dataclass(frozen=True, repr=False)
class BlinnPhong(NDF):
    """Normalised Blinn–Phong NDF, D = (e + 2)/(2π) cos^e θ, e ≥ 0 (Mikkelsen 2009, eq. 19;
    Mally 2015)."""

    e: float
    name = "blinn-phong"
    scene_params = {"e": (1e-6, 1e12)}
    scene_aliases = ("blinn_phong", "phong")

    def __post_init__(self):
        object.__setattr__(self, "e", _checks.in_range("e", self.e, 0.0, np.inf, hi_open=True))

    def params(self) -> dict:
        return {"e": self.e}

    def D_cos(self, cos_theta):
        """D(cos θ) in sr⁻¹; 0 for c ≤ 0."""
        c = np.minimum(_cos_array(cos_theta), 1.0)
        pos = c > 0.0
        return np.where(pos, (self.e + 2.0) / (2.0 * np.pi) * np.where(pos, c, 1.0) ** self.e, 0.0)

    def _cdf_theta(self, theta):
        """P(θ_h ≤ θ) = 1 − cos^{e+2} θ, evaluated as −expm1((e + 2) log1p(−x)), x = 1 − cos θ."""
        x = _one_minus_cos(theta)
        with np.errstate(divide="ignore"):
            return -np.expm1((self.e + 2.0) * np.log1p(-np.minimum(x, 1.0)))

    def tilt_quantile_rad(self, u):
        """θ_h with cos θ = (1 − u)^{1/(e+2)}; 1 − cos θ = −expm1(log1p(−u)/(e + 2))."""
        u = _unit_interval(u)
        with np.errstate(divide="ignore"):
            x = -np.expm1(np.log1p(-u) / (self.e + 2.0))
        return _theta_from_x(x)


def beckmann_to_phong(m) -> float:
    """Phong exponent with the same normalisation constant as Beckmann m: e = 2/m² − 2.

    Mikkelsen 2009, eq. 21 (equates (e+2)/2π with 1/(π m²)); needs 0 < m ≤ 1 so that e ≥ 0.
    Visually close for e > 8 (Mikkelsen).
    """
    m = _checks.in_range("m", m, 0.0, 1.0, lo_open=True)
    return 2.0 / m**2 - 2.0


def phong_to_beckmann(e) -> float:
    """Inverse of Mikkelsen 2009, eq. 21: m = √(2/(e + 2)) for e ≥ 0."""
    e = _checks.in_range("e", e, 0.0, np.inf, hi_open=True)
    return float(np.sqrt(2.0 / (e + 2.0)))


# --- von Mises–Fisher on the hemisphere -----------------------------------------------------
@dataclass(frozen=True, repr=False)
class VonMisesFisher(NDF):
    """Hemispherical von Mises–Fisher lobe, concentration κ > 0 (Mikkelsen 2009, eq. 29–33).

    pdf p(h) = κ e^{κ(h·n)}/(2π(e^κ − 1)) (Mikkelsen 2009, eq. 29), normalised over the hemisphere,
    and D = p/(h·n) (Mikkelsen 2009, eq. 18 / 14). Evaluated as κ e^{−κ(1 − h·n)}/(2π(1 − e^{−κ})),
    which never forms e^κ. D grows like p(0)/cos θ towards the horizon (p(0) > 0) and is
    set to 0 for cos θ ≤ 0 (base-class convention); pdf = D cos θ stays finite.
    """

    kappa: float
    name = "vmf"
    scene_params = {"kappa": (1e-6, 1e12)}
    scene_aliases = ("von-mises-fisher",)

    def __post_init__(self):
        object.__setattr__(self, "kappa", _checks.positive("kappa", self.kappa))

    def params(self) -> dict:
        return {"kappa": self.kappa}

    def _p_x(self, x):
        """Solid-angle density p as a function of x = 1 − h·n (Mikkelsen 2009, eq. 29)."""
        k = self.kappa
        return k * np.exp(-k * x) / (2.0 * np.pi * -np.expm1(-k))

    def D_cos(self, cos_theta):
        """D = p/cos θ in sr⁻¹; 0 for c ≤ 0."""
        c = np.minimum(_cos_array(cos_theta), 1.0)
        pos = c > 0.0
        cs = np.where(pos, c, 1.0)
        return np.where(pos, self._p_x(1.0 - cs) / cs, 0.0)

    def _cdf_theta(self, theta):
        """P(θ_h ≤ θ) = (1 − e^{−κ(1 − cos θ)})/(1 − e^{−κ}) (Mikkelsen's CDF before eq. 31)."""
        x = _one_minus_cos(theta)
        return np.minimum(np.expm1(-self.kappa * x) / np.expm1(-self.kappa), 1.0)

    def tilt_quantile_rad(self, u):
        """θ_h with 1 − cos θ = −ln(1 − u(1 − e^{−κ}))/κ (Mikkelsen 2009, eq. 31 without e^κ)."""
        u = _unit_interval(u)
        with np.errstate(divide="ignore"):
            x = -np.log1p(u * np.expm1(-self.kappa)) / self.kappa
        return _theta_from_x(np.where(u == 1.0, 1.0, x))


# --- Löw's ABC facet distribution -----------------------------------------------------------
@dataclass(frozen=True, repr=False)
class ABC(NDF):
    """ABC facet distribution D(h) = M/(1 + B(1 − h·n))^C, B > 0, C > 0 (Löw et al. 2012,
    eq. 15, 23).

    Löw normalises the *solid-angle* pdf M_h A/(1 + B(1 − cos θ))^C (eq. 23–24); here D is a
    true NDF, ∫ D (h·n) dω = 1 (Mikkelsen 2009, eq. 14), so the normaliser carries the cos factor.
    With x = 1 − cos θ, y = B x and L = ln(1 + y):

        J(x) = ∫₀ˣ (1 − t)(1 + Bt)^{−C} dt
             = ∫₀ˣ (1 + Bt)^{−C} dt − ∫₀ˣ t (1 + Bt)^{−C} dt
             = L·φ((1−C)L)/B − L·[φ((2−C)L) − φ((1−C)L)]/B²,     φ(z) = (e^z − 1)/z,

    using s = 1 + Bt = e^v: ∫₁^{1+y} s^{−a} ds = ∫₀^L e^{(1−a)v} dv = L φ((1−a)L).
    φ is evaluated with expm1 and is smooth through z = 0, so C = 1 (where both integrals
    become logarithms) needs no special case and C = 1 ± 1e−9 loses nothing. The second
    difference costs a relative error of about ε(1 + 1/B) — fine for B ≳ 1e−6.

        normaliser  M = 1/(2π J(1)),   tilt CDF  P(θ_h ≤ θ) = J(1 − cos θ)/J(1).

    The CDF has no closed-form inverse (the cos factor adds a term linear in s to Löw's
    eq. 25 power law), so ``tilt_quantile_rad`` inverts it by safeguarded Newton steps in
    w = ln(1 + Bx), started from a table of the CDF on a uniform grid in w.
    """

    B: float
    C: float
    M: float = field(init=False, repr=False, compare=False)
    _table: tuple = field(init=False, repr=False, compare=False)  # (P_k, w_k): Newton starts
    name = "abc"
    scene_params = {"B": (1e-6, 1e6), "C": (1e-6, 1e6)}
    _TABLE_SIZE = 2049

    def __post_init__(self):
        object.__setattr__(self, "B", _checks.positive("B", self.B))
        object.__setattr__(self, "C", _checks.positive("C", self.C))
        w_k = np.linspace(0.0, np.log1p(self.B), self._TABLE_SIZE)
        j_k = self._J_w(w_k)
        object.__setattr__(self, "M", 1.0 / (2.0 * np.pi * j_k[-1]))
        object.__setattr__(self, "_table", (np.maximum.accumulate(j_k / j_k[-1]), w_k))

    def params(self) -> dict:
        return {"B": self.B, "C": self.C}

    def _J_w(self, w):
        """J (class docstring) as a function of w = ln(1 + Bx)."""
        C, B = self.C, self.B
        first = _expm1x((1.0 - C) * w)
        second = _expm1x((2.0 - C) * w) - first
        return w * (first / B - second / B**2)

    def _D_x(self, x):
        """D as a function of x = 1 − h·n ∈ [0, 1]."""
        return self.M * np.exp(-self.C * np.log1p(self.B * x))

    def D_cos(self, cos_theta):
        """D(cos θ) in sr⁻¹; 0 for c ≤ 0 (use ``D(h)`` for full accuracy near the peak)."""
        c = np.minimum(_cos_array(cos_theta), 1.0)
        return np.where(c > 0.0, self._D_x(1.0 - np.clip(c, 0.0, 1.0)), 0.0)

    def D(self, h):
        """D(h) with 1 − h_z = (h_x² + h_y²)/(1 + h_z), exact for unit h; 0 for h_z ≤ 0."""
        h = _checks.directions("h", h)
        hz = h[..., 2]
        up = hz > 0.0
        x = (h[..., 0] ** 2 + h[..., 1] ** 2) / (1.0 + np.where(up, hz, 1.0))
        return np.where(up, self._D_x(np.minimum(x, 1.0)), 0.0)

    def pdf(self, h):
        """D(h)(h·n) with the accurate D(h)."""
        h = _checks.directions("h", h)
        return self.D(h) * np.maximum(h[..., 2], 0.0)

    def _cdf_theta(self, theta):
        """P(θ_h ≤ θ) = J(1 − cos θ)/J(1) (class docstring)."""
        w = np.log1p(self.B * _one_minus_cos(theta))
        return np.clip(self._J_w(w) * (2.0 * np.pi * self.M), 0.0, 1.0)

    def tilt_quantile_rad(self, u, *, tol: float = 1e-14, max_iter: int = 100):
        """θ_h with cdf_theta_rad(θ_h) = u, to |cdf − u| ≤ tol (safeguarded Newton in w)."""
        u = _unit_interval(u)
        B, C = self.B, self.C
        w_max = np.log1p(B)
        norm = 2.0 * np.pi * self.M  # 1/J(1)
        w = np.interp(u, *self._table)
        lo, hi = np.zeros_like(u), np.full_like(u, w_max)
        for _ in range(max_iter):
            f = self._J_w(w) * norm - u
            lo = np.where(f <= 0.0, w, lo)
            hi = np.where(f >= 0.0, w, hi)
            done = (np.abs(f) <= tol) | (hi - lo <= 4e-16 * w_max)
            if np.all(done):
                break
            x = np.expm1(w) / B
            dfdw = (1.0 - x) * np.exp((1.0 - C) * w) / B * norm  # dP/dw
            with np.errstate(divide="ignore", invalid="ignore"):
                step = w - f / dfdw
            inside = np.isfinite(step) & (step >= lo) & (step <= hi)
            w = np.where(done, w, np.where(inside, step, 0.5 * (lo + hi)))
        x = np.where(u == 1.0, 1.0, np.where(u == 0.0, 0.0, np.expm1(w) / B))  # exact ends
        return _theta_from_x(x)
