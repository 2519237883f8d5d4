"""Markdown reports: one per scene (``report.md``) and the summary ``microsim run`` prints; the
catalogue index (``index.md``) is ``report_index``, the wave-optics sections ``report_wave``,
the methods' costs ``report_methods``, the shared cells ``report_cells`` (their public names are
importable from here too).

Pure formatting: every number comes from the verdict document written as ``verdicts.json`` (see
``microsim.app.runner`` and docs/verdicts.md for its schema) and, for the energy ledger, from the
``Result``. No wall-clock time appears in either report (they are in ``timings.json``), so rerunning
an unchanged scene rewrites them byte for byte. Signed percentages are relative
deviations (simulation − model)/simulation, the one sign convention of every output (negative:
the model is too bright); BRDFs in sr⁻¹, angles in degrees.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from . import incidence
from .budget import BudgetRow
from .glass_report import glass_section
from .json_record import JsonRecord
from .markdown import md_table, percent
from .report_cells import converged_text, fmt, params_text, pct, ranges_text
from .report_index import index_report
from .report_methods import load_methods, methods_section
from .report_wave import regime_section, wave_section
from .study_records import Fit, OrdersStudy, RunDocument, Speed, Stability
from .verdicts import Verdict, as_verdicts, summary_row, verdict_symbol

__all__ = [
    "md_table",
    "scene_report",
    "index_report",
    "fmt",
    "albedo_stderr",
    "wave_section",
    "regime_section",
    "methods_section",
    "load_methods",
    "OUT_OF_DOMAIN",
    "AutoRealisations",
    "auto_realisations",
]


def _material(mat: Mapping) -> str:
    ior = mat.get("ior")
    if ior is None:
        return "mirror (F = 1)"
    n, k = ior
    text = f"n = {n:g}" if k == 0 else f"n + ik = {n:g} + {k:g}i"
    name = mat.get("name")
    return f"{name}, {text}" if name else text


def albedo_stderr(result) -> np.ndarray:
    """(T,) per-ray standard error of the single-bounce albedo ρ(θi) = ledger "single_fresnel"
    (Mikkelsen eq. 27): √((Σw²/N − ρ²)/(N − 1)), Σw² over the binned single-bounce rays."""
    n = result.rays.astype(np.float64)
    m2 = result.sum_w2.reshape(len(n), -1).sum(axis=1) / np.maximum(n, 1)
    rho = result.ledger["single_fresnel"]
    return np.sqrt(np.maximum(m2 - rho**2, 0.0) / np.maximum(n - 1, 1))


_LEDGER_COLUMNS = (
    ("single", ".4f"),
    ("masked", ".4f"),
    ("downward", ".4f"),
    ("unresolved", ".2g"),
    ("lost_fresnel", ".4f"),
)
"""The ledger entries of the energy table after ρ, in order, with their number format."""


def _ledger_rows(doc, result, with_phi: bool) -> list[list[str]]:
    led = result.ledger
    rho, se = led["single_fresnel"], albedo_stderr(result)
    return [
        [
            *([f"{t:g}", f"{p:g}"] if with_phi else [f"{t:g}"]),
            f"{int(r)}",
            f"{rho[k]:.4f} ± {se[k]:.1g}",
            *(format(led[name][k], spec) for name, spec in _LEDGER_COLUMNS),
        ]
        for k, (t, p, r) in enumerate(zip(result.theta_i, result.phi_i, result.rays))
    ]


def _verdict_word(v: Verdict) -> str:
    return "**agrees**" if v.kind == "agrees" else v.kind


OUT_OF_DOMAIN = "outside its domain (wave-optics model; fit-only)"
"""Summary text of a model the verdict document lists under ``outside_domain``: its
verdicts against the ray tracer are no test of it (the fit numbers are kept)."""


def _reference_text(v: Verdict) -> str:
    """The verdict's reference, its R and, for a tile whose departure is known, its size."""
    text = f"{v.reference} (R = {v.realisations})"
    if v.tile_departure is not None:
        text += f", tile departs {pct(v.tile_departure)}"
    return text


