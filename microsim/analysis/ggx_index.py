"""The index section "Smith-GGX on surfaces that are GGX": Torrance–Sparrow with the Smith G of
the surface's own Student-t (GGX at γ = 2) distribution — separable and height-correlated —
judged against explicit surfaces whose facet normals follow that distribution, per θi and per
construction (``surfaces.student_t``: one transformed Gaussian tile, or a mixture of Beckmann
patches), beside the random walk's and Kulla–Conty's orders ≥ 2; and the series γ = 2, 3, …, ∞
at one roughness (γ = ∞: the Beckmann heightfields of that m). Pure formatting of the verdict
documents."""

from __future__ import annotations

from typing import Sequence

from .markdown import md_table
from .multiple_report import deviation_text
from .report_cells import verdict_cell
from .study_records import RunDocument

__all__ = ["ggx_section", "CONSTRUCTIONS"]

CONSTRUCTIONS = {
    "student-t-transform": "transform of a Gaussian field (one tile)",
    "student-t-mixture": "mixture of Beckmann patches",
    "gaussian": "Gaussian field",
}
"""How the section names each surface kind."""
_STUDENT_T = ("ggx", "student-t")


def _ndf(d: RunDocument) -> dict:
    return dict((d.surface or {}).get("ensemble_ndf") or {})


def _alpha(ndf: dict):
    return ndf.get("alpha", ndf.get("m"))


def _gamma(ndf: dict) -> float:
    return {"ggx": 2.0, "beckmann": float("inf")}.get(ndf.get("name"), ndf.get("gamma"))


def _gamma_text(gamma: float) -> str:
    return "∞" if gamma == float("inf") else f"{gamma:g}"


def _cell(d: RunDocument, model: str, theta: float) -> str:
    """``model``'s verdict at ``theta`` (``report_cells.verdict_cell``), "–" where it has none."""
    for v in d.verdicts:
        if v.model == model and v.theta_i == theta:
            return verdict_cell(v.kind, v.energy_dev, v.energy_dev_se, v.rel_rms)
    return "–"


def _orders_cell(d: RunDocument, name: str, theta: float) -> str:
    comparison = (d.orders.comparison if d.orders else None) or {}
    for inc in comparison.get("incidences", []):
        if inc["theta_i"] == theta and name in inc["models"]:
            return deviation_text(inc, name)
    return "–"


def _link(d: RunDocument) -> str:
    return f"[{d.scene}]({d.scene}/report.md)"


def _surface_text(d: RunDocument) -> str:
    ndf = _ndf(d)
    law = "GGX" if ndf["name"] == "ggx" else f"Student-t γ = {ndf['gamma']:g}"
    kind = (d.surface or {}).get("kind", "")
    return f"{CONSTRUCTIONS.get(kind, kind)}, {law}, α = {_alpha(ndf):g}"


def _series(docs: Sequence[RunDocument], student: Sequence[RunDocument]) -> list[str]:
    """γ = 2, 3, …, ∞ at each α of the Student-t scenes: the height-correlated Smith energy
    deviation per θi, one row per scene (γ = ∞: isotropic Gaussian scenes of m = α)."""
    alphas = {_alpha(_ndf(d)) for d in student}
    beck = [
        d
        for d in docs
        if _ndf(d).get("name") == "beckmann"
        and (d.surface or {}).get("kind") == "gaussian"
        and _alpha(_ndf(d)) in alphas
    ]
    rows_docs = sorted(
        list(student) + beck, key=lambda d: (_alpha(_ndf(d)), _gamma(_ndf(d)), d.scene)
    )
    thetas = sorted({t for d in rows_docs for t in d.theta_i})
    rows = []
    for d in rows_docs:
        ndf = _ndf(d)
        model = f"ts-{ndf['name']}-nominal-smith-corr"
        rows.append(
            [
                f"{_alpha(ndf):g}",
                _gamma_text(_gamma(ndf)),
                _link(d),
                CONSTRUCTIONS[d.surface["kind"]],
            ]
            + [_cell(d, model, t) for t in thetas]
        )
    return [
        "From GGX to Beckmann: Torrance–Sparrow with the height-correlated Smith G of each "
        "surface's own distribution, at one roughness, as the tail thins (γ = ∞: the Gaussian "
        "heightfield of m = α, Beckmann).",
        "",
        md_table(["α", "γ", "scene", "construction"] + [f"θi {t:g}°" for t in thetas], rows),
        "",
    ]


def ggx_section(docs: Sequence[RunDocument]) -> list[str]:
    """The section's markdown lines; [] when no heightfield scene has an isotropic Student-t
    (or GGX) ensemble (V-grooves with those tilts have their own exact G: not shown here)."""
    docs = [RunDocument.from_json(d) for d in docs]
    student = [
        d
        for d in docs
        if _ndf(d).get("name") in _STUDENT_T and (d.surface or {}).get("kind") in CONSTRUCTIONS
    ]
    if not student:
        return []
    student.sort(key=lambda d: (_gamma(_ndf(d)), _alpha(_ndf(d)), d.surface["kind"], d.scene))
    rows = []
    for d in student:
        family = _ndf(d)["name"]
        for t in d.theta_i:
            rows.append(
                [_link(d), _surface_text(d), f"{t:g}°"]
                + [_cell(d, f"ts-{family}-nominal-{g}", t) for g in ("smith", "smith-corr")]
                + [_orders_cell(d, name, t) for name in ("random-walk", "kulla-conty")]
            )
    return [
        "## Smith-GGX on surfaces that are GGX",
        "",
        "Explicit heightfields whose facet normals follow GGX (Student-t with γ = 2; Ribardière "
        "et al. 2017) or a Student-t law, built two ways: a memoryless transform of one "
        "Gaussian field — one tile whose heights and slopes are correlated, which Smith's "
        "masking assumes they are not — and a mixture of Beckmann patches, each an independent "
        "Gaussian field of its own roughness (one patch per realisation: the NDF is exactly "
        "Student-t, the BRDF a blend of Beckmann BRDFs). Same NDF, different surfaces: the "
        "difference between the two is what the masking function alone decides. Columns: "
        "Torrance–Sparrow with the distribution's D and its Smith G, separable and "
        "height-correlated, against the simulation's single scattering: verdict symbol, energy "
        "deviation (simulation − model)/model ± standard error, and energy-weighted relative "
        "RMS error; then the relative energy deviation of orders ≥ 2 (simulation − model)/"
        "simulation ± standard error of Heitz et al.'s random walk on the Smith microsurface "
        "and of Kulla–Conty's compensation (pp: absolute, where the simulated orders ≥ 2 are "
        "not resolved). Each scene's report shows where in the hemisphere the models deviate; "
        "`microsim surface <scene>` prints how closely the tile realises its slope law.",
        "",
        md_table(
            [
                "scene",
                "surface",
                "θi",
                "Smith separable",
                "Smith height-correlated",
                "random walk (orders ≥ 2)",
                "Kulla–Conty (orders ≥ 2)",
            ],
            rows,
        ),
        "",
    ] + _series(docs, student)
