"""Markdown reports: one per scene (``report.md``) and the catalogue index (``index.md``).

Pure formatting: every number comes from the verdict document written as ``verdicts.json`` (see
``microsim.app.runner`` and docs/verdicts.md for its schema) and, for the energy ledger, from the
``Result``. No wall-clock time appears in either report (they are in ``timings.json``), so rerunning
an unchanged scene rewrites them byte for byte. Signed percentages are relative
deviations (simulation − model)/simulation, the one sign convention of every output (negative:
the model is too bright); BRDFs in sr⁻¹, angles in degrees.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from microsim.atomic import read_json
from microsim.errors import UsageError
from microsim.stats import t_isf

from . import incidence
from .anisotropy import VARIANTS as ANISOTROPY_VARIANTS
from .markdown import md_table, percent, plain
from .multiple import NOT_EXPECTED, RESOLVED_SE, deviation_text
from .verdicts import summary_row, verdict_kind, verdict_symbol

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
]


def fmt(x, digits: int = 3) -> str:
    """Compact number: None/NaN → "–", else ``digits`` significant figures (``plain``); a string
    as is; a sequence (e.g. a grid shape) as "a × b" of its formatted items."""
    if x is None:
        return "–"
    if isinstance(x, str):
        return x
    if isinstance(x, bool):
        return "yes" if x else "no"
    if isinstance(x, (list, tuple, np.ndarray)):
        return " × ".join(fmt(v, digits) for v in x) if len(x) else "–"
    if isinstance(x, (int, np.integer)):
        return str(int(x))
    x = float(x)
    if not math.isfinite(x):
        return "–"
    return plain(x, digits)


def _pct(x) -> str:
    """A table's percentage column: 3 significant figures, "12.3%"."""
    return percent(x, 3)


def _ranges(dev) -> str:
    return ", ".join(f"{a:g}–{b:g}°" for a, b in dev) if dev else "–"


def _params(p: Mapping) -> str:
    return ", ".join(f"{k} = {fmt(v, 4)}" for k, v in p.items()) if p else "–"


def _material(mat: Mapping) -> str:
    ior = mat.get("ior")
    if ior is None:
        return "mirror (F = 1)"
    n, k = ior
    text = f"n = {n:g}" if k == 0 else f"n + ik = {n:g} + {k:g}i"
    return f"{mat['name']}, {text}" if mat.get("name") else text


def albedo_stderr(result) -> np.ndarray:
    """(T,) per-ray standard error of the single-bounce albedo ρ(θi) = ledger "single_fresnel"
    (Mikkelsen eq. 27): √((Σw²/N − ρ²)/(N − 1)), Σw² over the binned single-bounce rays."""
    n = result.rays.astype(np.float64)
    m2 = result.sum_w2.reshape(len(n), -1).sum(axis=1) / np.maximum(n, 1)
    rho = result.ledger["single_fresnel"]
    return np.sqrt(np.maximum(m2 - rho**2, 0.0) / np.maximum(n - 1, 1))


def _ledger_rows(doc, result, with_phi: bool) -> list[list[str]]:
    led = result.ledger
    rho, se = led["single_fresnel"], albedo_stderr(result)
    return [
        [
            *([f"{t:g}", f"{p:g}"] if with_phi else [f"{t:g}"]),
            f"{int(r)}",
            f"{rho[k]:.4f} ± {se[k]:.1g}",
            f"{led['single'][k]:.4f}",
            f"{led['masked'][k]:.4f}",
            f"{led['downward'][k]:.4f}",
            f"{led['unresolved'][k]:.2g}",
            f"{led['lost_fresnel'][k]:.4f}",
        ]
        for k, (t, p, r) in enumerate(zip(result.theta_i, result.phi_i, result.rays))
    ]


def _verdict_word(v: Mapping) -> str:
    kind = verdict_kind(v)
    return "**agrees**" if kind == "agrees" else kind


OUT_OF_DOMAIN = "outside its domain (wave-optics model; fit-only)"
"""Summary text of a model the verdict document lists under ``outside_domain``: its
verdicts against the ray tracer are no test of it (the fit numbers are kept)."""


def _reference_text(v: Mapping) -> str:
    """The verdict's reference, its R and, for a tile whose departure is known, its size."""
    text = f"{v.get('reference', 'ray-noise')} (R = {v.get('realisations', 1)})"
    if v.get("tile_departure") is not None:
        text += f", tile departs {_pct(v['tile_departure'])}"
    return text


def _verdict_rows(
    verdicts, outside: Mapping | None = None, with_phi: bool = False
) -> list[list[str]]:
    outside = outside or {}
    return [
        [
            *([f"{v['theta_i']:g}", f"{v['phi_i']:g}"] if with_phi else [f"{v['theta_i']:g}"]),
            v["model"] + (" (fit)" if v["fitted"] else ""),
            "outside domain" if v["model"] in outside else _verdict_word(v),
            _reference_text(v),
            fmt(v["chi2_dof"]),
            fmt(v["p_value"]),
            fmt(v["max_abs_z"]),
            _pct(v["rel_rms"]),
            _pct(v["max_rel_dev"]),
            (
                "–"
                if v["worst_bin"] is None
                else f"θo {v['worst_bin'][0]:g}°, Δφ {v['worst_bin'][1]:g}°"
            ),
            _ranges(v["deviations"]),
            str(v["n_bins"]),
        ]
        for v in verdicts
    ]


