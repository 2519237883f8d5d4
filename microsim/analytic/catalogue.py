"""The list of closed-form models microsim implements, for `microsim models` and reports.

Generated: the BRDFs and masking terms from the class attributes of ``models.MODEL_CLASSES``,
``dielectric.WalterDielectric`` (a BSDF: reflection and transmission, listed with the BRDFs)
and ``masking.MASKING_CLASSES`` (``name``, ``params_doc``, ``source``, ``functions``; a
sampleable class adds a "sampler" row from ``sampler_doc``, ``sampler_source``,
``sampler_functions``), the NDFs, Fresnel terms, albedo tools, the random walk and the metrics
(which stay plain functions or classes without such attributes) from ``_FUNCTIONS`` below.
Each entry names the Python object in ``microsim.analytic``, its free functions, its
parameters (units and ranges) and the paper and equation; docs/references.md has the full
entries. Directions come first — ``(wi, wo, ...)``, samplers ``(wo, u1, u2, ...)`` — then the
model; ``material`` is a name, n, n + ik or None (``resolve_material``).
"""

from __future__ import annotations

import os
import textwrap
from dataclasses import dataclass

from .dielectric import WalterDielectric
from .masking import MASKING_CLASSES
from .models import MODEL_CLASSES

__all__ = ["ModelInfo", "MODELS", "ReportModel", "REPORT_MODELS", "report_names", "model_table"]

KINDS = ("fresnel", "ndf", "shadowing", "brdf", "sampler", "metric")


