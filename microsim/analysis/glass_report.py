"""The "Rough glass" section of a scene report and of the index (``glass_section``,
``glass_index``) and its chart (``glass_chart``), from the ``GlassStudy`` of verdicts.json
(``analysis.glass``)."""

from __future__ import annotations

from typing import Mapping

import numpy as np
from matplotlib.figure import Figure

from .chart_style import SIM_COLOUR, _figure, _log_limits, _output, _positive, chart_styles
from .glass import MULTIPLE_MODELS
from .markdown import md_table, percent
from .study_records import GlassStudy
from .verdicts import verdict_symbol

__all__ = ["glass_section", "glass_index", "glass_energy_table", "glass_chart", "SIDE_NAMES"]

SIDE_NAMES = {"air": "air → medium", "medium": "medium → air"}
"""How a table names the side light comes from."""


def _pm(value: float, se: float) -> str:
    return f"{percent(value, 3)} ± {percent(se, 1)}"


def glass_energy_table(study: GlassStudy) -> str:
    """Per incidence: R, T and R + T of all orders, the traced single scattering R₁ + T₁, and
    each model's single-scattering R + T (what it loses is 1 minus that)."""
    names = list(study.incidences[0].models) if study.incidences else []
    rows = []
    for g in study.incidences:
        rows.append(
            [
                SIDE_NAMES[g.side],
                f"{g.theta:g}",
                _pm(g.reflected, g.reflected_se),
                _pm(g.transmitted, g.transmitted_se),
                percent(g.reflected + g.transmitted, 4),
                _pm(g.single, g.single_se),
                *(percent(sum(g.models[n]), 3) for n in names),
                percent(g.tir, 2),
            ]
        )
    header = ["light", "θi", "R", "T", "R + T", "order 1: R₁ + T₁"]
    header += [f"{n}: R + T" for n in names] + ["TIR at 1st hit"]
    return md_table(header, rows)


def _pp(model: float, traced: float) -> str:
    """model − traced in percentage points."""
    return percent(model - traced, 2, signed=True, unit=" pp")


def _multiple_table(study: GlassStudy) -> str | None:
    """Per incidence, R and T of every order traced, and each model of every order's minus
    them (pp; the walk's own standard error beside it)."""
    names = [n for n in MULTIPLE_MODELS if study.incidences and n in study.incidences[0].multiple]
    if not names:
        return None
    rows = []
    for g in study.incidences:
        cells = []
        for n in names:
            r, t, r_se, t_se = g.multiple[n]
            se = f" (± {percent(max(r_se, t_se), 1, unit=' pp')})" if r_se or t_se else ""
            cells.append(f"R {_pp(r, g.reflected)}, T {_pp(t, g.transmitted)}{se}")
        rows.append([SIDE_NAMES[g.side], f"{g.theta:g}", percent(g.reflected, 3), *cells])
    return md_table(["light", "θi", "R traced", *(f"{n} − traced" for n in names)], rows)


def _verdict_table(study: GlassStudy) -> str:
    """Per incidence and lobe, each model's verdict against order 1 (``verdict_symbol``)."""
    rows = []
    for g in study.incidences:
        by_lobe: dict = {}
        for v in g.verdicts:
            name, lobe = v.model.rsplit(" (", 1)
            by_lobe.setdefault(lobe.rstrip(")"), {})[name] = verdict_symbol(v)
        for lobe in ("reflected", "transmitted"):
            cells = by_lobe.get(lobe)
            if cells is None:  # no traced light leaves this way
                rows.append([SIDE_NAMES[g.side], f"{g.theta:g}", lobe, "too few events at order 1"])
            else:
                rows.append([SIDE_NAMES[g.side], f"{g.theta:g}", lobe, *cells.values()])
    names = []
    for g in study.incidences[:1]:
        names = list(dict.fromkeys(v.model.rsplit(" (", 1)[0] for v in g.verdicts))
    return md_table(["light", "θi", "lobe", *names], rows)


