"""The closed-form BRDFs as frozen model objects (the shape of pbrt-v4's BxDFs, Mitsuba 3's
BSDFs). ``TorranceSparrow`` (and ``CookTorrance`` on it, both defined in ``brdf``) computes f
itself from its distribution, masking object and material; ``brdf.torrance_sparrow`` is a
wrapper over it. The other models evaluate the functions of their paper's module (``low``,
``edwards``, ...). The protocol classes are in ``protocol``.

Protocol (``BRDFModel``): ``f(wi, wo)`` in sr⁻¹ for unit (..., 3) directions pointing away from
the surface, n = +z (the wrapped function's argument order and conventions); ``params()``, a
dict of the model's parameters (its dataclass fields); ``source``, paper and equation
(docs/references.md). Models with an importance sampler also satisfy ``SampleableBRDF``:
``sample(wo, u1, u2)`` draws wi from uniforms in [0, 1) and returns a NamedTuple whose first
fields are ``wi`` and ``pdf`` (``BRDFSample``, or ``LowSample`` for Löw's samplers, which adds
``above``); ``pdf(wi, wo)`` is that sampler's solid-angle density over the whole sphere of wi
(sr⁻¹; samples below the horizon keep their density, f is 0 there). A sampler importance-samples
the model's specular lobe; diffuse terms (kd, cd) are not sampled. Models without a sampler have
no ``sample``/``pdf`` attributes at all: ``isinstance(m, SampleableBRDF)`` tells them apart.

Class attributes feed ``catalogue.MODELS``: ``name`` (the class name), ``params_doc``,
``source``, ``functions`` (the free functions wrapped) and, for samplers, ``sampler_doc``,
``sampler_source``, ``sampler_functions``. ``symmetric``: f is unchanged by mirroring wo about
the plane of incidence (lets ``predict.bin_average`` integrate half of a folded bin).

Objects are frozen (assignment raises ``FrozenInstanceError``) and hashable when their fields
are (NDFs, materials, lumps, tables, callables are; arrays are not). Parameters are checked at
construction by one evaluation of ``f`` at wi = wo = n. Heitz et al. 2016's random walk has no
pointwise f (only bin averages, ``walk_bin_averages``), so it has no model object.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from microsim.errors import UsageError

from .brdf import (
    AlbedoTable,
    CookTorrance,
    TorranceSparrow,
    mikkelsen_mix,
    pdf_microfacet,
    sample_microfacet,
)
from .edwards import (
    EdwardsParams,
    Lump,
    LumpMixture,
    edwards_empirical,
    edwards_fit_brdf,
    pdf_edwards,
    sample_edwards,
)
from .energy_compensation import KullaConty, mikkelsen_diffuse
from .low import LowMicrofacet, LowSmooth, RayleighRice
from .protocol import BRDFModel, BRDFSample, ModelBase, SampleableBRDF

__all__ = [
    "BRDFModel",
    "SampleableBRDF",
    "BRDFSample",
    "TorranceSparrow",
    "CookTorrance",
    "LowSmooth",
    "LowMicrofacet",
    "RayleighRice",
    "EdwardsEmpirical",
    "EdwardsFit",
    "MikkelsenMix",
    "MikkelsenDiffuse",
    "KullaContyLobe",
    "MODEL_CLASSES",
]


def _isotropic(ndf) -> bool:
    return bool(getattr(ndf, "isotropic", True))


# --- Edwards et al. 2006 ------------------------------------------------------------------------
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
    (Edwards et al. 2006, eq. 30–33): ``edwards_empirical``. Not reciprocal. Sampler: the lump
    density on the halfway disk (``sample_edwards``; Lump/LumpMixture lumps only)."""

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
        return edwards_empirical(wi, wo, self.lumps, self.projection, self.fresnel, self.diffuse)

    def sample(self, wo, u1, u2) -> BRDFSample:
        return BRDFSample(*sample_edwards(wo, u1, u2, self.lumps, self.projection))

    def pdf(self, wi, wo):
        return pdf_edwards(wi, wo, self.lumps, self.projection)


