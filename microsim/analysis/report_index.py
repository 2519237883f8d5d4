"""The catalogue index (``index.md``): verdict tables (scenes × models), scattering orders,
the anisotropic Smith G variants, Smith-GGX on surfaces that are GGX (``ggx_index``), the fit
table, Mikkelsen Fig. 6 and "Where each method holds" (``report_wave.regime_section``). Pure
formatting of the verdict documents; no wall time is written, so the index is reproducible."""

from __future__ import annotations

from typing import Mapping, Sequence

from microsim.stats import t_isf

from . import incidence
from .anisotropy import VARIANTS as ANISOTROPY_VARIANTS
from .ggx_index import ggx_section
from .glass_report import glass_index
from .markdown import md_table, percent, plain
from .multiple import NOT_EXPECTED
from .multiple_report import RESOLVED_SE, deviation_text
from .report_cells import bounds_brief, fmt, signed_pct, verdict_cell
from .report_wave import regime_section
from .study_records import Fit, RunDocument, VariantVerdict
from .verdicts import Verdict, as_verdicts, summary_row

__all__ = ["index_report"]


def _orders_index(docs: Sequence[RunDocument]) -> list[str]:
    """ "How much light single scattering misses": per scene traced with ``bounces`` > 1, the
    fraction of the reflected energy in orders ≥ 2 at each θi and whether it exceeds 1 % (the
    scene then needs more than one bounce), and the random walk's and Kulla–Conty's relative
    energy deviation there."""
    rows, not_expected = [], False
    for d in docs:
        o = d.orders
        if not o:
            continue
        need = [n for n in o.needs if n.needs]
        with_phi = incidence.several_azimuths(o.needs)
        cells = ", ".join(
            f"{incidence.label(*incidence.key(n), with_phi, symbol=False)}: "
            f"{percent(n.multiple_fraction, unit=' %')}"
            for n in o.needs
        )
        comparison = o.comparison or {}
        dev = {}
        for inc in comparison.get("incidences", []):
            for name in ("random-walk", "kulla-conty"):
                if name in inc["models"]:
                    at = incidence.label(*incidence.key(inc), True, symbol=False) + ": "
                    dev.setdefault(name, []).append(
                        (at if with_phi else "") + deviation_text(inc, name, with_se=False)
                    )
        mark = " †" if comparison.get("expected") is False else ""
        rows.append(
            [_scene_link(d), cells, "yes" if need else "no"]
            + [", ".join(dev.get(name, ["–"])) + mark for name in ("random-walk", "kulla-conty")]
        )
        not_expected = not_expected or bool(mark)
    if not rows:
        return []
    return [
        "## How much light single scattering misses",
        "",
        'Scenes traced with `bounces = "all"`. Columns: the fraction of the reflected energy '
        "in scattering orders ≥ 2 at each θi; whether a single-bounce model misses more than "
        "1 % of it (then the scene needs more than one bounce); and, at the same θi in the "
        "same order, the relative energy deviation (simulation − model)/simulation of orders "
        "≥ 2 of Heitz et al.'s random walk and of Kulla–Conty's compensation (positive: the "
        "model has too little multiple scattering); where the simulated energy of orders ≥ 2 "
        f"is below {RESOLVED_SE:g} standard errors (not resolved), the absolute difference "
        "simulation − model in percentage points (pp) of the incident power instead. Each "
        "scene's report has the "
        "order-resolved tables, Mikkelsen eq. 28 and the lobes' shape errors.",
        "",
        md_table(
            ["scene", "orders ≥ 2 per θi", "> 1 bounce needed", "random walk", "Kulla–Conty"],
            rows,
        ),
        "",
    ] + ([f"† {NOT_EXPECTED}.", ""] if not_expected else [])


def _scene_link(d: RunDocument) -> str:
    return f"[{d.scene}]({d.scene}/report.md)"


def _variant_cell(v: VariantVerdict | None) -> str:
    """One Smith G variant against the simulation (``report_cells.verdict_cell``)."""
    if v is None:
        return "–"
    return verdict_cell(v.verdict, v.energy_dev, v.energy_dev_se, v.rel_rms)