@dataclass(frozen=True)
class ModelInfo:
    kind: str  # one of KINDS
    name: str  # Python name in microsim.analytic ("Class.sample" for a sampler row)
    params: str  # parameters with units / ranges
    source: str  # paper and equation
    functions: tuple[str, ...] = ()  # its free functions in microsim.analytic

    @property
    def label(self) -> str:
        """``name`` and its free functions, as printed: "TorranceSparrow / torrance_sparrow"."""
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
        "dielectric_fresnel",
        "cos_i ∈ [0,1] on the incident side, eta = η_t/η_i > 0 real (η < 1: total internal "
        "reflection gives 1)",
        "Walter et al. 2007, eq. 22; Mikkelsen 2009, §2.1",
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
        "AnisotropicBeckmann",
        "alpha_x, alpha_y > 0 along its axes, rotation (deg); exact Smith Λ with the projected "
        "roughness α(φ); sample_visible/pdf_visible (stretched visible normals); "
        "isotropic_equivalent(): α = √(αx αy) (MaterialX)",
        "Heitz 2014 (anisotropic distributions and their Smith Λ); Heitz 2018",
    ),
    ModelInfo(
        "ndf",
        "AnisotropicGGX",
        "alpha_x, alpha_y > 0 along its axes, rotation (deg); exact Smith Λ with the projected "
        "roughness α(φ); sample_visible/pdf_visible (stretched visible normals); "
        "isotropic_equivalent(): α = √(αx αy) (MaterialX)",
        "Heitz 2014 (anisotropic distributions and their Smith Λ); Heitz 2018",
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
        "theta_i (deg), theta_edges/phi_edges (deg, Bins conventions), ndf Beckmann|GGX|"
        "AnisotropicBeckmann|AnisotropicGGX, material, n_paths, orders, folded, seed, phi_i "
        "(deg, one or per θi) (no pointwise f: no model object)",
        "Heitz et al. 2016 (random walk on a Smith microsurface)",
        ("smith_random_walk",),
    ),
    ModelInfo(
        "sampler",
        "sample_visible_normals",
        "v (N,3) either hemisphere, ndf Beckmann|GGX|AnisotropicBeckmann|AnisotropicGGX, u1, u2",
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
    generated += [e for c in MODEL_CLASSES + (WalterDielectric,) for e in _class_entries(c, "brdf")]
    rows = list(_FUNCTIONS) + generated
    return tuple(sorted(rows, key=lambda m: KINDS.index(m.kind)))  # stable within a kind


MODELS: tuple[ModelInfo, ...] = _build()


@dataclass(frozen=True)
class ReportModel:
    """A model as ``microsim run``/``report`` name it: ``names`` (one, or the expansions of a
    family), ``role`` (where it appears: "closed form", "fit", "wave", "bounces"), what it is,
    the ``microsim.analytic`` object that computes it, and the paper and equation."""

    names: tuple[str, ...]
    role: str
    what: str
    python: str
    source: str

    @property
    def label(self) -> str:
        """The names as printed: a family as prefix{a|b|c}, others comma-separated."""
        prefix = os.path.commonprefix(list(self.names))
        if len(self.names) > 1 and prefix.endswith("-") and len(prefix) > 3:
            return prefix + "{" + "|".join(n[len(prefix) :] for n in self.names) + "}"
        return ", ".join(self.names)


_TS_FAMILY = ("vgroove", "smith", "smith-corr")
REPORT_MODELS: tuple[ReportModel, ...] = (
    ReportModel(
        ("ts-vgroove",),
        "closed form",
        "Torrance–Sparrow with Blinn's V-groove G and the surface's ensemble NDF",
        "TorranceSparrow(ndf, VGroove(), material)",
        "Mikkelsen 2009, eq. 13, 25 (Blinn 1977)",
    ),
    ReportModel(
        ("ts-smith",),
        "closed form",
        "Torrance–Sparrow with the separable Smith G and the ensemble NDF",
        "TorranceSparrow(ndf, Smith(correlated=False), material)",
        "Mikkelsen 2009, eq. 13; Smith 1967; Heitz 2014",
    ),
    ReportModel(
        ("ts-smith-corr",),
        "closed form",
        "Torrance–Sparrow with the height-correlated Smith G and the ensemble NDF",
        "TorranceSparrow(ndf, Smith(correlated=True), material)",
        "Mikkelsen 2009, eq. 13; Heitz 2014",
    ),
    ReportModel(
        ("ts-facets",),
        "closed form",
        "Torrance–Sparrow with the traced tile's own facets as D and the surface's exact G "
        "(V-groove G on V-grooves, height-correlated Smith on heightfields)",
        "TorranceSparrow(Empirical(normals, weights), ...)",
        "Mikkelsen 2009, eq. 13, 14, 17",
    ),
    ReportModel(
        ("ts-vgroove-oriented",),
        "closed form",
        "oriented V-grooves: Torrance–Sparrow with V-groove G on 2¹⁶ stratified tilts of the "
        "tilt NDF — the continuum of grooves the traced tile quantises, its ensemble form",
        "TorranceSparrow(Empirical(normals, weights), VGroove())",
        "Mikkelsen 2009, eq. 25",
    ),
    ReportModel(
        tuple(f"ts-{d}-nominal-{g}" for d in ("beckmann", "ggx", "student-t") for g in _TS_FAMILY),
        "closed form",
        "heightfields: Torrance–Sparrow with the ensemble NDF (Beckmann at the scene's nominal "
        "m; GGX or Student-t on Student-t heightfields), with each G",
        "TorranceSparrow(Beckmann(m) | GGX(α) | StudentT(α, γ), VGroove() | Smith(...), material)",
        "Mikkelsen 2009, eq. 13, 20",
    ),
    ReportModel(
        tuple(f"ts-beckmann-realised-{g}" for g in _TS_FAMILY),
        "closed form",
        "heightfields: the same with Beckmann at the rms slope the mesh realises",
        "TorranceSparrow(Beckmann(m_realised), ..., material)",
        "Mikkelsen 2009, eq. 13, 20",
    ),
    ReportModel(
        ("ts-beckmann-nominal-smith-corr-geomean",),
        "closed form",
        "anisotropic heightfields: the ensemble's anisotropic Beckmann D with the height-"
        "correlated Smith G of the isotropic α = √(αx αy) (MaterialX's stand-in for the "
        "anisotropic Smith G)",
        "TorranceSparrow(ndf, Smith(ndf.isotropic_equivalent(), correlated=True), material)",
        "Heitz 2014; MaterialX (geometric-mean roughness in G)",
    ),
    ReportModel(
        ("mirror-fresnel",),
        "closed form",
        "flat surfaces: all light in the mirror bin, weighted by Fresnel",
        "fresnel(cos θi, material)",
        "Mikkelsen 2009, §2.1",
    ),
    ReportModel(
        ("cook-torrance",),
        "fit",
        "kd/π + ks·Torrance–Sparrow(Beckmann(m), V-groove G), fitted: ks, m, kd",
        "CookTorrance(ndf, material, ks, kd)",
        "Cook & Torrance 1982; Mikkelsen 2009, eq. 13, 25",
    ),
    ReportModel(
        ("low-microfacet",),
        "fit",
        "Löw's ABC microfacet model, fitted: A, B, C, kd, n",
        "LowMicrofacet(A, B, C, kd, material)",
        "Löw et al. 2012, eq. 15",
    ),
    ReportModel(
        ("low-smooth",),
        "fit, wave",
        "Löw's smooth-surface model: fitted (A, B, C, kd, n) against the ray trace, where it "
        "is outside its domain; with A, B, C from the surface's PSD against the Kirchhoff "
        "solver (wave scenes)",
        "LowSmooth(A, B, C, kd, material)",
        "Löw et al. 2012, eq. 12–14",
    ),
    ReportModel(
        ("edwards",),
        "fit",
        "Edwards et al.'s data-fitting halfway-disk model",
        "EdwardsFit(fit_params)",
        "Edwards et al. 2006, eq. 34–36",
    ),
    ReportModel(
        ("rayleigh-rice",),
        "wave",
        "first-order vector perturbation theory on the surface's PSD",
        "RayleighRice(wavelength, A, B, C, material, B_y, rotation)",
        "Löw et al. 2012, eq. 3–8",
    ),
    ReportModel(
        ("kirchhoff-first-order",),
        "wave",
        "the Kirchhoff BRDF to first order in the heights",
        "analysis.wave_verdicts (Q_K · PSD)",
        "Beckmann & Spizzichino 1963, ch. 3",
    ),
    ReportModel(
        ("walk-2", "walk-2+"),
        "bounces",
        "the random walk on a Smith microsurface: order 2 and all orders ≥ 2",
        "walk_bin_averages(...)",
        "Heitz et al. 2016",
    ),
    ReportModel(
        ("random-walk", "kulla-conty", "mikkelsen-eq28"),
        "bounces",
        "multiple-scattering energy: the random walk, Kulla–Conty's compensation lobe, "
        "Mikkelsen's diffuse term",
        "walk_bin_averages, KullaContyLobe, MikkelsenDiffuse",
        "Heitz et al. 2016; Kulla & Conty 2017; Mikkelsen 2009, eq. 28",
    ),
)
"""Every model name the reports use, one entry per model (``microsim models`` lists them;
tests/test_catalogue.py checks that every name the runner produces is here)."""


def report_names() -> frozenset:
    """Every model name of ``REPORT_MODELS``."""
    return frozenset(n for m in REPORT_MODELS for n in m.names)


def _wrapped(head: str, lines: list[str], width: int, indent: int) -> list[str]:
    """``head`` padded to ``indent`` columns, then ``lines`` each wrapped to ``width``."""
    out, pad = [], " " * indent
    for k, text in enumerate(lines):
        first = head.ljust(indent - 1) + " " if k == 0 else pad
        if len(first) > indent:  # a long head gets lines of its own
            out += textwrap.wrap(head, width, subsequent_indent="  ", break_on_hyphens=False)
            first = pad
        out += textwrap.wrap(
            text, width, initial_indent=first, subsequent_indent=pad, break_on_hyphens=False
        ) or [first.rstrip()]
    return out


def model_table(width: int = 100) -> str:
    """``microsim models``: the models as the reports name them (name, what it is, the object
    that computes it, its source), then every building block of ``microsim.analytic``
    (kind, name / free functions, parameters, source); wrapped to ``width`` columns."""
    width = max(int(width), 40)
    out = ["Models as microsim run and microsim report name them", ""]
    for m in REPORT_MODELS:
        out += _wrapped(m.label, [f"{m.what} [{m.role}]", m.python, m.source], width, 26)
    out += ["", "Building blocks (microsim.analytic)", ""]
    for kind in KINDS:
        for m in (e for e in MODELS if e.kind == kind):
            out += _wrapped(f"{kind}: {m.label}", [m.params, m.source], width, 26)
    return "\n".join(out)
