"""Edwards et al. 2006, *The halfway vector disk for BRDF modeling*.

Equation, figure and section numbers below refer to that paper. Framework (eq. 9–13). For a
fixed outgoing direction wo, the unnormalised half vectors H = wi + wo of all upper-hemisphere
wi form the unit hemisphere translated to the tip of wo (Fig. 3). A projection maps them
bijectively onto the base of that hemisphere: the unit-radius disk in the plane z = cos θo
centred at wo. Points of the disk are written in (u, v) = their x, y
coordinates, so (u, v) = (0, 0) is Ĥ = n, mirror reflection, in both projections; the disk's
centre ``disk_centre(wo)`` = (wo_x, wo_y) is retro-reflection (wi = wo) in the scaling projection
(§3.1) but wi = n in the orthogonal one (Fig. 4; Fig. 13: "the disk shifts ... because it is
centred on wo in (u, v) space"). Any density p(u, v) on the disk defines

    f(wi, wo) = p(u(wi)) · J(wi, wo) / cos θi,      J = dA_disk / dω_i   (eq. 11)

whose cosine-weighted albedo ∫ f cos θi dω_i = ∫_disk p dA = 1 for every wo: the BRDF conserves
energy exactly. Here J is the Jacobian with respect to the incident solid angle, i.e. the
paper's dμ/dΩ(H) (eq. 19, 23) times dΩ(H)/dω_i = 1/(4 wi·Ĥ) (eq. 8).

Projections: scaling (eq. 15–21, central projection of H from the origin onto the disk plane) and
orthogonal (eq. 22–25, projection along the normal; then u, v = wo_xy + wi_xy and J = cos θi, so
the orthogonal BRDF is simply p(u, v) — eq. 24's factor |wi+wo|²/(4(wi·Ĥ)²) ≡ 1 because
|wi + wo| = 2 wi·Ĥ).

Densities: lumps (eq. 26–27, sampled by eq. 28–29) and their weighted sums (eq. 32, 35).
Models: the energy-conserving empirical BRDF (eq. 30–33) and the data-fitting BRDF (eq. 34–36).

Reciprocity: neither model is reciprocal — the framework enforces energy conservation "at the cost
of reciprocity" (§1, §6, Fig. 14): f(wi, wo) ≠ f(wo, wi) in general.

Conventions: local frame with the macro normal +z; unit directions of shape (..., 3) pointing away
from the surface; (u, v) points of shape (..., 2); BRDFs and densities in solid angle in sr⁻¹,
disk densities per unit disk area. All functions broadcast over leading axes. Arguments come
directions first: ``(wi, wo, ...)`` where both are given, ``(wo, h)``, ``(wo, uv)`` or
``(wo, u1, u2, ...)`` where wo alone fixes the disk.
"""

from __future__ import annotations

from dataclasses import astuple, dataclass, fields
from typing import Any, Callable, ClassVar, Union

import numpy as np

from microsim import checks as _checks
from microsim import vectors
from microsim.errors import UsageError

from .fresnel import schlick
from .protocol import BRDFSample, ModelBase

__all__ = [
    "EdwardsEmpirical",
    "EdwardsFit",
    "DISK_PROJECTIONS",
    "disk_centre",
    "reflect_halfway",
    "scaling_projection",
    "scaling_projection_inverse",
    "scaling_jacobian",
    "orthogonal_projection",
    "orthogonal_projection_inverse",
    "orthogonal_jacobian",
    "disk_projection",
    "disk_projection_inverse",
    "disk_jacobian",
    "incident_to_disk",
    "disk_to_incident",
    "Lump",
    "LumpMixture",
    "empirical_lumps",
    "edwards_empirical",
    "brdf_to_disk_density",
    "EdwardsParams",
    "DiskPoints",
    "edwards_fit_brdf",
    "sample_edwards",
    "pdf_edwards",
]

DISK_PROJECTIONS = ("scaling", "orthogonal")

DiskDensity = Union["Lump", "LumpMixture", Callable[[np.ndarray, np.ndarray], np.ndarray]]


# --------------------------------------------------------------------------------------------
# small helpers
# --------------------------------------------------------------------------------------------
def _check_projection(projection: str) -> str:
    if projection not in DISK_PROJECTIONS:
        raise UsageError(f"projection must be one of {DISK_PROJECTIONS}, got {projection!r}")
    return projection


def _safe_div(a, b):
    """a / b, and 0 where b == 0 (the degenerate grazing limits documented per function)."""
    a, b = np.broadcast_arrays(np.asarray(a, float), np.asarray(b, float))
    return np.divide(a, b, out=np.zeros_like(a), where=b != 0)


def _cos_o(wo: np.ndarray) -> np.ndarray:
    """cos θo clipped to [0, 1] (the height of the disk plane)."""
    return np.clip(wo[..., 2], 0.0, 1.0)