def _orders_section(orders) -> list[str]:
    """ "How much light single scattering misses" for a run with ``bounces`` > 1: per θi the
    fraction of reflected energy in orders ≥ 2 (``analysis.multiple.needs_more_bounces``), then
    the order-resolved comparison (``analysis.multiple.multiple_section``)."""
    if not orders:
        return []
    from .multiple import multiple_section

    with_phi = incidence.several_azimuths(orders["needs"])
    rows = [
        [
            *([f"{n['theta_i']:g}", f"{n['phi_i']:g}"] if with_phi else [f"{n['theta_i']:g}"]),
            f"{percent(n['multiple_fraction'], 3, unit=' %')} ± "
            f"{percent(n['multiple_fraction_se'], unit=' %')}",
            _pct(n["cut"]),
            "yes" if n["needs"] else "no",
        ]
        for n in orders["needs"]
    ]
    out = [
        "## Scattering orders",
        "",
        f"Traced with `bounces = {orders['bounces']}`; the verdicts above judge order 1. "
        "Fraction of the reflected energy in orders ≥ 2 (± standard error), the energy cut off "
        "by the bounce limit, and whether single scattering misses more than 1 % of it.",
        "",
        md_table(["θi", *(["φi"] if with_phi else []), "orders ≥ 2", "cut", "> 1 %"], rows),
        "",
    ]
    if orders.get("note"):
        out += [f"Note: {orders['note']}.", ""]
    if orders.get("comparison"):
        out += multiple_section(orders["comparison"]) + [""]
    return out


def _orders_index(docs: Sequence[Mapping]) -> list[str]:
    """ "How much light single scattering misses": per scene traced with ``bounces`` > 1, the
    fraction of the reflected energy in orders ≥ 2 at each θi and whether it exceeds 1 % (the
    scene then needs more than one bounce), and the random walk's and Kulla–Conty's relative
    energy deviation there."""
    rows, not_expected = [], False
    for d in docs:
        o = d.get("orders")
        if not o:
            continue
        need = [n for n in o["needs"] if n["needs"]]
        with_phi = incidence.several_azimuths(o["needs"])
        cells = ", ".join(
            f"{incidence.label(*incidence.key(n), with_phi, symbol=False)}: "
            f"{percent(n['multiple_fraction'], unit=' %')}"
            for n in o["needs"]
        )
        comparison = o.get("comparison") or {}
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
            [f"[{d['scene']}]({d['scene']}/report.md)", cells, "yes" if need else "no"]
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


def _realisations_text(run: Mapping) -> str:
    """The realisation count; for ``realisations = "auto"`` also the pilot and the target."""
    auto = run.get("realisations_auto")
    if not auto:
        return str(run.get("realisations"))
    return (
        f"{auto['realisations']} (auto: pilot of {auto['pilot_realisations']}, tile-scatter "
        f"target {percent(auto['target'], 3, unit=' %')}, at most {auto['max_realisations']})"
    )


def _budget_section(budget, auto) -> list[str]:
    """ "Error budget": per incidence the energy-weighted relative standard errors of the mean
    BRDF from ray noise and from tile scatter (``analysis.budget``); empty for one realisation."""
    if not budget or all(b.get("tile") is None for b in budget):
        return []
    target = auto["target"] if auto else None
    with_phi = incidence.several_azimuths(budget)
    rows = [
        [
            *([f"{b['theta_i']:g}", f"{b['phi_i']:g}"] if with_phi else [f"{b['theta_i']:g}"]),
            str(b["realisations"]),
            _pct(b["ray"]),
            _pct(b["tile"]),
            _pct(b["total"]),
            _pct(b["energy"]),
        ]
        + ([("yes" if b["tile"] is not None and b["tile"] <= target else "no")] if target else [])
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
            f"{auto['max_realisations']}."
        )
    return ["## Error budget", "", text, "", md_table(head, rows), ""]