def glass_section(study: GlassStudy | None) -> list[str]:
    """ "Rough glass" for a scene traced through a dielectric interface (None: nothing)."""
    if not study:
        return []
    out = [
        "## Rough glass",
        "",
        f"A dielectric interface of index n = {study.eta:g}, lit from the air (θi from +z) and "
        f"from inside the medium (θi from −z; that run is in `{study.inside}/`). R and T are "
        "the fractions of the incident flux reflected and transmitted (all orders, ± standard "
        "error); R + T = 1 up to the paths cut or unresolved (the ledger). Order 1 is single "
        "scattering as traced; each model's R + T is Walter et al. 2007's single-scattering "
        "BSDF by quadrature, so 1 − (R + T) is the energy it loses — the light the traced "
        "orders ≥ 2 carry. TIR: paths totally internally reflected at their first hit.",
        "",
        glass_energy_table(study),
        "",
    ]
    multiple = _multiple_table(study)
    if multiple is not None:
        out += [
            "Every order: Heitz et al. 2016's dielectric random walk and Kulla & Conty 2017's "
            "compensation (added to Walter's BSDF with Heitz's height-correlated G, the walk's "
            "first order) against the traced R and T, in percentage points of the incident "
            "flux (the walk's R + T = 1, so its two differences are opposite; the "
            "compensation's closes up to its table's interpolation in cos θi).",
            "",
            multiple,
            "",
        ]
    if study.incidences and study.incidences[0].verdicts:
        out += [
            f"Walter et al. 2007's BRDF and BTDF (microfacet distribution {study.ndf}) against "
            "the traced order 1, bin by bin (✓ agrees, ✗ deviates by its energy-weighted "
            "relative RMS error; docs/verdicts.md):",
            "",
            _verdict_table(study),
            "",
        ]
    return out


def _verdicts_cell(symbols: dict, names: list, lobe: str) -> str:
    """The models' verdicts on one lobe, in the order of ``names``."""
    cells = [symbols.get(f"{n} ({lobe})") for n in names]
    return (
        "too few events at order 1" if cells and all(c is None for c in cells) else ", ".join(cells)
    )


def glass_index(docs) -> list[str]:
    """ "Rough glass" of the index: per scene traced through a dielectric interface and per
    incidence from either side, R and T (all orders), the single scattering traced and what
    Walter et al. 2007's single-scattering BSDF keeps of the energy, and its verdicts against
    the traced first order."""
    rows, names = [], []
    for d in docs:
        g = d.glass
        if not g:
            continue
        for inc in g.incidences:
            names = names or list(inc.models)
            symbols = {v.model: verdict_symbol(v) for v in inc.verdicts}
            rows.append(
                [
                    f"[{d.scene}]({d.scene}/report.md)",
                    SIDE_NAMES[inc.side],
                    f"{inc.theta:g}",
                    _pm(inc.reflected, inc.reflected_se),
                    _pm(inc.transmitted, inc.transmitted_se),
                    _pm(inc.single, inc.single_se),
                    *(percent(sum(inc.models[n]), 3) for n in names),
                    *(
                        _verdicts_cell(symbols, names, lobe)
                        for lobe in ("reflected", "transmitted")
                    ),
                    *(
                        _pp(inc.multiple[m][0], inc.reflected) if m in inc.multiple else "–"
                        for m in MULTIPLE_MODELS
                    ),
                ]
            )
    if not rows:
        return []
    return [
        "## Rough glass",
        "",
        "Scenes traced through a dielectric interface (`[material] transmission = true`), lit "
        "from the air and from inside the medium at the same angles from each side's pole. "
        "R and T: the fractions of the incident flux reflected and transmitted, all orders "
        "(R + T = 1: nothing is lost, path by path); order 1: single scattering as traced; "
        f"then {' and '.join(names)}: Walter et al. 2007's single-scattering R + T by "
        "quadrature (separable Smith G; height-correlated, the reflection's form also across "
        "the interface as renderers ship it; height-correlated across by Heitz 2014's Beta "
        "form) — 1 minus it is the energy a "
        "single-scattering BSDF loses, the white-furnace number; last, the verdicts of the "
        "same models (in that order) against the traced order 1, reflected and transmitted "
        "lobes (✓ agrees; ✗ deviates by its energy-weighted relative RMS error); then, of "
        "every order, the reflectance of Heitz et al. 2016's dielectric random walk and of "
        "Kulla & Conty 2017's compensation minus the traced R (percentage points; T differs "
        "by the opposite).",
        "",
        md_table(
            ["scene", "light", "θi", "R", "T", "order 1: R₁ + T₁"]
            + [f"{n}: R + T" for n in names]
            + ["BRDF verdicts", "BTDF verdicts"]
            + [f"{m}: R − traced" for m in MULTIPLE_MODELS],
            rows,
        ),
        "",
    ]


