"""The list of closed-form models microsim implements, for `microsim models` and reports.

Each entry names the Python callable, its parameters (with units and allowed ranges) and the
paper and equation it comes from. Paper keys: Mikkelsen 2009 (seed 000), Mally slides (001),
Edwards et al. (002), Löw et al. 2012 (004).
"""
from __future__ import annotations

from dataclasses import dataclass

__all__ = ["ModelInfo", "MODELS", "model_table"]


@dataclass(frozen=True)
class ModelInfo:
    kind: str          # "fresnel" | "ndf" | "shadowing" | "brdf" | "sampler" | "metric"
    name: str          # Python name in microsim.analytic
    params: str        # parameters with units / ranges
    source: str        # paper and equation


MODELS: tuple[ModelInfo, ...] = (
    ModelInfo("fresnel", "fresnel", "cos_theta ∈ [0,1]; ior: None (F≡1) | n>0 (dielectric) | n+ik (conductor)", "Mally slides; Mikkelsen §2.1"),
    ModelInfo("fresnel", "schlick", "cos_theta; f0 ∈ [0,1]", "Edwards eq. 30–31"),
    ModelInfo("ndf", "Beckmann", "m > 0 (rms slope)", "Mikkelsen eq. 20"),
    ModelInfo("ndf", "GGX", "alpha > 0", "Walter et al. 2007 (Trowbridge–Reitz)"),
    ModelInfo("ndf", "BlinnPhong", "e ≥ 0 (exponent), normalised (e+2)/2π", "Mikkelsen eq. 19; Mally"),
    ModelInfo("ndf", "VonMisesFisher", "kappa > 0 (concentration); D = p/(h·n)", "Mikkelsen eq. 29–33"),
    ModelInfo("ndf", "ABC", "B > 0, C > 0; D ∝ (1 + B(1−h·n))^−C normalised", "Löw eq. 15, 23–24"),
    ModelInfo("ndf", "Empirical", "normals (N,3), projected-area weights", "histogram of the surface's own facets"),
    ModelInfo("ndf", "beckmann_to_phong", "0 < m ≤ 1 → Phong exponent e = 2/m² − 2 (and phong_to_beckmann)", "Mikkelsen eq. 21"),
    ModelInfo("shadowing", "vgroove_g", "wi, wo, h", "Mikkelsen eq. 25 (Blinn / Cook–Torrance V-groove)"),
    ModelInfo("shadowing", "smith_g1", "ndf, w, h; closed Λ for Beckmann/GGX, projected-area identity otherwise", "Smith; DESIGN.md"),
    ModelInfo("shadowing", "smith_g2", "ndf, wi, wo, h, correlated=False|True", "separable / height-correlated Smith"),
    ModelInfo("brdf", "torrance_sparrow", "wi, wo, ndf, shadowing=vgroove|smith|smith-correlated|none, ior", "Mikkelsen eq. 13/18"),
    ModelInfo("brdf", "directional_albedo / AlbedoTable", "brdf, θ (deg)", "Mikkelsen eq. 27"),
    ModelInfo("brdf", "mikkelsen_mix", "specular albedo table, diffuse colour", "Mikkelsen eq. 28"),
    ModelInfo("brdf", "rayleigh_rice", "wavelength > 0, A ≥ 0, B > 0, C > 1, ior", "Löw eq. 3–8"),
    ModelInfo("brdf", "low_smooth", "A ≥ 0, B > 0, C > 0, kd ≥ 0, ior", "Löw eq. 12–14"),
    ModelInfo("brdf", "low_microfacet", "A ≥ 0, B > 0, C > 0, kd ≥ 0, ior", "Löw eq. 15"),
    ModelInfo("brdf", "edwards_empirical", "disk density, projection=scaling|orthogonal", "Edwards eq. 33"),
    ModelInfo("brdf", "edwards_fit_brdf", "EdwardsParams, projection", "Edwards eq. 34–36"),
    ModelInfo("sampler", "sample_microfacet", "ndf, wo, u1, u2", "Mikkelsen eq. 15 (Jacobian)"),
    ModelInfo("sampler", "sample_low_smooth", "wo, u1, u2, B", "Löw eq. 17–22"),
    ModelInfo("sampler", "sample_low_microfacet", "wo, u1, u2, B, C", "Löw eq. 23–28"),
    ModelInfo("sampler", "sample_edwards", "wo, u1, u2, lumps, projection", "Edwards eq. 26–29"),
    ModelInfo("metric", "low_e1 / low_e2", "measured, model, bins", "Löw eq. 29–33"),
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