def scene_report(doc: Mapping, result, charts: Mapping[str, str]) -> str:
    """``report.md`` of one run: settings, energy ledger, verdicts, fits, charts."""
    meta = result.meta
    surf = meta.get("surface") or {}
    run = meta.get("run", {})
    mat = meta.get("material", {})
    phis = doc.get("phi_i", [0.0])
    with_phi = incidence.several_azimuths(phis)
    inc_cols = ["θi", "φi"] if with_phi else ["θi"]
    lines = [f"# {doc['scene']}", ""]
    if doc.get("description"):
        lines += [doc["description"], ""]
    lines += [
        "## Run",
        "",
        md_table(
            ["setting", "value"],
            [
                ["scene file", f"`{doc.get('scene_file')}`"],
                [
                    "surface",
                    f"{surf.get('kind')}, tile "
                    f"{' × '.join(fmt(x, 4) for x in surf.get('tile_size', []))}, "
                    f"{surf.get('triangles')} triangles (scale {fmt(run.get('surface_scale'))})",
                ],
                ["nominal", _params(surf.get("nominal", {}))],
                ["material", _material(mat)],
                ["incidences θi", ", ".join(f"{t:g}°" for t in doc["theta_i"])],
                *(
                    [["incidence azimuths φi", _azimuths_text(phis)]]
                    if with_phi or any(phis)
                    else []
                ),
                ["rays per incidence", f"{doc['rays']:,}"],
                ["realisations", _realisations_text(run)],
                ["bins (θo × Δφ)", " × ".join(str(b) for b in run.get("bins", []))],
                ["seed", str(doc["seed"])],
                ["mode", "quick (`--quick`)" if doc["quick"] else "full"],
                ["wall times", "`timings.json` (machine-dependent)"],
            ],
        ),
        "",
    ]
    warns = list(surf.get("warnings", [])) + list(meta.get("model_warnings", []))
    if warns:
        lines += (
            ["Warnings (surface generator, tracer, model quadrature):", ""]
            + [f"- {w}" for w in warns]
            + [""]
        )
    lines += [
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
    lines += _budget_section(meta.get("error_budget"), run.get("realisations_auto"))
    summary = summary_row(doc["verdicts"])
    outside = doc.get("outside_domain") or {}
    summary.update({m: OUT_OF_DOMAIN for m in outside if m in summary})
    lines += [
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
    lines += [
        "Best to worst by mean relative RMS error: "
        + ", ".join(f"`{m}`" for m in doc.get("ranking", []))
        + ".",
        "",
        "<details><summary>Every incidence × model</summary>",
        "",
        md_table(
            [
                *inc_cols,
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
            ],
            _verdict_rows(doc["verdicts"], outside, with_phi),
        ),
        "",
        "</details>",
        "",
    ]
    lines += wave_section(doc.get("wave"))
    if doc.get("fits"):
        lines += [
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
                        f["model"],
                        _params(f["params"]),
                        fmt(f["sqrt_e1"]),
                        fmt(f["sqrt_e2"]),
                        _converged(f),
                        str(f["n_starts"]),
                    ]
                    for f in doc["fits"]
                ],
            ),
            "",
        ]
    lines += _orders_section(doc.get("orders"))
    captions = {
        "multiple": "Energy in scattering orders ≥ 2 against θi, with the models' predictions",
        "inplane": "In-plane scattering curves (simulation ± 1σ, models as bin averages)",
        "hemisphere": "Hemisphere maps: simulation, best and worst model, z-scores",
        "appearance": "Appearance: a plane under a directional light, from the tables",
        "energy": "Single-bounce albedo ρ(θi) and lost energy against θi",
        "stability": "Stability: model relative RMS error against θi",
        "speed": "Speed against accuracy of the estimator variants",
    }
    lines += ["## Charts", ""]
    for key, path in charts.items():
        lines += [f"### {captions.get(key, key)}", "", f"![{key}]({path})", ""]
        if key == "stability":
            st = doc.get("stability", {})
            lines += (
                [
                    f"Sweep: {len(st.get('theta_i', []))} incidences, {st.get('rays')} rays "
                    f"each{_first_azimuth(phis, with_phi)}."
                ]
                + [f"- warning: {w}" for w in st.get("warnings", [])]
                + [""]
            )
        if key == "speed":
            sp = doc.get("speed", {})
            rows = [
                [name, f"{n:,}", _pct(e)]
                for name, r in sp.get("runs", {}).items()
                for n, e in zip(r["rays"], r["rel_rms"])
            ]
            lines += [
                f"θi = {fmt(sp.get('theta_i'))}°{_first_azimuth(phis, with_phi)}, "
                f"error against {sp.get('reference')}; "
                "the wall times (this chart's x axis: tracing only, the surface and its "
                "BVH are built once before the runs) are in `timings.json`. Both files "
                "are written by every run but not kept in git, since wall times differ "
                "from run to run.",
                "",
                md_table(["origins", "rays", "rel RMS error"], rows),
                "",
            ]
    return "\n".join(lines).rstrip() + "\n"


def _azimuths_text(phis) -> str:
    text = ", ".join(f"{p:g}°" for p in phis)
    if len(phis) > 1:
        text += " (every θi at each; the side studies at the first)"
    return text


def _first_azimuth(phis, with_phi: bool) -> str:
    """ ", at φi = 0°" for the side studies of a run with several azimuths (they trace the
    first), else ""."""
    return f", at φi = {phis[0]:g}°" if with_phi else ""


_WAVE_STATUS = {
    "agrees": "**agrees**",
    "agrees-in-region": "agrees only in a region",
    "differs": "differs",
}


def _signed_pct(x, se=None) -> str:
    """A signed deviation, 3 significant figures, ± its standard error when given."""
    text = percent(x, 3, signed=True, unit=" %")
    return text if se is None or text == "–" else f"{text} ± {percent(se, unit=' %')}"


def _region_text(v: Mapping) -> str:
    """θo ranges of agreement per side: "forward 0–40°; backward 0–15°"; "none" for a side
    with tested rows and no agreeing one; sides without tested rows left out."""
    parts = []
    for side in ("forward", "backward"):
        r = v["region"].get(side)
        if r is None:
            continue
        parts.append(f"{side} {_ranges(r) if r else 'none'}")
    return "; ".join(parts) or "–"


def _outside_text(v: Mapping) -> str:
    parts = []
    for side in ("forward", "backward"):
        o = v["outside"].get(side)
        if o:
            lo, hi = (percent(x, 3, signed=True, unit="") for x in o)
            parts.append(f"{side} {lo} … {hi} %")
    return "; ".join(parts) or "–"


def _bound(b: Mapping) -> str:
    return f"{b['param']} = {fmt(b['bound'], 4)}"