def _verdict_rows(
    verdicts, outside: Mapping | None = None, with_phi: bool = False
) -> list[list[str]]:
    """The rows of "Every incidence × model" (``verdicts``: Verdicts or their JSON dicts)."""
    outside = outside or {}
    return [
        [
            *([f"{v.theta_i:g}", f"{v.phi_i:g}"] if with_phi else [f"{v.theta_i:g}"]),
            v.model + (" (fit)" if v.fitted else ""),
            "outside domain" if v.model in outside else _verdict_word(v),
            _reference_text(v),
            fmt(v.chi2_dof),
            fmt(v.p_value),
            fmt(v.max_abs_z),
            pct(v.rel_rms),
            pct(v.max_rel_dev),
            "–" if v.worst_bin is None else f"θo {v.worst_bin[0]:g}°, Δφ {v.worst_bin[1]:g}°",
            ranges_text(v.deviations),
            str(v.n_bins),
        ]
        for v in as_verdicts(verdicts)
    ]


def _orders_section(orders: OrdersStudy | None) -> list[str]:
    """ "How much light single scattering misses" for a run with ``bounces`` > 1: per θi the
    fraction of reflected energy in orders ≥ 2 (``analysis.multiple.needs_more_bounces``), then
    the order-resolved comparison (``analysis.multiple_report.multiple_section``)."""
    if not orders:
        return []
    from .multiple_report import multiple_section

    with_phi = incidence.several_azimuths(orders.needs)
    rows = [
        [
            *([f"{n.theta_i:g}", f"{n.phi_i:g}"] if with_phi else [f"{n.theta_i:g}"]),
            f"{percent(n.multiple_fraction, 3, unit=' %')} ± "
            f"{percent(n.multiple_fraction_se, unit=' %')}",
            pct(n.cut),
            "yes" if n.needs else "no",
        ]
        for n in orders.needs
    ]
    out = [
        "## Scattering orders",
        "",
        f"Traced with `bounces = {orders.bounces}`; the verdicts above judge order 1. "
        "Fraction of the reflected energy in orders ≥ 2 (± standard error), the energy cut off "
        "by the bounce limit, and whether single scattering misses more than 1 % of it.",
        "",
        md_table(["θi", *(["φi"] if with_phi else []), "orders ≥ 2", "cut", "> 1 %"], rows),
        "",
    ]
    if orders.note:
        out += [f"Note: {orders.note}.", ""]
    if orders.comparison:
        out += multiple_section(orders.comparison) + [""]
    return out


@dataclass(frozen=True, eq=False)
class AutoRealisations(JsonRecord):
    """meta.json ``run.realisations_auto`` (``runner.tracing.realisations_record``): the
    ``stage`` ("pilot", then "final"), the tile-scatter ``target``, the pilot's and the chosen
    realisations, at most ``max_realisations``."""

    stage: str = "final"
    target: float | None = None
    max_realisations: int | None = None
    pilot_realisations: int | None = None
    realisations: int | None = None


def auto_realisations(run: Mapping) -> AutoRealisations | None:
    """The run's ``realisations_auto`` record; None when the count was given."""
    auto = run.get("realisations_auto")
    return AutoRealisations.from_json(auto) if auto else None


def _realisations_text(run: Mapping) -> str:
    """The realisation count; for ``realisations = "auto"`` also the pilot and the target."""
    auto = auto_realisations(run)
    if auto is None:
        return str(run.get("realisations"))
    return (
        f"{auto.realisations} (auto: pilot of {auto.pilot_realisations}, tile-scatter "
        f"target {percent(auto.target, 3, unit=' %')}, at most {auto.max_realisations})"
    )


