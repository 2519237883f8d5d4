"""The closed-form BRDFs as frozen model objects (the shape of pbrt-v4's BxDFs, Mitsuba 3's
BSDFs), gathered in ``MODEL_CLASSES``. Each model is the implementation and lives beside the
physics of its paper: ``TorranceSparrow`` (f from its distribution, masking object and material)
and ``CookTorrance`` in ``brdf``, ``LowSmooth``, ``LowMicrofacet`` and ``RayleighRice`` in
``low``, ``EdwardsEmpirical`` and ``EdwardsFit`` in ``edwards``; their free functions
(``torrance_sparrow``, ``low_smooth``, ...) are wrappers over them. Defined here: the Mikkelsen
2009, eq. 28 models, views of ``mikkelsen_mix``/``mikkelsen_diffuse`` with a scalar kd (the
functions also take one kd per colour), and ``KullaContyLobe``, the lobe of a ``KullaConty``.
The protocol classes are in ``protocol``.

Protocol (``BRDFModel``): ``f(wi, wo)`` in sr⁻¹ for unit (..., 3) directions pointing away from
the surface, n = +z (the free functions' argument order and conventions); ``params()``, a
dict of the model's parameters (its dataclass fields); ``source``, paper and equation
(docs/references.md). Models with an importance sampler also satisfy ``SampleableBRDF``:
``sample(wo, u1, u2)`` draws wi from uniforms in [0, 1) and returns a NamedTuple whose first
fields are ``wi`` and ``pdf`` (``BRDFSample``, or ``LowSample`` for Löw's samplers, which adds
``above``); ``pdf(wi, wo)`` is that sampler's solid-angle density over the whole sphere of wi
(sr⁻¹; samples below the horizon keep their density, f is 0 there). A sampler importance-samples
the model's specular lobe; diffuse terms (kd, cd) are not sampled. Models without a sampler have
no ``sample``/``pdf`` attributes at all: ``isinstance(m, SampleableBRDF)`` tells them apart.

Class attributes feed ``catalogue.MODELS``: ``name`` (the class name), ``params_doc``,
``source``, ``functions`` (the free functions of the model) and, for samplers, ``sampler_doc``,
``sampler_source``, ``sampler_functions``. ``symmetric``: f is unchanged by mirroring wo about
the plane of incidence (lets ``predict.bin_average`` integrate half of a folded bin).

Objects are frozen (assignment raises ``FrozenInstanceError``) and hashable when their fields
are (NDFs, materials, lumps, tables, callables are; arrays are not). Parameters are checked at
construction by one evaluation of ``f`` at wi = wo = n. Heitz et al. 2016's random walk has no
pointwise f (only bin averages, ``walk_bin_averages``), so it has no model object.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

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
from .edwards import EdwardsEmpirical, EdwardsFit
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
    return bool(ndf.isotropic)


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