def _bounds_text(at_bounds: Sequence[Mapping]) -> str:
    """The bounds a fit ended on (``fits.BoundReached`` records), search limits first:
    "stopped at the search limit C = 10: the best fit may lie beyond; kd = 0, on its physical
    bound kd ≥ 0"; "" for none."""
    limits = [_bound(b) for b in at_bounds if not b["physical"]]
    parts = []
    if limits:
        plural = "s" if len(limits) > 1 else ""
        parts.append(
            f"stopped at the search limit{plural} {', '.join(limits)}: the best fit may lie beyond"
        )
    parts += [
        f"{_bound(b)}, on its physical bound {b['param']} "
        f"{'≥' if b['side'] == 'lower' else '≤'} {fmt(b['bound'], 4)}"
        for b in at_bounds
        if b["physical"]
    ]
    return "; ".join(parts)


def _bounds_brief(at_bounds: Sequence[Mapping]) -> str:
    """``_bounds_text`` for an index cell: "search limit: C = 10; physical bound: kd = 0"."""
    parts = []
    for physical, name in ((False, "search limit"), (True, "physical bound")):
        mine = [_bound(b) for b in at_bounds if b["physical"] == physical]
        parts += [f"{name}{'s' if len(mine) > 1 else ''}: {', '.join(mine)}"] if mine else []
    return "; ".join(parts)


def _converged(fit: dict) -> str:
    """The fits table's "converged" cell: yes or no (the optimiser's evaluation limit or a
    search limit reached), with the bounds the fit ended on."""
    why = [] if fit["success"] else ["the optimiser stopped at its evaluation limit"]
    why += [_bounds_text(fit["at_bounds"])] if fit["at_bounds"] else []
    return fmt(fit["converged"]) + (f": {'; '.join(why)}" if why else "")


def wave_section(wave: Mapping | None) -> list[str]:
    """Report lines of the wave-optics verdicts (``runner.wave_run``: verdicts.json "wave");
    empty for a geometric scene. Every verdict names its reference (Kirchhoff, theory vs
    theory) and gives the agreement region rather than a bare pass/fail."""
    if not wave:
        return []
    tile = " × ".join(
        f"{fmt(a, 4)} ({fmt(b, 3)} λ)" for a, b in zip(wave["tile"], wave["tile_over_lambda"])
    )
    n, n_run = wave["realisations"], wave["run_realisations"]
    tiles = (
        ("the run's tile" if n == 1 else f"the run's {n} tiles")
        if n == n_run
        else f"{n} of the run's {n_run} tiles"
    )
    se_from = (
        "the scatter over the tiles"
        if wave["stderr_method"] == "realisations"
        else "the speckle of the orders in each bin"
    )
    lines = [
        "## Wave optics: closed forms against Kirchhoff (theory vs theory)",
        "",
        f"Reference of every verdict in this section: the scalar Kirchhoff (tangent-plane) "
        f"solver (`microsim.wave`, surface model `{wave['surface_model']}`, Fresnel at the "
        f"{'half-vector' if wave['fresnel_angle'] == 'half' else 'incidence'} angle, "
        f"upsample {wave['upsample']}) on {tiles}, tile {tile}, wavelength λ = "
        f"{fmt(wave['wavelength'], 4)} in the {wave['length_unit']}, σ/λ = "
        f"{fmt(wave['sigma_over_lambda'])} (nominal; the tiles' realised rms height: "
        f"{fmt(wave['realised_sigma_over_lambda'])} λ, the σ in g below), on the run's bins; "
        "its diffuse part "
        "(the coherent specular order removed); standard errors from "
        f"{se_from}. "
        "Both sides are approximations: each verdict gives how far they are apart over the "
        "bins carrying 90 % of the diffuse energy (energy deviation (Kirchhoff − model)/Kirchhoff, "
        "negative where the model is too bright; the energy-weighted "
        "relative RMS error beside the RMS a perfect model would show from the reference's "
        "noise), and the θo region where they agree within 2 % + 2 standard errors (forward: "
        "the mirror side, Δφ ≥ 90°); it never calls either wrong. Bins beyond θo = 80° are "
        "left out (grazing: outside Kirchhoff). The geometric verdicts above are judged "
        "against the ray tracer.",
        "",
        md_table(
            [
                "θi",
                "g = (4πσ cos θi/λ)²",
                "specular order power",
                "F(θi)·e^(−g)",
                "masked (ray tracer)",
                "Kirchhoff's domain",
            ],
            [
                [
                    f"{t:g}",
                    fmt(g),
                    fmt(p, 4),
                    fmt(dw, 4),
                    f"{m:.3g}",
                    "yes" if ok else f"no (masked ≥ {100 * wave['masked_limit']:g} %)",
                ]
                for t, g, p, dw, m, ok in zip(
                    wave["theta_i"],
                    wave["g"],
                    wave["specular_power"],
                    wave["debye_waller"],
                    wave["masked_fraction"],
                    wave["in_domain"],
                )
            ],
        ),
        "",
        "F(θi)·e^(−g): the coherent (specular) power of the ensemble for Gaussian heights "
        "(Davies/Debye–Waller); one tile keeps a speckle floor of about the incident power "
        "over its number of correlation cells. Kirchhoff's domain: correlation length and "
        "radii of curvature ≫ λ, no shadowing or multiple scattering (the ray tracer's masked "
        "fraction stands for the shadowing). "
        "Rayleigh–Rice is first order in σ/λ (σ ≪ λ); for small g the Kirchhoff diffuse power "
        "is F(1 − e^(−g)) while Rayleigh–Rice's is ≈ F·g, so Rayleigh–Rice lies ≈ g/2 above.",
        "",
        md_table(
            [
                "θi",
                "model",
                "judged against",
                "status",
                "energy deviation",
                "rel RMS (noise floor)",
                "agreement region (θo)",
                "outside the region",
                "energy bins",
            ],
            [
                [
                    f"{v['theta_i']:g}",
                    v["model"],
                    "Kirchhoff, theory vs theory",
                    _WAVE_STATUS.get(v["status"], v["status"]),
                    _signed_pct(v["energy_dev"], v["energy_dev_se"]),
                    f"{_pct(v['rel_error'])} ({_pct(v['noise_floor'])})",
                    _region_text(v),
                    _outside_text(v),
                    str(v["energy_bins"]),
                ]
                for v in wave["verdicts"]
            ],
        ),
        "",
        f"The Kirchhoff result (order powers as bin-averaged BRDF, `Result` schema, "
        f'`meta.method = "kirchhoff"`) is in `{wave["file"]}`.',
        "",
    ]
    return lines