def _budget_section(budget, auto: AutoRealisations | None) -> list[str]:
    """ "Error budget": per incidence the energy-weighted relative standard errors of the mean
    BRDF from ray noise and from tile scatter (``analysis.budget``); empty for one realisation."""
    budget = [BudgetRow.from_json(b) for b in budget or ()]
    if all(b.tile is None for b in budget):
        return []
    target = auto.target if auto else None
    with_phi = incidence.several_azimuths(budget)
    rows = [
        [
            *([f"{b.theta_i:g}", f"{b.phi_i:g}"] if with_phi else [f"{b.theta_i:g}"]),
            str(b.realisations),
            pct(b.ray),
            pct(b.tile),
            pct(b.total),
            pct(b.energy),
        ]
        + ([("yes" if b.tile is not None and b.tile <= target else "no")] if target else [])
        for b in budget
    ]
    head = ["θi", *(["φi"] if with_phi else []), "R", "ray noise", "tile scatter", "total"]
    head.append("energy")
    text = (
        "Standard errors of the mean BRDF, energy-weighted relative RMS over the bins carrying "
        "90 % of the energy (`microsim.analysis.budget`): from the rays' noise, from the "
        "tile-to-tile scatter of the realisations, and in total; *energy*: the relative "
        "standard error of the mean's energy from the scatter of the tiles' energies. Ensemble "
        "models are judged against the realisations' scatter, which includes both."
    )
    if target:
        head.append(f"tile ≤ {percent(target, 3, unit=' %')}")
        text += (
            f' With `realisations = "auto"` the realisations are added until the tile scatter '
            f"is below {percent(target, 3, unit=' %')} at every θi, up to "
            f"{auto.max_realisations}."
        )
    return ["## Error budget", "", text, "", md_table(head, rows), ""]


def scene_report(doc: Mapping, result, charts: Mapping[str, str]) -> str:
    """``report.md`` of one run: settings, energy ledger, verdicts, fits, charts."""
    doc = RunDocument.from_json(doc)
    info = result.info
    phis = doc.phi_i
    with_phi = incidence.several_azimuths(phis)
    lines = [f"# {doc.scene}", ""]
    if doc.description:
        lines += [doc.description, ""]
    lines += _run_section(doc, info, phis, with_phi)
    lines += _ledger_section(doc, result, with_phi)
    lines += _budget_section(info.error_budget, auto_realisations(info.run or {}))
    lines += _verdicts_section(doc, with_phi)
    lines += wave_section(doc.wave)
    lines += _fits_section(doc.fits)
    lines += _orders_section(doc.orders)
    lines += glass_section(doc.glass)
    lines += _charts_section(doc, charts, phis, with_phi)
    return "\n".join(lines).rstrip() + "\n"


def _run_section(doc: RunDocument, info, phis, with_phi: bool) -> list[str]:
    """ "Run": the settings table, then the warnings of the surface generator and models."""
    surf = info.surface or {}
    run = info.run or {}
    lines = [
        "## Run",
        "",
        md_table(
            ["setting", "value"],
            [
                ["scene file", f"`{doc.scene_file}`"],
                [
                    "surface",
                    f"{surf.get('kind')}, tile "
                    f"{' × '.join(fmt(x, 4) for x in surf.get('tile_size', []))}, "
                    f"{surf.get('triangles')} triangles (scale {fmt(run.get('surface_scale'))})",
                ],
                ["nominal", params_text(surf.get("nominal", {}))],
                ["material", _material(info.material or {})],
                ["incidences θi", ", ".join(f"{t:g}°" for t in doc.theta_i)],
                *(
                    [["incidence azimuths φi", _azimuths_text(phis)]]
                    if with_phi or any(phis)
                    else []
                ),
                ["rays per incidence", f"{doc.rays:,}"],
                ["realisations", _realisations_text(run)],
                ["bins (θo × Δφ)", " × ".join(str(b) for b in run.get("bins", []))],
                ["seed", str(doc.seed)],
                ["mode", "quick (`--quick`)" if doc.quick else "full"],
                ["wall times", "`timings.json` (machine-dependent)"],
            ],
        ),
        "",
    ]
    warns = list(surf.get("warnings", [])) + list(info.model_warnings)
    if warns:
        lines += (
            ["Warnings (surface generator, tracer, model quadrature):", ""]
            + [f"- {w}" for w in warns]
            + [""]
        )
    return lines


def _ledger_section(doc: Mapping, result, with_phi: bool) -> list[str]:
    inc_cols = ["θi", "φi"] if with_phi else ["θi"]
    return [
        "## Energy ledger",
        "",
        "Fractions of the incident rays (ρ: Fresnel-weighted single-bounce albedo, "
        "Mikkelsen eq. 27, ± 1 standard error; lost: Fresnel-weighted masked + downward).",
        "",
        md_table(
            [*inc_cols, "rays", "ρ", "single", "masked", "downward", "unresolved", "lost"],
            _ledger_rows(doc, result, with_phi),
        ),
        "",
    ]