def _unit_or_normal(v: np.ndarray) -> np.ndarray:
    """Normalise v; a zero vector becomes the normal +z."""
    h = vectors.normalize(v)
    zero = np.all(h == 0.0, axis=-1, keepdims=True)
    return np.where(zero, np.array([0.0, 0.0, 1.0]), h)


def disk_centre(wo) -> np.ndarray:
    """Centre (wo_x, wo_y) of the halfway disk in (u, v) (Fig. 4).

    Retro-reflection (wi = wo) under the scaling projection; wi = n under the orthogonal one.
    """
    wo = _checks.directions("wo", wo, upper=True)
    return wo[..., :2].copy()


def reflect_halfway(wo, h) -> np.ndarray:
    """Incident direction wi = 2(wo·h)h − wo for a unit half vector h (eq. 13)."""
    wo, h = np.asarray(wo, float), np.asarray(h, float)
    _checks.broadcast({"wo": wo, "h": h})
    return 2.0 * vectors.dot(wo, h)[..., None] * h - wo


# --------------------------------------------------------------------------------------------
# scaling projection (eq. 15–21)
# --------------------------------------------------------------------------------------------
def scaling_projection(wo, h) -> np.ndarray:
    """(u, v) of half vector h under the scaling projection: cos θo · h_xy / h_z (eq. 15).

    At cos θo = 0 the disk plane contains the origin and every half vector maps to (0, 0).
    """
    wo = _checks.directions("wo", wo, upper=True)
    h = _checks.directions("h", h)
    _checks.broadcast({"wo": wo, "h": h})
    return _safe_div(_cos_o(wo)[..., None] * h[..., :2], h[..., 2:3])


def scaling_projection_inverse(wo, uv) -> np.ndarray:
    """Unit half vector of the disk point (u, v): normalise (u, v, cos θo) (eq. 21).

    At cos θo = 0 and (u, v) = (0, 0) the inverse is undefined; the normal is returned.
    """
    wo = _checks.directions("wo", wo, upper=True)
    uv = np.asarray(uv, dtype=np.float64)
    _checks.broadcast({"wo": wo, "uv": uv})
    c = np.broadcast_to(_cos_o(wo), np.broadcast_shapes(wo.shape[:-1], uv.shape[:-1]))
    return _unit_or_normal(np.concatenate([np.broadcast_to(uv, c.shape + (2,)), c[..., None]], -1))


def scaling_jacobian(wi, wo) -> np.ndarray:
    """dA_disk/dω_i of the scaling projection (dimensionless per sr).

    eq. 19 gives dμ/dΩ(Ĥ) = cos²θo/(Ĥ·n)³ (re-derived: the plane z = cos θo seen from
    the origin, dΩ = dA (Ĥ·n)/|h|² with |h| = cos θo/(Ĥ·n)); with dΩ(Ĥ)/dω_i = 1/(4 wi·Ĥ) (eq. 8)
    and |H| = 2 wi·Ĥ, Ĥ·n = H_z/|H| this is J = cos²θo |H|² / (2 H_z³), H = wi + wo.
    0 where wi is below the horizon, and 0 at cos θo = 0 (the projection collapses the disk).
    """
    wo = _checks.directions("wo", wo, upper=True)
    wi = _checks.directions("wi", wi)
    _checks.broadcast({"wi": wi, "wo": wo})
    c = _cos_o(wo)
    H = wi + wo
    Hz = H[..., 2]
    J = _safe_div(c * c * vectors.dot(H, H), 2.0 * Hz**3)
    return np.where(wi[..., 2] >= 0.0, J, 0.0)


# --------------------------------------------------------------------------------------------
# orthogonal projection (eq. 22–25)
# --------------------------------------------------------------------------------------------
def orthogonal_projection(wo, h) -> np.ndarray:
    """(u, v) of half vector h under the orthogonal projection (eq. 22).

    H − (wi·n)n keeps the x, y part of H = wi + wo = 2(wo·h)h, so (u, v) = 2(wo·h) h_xy.
    """
    wo = _checks.directions("wo", wo, upper=True)
    h = _checks.directions("h", h)
    _checks.broadcast({"wo": wo, "h": h})
    return 2.0 * vectors.dot(wo, h)[..., None] * h[..., :2]


def orthogonal_projection_inverse(wo, uv) -> np.ndarray:
    """Unit half vector of (u, v): normalise (u, v, cos θo + cos θi) (eq. 25).

    Eq. 25 adds (wi·n) n, which the disk point itself fixes: wi_xy = (u, v) − wo_xy, so
    wi·n = √(1 − |(u, v) − wo_xy|²) (clipped to 0 outside the disk).
    """
    wo = _checks.directions("wo", wo, upper=True)
    uv = np.asarray(uv, dtype=np.float64)
    _checks.broadcast({"wo": wo, "uv": uv})
    d = uv - wo[..., :2]
    wi_z = np.sqrt(np.clip(1.0 - np.sum(d * d, axis=-1), 0.0, 1.0))
    hz = _cos_o(wo) + wi_z
    uv = np.broadcast_to(uv, hz.shape + (2,))
    return _unit_or_normal(np.concatenate([uv, hz[..., None]], -1))