def _anisotropy_incidences(docs: Sequence[RunDocument]):
    """(document, incidence) of every scene's ``anisotropy`` block."""
    return [(d, inc) for d in docs if d.anisotropy for inc in d.anisotropy.incidences]


def _anisotropy_index(docs: Sequence[RunDocument]) -> list[str]:
    """ "Anisotropy: the Smith G variants" for the scenes with an ``anisotropy`` block
    (``analysis.anisotropy``): per θi, the isotropic stand-in against the exact Λ (model
    against model) and each variant against the simulation."""
    rows = []
    for d, inc in _anisotropy_incidences(docs):
        sv = inc.stand_in_vs_exact
        rows.append(
            [
                _scene_link(d),
                f"{inc.theta_i:g}°",
                f"{inc.phi_i:g}°",
                f"{signed_pct(sv.energy_dev)}, rel RMS {percent(sv.rel_rms, unit=' %')}",
            ]
            + [_variant_cell(inc.against_simulation.get(x)) for x in ANISOTROPY_VARIANTS]
        )
    if not rows:
        return []
    labels = list(ANISOTROPY_VARIANTS)
    missed = _anisotropy_missed(docs)
    return [
        "## Anisotropy: the Smith G variants",
        "",
        "Anisotropic heightfields (Gaussian, ABC) against Torrance–Sparrow with the "
        "ensemble's anisotropic Beckmann D and three Smith G: the exact anisotropic Λ "
        "(projected roughness α(φ)), "
        "height-correlated and separable, and the Λ of the isotropic α = √(αx αy) that "
        "MaterialX uses. Columns: the stand-in against the exact Λ, model against model "
        "(energy deviation and relative RMS over the exact model's 90 % energy bins); then "
        "each variant against the simulation: its verdict symbol, energy deviation "
        "(simulation − model)/model ± standard error, and relative RMS error. φi is the "
        "incidence azimuth (0°: along the field's x axis).",
        "",
        md_table(
            ["scene", "θi", "φi", "stand-in vs exact Λ"] + [f"{x} vs simulation" for x in labels],
            rows,
        ),
        "",
    ] + missed


def _anisotropy_missed(docs: Sequence[RunDocument]) -> list[str]:
    """The energy the anisotropic single-scattering models miss, for the scenes traced with
    more than one bounce (``analysis.anisotropy``: ``missed``)."""
    rows = []
    for d, inc in _anisotropy_incidences(docs):
        m = inc.missed
        if m is None:
            continue
        rows.append(
            [
                _scene_link(d),
                f"{inc.theta_i:g}°",
                f"{inc.phi_i:g}°",
                f"{plain(m.reflected, 3)} ± {plain(m.reflected_se, 1)}",
                f"{percent(m.multiple / m.reflected, 3, unit=' %')} ± "
                f"{percent(m.multiple_se / m.reflected, unit=' %')}",
                "–"
                if m.walk_multiple is None
                else f"{percent(m.walk_multiple / m.reflected, 3, unit=' %')} ± "
                f"{percent(m.walk_multiple_se / m.reflected, unit=' %')}",
            ]
            + [signed_pct(m.models[x].missed, m.models[x].missed_se) for x in ANISOTROPY_VARIANTS]
        )
    if not rows:
        return []
    return [
        "Energy the single-scattering models miss (scenes traced with every bounce): the "
        "simulated reflected energy of all orders (fraction of the incident power ± standard "
        "error), the share of it in orders ≥ 2 — light no single-scattering model carries — "
        "beside the share the random walk on the anisotropic Smith microsurface predicts "
        "(Heitz et al. 2016; the same realised αx, αy), and for each variant (simulated − "
        "model)/simulated energy over the hemisphere: positive, the model is darker than the "
        "surface.",
        "",
        md_table(
            ["scene", "θi", "φi", "reflected (all orders)", "orders ≥ 2", "Smith walk: orders ≥ 2"]
            + [f"{x} misses" for x in ANISOTROPY_VARIANTS],
            rows,
        ),
        "",
    ]