_VERDICT_COLUMNS = [
    "model",
    "verdict",
    "judged against",
    "χ²/dof",
    "p",
    "max |z|",
    "rel RMS",
    "max rel dev (sim − model)/sim",
    "worst bin",
    "deviating θo",
    "bins",
]


def _verdicts_section(doc: RunDocument, with_phi: bool) -> list[str]:
    """ "Verdicts": one summary per model, the ranking, and every incidence × model folded."""
    summary = summary_row(doc.verdicts)
    outside = doc.outside_domain
    summary.update({m: OUT_OF_DOMAIN for m in outside if m in summary})
    lines = [
        "## Verdicts",
        "",
        "A model *agrees* when the χ² and max-|z| tests (Šidák-corrected over the run's "
        "family of verdicts, α = 0.01) cannot tell it from the simulation; otherwise the "
        "size and place of the deviation are given.",
        "",
        md_table(["model", "verdict"], [[m, s] for m, s in summary.items()]),
        "",
    ]
    lines += [f"- `{m}`: {why}." for m, why in outside.items()] + ([""] if outside else [])
    inc_cols = ["θi", "φi"] if with_phi else ["θi"]
    return lines + [
        "Best to worst by mean relative RMS error: "
        + ", ".join(f"`{m}`" for m in doc.ranking)
        + ".",
        "",
        "<details><summary>Every incidence × model</summary>",
        "",
        md_table([*inc_cols, *_VERDICT_COLUMNS], _verdict_rows(doc.verdicts, outside, with_phi)),
        "",
        "</details>",
        "",
    ]


def _fits_section(fits: Sequence[Fit]) -> list[str]:
    if not fits:
        return []
    return [
        "## Fits (Löw eq. 29–33)",
        "",
        "One parameter set per model for all incidences, least squares on E2; "
        "√E1 and √E2 as in Löw Table II. A parameter on a physical bound of its box "
        "(kd ≥ 0, a fraction ≤ 1) is a constrained minimum; one at a search limit (the "
        "box's practical ends, e.g. C = 10, ior = 100) means the optimiser was stopped "
        "there and the best fit may lie beyond: that fit is not converged.",
        "",
        md_table(
            ["model", "parameters", "√E1", "√E2", "converged", "starts"],
            [
                [
                    f.model,
                    params_text(f.params),
                    fmt(f.sqrt_e1),
                    fmt(f.sqrt_e2),
                    converged_text(f),
                    str(f.n_starts),
                ]
                for f in fits
            ],
        ),
        "",
    ]


_CAPTIONS = {
    "multiple": "Energy in scattering orders ≥ 2 against θi, with the models' predictions",
    "inplane": "In-plane scattering curves (simulation ± 1σ, models as bin averages)",
    "hemisphere": "Hemisphere maps: simulation, best and worst model, z-scores",
    "appearance": "Appearance: a plane under a directional light, from the tables",
    "energy": "Single-bounce albedo ρ(θi) and lost energy against θi",
    "stability": "Stability: model relative RMS error against θi",
    "speed": "Speed against accuracy of the estimator variants",
    "glass": "Rough glass: the traced order 1, reflected and transmitted, from the air and "
    "from inside, against Walter et al. 2007 (in-plane bin averages)",
}


def _charts_section(doc: RunDocument, charts: Mapping[str, str], phis, with_phi: bool) -> list[str]:
    """ "Charts": each chart under its caption; the stability and speed charts with the
    settings of their side studies."""
    lines = ["## Charts", ""]
    for key, path in charts.items():
        lines += [f"### {_CAPTIONS.get(key, key)}", "", f"![{key}]({path})", ""]
        if key == "stability":
            lines += _stability_text(doc.stability, phis, with_phi)
        if key == "speed":
            lines += _speed_text(doc.speed, phis, with_phi)
    return lines


def _stability_text(st: Stability, phis, with_phi: bool) -> list[str]:
    return (
        [
            f"Sweep: {len(st.theta_i)} incidences, {st.rays} rays "
            f"each{_first_azimuth(phis, with_phi)}."
        ]
        + [f"- warning: {w}" for w in st.warnings]
        + [""]
    )