def orthogonal_jacobian(wi, wo) -> np.ndarray:
    """dA_disk/dω_i of the orthogonal projection: cos θi (0 below the horizon).

    eq. 23, dμ/dΩ(Ĥ) = |wi+wo|² (wi·n)/(wi·Ĥ), times dΩ(Ĥ)/dω_i = 1/(4 wi·Ĥ) (eq. 8)
    is cos θi, since |wi + wo| = 2 wi·Ĥ. (Equivalently: (u, v) = wo_xy + wi_xy, the orthographic
    projection of the unit hemisphere onto its base.)
    """
    wo = _checks.directions("wo", wo, upper=True)
    wi = _checks.directions("wi", wi)
    _checks.broadcast({"wi": wi, "wo": wo})
    return np.broadcast_to(
        np.maximum(wi[..., 2], 0.0), np.broadcast_shapes(wo.shape[:-1], wi.shape[:-1])
    ).copy()


# --------------------------------------------------------------------------------------------
# dispatch
# --------------------------------------------------------------------------------------------
_FORWARD = {"scaling": scaling_projection, "orthogonal": orthogonal_projection}
_INVERSE = {"scaling": scaling_projection_inverse, "orthogonal": orthogonal_projection_inverse}
_JACOBIAN = {"scaling": scaling_jacobian, "orthogonal": orthogonal_jacobian}


def disk_projection(wo, h, projection: str = "scaling") -> np.ndarray:
    """(u, v) of unit half vector h for the named projection (eq. 15 or 22)."""
    return _FORWARD[_check_projection(projection)](wo, h)


def disk_projection_inverse(wo, uv, projection: str = "scaling") -> np.ndarray:
    """Unit half vector of disk point (u, v) for the named projection (eq. 21 or 25)."""
    return _INVERSE[_check_projection(projection)](wo, uv)


def disk_jacobian(wi, wo, projection: str = "scaling") -> np.ndarray:
    """dA_disk/dω_i for the named projection (eq. 19 or 23 over 4 wi·Ĥ)."""
    return _JACOBIAN[_check_projection(projection)](wi, wo)


def incident_to_disk(wi, wo, projection: str = "scaling") -> np.ndarray:
    """Disk point (u, v) of the pair (wi, wo): project Ĥ = (wi + wo)/|wi + wo| (Fig. 13 view).

    For wi = −wo (both on the horizon) Ĥ is undefined and the normal is used.
    """
    wo = _checks.directions("wo", wo, upper=True)
    wi = _checks.directions("wi", wi)
    _checks.broadcast({"wi": wi, "wo": wo})
    return disk_projection(wo, _unit_or_normal(wi + wo), projection)


def disk_to_incident(wo, uv, projection: str = "scaling") -> np.ndarray:
    """Incident direction of disk point (u, v): inverse projection then reflection (eq. 12–13)."""
    return reflect_halfway(wo, disk_projection_inverse(wo, uv, projection))


def _brdf_factor(wi, wo, projection: str) -> np.ndarray:
    """J(wi, wo)/cos θi: the BRDF per unit disk density (eq. 20 and 24); 0 if cos θi ≤ 0.

    Scaling: cos²θo/(4 cos θi (wi·Ĥ)(Ĥ·n)³) (eq. 20). Orthogonal: 1 (eq. 24, see module doc).
    """
    wi_z = np.asarray(wi, float)[..., 2]
    if projection == "orthogonal":
        return np.broadcast_to(
            np.where(wi_z > 0.0, 1.0, 0.0), np.broadcast_shapes(np.shape(wo)[:-1], wi_z.shape)
        ).copy()
    J = scaling_jacobian(wi, wo)
    return np.where(wi_z > 0.0, _safe_div(J, wi_z), 0.0)


# --------------------------------------------------------------------------------------------
# lumps (eq. 26–29)
# --------------------------------------------------------------------------------------------
_ANCHORS = ("normal", "centre")