CHART_MODELS = ("walter-smith", "walter-smith-corr", "walter-smith-corr-beta")
"""The models ``glass_chart`` draws."""


def glass_chart(above, inside, predictions: Mapping, path=None, title: str = "") -> Figure:
    """The traced order 1 of a run through a dielectric interface against Walter et al.
    2007's BSDF in the plane of incidence: one panel per incidence, from the air (top row)
    and from inside the medium (bottom row); signed θo from the pole of the side the light
    leaves by (+: the forward side, Δφ = 180°; −: Δφ = 0°), the reflected lobe (points) and
    the transmitted one (squares) ±1σ, and the models' bin averages (``predictions`` of
    ``glass.glass_study``). Log scale, sr⁻¹. ``path``: also write a PNG. Returns the Figure."""
    runs = [above, inside]
    cols = max(len(r.theta_i) for r in runs)
    fig = _figure((3.2 * cols + 1.8, 6.6))
    axes = np.atleast_2d(fig.subplots(2, cols, sharey=True, squeeze=False))
    styles = chart_styles(CHART_MODELS)
    for row, result in enumerate(runs):
        f_idx, b_idx = result.bins.forward_index, result.bins.backward_index
        tc = result.bins.theta_centers
        signed = np.concatenate([-tc[::-1], tc])
        cut = lambda a: np.concatenate([a[::-1, b_idx], a[:, f_idx]])  # noqa: E731
        for t, theta_i in enumerate(result.theta_i):
            ax = axes[row, t]
            for lobe, values, stderr, marker in (
                ("reflected", result.brdf_orders, result.stderr_orders, "o"),
                ("transmitted", result.btdf_orders, result.stderr_btdf_orders, "s"),
            ):
                y, e = cut(values[0, t]), cut(stderr[0, t])
                ok = y > 0
                ax.errorbar(
                    signed[ok], y[ok], yerr=e[ok], fmt=marker, ms=2.5, lw=0.6,
                    color=SIM_COLOUR if lobe == "reflected" else "#555555",
                    label=f"traced order 1, {lobe}",
                )  # fmt: skip
                for name in CHART_MODELS:
                    m = predictions.get((float(theta_i), lobe, name))
                    if m is None:
                        continue
                    colour, dash = styles[name]
                    ax.step(signed, _positive(cut(m)), where="mid", color=colour, ls=dash,
                            lw=1.0, label=name)  # fmt: skip
            side, theta = (
                ("from inside", 180.0 - theta_i) if theta_i > 90 else ("from the air", theta_i)
            )
            ax.set_title(f"θi = {theta:g}° {side}", fontsize=9)
            ax.set_yscale("log")
            ax.set_xlim(-90, 90)
            ax.set_xlabel("θo (°)")
        axes[row, 0].set_ylabel("f (sr⁻¹), order 1")
    values = [v for v in predictions.values()]
    lo, hi = _log_limits(values + [r.brdf_orders[0] for r in runs], 1e-4)
    axes[0, 0].set_ylim(lo, hi)
    handles, labels = axes[0, 0].get_legend_handles_labels()
    unique = dict(zip(labels, handles))
    fig.legend(unique.values(), unique.keys(), loc="outside right center", fontsize=8)
    fig.suptitle(f"{title} — rough glass: traced order 1 against Walter et al. 2007", fontsize=10)
    return _output(fig, path)