def _wave_index_rows(docs: Sequence[Mapping]) -> tuple[list[str], list[list[str]]]:
    models: list[str] = []
    for d in docs:
        for v in (d.get("wave") or {}).get("verdicts", []):
            if v["model"] not in models:
                models.append(v["model"])
    rows = []
    for d in docs:
        w = d.get("wave")
        if not w:
            continue
        for t in w["theta_i"]:
            cells = []
            for m in models:
                v = next(
                    (x for x in w["verdicts"] if x["model"] == m and abs(x["theta_i"] - t) < 1e-9),
                    None,
                )
                if v is None:
                    cells.append("–")
                    continue
                text = _signed_pct(v["energy_dev"], v["energy_dev_se"])
                if v["status"] == "agrees":
                    text = f"**agrees** {text}"
                elif v["status"] == "agrees-in-region":
                    text += f"; agrees only in θo {_region_text(v)}"
                else:
                    text += "; differs"
                cells.append(text)
            rows.append(
                [f"[{d['scene']}]({d['scene']}/report.md)", fmt(w["sigma_over_lambda"]), f"{t:g}"]
                + cells
            )
    return models, rows


def _crossover_cell(x, devs, criterion: float, below: bool) -> str:
    """Where a method holds within ``criterion`` on the σ/λ grid, in words: "σ/λ < 0.046"
    (``below``: a small-roughness theory) or "σ/λ > 0.25"; "never" (beyond it everywhere),
    "everywhere" (within it everywhere); "–" otherwise (no single crossing)."""
    if x is not None:
        return f"σ/λ {'<' if below else '>'} {fmt(x)}"
    d = [abs(v) for v in devs if v is not None and math.isfinite(v)]
    if not d:
        return "–"
    if all(v > criterion for v in d):
        return "never"
    if all(v <= criterion for v in d):
        return "everywhere"
    return "–"


def regime_section(
    docs: Sequence[Mapping], regimes: Mapping | None, methods=None, fullwave=None
) -> list[str]:
    """Index section "Where each method holds": the wave scenes' verdicts against Kirchhoff
    and, when ``regimes`` is given (``runner.wave_run.regime_maps``: ``chart``, ``maps`` as
    ``RegimeMap.to_dict``, ``settings`` text), the regime chart and crossover table; then
    "What each method costs" (``methods_section``) when ``methods`` is given (the path of
    ``methods.json``, or its loaded dict); before it "The rung above Kirchhoff"
    (``fullwave_map.fullwave_section``, with its chart when ``fullwave-map.png`` lies beside
    it) when ``fullwave``, the path of ``fullwave.json``, exists."""
    models, rows = _wave_index_rows(docs)
    if not rows and not regimes and methods is None:
        return []
    lines = ["## Where each method holds", ""]
    if rows:
        lines += [
            "Wave-optics closed forms on the catalogue's scenes with a wavelength, each judged "
            "against the Kirchhoff solver on the same tiles (theory vs theory: energy "
            "deviation (Kirchhoff − model)/Kirchhoff ± standard error over the bins carrying "
            "90 % of the diffuse energy; "
            "**agrees**: within 2 % + 2 se over that energy set; *agrees only in θo …*: the "
            "ranges where they agree within 2 % + 2 se, forward = mirror side). The "
            "geometric models of these scenes are judged against the ray tracer above.",
            "",
            md_table(["scene", "σ/λ", "θi"] + models, rows),
            "",
        ]
    if regimes:
        lines += [
            "Regime map: the energy-weighted error (energy deviation over the 90 % energy set) "
            "of each method against the Kirchhoff reference as the roughness σ/λ grows, for an "
            "ABC-PSD and a Gaussian family at fixed correlation length "
            "(`microsim.analysis.regimes`). Rayleigh–Rice and Löw smooth hold at small σ/λ, "
            "geometric optics (Torrance–Sparrow with Smith masking, and the tile's own facets "
            "without masking: the ray tracer with masking off) at large σ/λ; Kirchhoff has no "
            "masking, so the geometric verdicts are clean only where masking is below 1 %.",
            "",
            f"Settings: {regimes['settings']}.",
            "",
            f"![Where each method holds]({regimes['chart']})",
            "",
        ]
        crit = None
        table = []
        for m in regimes["maps"]:
            crit = m["meta"].get("criterion", crit)
            for model, by_theta in m["crossovers"].items():
                below = model in ("rayleigh-rice", "low-smooth")  # small-roughness theories
                i = m["models"].index(model)
                table.append(
                    [m["family"], model]
                    + [
                        _crossover_cell(
                            by_theta.get(str(float(t))),
                            [row[k] for row in m["energy_dev"][i]],
                            crit or 0.05,
                            below,
                        )
                        for k, t in enumerate(m["theta_i"])
                    ]
                )
        thetas = regimes["maps"][0]["theta_i"]
        lines += [
            f"Where each method holds: the σ/λ range in which its |energy deviation| from "
            f"Kirchhoff stays within {100 * (crit or 0.05):g} % (the crossing interpolated in "
            "log σ); *never*: beyond it at every σ/λ of the grid; *everywhere*: within it at "
            "every σ/λ; –: no single crossing (e.g. a method that holds only in the middle "
            "of the grid).",
            "",
            md_table(["family", "method"] + [f"θi = {t:g}°" for t in thetas], table),
            "",
        ]
    if fullwave is not None and Path(fullwave).is_file():
        from .fullwave_map import (
            FULLWAVE_CHART,
            FULLWAVE_COMMAND,
            fullwave_section,
            load_fullwave,
        )

        chart = FULLWAVE_CHART if (Path(fullwave).parent / FULLWAVE_CHART).is_file() else None
        try:
            lines += fullwave_section(load_fullwave(fullwave), chart=chart)
        except UsageError as err:
            name = Path(fullwave).name
            lines += [f"`{name}` unreadable ({err}); rerun `{FULLWAVE_COMMAND}`.", ""]
    if methods is not None:
        lines += methods_section(methods)
    return lines


