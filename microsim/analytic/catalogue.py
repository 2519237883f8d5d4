"""The list of closed-form models microsim implements, for `microsim models` and reports.

Each entry names the Python callable, its arguments in order (with units and allowed ranges)
and the paper and equation it comes from; docs/references.md has the full entries. Directions
come first — ``(wi, wo, ...)``, samplers ``(wo, u1, u2, ...)`` — then the model; ``material``
is a name, n, n + ik or None (``resolve_material``).
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["ModelInfo", "MODELS", "model_table"]


@dataclass(frozen=True)
class ModelInfo:
    kind: str  # "fresnel" | "ndf" | "shadowing" | "brdf" | "sampler" | "metric"
    name: str  # Python name in microsim.analytic
    params: str  # parameters with units / ranges
    source: str  # paper and equation


MODELS: tuple[ModelInfo, ...] = (
    ModelInfo(
        "fresnel",
        "fresnel",
        "cos_theta ∈ [0,1], material: None (F≡1) | name | n>0 | n+ik (conductor)",
        "Mally 2015; Mikkelsen 2009, §2.1",
    ),
    ModelInfo(
        "fresnel",
        "schlick",
        "cos_theta, f0 ∈ [0,1]",
        "Schlick 1994; Edwards et al. 2006, eq. 30–31",
    ),
    ModelInfo("ndf", "Beckmann", "m > 0 (rms slope)", "Mikkelsen 2009, eq. 20"),
    ModelInfo("ndf", "GGX", "alpha > 0", "Walter et al. 2007 (Trowbridge & Reitz 1975)"),
    ModelInfo(
        "ndf",
        "BlinnPhong",
        "e ≥ 0 (exponent), normalised (e+2)/2π",
        "Mikkelsen 2009, eq. 19; Mally 2015",
    ),
    ModelInfo(
        "ndf",
        "VonMisesFisher",
        "kappa > 0 (concentration); D = p/(h·n)",
        "Mikkelsen 2009, eq. 29–33",
    ),
    ModelInfo(
        "ndf",
        "ABC",
        "B > 0, C > 0; D ∝ (1 + B(1−h·n))^−C normalised",
        "Löw et al. 2012, eq. 15, 23–24",
    ),
    ModelInfo(
        "ndf",
        "Empirical",
        "normals (N,3), projected-area weights",
        "histogram of the surface's own facets",
    ),
    ModelInfo(
        "ndf",
        "beckmann_to_phong",
        "0 < m ≤ 1 → Phong exponent e = 2/m² − 2 (and phong_to_beckmann)",
        "Mikkelsen 2009, eq. 21",
    ),
    ModelInfo("shadowing", "vgroove_g", "wi, wo, h", "Mikkelsen 2009, eq. 25 (Blinn 1977)"),
    ModelInfo(
        "shadowing",
        "smith_g1",
        "w, h, ndf; closed Λ for Beckmann/GGX, projected-area identity otherwise",
        "Smith 1967; Heitz 2014",
    ),
    ModelInfo(
        "shadowing",
        "smith_g2",
        "wi, wo, h, ndf, correlated=False|True",
        "separable / height-correlated Smith (Heitz 2014)",
    ),
    ModelInfo(
        "brdf",
        "torrance_sparrow",
        "wi, wo, ndf, shadowing=vgroove|smith|smith-correlated|none, material",
        "Mikkelsen 2009, eq. 13/18",
    ),
    ModelInfo(
        "brdf",
        "directional_albedo / AlbedoTable",
        "θ (deg), brdf / ndf, shadowing, material",
        "Mikkelsen 2009, eq. 27",
    ),
    ModelInfo(
        "brdf",
        "mikkelsen_mix",
        "wi, wo, specular albedo table, diffuse colour",
        "Mikkelsen 2009, eq. 28",
    ),
    ModelInfo(
        "brdf",
        "mikkelsen_diffuse / mikkelsen_kd",
        "wi, wo, AlbedoTable, kd ≥ 0 (fitted to a target energy), ks",
        "Mikkelsen 2009, eq. 28",
    ),
    ModelInfo(
        "brdf",
        "KullaConty",
        "ndf or AlbedoTable (F = 1); fresnel_factor, material",
        "Kulla & Conty 2017; Kelemen & Szirmay-Kalos 2001",
    ),
    ModelInfo(
        "brdf",
        "walk_bin_averages",
        "theta_i (deg), theta_edges/phi_edges (deg, Bins conventions), ndf Beckmann|GGX, "
        "material, n_paths, orders, folded, seed",
        "Heitz et al. 2016 (random walk on a Smith microsurface)",
    ),
    ModelInfo(
        "sampler",
        "sample_visible_normals",
        "v (N,3) either hemisphere, ndf Beckmann|GGX, u1, u2",
        "Heitz & d'Eon 2014 (Beckmann); Heitz 2018 (GGX)",
    ),
    ModelInfo(
        "brdf",
        "rayleigh_rice",
        "wi, wo, wavelength > 0, A ≥ 0, B > 0, C > 1, material",
        "Löw et al. 2012, eq. 3–8",
    ),
    ModelInfo(
        "brdf",
        "low_smooth",
        "wi, wo, A ≥ 0, B > 0, C > 0, kd ≥ 0, material",
        "Löw et al. 2012, eq. 12–14",
    ),
    ModelInfo(
        "brdf",
        "low_microfacet",
        "wi, wo, A ≥ 0, B > 0, C > 0, kd ≥ 0, material",
        "Löw et al. 2012, eq. 15",
    ),
    ModelInfo(
        "brdf",
        "edwards_empirical",
        "wi, wo, disk density, projection=scaling|orthogonal",
        "Edwards et al. 2006, eq. 33",
    ),
    ModelInfo(
        "brdf",
        "edwards_fit_brdf",
        "wi, wo, EdwardsParams, projection",
        "Edwards et al. 2006, eq. 34–36",
    ),
    ModelInfo(
        "sampler",
        "sample_microfacet",
        "wo, u1, u2, ndf (pdf: pdf_microfacet(wi, wo, ndf))",
        "Mikkelsen 2009, eq. 15 (Jacobian)",
    ),
    ModelInfo("sampler", "sample_low_smooth", "wo, u1, u2, B", "Löw et al. 2012, eq. 17–22"),
    ModelInfo("sampler", "sample_low_microfacet", "wo, u1, u2, B, C", "Löw et al. 2012, eq. 23–28"),
    ModelInfo(
        "sampler",
        "sample_edwards",
        "wo, u1, u2, lumps, projection",
        "Edwards et al. 2006, eq. 26–29",
    ),
    ModelInfo(
        "metric",
        "low_e1 / low_e2",
        "measured, model, bins (θ in degrees)",
        "Löw et al. 2012, eq. 29–33",
    ),
)


def model_table() -> str:
    """Plain-text table of every model: kind, name, parameters, source."""
    rows = [("kind", "name", "parameters", "source")]
    rows += [(m.kind, m.name, m.params, m.source) for m in MODELS]
    widths = [max(len(r[i]) for r in rows) for i in range(3)]
    lines = []
    for k, r in enumerate(rows):
        lines.append("  ".join(r[i].ljust(widths[i]) for i in range(3)) + "  " + r[3])
        if k == 0:
            lines.append("-" * (sum(widths) + 6 + max(len(r[3]) for r in rows)))
    return "\n".join(lines)