@dataclass(frozen=True)
class Lump:
    """Lump density on the disk (eq. 26; elliptical eq. 27), per unit (u, v) area.

    p = (n+1)/(π R_u R_v) [1 − (Δu/R_u)² − (Δv/R_v)²]^n inside the ellipse, 0 outside; it has
    unit volume over its own ellipse, so it is a pdf on the disk when the ellipse lies on the disk.

    n       exponent ≥ 0 (0: uniform; large: narrow).
    radius  R_u > 0, or None for the largest lump that stays on the disk for each wo
            (max(R_u, R_v) = 1 − |centre − disk centre|; the paper's R_s = 1 − sin θo, R_r = 1).
    aspect  R_v / R_u > 0 (1: isotropic eq. 26).
    anchor  "normal": centre = offset from (u, v) = 0 (Ĥ = n: the specular lump);
            "centre": centre = offset from the disk centre wo_xy (the retro-reflection lump of
            eq. 32 under the scaling projection).
    offset  (Δu, Δv) of the centre from the anchor.
    """

    n: float = 0.0
    radius: float | None = None
    aspect: float = 1.0
    anchor: str = "normal"
    offset: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self):
        _checks.in_range("Lump.n", self.n, 0.0, np.inf, hi_open=True)
        if self.radius is not None:
            _checks.positive("Lump.radius", self.radius)
        _checks.positive("Lump.aspect", self.aspect)
        if self.anchor not in _ANCHORS:
            raise UsageError(f"Lump.anchor must be one of {_ANCHORS}, got {self.anchor!r}")
        off = np.asarray(self.offset, dtype=float)
        if off.shape != (2,) or not np.all(np.isfinite(off)):
            raise UsageError(
                f"Lump.offset must be two finite numbers (Δu, Δv), got {self.offset!r}"
            )

    def geometry(self, wo):
        """(centre (..., 2), R_u (...), R_v (...)) of the lump for outgoing direction(s) wo."""
        wo = _checks.directions("wo", wo, upper=True)
        centre = np.asarray(self.offset, float) + (wo[..., :2] if self.anchor == "centre" else 0.0)
        centre = np.broadcast_to(centre, wo.shape[:-1] + (2,))
        if self.radius is None:
            r_max = np.maximum(1.0 - np.linalg.norm(centre - wo[..., :2], axis=-1), 0.0)
            ru = r_max * min(1.0, 1.0 / self.aspect)
        else:
            ru = np.full(wo.shape[:-1], float(self.radius))
        return centre, ru, ru * self.aspect

    def fits_on_disk(self, wo, tol: float = 1e-12) -> np.ndarray:
        """True where the lump's ellipse lies on the disk: max(R_u, R_v) + |centre − wo_xy| ≤ 1.

        Exact for isotropic lumps, conservative (sufficient) for elliptical ones.
        """
        wo = _checks.directions("wo", wo, upper=True)
        centre, ru, rv = self.geometry(wo)
        return np.maximum(ru, rv) + np.linalg.norm(centre - wo[..., :2], axis=-1) <= 1.0 + tol

    def pdf(self, wo, uv) -> np.ndarray:
        """Density per unit disk area at (u, v) (eq. 26/27); 0 for a zero-radius lump."""
        wo, uv = _checks.directions("wo", wo, upper=True), np.asarray(uv, float)
        _checks.broadcast({"wo": wo, "uv": uv})
        centre, ru, rv = self.geometry(wo)
        d = uv - centre
        q = _safe_div(d[..., 0], ru) ** 2 + _safe_div(d[..., 1], rv) ** 2
        inside = (q < 1.0) & (ru > 0.0)
        norm = _safe_div(self.n + 1.0, np.pi * ru * rv)
        return np.where(inside, norm * np.clip(1.0 - q, 0.0, 1.0) ** self.n, 0.0)

    def sample(self, wo, u1, u2) -> np.ndarray:
        """(u, v) ~ lump from uniforms u1, u2 ∈ [0, 1] (eq. 28–29, scaled by R_u, R_v).

        r/R = √(1 − u1^(1/(n+1))), evaluated as √(−expm1(ln u1/(n+1))) for large n.
        """
        wo = _checks.directions("wo", wo, upper=True)
        u1, u2 = np.asarray(u1, float), np.asarray(u2, float)
        _checks.broadcast({"wo": wo}, {"u1": u1, "u2": u2})
        centre, ru, rv = self.geometry(wo)
        with np.errstate(divide="ignore"):
            rho = np.sqrt(-np.expm1(np.log(np.clip(u1, 0.0, 1.0)) / (self.n + 1.0)))
        phi = 2.0 * np.pi * u2
        return centre + np.stack([ru * rho * np.cos(phi), rv * rho * np.sin(phi)], axis=-1)