METHODS_COMMAND = "microsim bench --methods"
_METHODS_KEYS = {
    "machine": ("cpus", "load_average_start", "threads", "commit"),
    "panel": ("title", "scene", "reference", "error_measure", "points"),
    "point": ("method", "kind", "setting", "seconds", "error", "error_se"),
}


def load_methods(path) -> dict:
    """``methods.json`` (``microsim bench --methods``) read and checked: top-level ``machine``,
    ``panels``, and the keys ``_METHODS_KEYS`` names in each machine, panel and point; a
    missing, damaged (``atomic.read_json``) or incomplete file raises ``UsageError`` naming
    what is wrong (an ``OSError`` if the environment fails)."""
    d = read_json(path)
    if not isinstance(d.get("panels"), list) or not all(isinstance(p, dict) for p in d["panels"]):
        raise UsageError(f"{path}: no 'panels' list of objects")
    if not isinstance(d.get("machine"), dict):
        raise UsageError(f"{path}: no 'machine' object")
    missing = [k for k in _METHODS_KEYS["machine"] if k not in d["machine"]]
    for i, p in enumerate(d["panels"]):
        missing += [f"panels[{i}].{k}" for k in _METHODS_KEYS["panel"] if k not in p]
        for j, q in enumerate(p.get("points") or []):
            missing += [
                f"panels[{i}].points[{j}].{k}" for k in _METHODS_KEYS["point"] if k not in q
            ]
    if missing:
        raise UsageError(f"{path}: missing keys {missing[:5]}{' …' if len(missing) > 5 else ''}")
    return d


def _setting(text: str) -> str:
    """A method's setting with its ray count written out ("1.02e+07 rays" → "10,200,000 rays")."""
    import re

    m = re.fullmatch(r"([0-9.]+(?:e[+-]?[0-9]+)?) rays", str(text))
    return f"{int(round(float(m.group(1)))):,} rays" if m else str(text)


def _methods_rows(panel: Mapping) -> list[list[str]]:
    """Every closed form; of each method with several points (ray counts, tile sizes) the
    first and the last."""
    by: dict[str, list] = {}
    for p in panel["points"]:
        by.setdefault(p["method"], []).append(p)
    rows = []
    for method, pts in by.items():
        for p in pts if len(pts) <= 2 else [pts[0], pts[-1]]:
            err = percent(p["error"], 3, unit=" %")
            if p["error"] is not None and p.get("error_se") is not None:
                err = f"{percent(p['error'], 3, unit='')} ± {percent(p['error_se'], unit=' %')}"
            if p.get("error_se") is None and p.get("noise_floor") is not None:
                err += f" (ray noise alone {percent(p['noise_floor'], unit=' %')})"
            rows.append([f"{method}, {_setting(p['setting'])}", f"{fmt(p['seconds'])} s", err])
    return rows


def methods_section(methods) -> list[str]:
    """Subsection "What each method costs": the chart ``methods.png`` and a table (method,
    wall time, error, scene) from ``methods`` (the path of ``methods.json`` or its dict,
    ``load_methods``); when the file is absent or unreadable, the command that makes it.
    Nothing is timed here: the figures are those of the last ``microsim bench --methods``."""
    head = ["### What each method costs", ""]
    if not isinstance(methods, Mapping):
        import os

        if not os.path.isfile(methods):
            return head + [
                f"Not measured yet: `{METHODS_COMMAND}` writes `methods.json` and "
                "`methods.png` here (a few minutes; `--quick` for a small version).",
                "",
            ]
        try:
            methods = load_methods(methods)
        except (OSError, ValueError) as err:
            return head + [f"`methods.json` unreadable ({err}); rerun `{METHODS_COMMAND}`.", ""]
    m = methods["machine"]
    load = m["load_average_start"]
    load = load[0] if isinstance(load, (list, tuple)) else load
    commit = (m.get("commit") or "unknown")[:7]
    lines = head + [
        "Wall time for one incidence against the error of each method on a geometric scene, "
        "a wave scene and (with the `fullwave` extra) a 1D random grating against rigorous "
        "coupled-wave solutions, each against its own reference (ray-trace errors include their "
        "noise, so they fall with the ray count until the method's own error; ± is one "
        "standard error where a point has one).",
        "",
        "![What each method costs](methods.png)",
        "",
    ]
    for p in methods["panels"]:
        lines += [
            f"*{p['title']}* — scene: {p['scene']}; reference: {p['reference']}"
            + (
                f" ({fmt(p['reference_seconds'])} s)"
                if isinstance(p.get("reference_seconds"), (int, float))
                else ""
            )
            + f"; error: {p['error_measure']}.",
            "",
            md_table(["method", "time", "error"], _methods_rows(p)),
            "",
        ]
    lines += [
        f"Measured by `{METHODS_COMMAND}`{' --quick' if methods.get('quick') else ''} on "
        f"{m['cpus']} cores at load {float(load):.2f}, commit {commit}"
        f"{' (with uncommitted changes)' if m.get('worktree_modified') else ''}; "
        f"{m['threads']} threads; the machine may be shared, so the times are indicative.",
        "",
    ]
    return lines


