"""The list of closed-form models microsim implements, for `microsim models` and reports.

Generated: the BRDFs and masking terms from the class attributes of ``models.MODEL_CLASSES``
and ``masking.MASKING_CLASSES`` (``name``, ``params_doc``, ``source``, ``functions``; a
sampleable class adds a "sampler" row from ``sampler_doc``, ``sampler_source``,
``sampler_functions``), the NDFs, Fresnel terms, albedo tools, the random walk and the metrics
(which stay plain functions or classes without such attributes) from ``_FUNCTIONS`` below.
Each entry names the Python object in ``microsim.analytic``, the free functions it wraps, its
parameters (units and ranges) and the paper and equation; docs/references.md has the full
entries. Directions come first — ``(wi, wo, ...)``, samplers ``(wo, u1, u2, ...)`` — then the
model; ``material`` is a name, n, n + ik or None (``resolve_material``).
"""

from __future__ import annotations

from dataclasses import dataclass

from .masking import MASKING_CLASSES
from .models import MODEL_CLASSES

__all__ = ["ModelInfo", "MODELS", "model_table"]

KINDS = ("fresnel", "ndf", "shadowing", "brdf", "sampler", "metric")


@dataclass(frozen=True)
class ModelInfo:
    kind: str  # one of KINDS
    name: str  # Python name in microsim.analytic ("Class.sample" for a sampler row)
    params: str  # parameters with units / ranges
    source: str  # paper and equation
    functions: tuple[str, ...] = ()  # free functions of microsim.analytic it wraps

    @property
    def label(self) -> str:
        """``name`` and the wrapped functions, as printed: "TorranceSparrow / torrance_sparrow"."""
        return " / ".join((self.name,) + tuple(self.functions))


_FUNCTIONS: tuple[ModelInfo, ...] = (
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
        ("phong_to_beckmann",),
    ),
    ModelInfo(
        "brdf",
        "AlbedoTable",
        "θ (deg), brdf / ndf, shadowing, material",
        "Mikkelsen 2009, eq. 27",
        ("directional_albedo",),
    ),
    ModelInfo(
        "brdf",
        "walk_bin_averages",
        "theta_i (deg), theta_edges/phi_edges (deg, Bins conventions), ndf Beckmann|GGX, "
        "material, n_paths, orders, folded, seed (no pointwise f: no model object)",
        "Heitz et al. 2016 (random walk on a Smith microsurface)",
        ("smith_random_walk",),
    ),
    ModelInfo(
        "sampler",
        "sample_visible_normals",
        "v (N,3) either hemisphere, ndf Beckmann|GGX, u1, u2",
        "Heitz & d'Eon 2014 (Beckmann); Heitz 2018 (GGX)",
    ),
    ModelInfo(
        "metric",
        "low_e1",
        "measured, model, bins (θ in degrees)",
        "Löw et al. 2012, eq. 29–33",
        ("low_e2",),
    ),
)
"""The entries that stay plain functions (or classes without catalogue attributes)."""


def _class_entries(cls, kind: str) -> list[ModelInfo]:
    rows = [ModelInfo(kind, cls.name, cls.params_doc, cls.source, tuple(cls.functions))]
    if hasattr(cls, "sample"):
        rows.append(
            ModelInfo(
                "sampler",
                f"{cls.name}.sample",
                cls.sampler_doc,
                cls.sampler_source,
                tuple(cls.sampler_functions),
            )
        )
    return rows


def _build() -> tuple[ModelInfo, ...]:
    generated = [e for c in MASKING_CLASSES for e in _class_entries(c, "shadowing")]
    generated += [e for c in MODEL_CLASSES for e in _class_entries(c, "brdf")]
    rows = list(_FUNCTIONS) + generated
    return tuple(sorted(rows, key=lambda m: KINDS.index(m.kind)))  # stable within a kind


MODELS: tuple[ModelInfo, ...] = _build()


def model_table() -> str:
    """Plain-text table of every model: kind, name (/ wrapped functions), parameters, source."""
    rows = [("kind", "name", "parameters", "source")]
    rows += [(m.kind, m.label, m.params, m.source) for m in MODELS]
    widths = [max(len(r[i]) for r in rows) for i in range(3)]
    lines = []
    for k, r in enumerate(rows):
        lines.append("  ".join(r[i].ljust(widths[i]) for i in range(3)) + "  " + r[3])
        if k == 0:
            lines.append("-" * (sum(widths) + 6 + max(len(r[3]) for r in rows)))
    return "\n".join(lines)
