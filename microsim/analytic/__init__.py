"""Closed-form microfacet models of the four papers (see docs/design.md).

from microsim import analytic as an
an.fresnel(cos_theta, material); an.Beckmann(m); an.torrance_sparrow(wi, wo, ndf, ...)
an.TorranceSparrow(an.GGX(0.3), an.Smith(correlated=True)).f(wi, wo)   # model objects

The public names are the ones imported below (``__all__``): the distributions, the masking
objects, the model classes and the free functions the catalogue lists (``microsim models``).
Helpers used inside the package stay in their modules (``microsim.analytic.random_walk.WalkNDF``,
...); reading one of those from here still works but warns (DeprecationWarning).
"""

import warnings

from .anisotropic import (
    AnisotropicBeckmann,
    AnisotropicGGX,
    AnisotropicNDF,
)
from .brdf import (
    AlbedoTable,
    directional_albedo,
    mikkelsen_mix,
    pdf_microfacet,
    sample_microfacet,
    torrance_sparrow,
)
from .dielectric import (
    WalterDielectric,
    dielectric_albedo,
    dielectric_fresnel,
)
from .edwards import (
    EdwardsParams,
    Lump,
    LumpMixture,
    brdf_to_disk_density,
    disk_centre,
    disk_jacobian,
    disk_projection,
    disk_projection_inverse,
    disk_to_incident,
    edwards_empirical,
    edwards_fit_brdf,
    empirical_lumps,
    incident_to_disk,
    orthogonal_jacobian,
    orthogonal_projection,
    orthogonal_projection_inverse,
    pdf_edwards,
    reflect_halfway,
    sample_edwards,
    scaling_jacobian,
    scaling_projection,
    scaling_projection_inverse,
)
from .empirical import (
    Empirical,
)
from .energy_compensation import (
    KullaConty,
    mikkelsen_diffuse,
    mikkelsen_kd,
)
from .fresnel import (
    MATERIALS,
    f0_from_material,
    fresnel,
    fresnel_transmittance,
    material_name,
    resolve_material,
    schlick,
)
from .low import (
    LOW_OBLIQUITIES,
    RR_POLARISATIONS,
    LowSample,
    abc_psd,
    abc_psd_anisotropic,
    abc_psd_church,
    abc_psd_church_integral,
    church_to_condensed,
    low_e1,
    low_e2,
    low_microfacet,
    low_microfacet_A_from_ndf,
    low_smooth,
    pdf_low_halfvector,
    pdf_low_microfacet,
    pdf_low_smooth,
    rayleigh_rice,
    sample_low_microfacet,
    sample_low_smooth,
)
from .masking import (
    MASKING_CLASSES,
    SHADOWING_KINDS,
    Masking,
    NoMasking,
    Smith,
    VGroove,
    masking_from_kind,
    shadowing_g,
    vgroove_g,
    vgroove_g1,
)
from .models import (
    MODEL_CLASSES,
    BRDFModel,
    BRDFSample,
    CookTorrance,
    EdwardsEmpirical,
    EdwardsFit,
    KullaContyLobe,
    LowMicrofacet,
    LowSmooth,
    MikkelsenDiffuse,
    MikkelsenMix,
    RayleighRice,
    SampleableBRDF,
    TorranceSparrow,
)
from .ndf import (
    ABC,
    GGX,
    NDF,
    Beckmann,
    BlinnPhong,
    VonMisesFisher,
    beckmann_to_phong,
    phong_to_beckmann,
    scene_distribution,
    scene_distributions,
)
from .random_walk import (
    WalkBinAverages,
    sample_visible_normals,
    smith_random_walk,
    walk_bin_averages,
)
from .shadowing import (
    smith_g1,
    smith_g2,
    smith_lambda,
)
from .student_t import (
    AnisotropicStudentT,
    StudentT,
)

__all__ = [
    "AnisotropicNDF",
    "scene_distribution",
    "scene_distributions",
    "Lump",
    "LumpMixture",
    "NDF",
    "Beckmann",
    "GGX",
    "BlinnPhong",
    "VonMisesFisher",
    "ABC",
    "beckmann_to_phong",
    "phong_to_beckmann",
    "AnisotropicBeckmann",
    "AnisotropicGGX",
    "StudentT",
    "AnisotropicStudentT",
    "Empirical",
    "fresnel",
    "fresnel_transmittance",
    "schlick",
    "f0_from_material",
    "MATERIALS",
    "resolve_material",
    "material_name",
    "Masking",
    "VGroove",
    "Smith",
    "NoMasking",
    "MASKING_CLASSES",
    "SHADOWING_KINDS",
    "masking_from_kind",
    "vgroove_g",
    "vgroove_g1",
    "shadowing_g",
    "smith_lambda",
    "smith_g1",
    "smith_g2",
    "torrance_sparrow",
    "sample_microfacet",
    "pdf_microfacet",
    "directional_albedo",
    "AlbedoTable",
    "mikkelsen_mix",
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
    "WalterDielectric",
    "dielectric_fresnel",
    "dielectric_albedo",
    "abc_psd",
    "abc_psd_church",
    "abc_psd_church_integral",
    "abc_psd_anisotropic",
    "church_to_condensed",
    "rayleigh_rice",
    "RR_POLARISATIONS",
    "low_smooth",
    "LOW_OBLIQUITIES",
    "low_microfacet",
    "low_microfacet_A_from_ndf",
    "LowSample",
    "sample_low_smooth",
    "pdf_low_smooth",
    "sample_low_microfacet",
    "pdf_low_microfacet",
    "pdf_low_halfvector",
    "low_e1",
    "low_e2",
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
    "empirical_lumps",
    "edwards_empirical",
    "brdf_to_disk_density",
    "EdwardsParams",
    "edwards_fit_brdf",
    "sample_edwards",
    "pdf_edwards",
    "KullaConty",
    "mikkelsen_diffuse",
    "mikkelsen_kd",
    "sample_visible_normals",
    "smith_random_walk",
    "WalkBinAverages",
    "walk_bin_averages",
]

_IN_SUBMODULES = {
    "DISK_PROJECTIONS": "edwards",
    "HEIGHT_DISTRIBUTIONS": "random_walk",
    "WALK_NDFS": "random_walk",
    "WalkNDF": "random_walk",
    "WalkPaths": "random_walk",
    "beckmann_lambda": "ndf",
    "cos_lobe_bin_averages": "energy_compensation",
    "fresnel_average": "energy_compensation",
    "ggx_lambda": "ndf",
    "height_from_tau": "random_walk",
    "mikkelsen_diffuse_albedo": "energy_compensation",
    "tau_from_height": "random_walk",
    "visible_projected_area": "random_walk",
    "walk_alpha": "random_walk",
}
"""Names no longer exported here, and the module that holds each."""


def __getattr__(name):
    module = _IN_SUBMODULES.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    warnings.warn(
        f"microsim.analytic.{name} is deprecated: import it from microsim.analytic.{module}",
        DeprecationWarning,
        stacklevel=2,
    )
    from importlib import import_module

    return getattr(import_module(f"{__name__}.{module}"), name)