def _resolvable_energy(v: Verdict) -> float | None:
    """Smallest relative energy deviation the realisations test of ``v`` would detect:
    t quantile on ``realisation_dof`` (R − 1 in older files) at the test's level ×
    ``energy_dev_se`` (None for other references)."""
    if v.reference != "realisations" or v.energy_dev_se is None:
        return None
    dof = v.realisation_dof if v.realisation_dof is not None else v.realisations - 1
    return float(t_isf(0.5 * v.p_threshold, dof) * v.energy_dev_se)


def _compact(verdicts: Sequence[Mapping], model: str, summary: str) -> str:
    """Index cell: "✓" when ``summary_row`` says the model agrees everywhere, else "✗" with
    its largest relative RMS error over the deviating incidences and where."""
    verdicts = as_verdicts(verdicts)
    mine = [v for v in verdicts if v.model == model]
    with_phi = incidence.several_azimuths(verdicts)

    def at(vs) -> str:
        if with_phi:
            return "θi " + incidence.grouped(vs, ",")
        return "θi " + ",".join(f"{v.theta_i:g}" for v in vs) + "°"

    if summary == "agrees":
        res = [r for r in map(_resolvable_energy, mine) if r is not None]
        return f"✓ ±{percent(max(res))}" if res else "✓"
    deviating = [v for v in mine if v.kind == "deviates"]
    if not deviating:  # only inconclusive failures: within the tile's departure, or unknown
        unsure = [v for v in mine if not v.agrees]
        known = [v for v in unsure if v.tile_departure is not None]
        if not known or len(known) != len(unsure):
            return f"? ({at(unsure)})"
        rms = max(v.rel_rms for v in known)
        dep = max(v.tile_departure for v in known)
        return f"? {percent(rms)} (tile departs {percent(dep)}; {at(unsure)})"
    rms = [v for v in deviating if v.rel_rms is not None]
    if not rms:
        return f"✗ ({at(deviating)})"
    w = max(rms, key=lambda v: v.rel_rms)
    return f"✗ {percent(w.rel_rms)} ({at(deviating)})"


def _index_cell(d: Mapping, model: str, summary: Mapping[str, str]) -> str:
    if model not in summary:
        return "–"
    d = RunDocument.from_json(d)
    if model in d.outside_domain:
        return "outside its domain"
    return _compact(d.verdicts, model, summary[model])


def _verdict_tables(docs: Sequence[RunDocument]) -> list[str]:
    """One scenes × models table per set of prescribed model names (V-grooves and
    heightfields are compared with different closed forms); fitted models at the end."""
    groups: dict[tuple, list] = {}
    for d in docs:
        pres = tuple(dict.fromkeys(v.model for v in d.verdicts if not v.fitted))
        groups.setdefault(pres, []).append(d)
    out, dropped = [], {}
    for pres, group in groups.items():
        fitted = list(dict.fromkeys(v.model for d in group for v in d.verdicts if v.fitted))
        models = list(pres) + fitted
        for m in list(models):  # a model outside its domain on every scene: said once below
            reasons = [d.outside_domain.get(m) for d in group]
            if all(reasons):
                models.remove(m)
                dropped[m + (" (fit)" if m in fitted else "")] = reasons[0]
        rows = []
        for d in group:
            s = summary_row(d.verdicts)
            n_real = max((v.realisations for v in d.verdicts), default=1)
            rows.append(
                [_scene_link(d) + (f" R={n_real}" if n_real > 1 else "")]
                + [_index_cell(d, m, s) for m in models]
            )
        out += [
            md_table(["scene"] + [m + (" (fit)" if m in fitted else "") for m in models], rows),
            "",
        ]
    for name, reason in dropped.items():
        out += [
            f"Not in these tables: {name}, outside its domain on every scene — {reason}. Its "
            "fit is in the fit table; the scenes with a wavelength judge it against the "
            "Kirchhoff solver under *Where each method holds*.",
            "",
        ]
    return out