@dataclass(frozen=True)
class LumpMixture:
    """Weighted sum of lumps, Σ w_j p_j (eq. 32, 35); weights ≥ 0 summing to 1."""

    lumps: tuple[Lump, ...]
    weights: tuple[float, ...]

    def __post_init__(self):
        if len(self.lumps) == 0 or len(self.lumps) != len(self.weights):
            raise UsageError(
                "LumpMixture.lumps and LumpMixture.weights must be non-empty and of "
                f"equal length, got {len(self.lumps)} and {len(self.weights)}"
            )
        w = np.asarray(self.weights, float)
        if np.any(~np.isfinite(w)) or np.any(w < 0) or abs(w.sum() - 1.0) > 1e-12:
            raise UsageError(f"LumpMixture.weights must be ≥ 0 and sum to 1, got {self.weights!r}")

    def fits_on_disk(self, wo) -> np.ndarray:
        """True where every lump with positive weight lies on the disk (see Lump.fits_on_disk)."""
        ok = [lump.fits_on_disk(wo) for lump, w in zip(self.lumps, self.weights) if w > 0]
        return np.logical_and.reduce(ok)

    def pdf(self, wo, uv) -> np.ndarray:
        """Mixture density per unit disk area at (u, v)."""
        _checks.broadcast({"wo": _checks.directions("wo", wo, upper=True), "uv": np.asarray(uv)})
        return sum(w * lump.pdf(wo, uv) for lump, w in zip(self.lumps, self.weights) if w > 0)

    def sample(self, wo, u1, u2):
        """((u, v), density) from uniforms u1, u2: u1 picks the lump and is rescaled for reuse."""
        _checks.broadcast({"wo": _checks.directions("wo", wo, upper=True)}, {"u1": u1, "u2": u2})
        w = np.asarray(self.weights, float)
        upper = np.cumsum(w)
        upper[-1] = 1.0
        u1 = np.clip(np.asarray(u1, float), 0.0, 1.0)
        last = int(np.flatnonzero(w > 0)[-1])
        j = np.minimum(np.searchsorted(upper, u1, side="right"), last)
        lower = upper[j] - w[j]
        u1r = np.clip(_safe_div(u1 - lower, w[j]), 0.0, 1.0)
        candidates = np.stack([lump.sample(wo, u1r, u2) for lump in self.lumps], axis=0)
        shape = np.broadcast_shapes(candidates.shape[1:], j.shape + (2,))
        jj = np.broadcast_to(j[..., None], shape)[None]
        uv = np.take_along_axis(np.broadcast_to(candidates, (len(self.lumps),) + shape), jj, 0)[0]
        return uv, self.pdf(wo, uv)


def empirical_lumps(
    k: float = 0.0,
    n_s: float = 0.0,
    n_r: float = 0.0,
    r_s: float | None = None,
    r_r: float | None = None,
) -> LumpMixture:
    """Disk density of the empirical BRDF (eq. 32).

    (1 − k) × specular lump at (u, v) = 0 (radius r_s, exponent n_s) + k × retro lump at the disk
    centre (r_r, n_r) — retro-reflective under the scaling projection the paper uses for this
    model. None radii take the largest value on the disk, as the paper does (R_s = 1 − sin θo,
    R_r = 1). k ∈ [0, 1].
    """
    k = _checks.in_range("k", k, 0.0, 1.0)
    return LumpMixture(
        (Lump(n_s, r_s, anchor="normal"), Lump(n_r, r_r, anchor="centre")), (1.0 - k, k)
    )


def _disk_density(density: DiskDensity, wo, uv) -> np.ndarray:
    """Evaluate a Lump, a LumpMixture or a callable pdf_disk(uv, wo) at (u, v)."""
    if isinstance(density, (Lump, LumpMixture)):
        return density.pdf(wo, uv)
    if callable(density):
        return np.asarray(density(uv, wo), dtype=np.float64)
    raise UsageError(
        "lumps must be a Lump, a LumpMixture or a callable pdf_disk(uv, wo), "
        f"got {type(density).__name__}"
    )


# --------------------------------------------------------------------------------------------
# empirical BRDF (eq. 30–33) and the Fig. 13 disk view
# --------------------------------------------------------------------------------------------
def _fresnel_factor(fresnel, cos_o) -> np.ndarray:
    """F(θo): 1 for None, Schlick with f0 for a number (eq. 30), or a callable F(cos θo)."""
    if fresnel is None:
        return np.ones_like(cos_o)
    if callable(fresnel):
        return np.asarray(fresnel(cos_o), dtype=np.float64)
    return np.asarray(schlick(cos_o, _checks.in_range("fresnel (f0)", fresnel, 0.0, 1.0)))


def edwards_empirical(
    wi, wo, lumps: DiskDensity, projection: str = "scaling", fresnel=None, diffuse: float = 0.0
) -> np.ndarray:
    """Energy-conserving empirical BRDF (eq. 33; eq. 11 for either projection), sr⁻¹.

    f = (1 − F(θo)) C_d/π + F(θo) p(u, v) J(wi, wo)/cos θi, with (u, v) the disk point of
    Ĥ = (wi + wo)/|wi + wo| and J from ``disk_jacobian``. With fresnel=None F = 1 and the albedo
    ∫ f cos θi dω_i = ∫_disk p dA, which is 1 for every wo when p is a pdf on the disk.

    lumps       a Lump / LumpMixture (e.g. ``empirical_lumps``; each must lie on the disk —
                ValueError otherwise, §4) or a callable pdf_disk(uv, wo) normalised on
                the disk of each wo (the caller's responsibility).
    projection  "scaling" (the paper's choice for this model) or "orthogonal".
    fresnel     None (F = 1), f0 ∈ [0, 1] for Schlick's F(θo) (eq. 30–31), or callable F(cos θo).
    diffuse     C_d ∈ [0, 1]. Then the albedo is (1 − F) C_d + F ≤ 1.
    0 where wi is on or below the horizon (for the scaling projection f ~ 1/cos θi there when p
    is non-zero on the disk rim). Not reciprocal (module doc).
    """
    return EdwardsEmpirical(lumps, projection, fresnel, diffuse).f(wi, wo)


