"""Multiple scattering on a Smith microsurface by a random walk (Heitz et al. 2016).

Heitz, Hanika, d'Eon & Dachsbacher 2016 ("Multiple-scattering microfacet BSDFs with the Smith
model", ACM TOG 35(4)) define the *Smith microsurface*: a random heightfield whose heights and
normals are uncorrelated, with height density P1 (CDF C1) and an NDF D. Its BRDF, including all
orders of scattering, is the expectation of a random walk on that surface; its first order is
exactly Torrance–Sparrow with height-correlated Smith shadowing. This module implements the walk
for a conductor (or ideal mirror) with a Beckmann or GGX NDF — isotropic (roughness α; α = m for
``Beckmann(m)``) or anisotropic (``AnisotropicBeckmann``, ``AnisotropicGGX``: αx, αy, rotation;
section "Anisotropic surfaces") — vectorised over paths, and its bin averages per scattering
order at any incidence azimuth.

Conventions (docs/design.md): n = +z, unit directions point *away* from the surface; the incident
direction wi points towards the light. A path starts as the ray −wi and is reflected at every
hit; the direction in which it finally leaves the surface is wo. Angles in public arguments are
degrees.

Derivation (the parts this module relies on)
---------------------------------------------
*Free flight.* Smith's masking from height h in an upward direction w is G1(w, h) = C1(h)^Λ(w)
(Smith 1967; Heitz et al. 2016). Differentiating, a ray going up meets the surface at a rate
Λ(w) P1(h)/C1(h) per unit of height. A ray going *down* sees the facets visible from −w, whose
projected area is (1 + Λ(−w)) cos θ, so it meets the surface at the rate (1 + Λ(−w)) P1/C1 per
unit of height descended (Heitz's signed Λ(w) = −1 − Λ(−w) for w_z < 0). In the variable

    τ = −ln C1(h) ∈ [0, ∞)     (τ = 0 at the top of the surface, growing downwards)

both rates are constant: an upward ray from τ₀ travels an Exp(Λ(w)) distance in τ and escapes
when it exceeds τ₀ (probability e^{−Λ τ₀} = C1(h₀)^Λ = G1), otherwise it hits at τ₀ − L; a
downward ray hits at τ₀ + E/(1 + Λ(−w)), E ~ Exp(1). This is Heitz et al.'s ``sampleHeight``
(τ-form of h = C1⁻¹(C1(h₀) (1 − U)^{−1/Λ(w)})), and it shows that the walk — hence the BRDF —
does not depend on the height distribution (as Heitz et al. 2016 also note). The walk
starts at τ = 0 (C1 = 1, above every facet). ``height_from_tau`` maps τ back to a height for the
uniform (on [−1, 1]: h = 2e^{−τ} − 1) and the standard Gaussian (h = Φ⁻¹(e^{−τ})) heights.

*Smith Λ.* From the NDF's closed form: ``Beckmann.smith_lambda_cos`` (Λ = [erf(a) − 1]/2 +
e^{−a²}/(2a√π), a = 1/(m tan θ)) and ``GGX.smith_lambda_cos`` (Λ = (−1 + √(1 + α² tan²θ))/2).

*Phase function.* At a hit by a ray travelling in direction d, the facet normal m is distributed
as the visible normals from v = −d, D_v(m) = ⟨v, m⟩⁺ D(m) / ∫⟨v, m⟩⁺ D dm (v may point below
the horizon after a bounce), and the ray leaves in wo = 2(v·m)m − v with weight F(v·m)
(exact Fresnel, ``fresnel.fresnel``; 1 for the mirror). The distribution draws them
(``Beckmann.sample_visible``, ``GGX.sample_visible``: ``microsim.analytic.ndf``, "Visible
normals").

*Order 1.* The first hit is at τ₁ ~ Exp(1 + Λ(wi)), m ~ D_wi, and the path escapes from τ₁ with
probability E[e^{−Λ(wo)τ₁}] = (1 + Λ(wi))/(1 + Λ(wi) + Λ(wo)); with the reflection Jacobian
1/(4 wi·m) the density of wo is F D(m)/(4 cos θi (1 + Λ(wi) + Λ(wo))) = f cos θo with
f = F D G2/(4 cos θi cos θo), G2 = 1/(1 + Λ(wi) + Λ(wo)): Torrance–Sparrow with
height-correlated Smith shadowing, exactly (tests/test_multiple_scattering_models.py).

*Anisotropic surfaces* (re-derived here). Nothing above needs D to be isotropic; it needs
(i) the Smith Λ of each flight direction and (ii) visible normals of D from each view. (i) The
Smith microsurface keeps heights uncorrelated with slopes whatever D is, so along a straight
flight in direction w the masking from height h is still C1(h)^Λ(w), with Λ(w) Smith's Λ of
*that* direction. For a stretched (αx, αy, rotation) distribution that is the isotropic Λ at
the projected roughness α(φ'_w) (``anisotropic`` module docstring) — exact, not an
approximation, because Λ(w) depends on D only through the 1-D distribution of the slope along
w's azimuth. Λ is constant along one flight, so the τ-form of the free flight holds unchanged,
with Λ looked up per path and per flight; α(φ') = α(φ' + 180°), so Λ(−w) for a downward w is
Λ of (w_x, w_y, |w_z|), as in the isotropic case. (ii) ``AnisotropicX.sample_visible``
stretches the view to unit roughness, samples the isotropic unit-roughness visible normals
(the distributions' samplers) and unstretches. That is exact for views on either side of the
horizon: slopes map linearly, s = diag(αx, αy) s' in the NDF's frame, so the slope density is
the unit one stretched, and ⟨v, m⟩ ∝ v_z − v_x s_x − v_y s_y is the same linear form in s' for the
stretched view v' = (αx v_x, αy v_y, v_z); hence ⟨v, m⟩⁺ D(m) dω maps to ⟨v', m'⟩⁺ D₁(m') dω'
(D₁ the unit-roughness isotropic NDF) up to a constant factor. The projected-area identity
∫⟨v, m⟩⁺ D dm = (1 + Λ(v)) v_z holds with the exact Λ (tests/test_anisotropic.py), so order 1
is Torrance–Sparrow with the anisotropic D and G2 = 1/(1 + Λ(wi) + Λ(wo)), each Λ at its own
azimuth (tests/test_anisotropic_walk.py; the isotropic equivalent α = √(αx αy) walks a
different surface). ``WalkNDF`` holds what the walk asks of an NDF.

*Dielectric interface* (Heitz et al. 2016, Sec. 5; ``transmission=True``). Air (index 1) above,
a medium of real index η below; the Smith microsurface is seen from both sides. Seen from below
(through the point reflection w → −w) it is again a Smith microsurface with the same D and Λ,
whose heights are the mirrored ones: a point at height h with C1(h) = e^{−τ} lies at depth
τ' = −ln(1 − C1(h)) = −ln(1 − e^{−τ}) for the other side. The walker keeps its direction and
depth in the frame of its side (the side's surface "above"), so free flights are those above.
At a hit from direction v (in the side's frame) on a facet m ~ D_v it reflects with the
probability F(v·m) of the exact dielectric Fresnel reflectance for the relative index η
(from the air) or 1/η (from the medium; total internal reflection: F = 1), else it refracts
by Snell's law into t = −v/η_r + (v·m/η_r − cos θt) m and continues on the other side:
direction −t, depth τ'. This Russian roulette keeps every path's weight 1, so each path
leaves up (into the air) or down (into the medium) with weight 1, or is cut: R + T + cut = 1
path by path. Order 1 is Walter et al. 2007's BSDF (eq. 20, 21) with height-correlated
Smith masking: G2 = 1/(1 + Λ(i) + Λ(o)) for reflection as above, and for refraction
E[(1 − e^{−τ₁})^{Λ(o)}] = (1 + Λ(i)) B(1 + Λ(i), 1 + Λ(o)), τ₁ ~ Exp(1 + Λ(i)), i.e.
G2 = B(1 + Λ(i), 1 + Λ(o)) (B the Beta function; Heitz 2014's height-correlated form for
transmission), Λ(o) that of the upward direction on o's side
(tests/test_dielectric_walk.py). ``dielectric_walk_bin_averages`` bins the exits like the
simulation's dielectric estimator (docs/dielectric.md): θo from the pole of the side the
light leaves by, Δφ = φo − φi of the direction itself (specular reflection and refraction
both at Δφ = 180°). Its bin averages are fractions of the incident flux per unit projected
solid angle: the BTDF in the radiance convention (Walter et al. 2007, eq. 21), which obeys
f_t(i, o)/η_o² = f_t(o, i)/η_i².

*Energy.* With F = 1 every path eventually leaves (the walk on a Smith microsurface conserves
energy; Heitz et al. 2016), so the escaping energy is 1 up to the paths cut at
``max_bounces``, which are reported.

Bins: a ``microsim.bins.Bins`` grid over θo and the relative azimuth Δφ = φo − φi, the mirror
direction at Δφ = 180°; ``Bins.locate`` bins each path's exit direction (the simulation's own
rule) and ``Bins.projected_solid_angle`` gives each bin's Ω_B. Folded bins hold |Δφ| ∈ [0°,
180°], each bin's Ω_B counting both halves. An anisotropic NDF has no mirror symmetry about the
plane of incidence unless φi lies along one of its axes; elsewhere a folded bin holds the mean
of f over ±Δφ (what a folded simulation measures) and full-azimuth bins resolve f. A bin
average is the energy escaping into the bin per incident path divided by Ω_B:
f̄_B = (1/Ω_B) ∫_B f cos θo dω_o in sr⁻¹.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
from scipy import special

from microsim import checks as _checks
from microsim import vectors
from microsim.bins import Bins
from microsim.errors import UsageError

from .anisotropic import AnisotropicNDF
from .fresnel import fresnel, resolve_material
from .ndf import GGX, Beckmann
from .student_t import StudentT

__all__ = [
    "HEIGHT_DISTRIBUTIONS",
    "height_from_tau",
    "tau_from_height",
    "walk_alpha",
    "WALK_NDFS",
    "WalkNDF",
    "sample_visible_normals",
    "visible_projected_area",
    "WalkPaths",
    "smith_random_walk",
    "WalkBinAverages",
    "walk_bin_averages",
    "DielectricWalkBinAverages",
    "dielectric_walk_bin_averages",
]

HEIGHT_DISTRIBUTIONS = ("uniform", "gaussian")
"""Height distributions of ``height_from_tau``: uniform on [−1, 1], standard normal."""

_SQRT_PI = np.sqrt(np.pi)


# --- heights -----------------------------------------------------------------------------------
def _check_heights(heights: str) -> str:
    if heights not in HEIGHT_DISTRIBUTIONS:
        raise UsageError(
            f"heights must be one of {', '.join(map(repr, HEIGHT_DISTRIBUTIONS))}, got {heights!r}"
        )
    return heights


def height_from_tau(tau, heights: str = "uniform"):
    """Height h with −ln C1(h) = τ (τ ≥ 0; the walk's depth variable) for ``heights``
    "uniform" (P1 uniform on [−1, 1]: h = 2e^{−τ} − 1) or "gaussian" (standard normal:
    h = Φ⁻¹(e^{−τ}), by ``scipy.special.ndtri_exp``). τ = 0 is the top (h = 1, resp. +∞).
    Uniform heights lose τ's digits near the top and bottom (h = −1 exactly for τ ≳ 37); the
    walk runs in τ and never needs h."""
    heights = _check_heights(heights)
    t = np.asarray(tau, dtype=np.float64)
    if np.any(t < 0) or np.any(np.isnan(t)):
        raise UsageError("tau must be >= 0 (tau = -ln C1(h))")
    if heights == "uniform":
        return 2.0 * np.exp(-t) - 1.0
    return special.ndtri_exp(-t)


def tau_from_height(h, heights: str = "uniform"):
    """τ = −ln C1(h), the inverse of ``height_from_tau`` (uniform: h ∈ [−1, 1]; gaussian: any h,
    by ``scipy.special.log_ndtr``)."""
    heights = _check_heights(heights)
    h = np.asarray(h, dtype=np.float64)
    if heights == "uniform":
        if np.any((h < -1) | (h > 1)) or np.any(np.isnan(h)):
            raise UsageError("h must lie in [-1, 1] for uniform heights")
        with np.errstate(divide="ignore"):
            return -np.log(0.5 * (h + 1.0))
    return -special.log_ndtr(h)


# --- NDF ---------------------------------------------------------------------------------------
def walk_alpha(ndf) -> tuple[str, float]:
    """(name, α) of an isotropic NDF the walk supports ("beckmann" with α = m, "ggx",
    "student-t"), else UsageError (the walk itself also takes anisotropic ones: ``WalkNDF``)."""
    if isinstance(ndf, Beckmann):
        return ndf.name, float(ndf.m)
    if isinstance(ndf, (GGX, StudentT)):
        return ndf.name, float(ndf.alpha)
    raise UsageError(
        f"ndf must be an isotropic Beckmann, GGX or Student-t NDF (closed Smith Λ and "
        f"visible-normal sampling), got {ndf!r}"
    )


WALK_NDFS = (
    "Beckmann",
    "GGX",
    "StudentT",
    "AnisotropicBeckmann",
    "AnisotropicGGX",
    "AnisotropicStudentT",
)
"""The NDFs the walk takes: those with a closed Smith Λ of every direction and an exact
visible-normal sampler for views on either side of the horizon."""


def _lambda_up(ndf, cos_abs):
    """Smith Λ of the upward direction with |cos θ| = cos_abs ∈ [0, 1] (inf at 0), isotropic."""
    return ndf.smith_lambda_cos(np.clip(cos_abs, 0.0, 1.0))


def _walk_family(ndf) -> tuple[str, float | None]:
    """(family, isotropic α or None) of an NDF of ``WALK_NDFS``, else UsageError."""
    if isinstance(ndf, (Beckmann, GGX, StudentT)):
        return walk_alpha(ndf)
    if isinstance(ndf, AnisotropicNDF):
        return walk_alpha(ndf.isotropic_equivalent())[0], None
    raise UsageError(
        f"ndf must be one of {', '.join(WALK_NDFS)} (the random walk needs the Smith Λ of "
        f"every direction and visible-normal sampling), got {ndf!r}"
    )


@dataclass(frozen=True)
class WalkNDF:
    """What the walk asks of its NDF (module docstring, "Anisotropic surfaces"): the Smith Λ of
    a flight direction (``lambda_up``), the projected area at the horizon (``horizon_area``)
    and visible normals (``visible``). ``ndf``: one of ``WALK_NDFS``; ``family``: "beckmann" |
    "ggx" | "student-t"; ``alpha``: the isotropic roughness (α = m for Beckmann), None for an
    anisotropic NDF (checked against ``ndf``; ``WalkNDF.of(ndf)`` fills them in). Visible
    normals come from the distribution's own sampler (``sample_visible``)."""

    ndf: object
    family: str
    alpha: float | None

    def __post_init__(self):
        family, alpha = _walk_family(self.ndf)
        if (self.family, self.alpha) != (family, alpha):
            raise UsageError(
                f"family and alpha must be those of ndf {self.ndf!r}: {family!r} and {alpha!r} "
                f"(use WalkNDF.of(ndf)), got {self.family!r} and {self.alpha!r}"
            )

    @classmethod
    def of(cls, ndf) -> WalkNDF:
        """``WalkNDF`` of ``ndf`` (returned as is if it is one); UsageError naming the allowed
        NDFs for any other."""
        if isinstance(ndf, WalkNDF):
            return ndf
        return cls(ndf, *_walk_family(ndf))

    def lambda_up(self, w):
        """Smith Λ of the upward direction (w_x, w_y, |w_z|) for unit w (..., 3): Λ(w) for
        w_z ≥ 0 and Λ(−w) for w_z < 0 (turning the azimuth through 180° leaves Λ unchanged);
        +inf at the horizon, 0 along ±n."""
        if self.alpha is not None:
            return _lambda_up(self.ndf, np.abs(w[..., 2]))
        up = np.stack([w[..., 0], w[..., 1], np.abs(w[..., 2])], axis=-1)
        return self.ndf.smith_lambda_w(up)

    def horizon_area(self, w):
        """lim Λ cos θ at the horizon in w's azimuth (the distribution's ``horizon_area``; for
        an anisotropic one that of its unit-roughness member times the roughness w sees)."""
        if self.alpha is not None:
            return self.ndf.horizon_area
        return self.ndf.isotropic_at(1.0).horizon_area * self.ndf.projected_alpha(w)

    def visible(self, v, u1, u2):
        """Facet normals m ~ D_v(m) for unit views v (N, 3) of either hemisphere and uniforms
        u1 ∈ (0, 1], u2 ∈ (0, 1) of shape (N,), without re-checking the inputs: the
        distribution's own sampler."""
        return self.ndf._sample_visible(v, u1, u2)


def visible_projected_area(v, ndf):
    """∫ ⟨v, m⟩⁺ D(m) dm for unit v of any sign of v_z: (1 + Λ(v)) v_z for v_z ≥ 0 and
    Λ(−v) |v_z| for v_z < 0 (Smith's projected-area identity), the normaliser of D_v.
    ``ndf``: one of ``WALK_NDFS`` (anisotropic: Λ at the direction's azimuth)."""
    v = _checks.directions("v", v)
    c = v[..., 2]
    walk = WalkNDF.of(ndf)
    lam = walk.lambda_up(v)
    with np.errstate(invalid="ignore"):
        out = np.where(c >= 0, (1.0 + lam) * c, lam * np.abs(c))
    # at the horizon Λ|v_z| → α/(2√π) (Beckmann), α/2 (GGX), K(γ)α (Student-t), α the
    # roughness v sees
    return np.where(c == 0.0, walk.horizon_area(v), out)


def sample_visible_normals(v, ndf, u1, u2):
    """Facet normals m ~ D_v(m) = ⟨v, m⟩⁺ D(m) / ∫⟨v, m'⟩⁺ D dm' for unit view directions v
    (N, 3) of either hemisphere (not straight down) and uniforms u1, u2 ∈ (0, 1) of shape (N,):
    ``ndf.sample_visible(v, u1, u2)`` for one of ``WALK_NDFS``."""
    return WalkNDF.of(ndf).ndf.sample_visible(v, u1, u2)


# --- the walk ----------------------------------------------------------------------------------
@dataclass(frozen=True)
class WalkPaths:
    """Outcome of ``smith_random_walk`` per path (arrays of length N).

    ``wo``: exit direction (unit, upper hemisphere — either hemisphere for the dielectric walk;
    NaN for paths cut off); ``weight``: the
    energy it carries out (product of the Fresnel factors; 0 if cut off); ``order``: number of
    reflections before it left (0 if cut off); ``absorbed``: energy lost to Fresnel absorption
    along the path; ``cut``: energy still on the surface after ``max_bounces`` reflections.
    Per path, weight + absorbed + cut = 1 up to rounding.
    """

    wo: np.ndarray
    weight: np.ndarray
    order: np.ndarray
    absorbed: np.ndarray
    cut: np.ndarray


def smith_random_walk(
    wi, ndf, material=None, rng=None, max_bounces: int = 256, transmission: bool = False
) -> WalkPaths:
    """Random walk of Heitz et al. 2016 on a Smith microsurface, one path per row of ``wi``.

    ``wi``: unit incident directions (N, 3) pointing to the light, z > 0, any azimuth (with an
    anisotropic NDF the azimuth relative to its axes matters). ``ndf``: one of ``WALK_NDFS``
    (or a ``WalkNDF``): Λ of every flight direction and the visible normals from the NDF
    (module docstring, "Anisotropic surfaces"). ``material``: None (mirror) or anything
    ``fresnel.resolve_material`` accepts (conductor or dielectric treated as reflector only).
    ``rng``: numpy Generator or seed. All live paths advance together (one NumPy step per
    reflection order).

    ``transmission=True``: the interface between air above and a medium of real index
    ``material`` below (module docstring, "Dielectric interface"): wi on either side
    (wi_z < 0: lit from inside the medium), every event reflects or refracts by Russian
    roulette on the exact Fresnel reflectance, and ``wo`` may lie below (light leaving into
    the medium).
    """
    walk = WalkNDF.of(ndf)
    eta = resolve_material(material)
    wi = _checks.directions("wi", wi)
    if wi.ndim != 2:
        raise UsageError(f"wi must have shape (N, 3), got {wi.shape}")
    if not isinstance(transmission, (bool, np.bool_)):
        raise UsageError(f"transmission must be True or False, got {transmission!r}")
    if transmission:
        eta = _dielectric_index(eta)
        if np.any(wi[:, 2] == 0):
            raise UsageError("wi must not lie on the horizon (z != 0)")
    elif np.any(wi[:, 2] <= 0):
        raise UsageError("wi must point above the horizon (z > 0)")
    max_bounces = _checks.integer("max_bounces", max_bounces, 1, 10**6)
    rng = np.random.default_rng(rng)
    n = len(wi)
    out_wo = np.full((n, 3), np.nan)
    out_w = np.zeros(n)
    out_k = np.zeros(n, dtype=np.int64)
    absorbed = np.zeros(n)
    cut = np.zeros(n)

    idx = np.arange(n)
    d = -wi.copy()  # ray direction (for the dielectric: in the frame of its side)
    side = np.where(wi[:, 2] > 0, 1.0, -1.0) if transmission else None
    if transmission:
        d *= side[:, None]
    tau = np.zeros(n)
    w = np.ones(n)
    for k in range(1, max_bounces + 1):
        # next intersection (or escape) of rays leaving the previous order
        e = rng.standard_exponential(len(idx))
        cz = d[:, 2]
        lam = walk.lambda_up(d)
        up = cz > 0
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            esc = up & ~(lam * tau > e)  # escape when Exp(Λ) flight ≥ τ (Λ = 0: always)
            tau_up = tau - e / lam
            tau_dn = tau + e / (1.0 + lam)
        if k > 1 and np.any(esc):
            j = idx[esc]
            out_wo[j] = d[esc] if side is None else d[esc] * side[esc, None]
            out_w[j], out_k[j] = w[esc], k - 1
        keep = ~esc
        idx, d, w = idx[keep], d[keep], w[keep]
        tau = np.where(up, tau_up, tau_dn)[keep]
        tau = np.maximum(tau, 0.0)
        if side is not None:
            side = side[keep]
        if len(idx) == 0:
            break
        # reflection (or refraction) at order k
        v = -d
        m = walk.visible(
            v,
            np.clip(1.0 - rng.random(len(idx)), 1e-300, 1.0),
            np.clip(rng.random(len(idx)), 1e-16, 1 - 1e-16),
        )
        vm = np.clip(np.einsum("ij,ij->i", v, m), 0.0, 1.0)
        if transmission:
            d, side, tau = _dielectric_event(v, m, vm, side, tau, eta, rng)
            continue
        d = 2.0 * vm[:, None] * m - v
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        if eta is not None:
            f = fresnel(vm, eta)
            absorbed[idx] += w * (1.0 - f)
            w = w * f
    if len(idx):  # paths that reflected max_bounces times without leaving
        cut[idx] = w
    return WalkPaths(out_wo, out_w, out_k, absorbed, cut)


def _dielectric_index(eta) -> float:
    """The real index η ≠ 1 of the medium of a dielectric walk, else UsageError."""
    if eta is None or isinstance(eta, complex) or eta == 1.0:
        raise UsageError(
            "material must be a real index of refraction > 0, != 1 (the medium below) for "
            f"transmission=True, got {eta!r}"
        )
    return float(eta)


def _dielectric_event(v, m, vm, side, tau, eta: float, rng):
    """One event of the dielectric walk at facets ``m`` seen from ``v`` (side frames, vm = v·m):
    reflect with the probability F(vm) of the relative index η (side +1) or 1/η (side −1),
    total internal reflection included, else refract (Snell) and continue on the other side
    of the microsurface: direction −t, side −side, depth τ' = −ln(1 − e^{−τ}) (module
    docstring, "Dielectric interface"). Returns (d, side, τ)."""
    outside = side > 0
    f = np.empty_like(vm)
    f[outside] = fresnel(vm[outside], eta)
    f[~outside] = fresnel(vm[~outside], 1.0 / eta)
    refract = rng.random(len(vm)) >= f
    d = 2.0 * vm[:, None] * m - v
    if np.any(refract):
        rel = np.where(outside, eta, 1.0 / eta)[refract]
        t, _ = vectors.refract(v[refract], m[refract], rel, vm[refract])
        d[refract] = -t
        side = np.where(refract, -side, side)
        flipped = -np.log(-np.expm1(-np.maximum(tau[refract], 1e-300)))
        tau = tau.copy()
        tau[refract] = flipped
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return d, side, tau


# --- bin averages ------------------------------------------------------------------------------
def _bins_of_edges(theta_edges, phi_edges, folded) -> Bins:
    """The ``Bins`` with these edges (degrees) and folding, for ``walk_bin_averages``'s older
    form (DeprecationWarning); UsageError for edges that no ``Bins`` has."""
    te = np.asarray(theta_edges, dtype=np.float64)
    pe = np.asarray(phi_edges, dtype=np.float64)
    folded = True if folded is None else folded
    bins = None
    if te.ndim == 1 and pe.ndim == 1 and len(te) >= 2 and len(pe) >= 3:
        bins = Bins(len(te) - 1, len(pe) - 1, folded)
    same = bins is not None and all(
        np.allclose(mine, theirs, rtol=0.0, atol=1e-9)
        for mine, theirs in ((bins.theta_edges, te), (bins.phi_edges, pe))
    )
    if not same:
        raise UsageError(
            "bins must be a microsim.bins.Bins (theta_edges and phi_edges are taken only as "
            "the edges of one: θo uniform over [0°, 90°], Δφ as Bins(n_theta, n_phi, folded) "
            f"builds them), got theta_edges {theta_edges!r} and phi_edges {phi_edges!r}"
        )
    warnings.warn(
        "walk_bin_averages(theta_i, theta_edges, phi_edges, ndf, ..., folded=) is deprecated: "
        "pass the Bins, walk_bin_averages(theta_i, bins, ndf, ...)",
        DeprecationWarning,
        stacklevel=3,
    )
    return bins


@dataclass(frozen=True)
class WalkBinAverages:
    """Bin averages of the walk, per incidence and scattering order.

    ``theta_i``: incidence angles (degrees), shape (I,); ``orders``: labels of the order axis
    ("1", "2", …, "≥K"); ``values``/``stderr``: f̄_B in sr⁻¹, shape (I, K, n_theta, n_phi);
    ``energy``/``energy_stderr``: escaping energy per order and incident path (I, K);
    ``absorbed``/``absorbed_stderr``, ``cut``: (I,) energy absorbed by Fresnel losses and energy
    of paths cut at ``max_bounces``; ``max_order``: the highest order seen per incidence;
    ``n_paths``: paths per incidence; ``omega``: Ω_B (sr), ``Bins.projected_solid_angle``.
    ``multiple_energy``/``multiple_stderr``: energy escaping in orders ≥ 2 (I,); ``phi_i``: the
    incidence azimuths (degrees, (I,)) the bins' Δφ is measured from. Standard errors are those of a
    mean over i.i.d. paths.
    """

    theta_i: np.ndarray
    orders: tuple
    values: np.ndarray
    stderr: np.ndarray
    energy: np.ndarray
    energy_stderr: np.ndarray
    absorbed: np.ndarray
    absorbed_stderr: np.ndarray
    cut: np.ndarray
    max_order: np.ndarray
    n_paths: int
    omega: np.ndarray

    multiple_energy: np.ndarray
    multiple_stderr: np.ndarray
    phi_i: np.ndarray | None = None


def walk_bin_averages(
    theta_i,
    bins: Bins,
    ndf,
    material=None,
    *legacy,
    n_paths: int = 1_000_000,
    orders: int = 4,
    seed=0,
    max_bounces: int = 256,
    chunk: int = 2**18,
    phi_i: float = 0.0,
    folded: bool | None = None,
) -> WalkBinAverages:
    """Heitz et al. 2016 random-walk BRDF averaged over the ``bins`` (a ``Bins``), per
    scattering order.

    ``theta_i``: incidence angles in degrees (scalar or 1-D, each in [0, 90)); ``phi_i``: the
    incidence azimuth in degrees (finite, any value; or one per θi), in the surface frame, where an
    anisotropic NDF's x axis lies at its ``rotation``: wi = (sin θi cos φi, sin θi sin φi,
    cos θi), and the bins' Δφ = φo − φi (module docstring; an anisotropic NDF wants
    ``folded=False`` bins unless φi lies on one of its axes). ``ndf``: one of ``WALK_NDFS``.
    ``orders``: K ≥ 1 tallies orders 1 … K − 1 separately and K and above together ("≥K").
    ``n_paths`` per incidence, processed ``chunk`` at a time; ``seed``: anything
    ``numpy.random.default_rng`` takes (one generator for the whole call: the same seed,
    incidences, φi and ``chunk`` give the same result bit for bit). Returns
    ``WalkBinAverages``.

    The older form ``walk_bin_averages(theta_i, theta_edges, phi_edges, ndf, material,
    folded=...)`` still works, with a DeprecationWarning, where the edges are those of a
    ``Bins``.
    """
    bins, ndf, material = _walk_arguments(bins, ndf, material, legacy, folded)
    walk = WalkNDF.of(ndf)
    thetas, phis = _walk_incidences(theta_i, phi_i)
    n_paths = _checks.integer("n_paths", n_paths, 2, 10**11)
    orders = _checks.integer("orders", orders, 1, 1000)
    chunk = _checks.integer("chunk", chunk, 1, 2**24)
    rng = np.random.default_rng(seed)
    omega = bins.projected_solid_angle()
    sums = _WalkSums(len(thetas), orders, omega.size)
    for a, th in enumerate(thetas):
        phi_i = float(phis[a])
        wi1 = _incidence(th, phi_i)
        done = 0
        while done < n_paths:
            m = min(chunk, n_paths - done)
            p = smith_random_walk(np.broadcast_to(wi1, (m, 3)), walk, material, rng, max_bounces)
            done += m
            sums.add(a, p, bins.locate(p.wo[p.order > 0], phi_i))
    return sums.averages(thetas, phis, n_paths, omega)


def _incidence(theta_deg: float, phi_deg: float) -> np.ndarray:
    """The unit incident direction at θi, φi (degrees); wi_y exactly 0 at φi = 0."""
    t = np.radians(theta_deg)
    if phi_deg == 0.0:
        return np.array([np.sin(t), 0.0, np.cos(t)])
    ph = np.radians(phi_deg)
    return np.array([np.sin(t) * np.cos(ph), np.sin(t) * np.sin(ph), np.cos(t)])


@dataclass(frozen=True)
class DielectricWalkBinAverages:
    """Bin averages of the dielectric walk (``dielectric_walk_bin_averages``) per incidence and
    scattering order, for the two hemispheres.

    ``reflected``: the light leaving on the incidence's side (its ``values``: the BRDF's bin
    averages, sr⁻¹, shape (I, K, n_theta, n_phi); ``energy``: the reflected energy per order);
    ``transmitted``: the light leaving on the other side (the BTDF, radiance convention), both
    ``WalkBinAverages`` on the same bins and orders (their ``absorbed`` and ``cut`` are 0: the
    walk absorbs nothing, and the paths cut off are counted here). ``R``, ``T``: reflected and
    transmitted fractions of the incident flux per incidence (I,), summed over orders, with
    ``R_stderr``, ``T_stderr``; ``cut``: the fraction of paths cut at ``max_bounces``. Every path
    is in exactly one of R, T and cut, so R + T + cut = 1 up to rounding.
    """

    reflected: WalkBinAverages
    transmitted: WalkBinAverages
    R: np.ndarray
    R_stderr: np.ndarray
    T: np.ndarray
    T_stderr: np.ndarray
    cut: np.ndarray

    @property
    def theta_i(self) -> np.ndarray:
        """The incidence angles (degrees; (90, 180]: from inside the medium)."""
        return self.reflected.theta_i


def dielectric_walk_bin_averages(
    theta_i,
    bins: Bins,
    ndf,
    eta,
    *,
    n_paths: int = 1_000_000,
    orders: int = 4,
    seed=0,
    max_bounces: int = 256,
    chunk: int = 2**18,
    phi_i: float = 0.0,
) -> DielectricWalkBinAverages:
    """Heitz et al. 2016's dielectric random walk (``smith_random_walk(...,
    transmission=True)``) averaged over ``bins`` per scattering order, reflected and
    transmitted.

    ``theta_i``: incidence angles in degrees, in [0, 90) (light from the air) or (90, 180]
    (light from inside the medium, wi_z < 0); ``eta``: the medium's real index (air above has
    1). Each exit is binned on its own side (module docstring, "Dielectric interface"): θo
    from the pole of the side it leaves by, Δφ = φo − φi of the direction itself. The other
    arguments are ``walk_bin_averages``'s (the same seed, incidences, φi and ``chunk`` give the
    same result bit for bit). Returns ``DielectricWalkBinAverages``.
    """
    if not isinstance(bins, Bins):
        raise UsageError(f"bins must be a microsim.bins.Bins, got {type(bins).__name__}")
    eta = _dielectric_index(resolve_material(eta))
    walk = WalkNDF.of(ndf)
    thetas, phis = _walk_incidences(theta_i, phi_i, below=True)
    n_paths = _checks.integer("n_paths", n_paths, 2, 10**11)
    orders = _checks.integer("orders", orders, 1, 1000)
    chunk = _checks.integer("chunk", chunk, 1, 2**24)
    rng = np.random.default_rng(seed)
    omega = bins.projected_solid_angle()
    sums = {side: _WalkSums(len(thetas), orders, omega.size) for side in ("r", "t")}
    cut = np.zeros(len(thetas))
    for a, th in enumerate(thetas):
        phi_a = float(phis[a])
        wi1 = _incidence(th, phi_a)
        done = 0
        while done < n_paths:
            m = min(chunk, n_paths - done)
            p = smith_random_walk(
                np.broadcast_to(wi1, (m, 3)), walk, eta, rng, max_bounces, transmission=True
            )
            done += m
            left = p.order > 0
            same = left & (np.sign(np.nan_to_num(p.wo[:, 2])) == np.sign(wi1[2]))
            for side, mine in (("r", same), ("t", left & ~same)):
                wo = p.wo[mine]  # θo from the pole of its own side
                wo[:, 2] = np.abs(wo[:, 2])
                sums[side].add(a, _exits(p, mine), bins.locate(wo, phi_a))
            cut[a] += p.cut.sum()
    n = float(n_paths)
    (r, r_se), (t, t_se) = (_total_energy(sums[side], n) for side in ("r", "t"))
    return DielectricWalkBinAverages(
        sums["r"].averages(thetas, phis, n_paths, omega),
        sums["t"].averages(thetas, phis, n_paths, omega),
        r,
        r_se,
        t,
        t_se,
        cut / n,
    )


def _exits(p: WalkPaths, mine: np.ndarray) -> WalkPaths:
    """The paths ``p`` with only the exits ``mine`` kept (nothing absorbed or cut)."""
    zero = np.zeros_like(p.weight)
    return WalkPaths(p.wo, p.weight, np.where(mine, p.order, 0), zero, zero)


def _total_energy(sums: "_WalkSums", n: float):
    """Mean and standard error of the energy summed over orders (each path leaves in one order
    at most, so its squared total is the sum of its squared per-order tallies)."""
    mean = sums.e1.sum(axis=1) / n
    var = np.maximum(sums.e2.sum(axis=1) / n - mean * mean, 0.0) / (n - 1.0)
    return mean, np.sqrt(var)


def _walk_arguments(bins, ndf, material, legacy, folded):
    """(bins, ndf, material) of ``walk_bin_averages``'s arguments, its older edge form
    (theta_edges, phi_edges, ndf, material) included."""
    if not isinstance(bins, Bins):
        if len(legacy) > 1:
            raise UsageError("walk_bin_averages: pass n_paths, orders, ... by keyword")
        return _bins_of_edges(bins, ndf, folded), material, (legacy[0] if legacy else None)
    if legacy or folded is not None:
        raise UsageError(
            "walk_bin_averages takes theta_i, bins, ndf and material by position, the rest "
            "by keyword; the folding is the bins' (Bins(..., folded=))"
        )
    return bins, ndf, material


def _walk_incidences(theta_i, phi_i, below: bool = False):
    """θi (degrees, 1-D, each in [0, 90), or also in (90, 180] if ``below``) and φi broadcast
    to it, checked."""
    thetas = np.atleast_1d(np.asarray(theta_i, dtype=np.float64))
    inside = (thetas >= 0) & (thetas < 90)
    if below:
        inside |= (thetas > 90) & (thetas <= 180)
    if thetas.ndim != 1 or np.any(~inside):
        allowed = "[0, 90) (from above) or (90, 180] (from inside)" if below else "[0, 90)"
        raise UsageError(f"theta_i must be angles in degrees within {allowed}, got {theta_i!r}")
    phis = np.atleast_1d(np.asarray(phi_i, dtype=np.float64))
    if phis.ndim != 1 or phis.size not in (1, thetas.size) or not np.all(np.isfinite(phis)):
        raise UsageError(
            f"phi_i must be a finite azimuth in degrees, or one per θi ({thetas.size}), "
            f"got {phi_i!r}"
        )
    return thetas, np.broadcast_to(phis, thetas.shape)


class _WalkSums:
    """Running sums of the walk's escaping weights (and their squares) per incidence, order
    and bin; of the energy per order, in orders ≥ 2, absorbed and cut."""

    def __init__(self, n_i: int, orders: int, nb: int):
        self.orders, self.nb = orders, nb
        self.s1, self.s2 = np.zeros((n_i, orders, nb)), np.zeros((n_i, orders, nb))
        self.e1, self.e2 = np.zeros((n_i, orders)), np.zeros((n_i, orders))
        self.ms1, self.ms2 = np.zeros(n_i), np.zeros(n_i)
        self.a1, self.a2, self.cut = np.zeros(n_i), np.zeros(n_i), np.zeros(n_i)
        self.kmax = np.zeros(n_i, dtype=np.int64)

    def add(self, a: int, p: WalkPaths, b: np.ndarray) -> None:
        """Add the paths ``p`` of incidence ``a``; ``b``: the bins of its escaping paths."""
        orders, nb = self.orders, self.nb
        esc = p.order > 0
        kk = np.minimum(p.order[esc], orders) - 1
        ww = p.weight[esc]
        inb = b >= 0
        key = kk[inb] * nb + b[inb]
        self.s1[a] += np.bincount(key, ww[inb], minlength=orders * nb).reshape(orders, nb)
        self.s2[a] += np.bincount(key, ww[inb] ** 2, minlength=orders * nb).reshape(orders, nb)
        self.e1[a] += np.bincount(kk, ww, minlength=orders)
        self.e2[a] += np.bincount(kk, ww**2, minlength=orders)
        ms = ww[p.order[esc] >= 2]
        self.ms1[a] += ms.sum()
        self.ms2[a] += np.sum(ms**2)
        self.a1[a] += p.absorbed.sum()
        self.a2[a] += np.sum(p.absorbed**2)
        self.cut[a] += p.cut.sum()
        if esc.any():
            self.kmax[a] = max(self.kmax[a], int(p.order.max()))

    def averages(self, thetas, phis, n_paths: int, omega) -> "WalkBinAverages":
        """Means over the ``n_paths`` i.i.d. paths per incidence with their standard errors;
        bin sums divided by Ω_B."""
        n = float(n_paths)

        def mean_se(s, q):
            mean = s / n
            var = np.maximum(q / n - mean * mean, 0.0) / (n - 1.0)
            return mean, np.sqrt(var)

        orders = self.orders
        f1, fse = mean_se(self.s1, self.s2)
        shape = (len(thetas), orders) + omega.shape
        energy, energy_se = mean_se(self.e1, self.e2)
        absorbed, absorbed_se = mean_se(self.a1, self.a2)
        ms, ms_se = mean_se(self.ms1, self.ms2)
        labels = tuple(str(k) for k in range(1, orders)) + (f"≥{orders}",)
        return WalkBinAverages(
            thetas,
            ("≥1",) if orders == 1 else labels,
            (f1 / omega.ravel()).reshape(shape),
            (fse / omega.ravel()).reshape(shape),
            energy,
            energy_se,
            absorbed,
            absorbed_se,
            self.cut / n,
            self.kmax,
            n_paths,
            omega,
            ms,
            ms_se,
            phis.copy(),
        )