def _index_fit_cell(fit: Fit | Mapping) -> str:
    """√E1 / √E2 of one fit (a ``Fit`` or its JSON object), with the bounds it ended on
    (``bounds_brief``)."""
    fit = Fit.from_json(fit)
    cell = f"{fmt(fit.sqrt_e1)} / {fmt(fit.sqrt_e2)}"
    at = bounds_brief(fit.at_bounds)
    return cell + (f" ({at})" if at else "")


def index_report(
    docs: Sequence[Mapping],
    fig6: str | None,
    quick: bool,
    regimes: Mapping | None = None,
    methods=None,
    fullwave=None,
) -> str:
    """``index.md``: verdict tables (scenes × models), Löw-style fit table, Mikkelsen Fig. 6,
    "Where each method holds" (``regime_section``: wave scenes' verdicts against Kirchhoff,
    the regime chart ``regimes``; "What each method costs" from ``methods``, the path of
    ``methods.json`` or its dict), links to every scene's ``<scene>/report.md``. No wall
    time is written: the index is reproducible."""
    docs = [RunDocument.from_json(d) for d in docs]
    fit_models: list[str] = []
    for d in docs:
        fit_models += [f.model for f in d.fits if f.model not in fit_models]
    fit_rows = []
    for d in docs:
        by = {f.model: f for f in d.fits}
        fit_rows.append(
            [d.scene] + [_index_fit_cell(by[m]) if m in by else "–" for m in fit_models]
        )
    lines = [
        "# microsim report",
        "",
        f"{len(docs)} scenes, "
        f"{'quick mode (`microsim report --quick`)' if quick else 'full runs'}. "
        f"Each scene links to its own report with charts, the energy "
        "ledger and every verdict.",
        "",
        "## Verdicts",
        "",
        "Key (the statistics behind each symbol: `docs/verdicts.md` in the microsim repository):",
        "",
        "- ✓ agrees: indistinguishable from the simulation at every incidence (χ² and max-|z| "
        "tests, Šidák-corrected, α = 0.01 per run).",
        "- ✓ ±x% agrees as far as the R realisations (R=… after the scene) can tell: energy "
        "deviations below x % are not resolved.",
        "- ✗ y% (θi …) deviates at those incidences; y is its largest energy-weighted relative "
        "RMS error there.",
        "- ? y% (tile departs z%) inconclusive: one tile, whose computed departure z from its "
        "ensemble explains the deviation y.",
        "- ? (θi …) inconclusive: one generated heightfield tile cannot tell tile scatter from "
        "model error.",
        "- A surface read from a file (a measured surface) is judged as itself, not as a draw "
        "of an ensemble: ✓ or ✗ against its ray noise (reference this-tile).",
        "- – not compared on this scene.",
        "",
    ] + _verdict_tables(docs)
    lines += _orders_index(docs)
    lines += _anisotropy_index(docs)
    lines += glass_index(docs)
    lines += ggx_section(docs)
    if fit_models:
        lines += [
            "## Fits: √E1 / √E2 (Löw et al. 2012, eq. 29–33, as their Table II)",
            "",
            "Each model fitted to all incidences of a scene at once; smaller is better. "
            "In brackets, the bounds of its box a fit ended on: a parameter on a physical "
            "bound (kd ≥ 0, a fraction ≤ 1) is a constrained minimum; at a search limit (a "
            "practical end of the box, e.g. C = 10) the optimiser was stopped and the best fit "
            "may lie beyond.",
            "",
            md_table(["scene"] + fit_models, fit_rows),
            "",
        ]
    if fig6:
        lines += [
            "## Mikkelsen Fig. 6(c)(d)",
            "",
            "1 − ρ(θ) of V-groove surfaces with the von Mises–Fisher NDF (κ = 17, 1024) "
            "for methanol and aluminium: simulation (points) against Mikkelsen eq. 27 "
            "(lines) and the Fresnel transmittance.",
            "",
            f"![Mikkelsen Fig. 6]({fig6})",
            "",
        ]
    lines += regime_section(docs, regimes, methods, fullwave)
    lines += ["## Scenes", ""] + [f"- {_scene_link(d)}: {d.description}" for d in docs]
    return "\n".join(lines).rstrip() + "\n"