def brdf_to_disk_density(wi, wo, rho, projection: str = "scaling") -> np.ndarray:
    """Disk density implied by BRDF values ``rho`` (sr⁻¹) at (wi, wo): p = f cos θi / J(wi, wo)
    (eq. 11 inverted), per area.

    Places measured or simulated BRDF samples on the halfway disk, as the fitting tool of
    Fig. 13 does (pair with ``incident_to_disk`` for the (u, v) positions). 0 where J = 0.
    """
    wo = _checks.directions("wo", wo, upper=True)
    wi = _checks.directions("wi", wi)
    _checks.broadcast({"wi": wi, "wo": wo}, {"rho": rho})
    cos_i = np.maximum(wi[..., 2], 0.0)
    return _safe_div(np.asarray(rho, float) * cos_i, disk_jacobian(wi, wo, projection))


# --------------------------------------------------------------------------------------------
# data-fitting BRDF (eq. 34–36)
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class EdwardsParams:
    """Parameters of the data-fitting BRDF (eq. 34–36), constant over wo.

    cd        diffuse colour C_d ∈ [0, 1]
    f0, f90   F_fit at normal incidence and at grazing, ∈ [0, 1] (eq. 34)
    k         weight of the second lump ∈ [0, 1] (eq. 35)
    r1, n1    radius > 0 and exponent ≥ 0 of the first lump, centred at the normal
    r2, n2    the same for the second lump
    Radii are not constrained to the disk (the paper lets the lumps leave it; energy is lost).
    """

    cd: float = 0.0
    f0: float = 0.04
    f90: float = 1.0
    k: float = 0.0
    r1: float = 1.0
    n1: float = 10.0
    r2: float = 1.0
    n2: float = 1.0

    # (lo, hi) for a least-squares fit: fractions in [0, 1]; radii from 1e-4 (far below any
    # measured lobe) to 4 (twice the disk diameter: flat over the disk); exponents up to 1e4.
    # These are practical choices, not from the paper.
    _BOUNDS = {
        "cd": (0.0, 1.0),
        "f0": (0.0, 1.0),
        "f90": (0.0, 1.0),
        "k": (0.0, 1.0),
        "r1": (1e-4, 4.0),
        "n1": (0.0, 1e4),
        "r2": (1e-4, 4.0),
        "n2": (0.0, 1e4),
    }

    def __post_init__(self):
        for name in ("cd", "f0", "f90", "k"):
            _checks.in_range(f"EdwardsParams.{name}", getattr(self, name), 0.0, 1.0)
        for name in ("r1", "r2"):
            _checks.positive(f"EdwardsParams.{name}", getattr(self, name))
        for name in ("n1", "n2"):
            _checks.in_range(
                f"EdwardsParams.{name}", getattr(self, name), 0.0, np.inf, hi_open=True
            )

    @classmethod
    def names(cls) -> tuple[str, ...]:
        """Field names in vector order."""
        return tuple(f.name for f in fields(cls))

    @classmethod
    def bounds(cls) -> tuple[np.ndarray, np.ndarray]:
        """(lower, upper) arrays in vector order, for scipy.optimize.least_squares(bounds=...)."""
        lo, hi = zip(*(cls._BOUNDS[name] for name in cls.names()))
        return np.array(lo), np.array(hi)

    def to_vector(self) -> np.ndarray:
        """Parameters as a float array in ``names()`` order."""
        return np.array(astuple(self), dtype=np.float64)

    @classmethod
    def from_vector(cls, x) -> "EdwardsParams":
        """Inverse of ``to_vector``."""
        x = np.asarray(x, dtype=np.float64)
        if x.shape != (len(cls.names()),):
            raise UsageError(
                f"x must have shape ({len(cls.names())},) in order {cls.names()}, got {x.shape}"
            )
        return cls(*map(float, x))

    def lumps(self) -> LumpMixture:
        """The disk density of eq. 35: (1 − k) lump(r1, n1) + k lump(r2, n2), both at the normal."""
        return LumpMixture((Lump(self.n1, self.r1), Lump(self.n2, self.r2)), (1.0 - self.k, self.k))

    def fresnel(self, cos_o) -> np.ndarray:
        """F_fit(θo) = F0 + (F_π/2 − F0)(1 − cos θo)⁵ (eq. 34), via Schlick with f0 = 0."""
        return self.f0 + (self.f90 - self.f0) * np.asarray(schlick(cos_o, 0.0))


