"""Markdown reports: one per scene (``report.md``) and the catalogue index (``index.md``).

Pure formatting: every number comes from the verdict document written as ``verdicts.json``
(see ``microsim.runner`` and the README for its schema) and, for the energy ledger, from the
``Result``. No wall-clock time appears in either report (they are in ``timings.json``), so
rerunning an unchanged scene rewrites them byte for byte. Percentages are relative errors
(model − sim)/sim; BRDFs in sr⁻¹, angles in degrees.
"""

from __future__ import annotations

import math
from typing import Iterable, Mapping, Sequence

import numpy as np
from scipy import stats

from .verdicts import summary_row

__all__ = ["md_table", "scene_report", "index_report", "fmt", "albedo_stderr"]


def fmt(x, digits: int = 3) -> str:
    """Compact number: None/NaN → "–", else ``digits`` significant figures; a string as is; a
    sequence (e.g. a grid shape) as "a × b" of its formatted items."""
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
    return f"{x:.{digits}g}"


def _pct(x) -> str:
    return "–" if x is None or not math.isfinite(float(x)) else f"{100 * float(x):.3g}%"


def _cell(s) -> str:
    return str(s).replace("|", "\\|").replace("\n", " ")


def md_table(header: Sequence[str], rows: Iterable[Sequence]) -> str:
    """GitHub-flavoured markdown table (cells escaped)."""
    lines = [
        "| " + " | ".join(_cell(h) for h in header) + " |",
        "|" + "|".join("---" for _ in header) + "|",
    ]
    lines += ["| " + " | ".join(_cell(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


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


def _ledger_rows(doc, result) -> list[list[str]]:
    led = result.ledger
    rho, se = led["single_fresnel"], albedo_stderr(result)
    return [
        [
            f"{t:g}",
            f"{int(r)}",
            f"{rho[k]:.4f} ± {se[k]:.1g}",
            f"{led['single'][k]:.4f}",
            f"{led['masked'][k]:.4f}",
            f"{led['downward'][k]:.4f}",
            f"{led['unresolved'][k]:.2g}",
            f"{led['lost_fresnel'][k]:.4f}",
        ]
        for k, (t, r) in enumerate(zip(result.theta_i, result.rays))
    ]


def _verdict_word(v: Mapping) -> str:
    """agrees / deviates / inconclusive (an ensemble model on one realisation that the ray-noise
    tests reject: tile scatter and model error cannot be told apart; ``verdicts`` docstring)."""
    if v["agrees"]:
        return "**agrees**"
    return "deviates" if v.get("conclusive", True) else "inconclusive"


def _verdict_rows(verdicts) -> list[list[str]]:
    return [
        [
            f"{v['theta_i']:g}",
            v["model"] + (" (fit)" if v["fitted"] else ""),
            _verdict_word(v),
            f"{v.get('reference', 'ray-noise')} (R = {v.get('realisations', 1)})",
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


def _realisations_text(run: Mapping) -> str:
    """The realisation count; for ``realisations = "auto"`` also the pilot and the target."""
    auto = run.get("realisations_auto")
    if not auto:
        return str(run.get("realisations"))
    return (
        f"{auto['realisations']} (auto: pilot of {auto['pilot_realisations']}, tile-scatter "
        f"target {100 * auto['target']:.3g} %, at most {auto['max_realisations']})"
    )


def _budget_section(budget, auto) -> list[str]:
    """ "Error budget": per incidence the energy-weighted relative standard errors of the mean
    BRDF from ray noise and from tile scatter (``analysis.budget``); empty for one realisation."""
    if not budget or all(b.get("tile") is None for b in budget):
        return []
    target = auto["target"] if auto else None
    rows = [
        [
            f"{b['theta_i']:g}",
            str(b["realisations"]),
            _pct(b["ray"]),
            _pct(b["tile"]),
            _pct(b["total"]),
            _pct(b["energy"]),
        ]
        + ([("yes" if b["tile"] is not None and b["tile"] <= target else "no")] if target else [])
        for b in budget
    ]
    head = ["θi", "R", "ray noise", "tile scatter", "total", "energy"]
    text = (
        "Standard errors of the mean BRDF, energy-weighted relative RMS over the bins carrying "
        "90 % of the energy (`microsim.analysis.budget`): from the rays' noise, from the "
        "tile-to-tile scatter of the realisations, and in total; *energy*: the relative "
        "standard error of the mean's energy from the scatter of the tiles' energies. Ensemble "
        "models are judged against the realisations' scatter, which includes both."
    )
    if target:
        head.append(f"tile ≤ {100 * target:.3g} %")
        text += (
            f' With `realisations = "auto"` the realisations are added until the tile scatter '
            f"is below {100 * target:.3g} % at every θi, up to {auto['max_realisations']}."
        )
    return ["## Error budget", "", text, "", md_table(head, rows), ""]


def scene_report(doc: Mapping, result, charts: Mapping[str, str]) -> str:
    """``report.md`` of one run: settings, energy ledger, verdicts, fits, charts."""
    meta = result.meta
    surf = meta.get("surface") or {}
    run = meta.get("run", {})
    mat = meta.get("material", {})
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
            ["θi", "rays", "ρ", "single", "masked", "downward", "unresolved", "lost"],
            _ledger_rows(doc, result),
        ),
        "",
    ]
    lines += _budget_section(meta.get("error_budget"), run.get("realisations_auto"))
    summary = summary_row(doc["verdicts"])
    lines += [
        "## Verdicts",
        "",
        "A model *agrees* when the χ² and max-|z| tests (Šidák-corrected over the run's "
        "family of verdicts, α = 0.01) cannot tell it from the simulation; otherwise the "
        "size and place of the deviation are given.",
        "",
        md_table(["model", "verdict"], [[m, s] for m, s in summary.items()]),
        "",
        "Best to worst by mean relative RMS error: "
        + ", ".join(f"`{m}`" for m in doc.get("ranking", []))
        + ".",
        "",
        "<details><summary>Every incidence × model</summary>",
        "",
        md_table(
            [
                "θi",
                "model",
                "verdict",
                "judged against",
                "χ²/dof",
                "p",
                "max |z|",
                "rel RMS",
                "max rel dev",
                "worst bin",
                "deviating θo",
                "bins",
            ],
            _verdict_rows(doc["verdicts"]),
        ),
        "",
        "</details>",
        "",
    ]
    if doc.get("fits"):
        lines += [
            "## Fits (Löw eq. 29–33)",
            "",
            "One parameter set per model for all incidences, least squares on E2; "
            "√E1 and √E2 as in Löw Table II.",
            "",
            md_table(
                ["model", "parameters", "√E1", "√E2", "converged", "starts"],
                [
                    [
                        f["model"],
                        _params(f["params"]),
                        fmt(f["sqrt_e1"]),
                        fmt(f["sqrt_e2"]),
                        fmt(f["success"]),
                        str(f["n_starts"]),
                    ]
                    for f in doc["fits"]
                ],
            ),
            "",
        ]
    captions = {
        "inplane": "In-plane scattering curves (simulation ± 1σ, models as bin averages)",
        "hemisphere": "Hemisphere maps: simulation, best and worst model, z-scores",
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
                [f"Sweep: {len(st.get('theta_i', []))} incidences, {st.get('rays')} rays each."]
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
                f"θi = {fmt(sp.get('theta_i'))}°, error against {sp.get('reference')}; "
                "the wall times (this chart's x axis) are in `timings.json`. Both files "
                "are written by every run but not kept in git, since wall times differ "
                "from run to run.",
                "",
                md_table(["origins", "rays", "rel RMS error"], rows),
                "",
            ]
    return "\n".join(lines).rstrip() + "\n"


def _resolvable_energy(v: Mapping) -> float | None:
    """Smallest relative energy deviation the realisations test of ``v`` would detect:
    t_{R−1} quantile at the test's level × ``energy_dev_se`` (None for other references)."""
    if v.get("reference") != "realisations" or v.get("energy_dev_se") is None:
        return None
    return float(stats.t.isf(0.5 * v["p_threshold"], v["realisations"] - 1) * v["energy_dev_se"])


def _compact(verdicts: Sequence[Mapping], model: str, summary: str) -> str:
    """Index cell: "✓" when ``summary_row`` says the model agrees everywhere, else "✗" with
    its largest relative RMS error over the deviating incidences and where."""
    mine = [v for v in verdicts if v["model"] == model]
    if summary == "agrees":
        res = [r for r in map(_resolvable_energy, mine) if r is not None]
        return f"✓ ±{100 * max(res):.2g}%" if res else "✓"
    deviating = [v for v in mine if not v["agrees"] and v.get("conclusive", True)]
    if not deviating:  # only inconclusive failures: one tile cannot judge an ensemble model
        where = ",".join(f"{v['theta_i']:g}" for v in mine if not v["agrees"])
        return f"? (θi {where}°)"
    where = ",".join(f"{v['theta_i']:g}" for v in deviating)
    rms = [v for v in deviating if v["rel_rms"] is not None]
    if not rms:
        return f"✗ (θi {where}°)"
    w = max(rms, key=lambda v: v["rel_rms"])
    return f"✗ {100 * w['rel_rms']:.2g}% (θi {where}°)"


def _verdict_tables(docs: Sequence[Mapping]) -> list[str]:
    """One scenes × models table per set of prescribed model names (V-grooves and
    heightfields are compared with different closed forms); fitted models at the end."""
    groups: dict[tuple, list] = {}
    for d in docs:
        pres = tuple(dict.fromkeys(v["model"] for v in d["verdicts"] if not v["fitted"]))
        groups.setdefault(pres, []).append(d)
    out = []
    for pres, group in groups.items():
        fitted = list(
            dict.fromkeys(v["model"] for d in group for v in d["verdicts"] if v["fitted"])
        )
        models = list(pres) + fitted
        rows = []
        for d in group:
            s = summary_row(d["verdicts"])
            n_real = max((v.get("realisations", 1) for v in d["verdicts"]), default=1)
            rows.append(
                [f"[{d['scene']}]({d['scene']}/report.md)" + (f" R={n_real}" if n_real > 1 else "")]
                + [_compact(d["verdicts"], m, s[m]) if m in s else "–" for m in models]
            )
        out += [
            md_table(["scene"] + [m + (" (fit)" if m in fitted else "") for m in models], rows),
            "",
        ]
    return out


def index_report(
    docs: Sequence[Mapping], fig6: str | None, quick: bool, seconds: float | None = None
) -> str:
    """``index.md``: verdict tables (scenes × models), Löw-style fit table, Mikkelsen Fig. 6,
    links to every scene's ``<scene>/report.md``. ``seconds`` (the wall time) is accepted for
    compatibility and not written: the index is reproducible."""
    fit_models: list[str] = []
    for d in docs:
        fit_models += [f["model"] for f in d.get("fits", []) if f["model"] not in fit_models]
    fit_rows = []
    for d in docs:
        by = {f["model"]: f for f in d.get("fits", [])}
        fit_rows.append(
            [d["scene"]]
            + [
                f"{fmt(by[m]['sqrt_e1'])} / {fmt(by[m]['sqrt_e2'])}" if m in by else "–"
                for m in fit_models
            ]
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
        "✓: statistically indistinguishable from the simulation at every incidence (χ² and "
        "max-|z| tests, Šidák-corrected, α = 0.01). ✗: the model deviates at the listed "
        "incidences; the percentage is its largest energy-weighted relative RMS error there. ✓ "
        "±x%: an ensemble model that agrees as far as the R realisations (after the scene's name) "
        "can tell — energy "
        "deviations below x % (at the test's level) are not resolved, so a large x means a weak "
        "verdict, not a confirmed model. ?: inconclusive — an ensemble model judged on one "
        "realisation, where tile-to-tile scatter cannot be told from model error. Ensemble models"
        " on several realisations are judged against the scatter between them (Student t over the"
        " realisations); models of the realised facets against ray noise. Each scene's report "
        "says where (θo ranges, worst bin) and by how much.",
        "",
    ] + _verdict_tables(docs)
    if fit_models:
        lines += [
            "## Fits: √E1 / √E2 (Löw et al. 2012, eq. 29–33, as their Table II)",
            "",
            "Each model fitted to all incidences of a scene at once; smaller is better.",
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
    lines += ["## Scenes", ""] + [
        f"- [{d['scene']}]({d['scene']}/report.md): {d.get('description', '')}" for d in docs
    ]
    return "\n".join(lines).rstrip() + "\n"