def _variant_cell(v: Mapping | None) -> str:
    """One Smith G variant against the simulation: verdict symbol, energy deviation ± se,
    relative RMS error."""
    if v is None or v["rel_rms"] is None:
        return "–"
    sym = {"agrees": "✓", "deviates": "✗", "inconclusive": "?"}[v["verdict"]]
    return (
        f"{sym} {_signed_pct(v['energy_dev'], v.get('energy_dev_se'))}, "
        f"rel RMS {percent(v['rel_rms'], unit=' %')}"
    )


def _anisotropy_index(docs: Sequence[Mapping]) -> list[str]:
    """ "Anisotropy: the Smith G variants" for the scenes with an ``anisotropy`` block
    (``analysis.anisotropy``): per θi, the isotropic stand-in against the exact Λ (model
    against model) and each variant against the simulation."""
    rows = []
    for d in docs:
        for inc in (d.get("anisotropy") or {}).get("incidences", []):
            sv = inc["stand_in_vs_exact"]
            rows.append(
                [
                    f"[{d['scene']}]({d['scene']}/report.md)",
                    f"{inc['theta_i']:g}°",
                    f"{inc['phi_i']:g}°",
                    f"{_signed_pct(sv['energy_dev'])}, rel RMS {percent(sv['rel_rms'], unit=' %')}",
                ]
                + [_variant_cell(inc["against_simulation"].get(x)) for x in ANISOTROPY_VARIANTS]
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


def _anisotropy_missed(docs: Sequence[Mapping]) -> list[str]:
    """The energy the anisotropic single-scattering models miss, for the scenes traced with
    more than one bounce (``analysis.anisotropy``: ``missed``)."""
    rows = []
    for d in docs:
        for inc in (d.get("anisotropy") or {}).get("incidences", []):
            m = inc.get("missed")
            if m is None:
                continue
            rows.append(
                [
                    f"[{d['scene']}]({d['scene']}/report.md)",
                    f"{inc['theta_i']:g}°",
                    f"{inc['phi_i']:g}°",
                    f"{plain(m['reflected'], 3)} ± {plain(m['reflected_se'], 1)}",
                    f"{percent(m['multiple'] / m['reflected'], 3, unit=' %')} ± "
                    f"{percent(m['multiple_se'] / m['reflected'], unit=' %')}",
                    "–"
                    if m.get("walk_multiple") is None
                    else f"{percent(m['walk_multiple'] / m['reflected'], 3, unit=' %')} ± "
                    f"{percent(m['walk_multiple_se'] / m['reflected'], unit=' %')}",
                ]
                + [
                    _signed_pct(m["models"][x]["missed"], m["models"][x]["missed_se"])
                    for x in ANISOTROPY_VARIANTS
                ]
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


def _resolvable_energy(v: Mapping) -> float | None:
    """Smallest relative energy deviation the realisations test of ``v`` would detect:
    t_{R−1} quantile at the test's level × ``energy_dev_se`` (None for other references)."""
    if v.get("reference") != "realisations" or v.get("energy_dev_se") is None:
        return None
    return float(t_isf(0.5 * v["p_threshold"], v["realisations"] - 1) * v["energy_dev_se"])


def _compact(verdicts: Sequence[Mapping], model: str, summary: str) -> str:
    """Index cell: "✓" when ``summary_row`` says the model agrees everywhere, else "✗" with
    its largest relative RMS error over the deviating incidences and where."""
    mine = [v for v in verdicts if v["model"] == model]
    with_phi = incidence.several_azimuths(verdicts)

    def at(vs) -> str:
        if with_phi:
            return "θi " + incidence.grouped(vs, ",")
        return "θi " + ",".join(f"{v['theta_i']:g}" for v in vs) + "°"

    if summary == "agrees":
        res = [r for r in map(_resolvable_energy, mine) if r is not None]
        return f"✓ ±{percent(max(res))}" if res else "✓"
    deviating = [v for v in mine if verdict_kind(v) == "deviates"]
    if not deviating:  # only inconclusive failures: within the tile's departure, or unknown
        unsure = [v for v in mine if not v["agrees"]]
        known = [v for v in unsure if v.get("tile_departure") is not None]
        if not known or len(known) != len(unsure):
            return f"? ({at(unsure)})"
        rms = max(v["rel_rms"] for v in known)
        dep = max(v["tile_departure"] for v in known)
        return f"? {percent(rms)} (tile departs {percent(dep)}; {at(unsure)})"
    rms = [v for v in deviating if v["rel_rms"] is not None]
    if not rms:
        return f"✗ ({at(deviating)})"
    w = max(rms, key=lambda v: v["rel_rms"])
    return f"✗ {percent(w['rel_rms'])} ({at(deviating)})"


def _index_cell(d: Mapping, model: str, summary: Mapping[str, str]) -> str:
    if model not in summary:
        return "–"
    if model in (d.get("outside_domain") or {}):
        return "outside its domain"
    return _compact(d["verdicts"], model, summary[model])


def _verdict_tables(docs: Sequence[Mapping]) -> list[str]:
    """One scenes × models table per set of prescribed model names (V-grooves and
    heightfields are compared with different closed forms); fitted models at the end."""
    groups: dict[tuple, list] = {}
    for d in docs:
        pres = tuple(dict.fromkeys(v["model"] for v in d["verdicts"] if not v["fitted"]))
        groups.setdefault(pres, []).append(d)
    out, dropped = [], {}
    for pres, group in groups.items():
        fitted = list(
            dict.fromkeys(v["model"] for d in group for v in d["verdicts"] if v["fitted"])
        )
        models = list(pres) + fitted
        for m in list(models):  # a model outside its domain on every scene: said once below
            reasons = [(d.get("outside_domain") or {}).get(m) for d in group]
            if all(reasons):
                models.remove(m)
                dropped[m + (" (fit)" if m in fitted else "")] = reasons[0]
        rows = []
        for d in group:
            s = summary_row(d["verdicts"])
            n_real = max((v.get("realisations", 1) for v in d["verdicts"]), default=1)
            rows.append(
                [f"[{d['scene']}]({d['scene']}/report.md)" + (f" R={n_real}" if n_real > 1 else "")]
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


def _index_fit_cell(fit: Mapping) -> str:
    """√E1 / √E2 of one fit, with the bounds it ended on (``_bounds_brief``)."""
    cell = f"{fmt(fit['sqrt_e1'])} / {fmt(fit['sqrt_e2'])}"
    at = _bounds_brief(fit["at_bounds"])
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
    fit_models: list[str] = []
    for d in docs:
        fit_models += [f["model"] for f in d.get("fits", []) if f["model"] not in fit_models]
    fit_rows = []
    for d in docs:
        by = {f["model"]: f for f in d.get("fits", [])}
        fit_rows.append(
            [d["scene"]] + [_index_fit_cell(by[m]) if m in by else "–" for m in fit_models]
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
        "- ? (θi …) inconclusive: one heightfield tile cannot tell tile scatter from model error.",
        "- – not compared on this scene.",
        "",
    ] + _verdict_tables(docs)
    lines += _orders_index(docs)
    lines += _anisotropy_index(docs)
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
    lines += ["## Scenes", ""] + [
        f"- [{d['scene']}]({d['scene']}/report.md): {d.get('description', '')}" for d in docs
    ]
    return "\n".join(lines).rstrip() + "\n"


def run_summary(doc: Mapping) -> str:
    """What ``microsim run`` prints on stdout: a models × θi table of the verdicts in the
    index's symbols and a one-line conclusion (models that agree at every incidence; models
    that deviate, where and by up to how much; inconclusive ones). Plain text, one line each."""
    verdicts = doc["verdicts"]
    outside = doc.get("outside_domain") or {}
    thetas = list(dict.fromkeys(incidence.key(v) for v in verdicts))  # (θi, φi) pairs
    with_phi = incidence.several_azimuths(verdicts)
    models = list(dict.fromkeys(v["model"] for v in verdicts))
    by = {(v["model"], incidence.key(v)): v for v in verdicts}
    rows = [["model"] + [incidence.label(t, p, with_phi).replace(" = ", " ") for t, p in thetas]]
    for m in models:
        label = m + (" (fit)" if any(v["fitted"] for v in verdicts if v["model"] == m) else "")
        if m in outside:
            rows.append([label, "outside its domain"] + [""] * (len(thetas) - 1))
            continue
        rows.append([label] + [verdict_symbol(by[m, t]) if (m, t) in by else "–" for t in thetas])
    table = [r for r in rows if r[1:2] != ["outside its domain"]]  # that note spans columns
    widths = [max(len(r[i]) for r in table) for i in range(len(rows[0]))]
    lines = ["  ".join(c.ljust(w) for c, w in zip(r, widths)).rstrip() for r in rows]
    agree, deviate, unsure = [], [], []
    for m in models:
        if m in outside:
            continue
        mine = [by[m, t] for t in thetas if (m, t) in by]
        bad = [v for v in mine if verdict_kind(v) == "deviates"]
        if all(v["agrees"] for v in mine):
            agree.append(m)
        elif bad:
            rms = [v["rel_rms"] for v in bad if v.get("rel_rms") is not None]
            size = f" by up to {percent(max(rms))}" if rms else ""
            where = (
                incidence.grouped(bad)
                if with_phi
                else ", ".join(f"{v['theta_i']:g}" for v in bad) + "°"
            )
            deviate.append(f"{m} at θi {where}{size}")
        else:
            unsure.append(m)
    parts = [f"agrees at every {'incidence' if with_phi else 'θi'}: {', '.join(agree) or 'none'}"]
    if deviate:
        parts.append(f"deviates: {'; '.join(deviate)}")
    if unsure:
        parts.append(f"inconclusive (one tile): {', '.join(unsure)}")
    scene = doc.get("scene", "")
    return "\n".join(
        [f"{scene}: ✓ agrees, ✗ deviates (relative RMS error), ? inconclusive"]
        + lines
        + ["; ".join(parts)]
    )