@dataclass(frozen=True, eq=False)
class DiskPoints:
    """The parameter-free part of the data-fitting BRDF at pairs (wi, wo), for evaluating it
    with many ``EdwardsParams`` (``EdwardsFit.f_at``; a least-squares fit).

    wo          validated outgoing directions (..., 3)
    uv          disk points of Ĥ under ``projection`` (..., 2) (``incident_to_disk``)
    factor      J(wi, wo)/cos θi, the BRDF per unit disk density (...), 0 where cos θi ≤ 0
    cos_o       cos θo (...), clipped to [0, 1]
    lit         cos θi > 0 (...): where f is non-zero
    projection  "orthogonal" or "scaling"
    """

    wo: np.ndarray
    uv: np.ndarray
    factor: np.ndarray
    cos_o: np.ndarray
    lit: np.ndarray
    projection: str

    @classmethod
    def of(cls, wi, wo, projection: str = "orthogonal") -> "DiskPoints":
        """Validate the directions once and compute the quantities for ``projection``."""
        projection = _check_projection(projection)
        wo = _checks.directions("wo", wo, upper=True)
        wi = _checks.directions("wi", wi)
        _checks.broadcast({"wi": wi, "wo": wo})
        return cls(
            wo,
            incident_to_disk(wi, wo, projection),
            _brdf_factor(wi, wo, projection),
            _cos_o(wo),
            wi[..., 2] > 0.0,
            projection,
        )


def edwards_fit_brdf(wi, wo, params: EdwardsParams, projection: str = "orthogonal") -> np.ndarray:
    """Data-fitting BRDF (eq. 36), sr⁻¹.

    f = (1 − F_fit(θo)) C_d/π + F_fit(θo) p(u, v) J(wi, wo)/cos θi with p from eq. 35. The paper
    uses the orthogonal projection, where the lump term is p(u, v) |wi+wo|²/(4(wi·Ĥ)²) = p(u, v);
    "scaling" swaps in eq. 20. Not energy conserving where the lumps leave the disk, and not
    reciprocal. 0 where wi is on or below the horizon.
    """
    return EdwardsFit(params, projection).f(wi, wo)


# --------------------------------------------------------------------------------------------
# importance sampling (eq. 12–13, 28–29)
# --------------------------------------------------------------------------------------------
def _as_mixture(lumps) -> LumpMixture:
    if isinstance(lumps, Lump):
        return LumpMixture((lumps,), (1.0,))
    if isinstance(lumps, LumpMixture):
        return lumps
    raise UsageError(f"lumps must be a Lump or a LumpMixture, got {type(lumps).__name__}")


def pdf_edwards(wi, wo, lumps: DiskDensity, projection: str = "scaling") -> np.ndarray:
    """Solid-angle density of ``sample_edwards``: p(u(wi)) J(wi, wo), sr⁻¹ (eq. 10–11).

    Equals edwards_empirical(wi, wo, lumps, projection) · cos θi (F = 1), so sampling is exact
    importance sampling of the specular term. 0 for wi on or below the horizon.
    """
    projection = _check_projection(projection)
    wo = _checks.directions("wo", wo, upper=True)
    wi = _checks.directions("wi", wi)
    _checks.broadcast({"wi": wi, "wo": wo})
    p = _disk_density(lumps, wo, incident_to_disk(wi, wo, projection))
    return np.where(wi[..., 2] > 0.0, p * disk_jacobian(wi, wo, projection), 0.0)


def sample_edwards(wo, u1, u2, lumps, projection: str = "scaling"):
    """Incident directions wi and their solid-angle pdf for outgoing wo (eq. 12–13, 28–29).

    Draws (u, v) from the lump density (u1 also chooses the lump), maps it to Ĥ by the inverse
    projection and reflects wo about Ĥ. pdf = p(u, v) J(wi, wo) (= ``pdf_edwards``). A sample
    with pdf 0 carries no density: it fell off the disk (lumps of the data-fitting model may leave
    it; wi then lies below the horizon) or came from a zero-radius lump (wo on the horizon).
    """
    projection = _check_projection(projection)
    mix = _as_mixture(lumps)
    wo = _checks.directions("wo", wo, upper=True)
    _checks.broadcast({"wo": wo}, {"u1": u1, "u2": u2})
    uv, p = mix.sample(wo, u1, u2)
    wi = disk_to_incident(wo, uv, projection)
    d = uv - wo[..., :2]
    on_disk = np.sum(d * d, axis=-1) < 1.0
    pdf = np.where(
        on_disk & (wi[..., 2] > 0.0), p * disk_jacobian(vectors.normalize(wi), wo, projection), 0.0
    )
    return wi, pdf


# --- the models as objects (the free functions above wrap them) ---------------------------------
def _lumps_symmetric(lumps) -> bool:
    """Lumps centred on their anchor and round are mirror symmetric; a callable may not be."""
    if isinstance(lumps, Lump):
        lumps = LumpMixture((lumps,), (1.0,))
    if not isinstance(lumps, LumpMixture):
        return False
    return all(
        tuple(lump.offset) == (0.0, 0.0) and lump.aspect == 1.0
        for lump, w in zip(lumps.lumps, lumps.weights)
        if w > 0
    )