def _speed_text(sp: Speed, phis, with_phi: bool) -> list[str]:
    rows = [
        [name, f"{n:,}", pct(e)] for name, r in sp.runs.items() for n, e in zip(r.rays, r.rel_rms)
    ]
    return [
        f"θi = {fmt(sp.theta_i)}°{_first_azimuth(phis, with_phi)}, "
        f"error against {sp.reference}; "
        "the wall times (this chart's x axis: tracing only, the surface and its "
        "BVH are built once before the runs) are in `timings.json`. Both files "
        "are written by every run but not kept in git, since wall times differ "
        "from run to run.",
        "",
        md_table(["origins", "rays", "rel RMS error"], rows),
        "",
    ]


def _azimuths_text(phis) -> str:
    text = ", ".join(f"{p:g}°" for p in phis)
    if len(phis) > 1:
        text += " (every θi at each; the side studies at the first)"
    return text


def _first_azimuth(phis, with_phi: bool) -> str:
    """ ", at φi = 0°" for the side studies of a run with several azimuths (they trace the
    first), else ""."""
    return f", at φi = {phis[0]:g}°" if with_phi else ""


def run_summary(doc: Mapping) -> str:
    """What ``microsim run`` prints on stdout: a models × θi table of the verdicts in the
    index's symbols and a one-line conclusion (models that agree at every incidence; models
    that deviate, where and by up to how much; inconclusive ones). Plain text, one line each."""
    doc = RunDocument.from_json(doc)
    verdicts = doc.verdicts
    outside = doc.outside_domain
    thetas = list(dict.fromkeys(incidence.key(v) for v in verdicts))  # (θi, φi) pairs
    with_phi = incidence.several_azimuths(verdicts)
    models = list(dict.fromkeys(v.model for v in verdicts))
    by = {(v.model, incidence.key(v)): v for v in verdicts}
    rows = [["model"] + [incidence.label(t, p, with_phi).replace(" = ", " ") for t, p in thetas]]
    for m in models:
        label = m + (" (fit)" if any(v.fitted for v in verdicts if v.model == m) else "")
        if m in outside:
            rows.append([label, "outside its domain"] + [""] * (len(thetas) - 1))
            continue
        rows.append([label] + [verdict_symbol(by[m, t]) if (m, t) in by else "–" for t in thetas])
    table = [r for r in rows if r[1:2] != ["outside its domain"]]  # that note spans columns
    widths = [max(len(r[i]) for r in table) for i in range(len(rows[0]))]
    lines = ["  ".join(c.ljust(w) for c, w in zip(r, widths)).rstrip() for r in rows]
    mine = {m: [by[m, t] for t in thetas if (m, t) in by] for m in models if m not in outside}
    scene = doc.scene
    return "\n".join(
        [f"{scene}: ✓ agrees, ✗ deviates (relative RMS error), ? inconclusive"]
        + lines
        + [_conclusion(mine, with_phi)]
    )


def _conclusion(by_model: Mapping[str, list], with_phi: bool) -> str:
    """``run_summary``'s last line: the models that agree at every incidence, those that
    deviate (where, by up to how much) and the inconclusive ones."""
    agree, deviate, unsure = [], [], []
    for m, mine in by_model.items():
        bad = [v for v in mine if v.kind == "deviates"]
        if all(v.agrees for v in mine):
            agree.append(m)
        elif bad:
            rms = [v.rel_rms for v in bad if v.rel_rms is not None]
            size = f" by up to {percent(max(rms))}" if rms else ""
            thetas = ", ".join(f"{v.theta_i:g}" for v in bad) + "°"
            where = incidence.grouped(bad) if with_phi else thetas
            deviate.append(f"{m} at θi {where}{size}")
        else:
            unsure.append(m)
    parts = [f"agrees at every {'incidence' if with_phi else 'θi'}: {', '.join(agree) or 'none'}"]
    if deviate:
        parts.append(f"deviates: {'; '.join(deviate)}")
    if unsure:
        parts.append(f"inconclusive (one tile): {', '.join(unsure)}")
    return "; ".join(parts)