@dataclass(frozen=True)
class EdwardsFit(ModelBase):
    """Edwards' data-fitting BRDF f = (1 − F_fit) C_d/π + F_fit p(u, v) J/cos θi with the
    two-lump p of eq. 35 (Edwards et al. 2006, eq. 34–36): ``edwards_fit_brdf``. Not
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
        return edwards_fit_brdf(wi, wo, self.fit_params, self.projection)

    def sample(self, wo, u1, u2) -> BRDFSample:
        return BRDFSample(*sample_edwards(wo, u1, u2, self.fit_params.lumps(), self.projection))

    def pdf(self, wi, wo):
        return pdf_edwards(wi, wo, self.fit_params.lumps(), self.projection)


# --- Mikkelsen 2009, eq. 28 and energy compensation ---------------------------------------------
def _scalar_kd(kd) -> float:
    if isinstance(kd, bool) or np.ndim(kd) != 0:
        raise UsageError(f"kd must be one number here (use the function for colours), got {kd!r}")
    return float(kd)


def _check_table(table):
    if not isinstance(table, AlbedoTable):
        raise UsageError(f"table must be an AlbedoTable, got {type(table).__name__}")


@dataclass(frozen=True)
class MikkelsenMix(ModelBase):
    """Specular + reciprocal diffuse f = ks f_s + (1 − ks ρ(wi))(kd/π)(1 − ks ρ(wo))
    [/(1 − ks ρ̄)] (Mikkelsen 2009, eq. 28): ``mikkelsen_mix`` with a scalar kd ∈ [0, 1].
    Sampler: the specular lobe's (``sample_microfacet`` of ``table.ndf``)."""

    table: AlbedoTable
    kd: float
    ks: float = 1.0
    renormalise: bool = False
    name: ClassVar[str] = "MikkelsenMix"
    params_doc: ClassVar[str] = (
        "table: AlbedoTable (specular albedo), kd ∈ [0, 1], ks ∈ [0, 1], renormalise"
    )
    source: ClassVar[str] = "Mikkelsen 2009, eq. 28"
    functions: ClassVar[tuple[str, ...]] = ("mikkelsen_mix",)
    sampler_doc: ClassVar[str] = "wo, u1, u2; specular lobe only (h ~ D(h)(h·n) of table.ndf)"
    sampler_source: ClassVar[str] = "Mikkelsen 2009, eq. 15 (Jacobian)"
    sampler_functions: ClassVar[tuple[str, ...]] = ("sample_microfacet", "pdf_microfacet")

    def __post_init__(self):
        _check_table(self.table)
        object.__setattr__(self, "kd", _scalar_kd(self.kd))
        super().__post_init__()

    @property
    def symmetric(self) -> bool:
        return _isotropic(self.table.ndf)

    def f(self, wi, wo):
        return mikkelsen_mix(wi, wo, self.table, self.kd, self.ks, self.renormalise)

    def sample(self, wo, u1, u2) -> BRDFSample:
        return BRDFSample(*sample_microfacet(wo, u1, u2, self.table.ndf))

    def pdf(self, wi, wo):
        return pdf_microfacet(wi, wo, self.table.ndf)


@dataclass(frozen=True)
class MikkelsenDiffuse(ModelBase):
    """The diffuse-like term (1 − ks ρ(wi))(kd/π)(1 − ks ρ(wo)) of Mikkelsen 2009, eq. 28
    (``mikkelsen_diffuse``; kd ≥ 0 may exceed 1, fitted by ``mikkelsen_kd``). No sampler."""

    table: AlbedoTable
    kd: float
    ks: float = 1.0
    name: ClassVar[str] = "MikkelsenDiffuse"
    params_doc: ClassVar[str] = (
        "table: AlbedoTable, kd ≥ 0 (fitted to a target energy by mikkelsen_kd), ks ∈ [0, 1]"
    )
    source: ClassVar[str] = "Mikkelsen 2009, eq. 28"
    functions: ClassVar[tuple[str, ...]] = ("mikkelsen_diffuse", "mikkelsen_kd")

    def __post_init__(self):
        _check_table(self.table)
        object.__setattr__(self, "kd", _scalar_kd(self.kd))
        super().__post_init__()

    def f(self, wi, wo):
        return mikkelsen_diffuse(wi, wo, self.table, self.kd, self.ks)


@dataclass(frozen=True)
class KullaContyLobe(ModelBase):
    """Kulla & Conty's compensation lobe f_ms = F_ms (1 − E(μi))(1 − E(μo))/(π(1 − E_avg))
    (Kulla & Conty 2017; Kelemen & Szirmay-Kalos 2001): ``KullaConty(...).brdf``. No sampler."""

    lobe: KullaConty
    name: ClassVar[str] = "KullaContyLobe"
    params_doc: ClassVar[str] = (
        "lobe: KullaConty(ndf or AlbedoTable (F = 1), shadowing, material, fresnel_factor)"
    )
    source: ClassVar[str] = "Kulla & Conty 2017; Kelemen & Szirmay-Kalos 2001"
    functions: ClassVar[tuple[str, ...]] = ("KullaConty",)

    def __post_init__(self):
        if not isinstance(self.lobe, KullaConty):
            raise UsageError(f"lobe must be a KullaConty, got {type(self.lobe).__name__}")
        super().__post_init__()

    def f(self, wi, wo):
        return self.lobe.brdf(wi, wo)


MODEL_CLASSES = (
    TorranceSparrow,
    CookTorrance,
    LowSmooth,
    LowMicrofacet,
    RayleighRice,
    EdwardsEmpirical,
    EdwardsFit,
    MikkelsenMix,
    MikkelsenDiffuse,
    KullaContyLobe,
)
"""Every model class, in catalogue order."""