@dataclass(frozen=True)
class EdwardsEmpirical(ModelBase):
    """Edwards' energy-conserving empirical BRDF f = (1 − F) C_d/π + F p(u, v) J/cos θi
    (Edwards et al. 2006, eq. 30–33); ``edwards_empirical`` wraps it. Not reciprocal. Sampler:
    the lump density on the halfway disk (``sample_edwards``; Lump/LumpMixture lumps only)."""

    lumps: Any
    projection: str = "scaling"
    fresnel: Any = None
    diffuse: float = 0.0
    name: ClassVar[str] = "EdwardsEmpirical"
    params_doc: ClassVar[str] = (
        "lumps (Lump | LumpMixture, e.g. empirical_lumps; or pdf_disk(uv, wo)), "
        "projection=scaling|orthogonal, fresnel None|f0|F(cos θo), diffuse C_d ∈ [0, 1]"
    )
    source: ClassVar[str] = "Edwards et al. 2006, eq. 33"
    functions: ClassVar[tuple[str, ...]] = ("edwards_empirical", "empirical_lumps")
    sampler_doc: ClassVar[str] = "wo, u1, u2; lumps on the halfway disk (u1 also picks the lump)"
    sampler_source: ClassVar[str] = "Edwards et al. 2006, eq. 26–29"
    sampler_functions: ClassVar[tuple[str, ...]] = ("sample_edwards", "pdf_edwards")

    @property
    def symmetric(self) -> bool:
        return _lumps_symmetric(self.lumps)

    def f(self, wi, wo):
        lumps, fresnel = self.lumps, self.fresnel
        projection = _check_projection(self.projection)
        diffuse = _checks.in_range("diffuse", self.diffuse, 0.0, 1.0)
        wo = _checks.directions("wo", wo, upper=True)
        wi = _checks.directions("wi", wi)
        _checks.broadcast({"wi": wi, "wo": wo})
        if isinstance(lumps, (Lump, LumpMixture)) and not np.all(lumps.fits_on_disk(wo)):
            raise UsageError(
                "lumps must lie on the halfway disk for every wo: each lump needs "
                "max(R_u, R_v) + |centre − wo_xy| <= 1 (§4: R_s <= 1 − sin θo, "
                "R_r <= 1); use radius=None for the largest allowed radius"
            )
        F = _fresnel_factor(fresnel, _cos_o(wo))
        spec = _disk_density(lumps, wo, incident_to_disk(wi, wo, projection)) * _brdf_factor(
            wi, wo, projection
        )
        return np.where(wi[..., 2] > 0.0, (1.0 - F) * diffuse / np.pi + F * spec, 0.0)

    def sample(self, wo, u1, u2) -> BRDFSample:
        return BRDFSample(*sample_edwards(wo, u1, u2, self.lumps, self.projection))

    def pdf(self, wi, wo):
        return pdf_edwards(wi, wo, self.lumps, self.projection)


@dataclass(frozen=True)
class EdwardsFit(ModelBase):
    """Edwards' data-fitting BRDF f = (1 − F_fit) C_d/π + F_fit p(u, v) J/cos θi with the
    two-lump p of eq. 35 (Edwards et al. 2006, eq. 34–36); ``edwards_fit_brdf`` wraps it. Not
    reciprocal. Sampler: ``sample_edwards`` of ``fit_params.lumps()``."""

    fit_params: EdwardsParams
    projection: str = "orthogonal"
    name: ClassVar[str] = "EdwardsFit"
    params_doc: ClassVar[str] = "fit_params: EdwardsParams, projection=orthogonal|scaling"
    source: ClassVar[str] = "Edwards et al. 2006, eq. 34–36"
    functions: ClassVar[tuple[str, ...]] = ("edwards_fit_brdf", "EdwardsParams")
    sampler_doc: ClassVar[str] = "wo, u1, u2; the two lumps of eq. 35 (may leave the disk)"
    sampler_source: ClassVar[str] = "Edwards et al. 2006, eq. 26–29"
    sampler_functions: ClassVar[tuple[str, ...]] = ("sample_edwards", "pdf_edwards")

    def f(self, wi, wo):
        return self.f_at(DiskPoints.of(wi, wo, self.projection))

    def f_at(self, points: DiskPoints) -> np.ndarray:
        """f (eq. 36) at the pairs (wi, wo) of ``points`` (``DiskPoints.of``), sr⁻¹."""
        params = self.fit_params
        if not isinstance(params, EdwardsParams):
            raise UsageError(f"params must be an EdwardsParams, got {type(params).__name__}")
        if points.projection != self.projection:
            raise UsageError(
                f"points must be of the model's projection {self.projection!r}, "
                f"got {points.projection!r}"
            )
        F = params.fresnel(points.cos_o)
        spec = params.lumps().pdf(points.wo, points.uv) * points.factor
        return np.where(points.lit, (1.0 - F) * params.cd / np.pi + F * spec, 0.0)

    def sample(self, wo, u1, u2) -> BRDFSample:
        return BRDFSample(*sample_edwards(wo, u1, u2, self.fit_params.lumps(), self.projection))

    def pdf(self, wi, wo):
        return pdf_edwards(wi, wo, self.fit_params.lumps(), self.projection)
