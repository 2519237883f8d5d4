"""The wave-optics parts of the reports: the scene report's "Wave optics" section (closed
forms against Kirchhoff) and the index section "Where each method holds" (the wave scenes'
verdicts, the regime map, the full-wave rung and the methods' costs)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Mapping, Sequence

from microsim.errors import UsageError

from .markdown import md_table, percent
from .report_cells import fmt, pct, ranges_text, signed_pct
from .report_methods import methods_section
from .study_records import RegimeMaps, RunDocument, WaveSection
from .wave_verdicts import WaveVerdict

__all__ = ["wave_section", "regime_section"]


_WAVE_STATUS = {
    "agrees": "**agrees**",
    "agrees-in-region": "agrees only in a region",
    "differs": "differs",
}


def _region_text(region: Mapping) -> str:
    """θo ranges of agreement per side (a wave verdict's ``region``): "forward 0–40°;
    backward 0–15°"; "none" for a side with tested rows and no agreeing one; sides without
    tested rows left out."""
    parts = []
    for side in ("forward", "backward"):
        r = region.get(side)
        if r is None:
            continue
        parts.append(f"{side} {ranges_text(r) if r else 'none'}")
    return "; ".join(parts) or "–"


def _outside_text(outside: Mapping) -> str:
    """The range of the row deviations outside the agreement region per side (a wave
    verdict's ``outside``), in %."""
    parts = []
    for side in ("forward", "backward"):
        o = outside.get(side)
        if o:
            lo, hi = (percent(x, 3, signed=True, unit="") for x in o)
            parts.append(f"{side} {lo} … {hi} %")
    return "; ".join(parts) or "–"


def wave_section(wave: Mapping | None) -> list[str]:
    """Report lines of the wave-optics verdicts (``runner.wave_run``: verdicts.json "wave");
    empty for a geometric scene. Every verdict names its reference (Kirchhoff, theory vs
    theory) and gives the agreement region rather than a bare pass/fail. ``wave``: a
    ``WaveSection`` (or its dict)."""
    if not wave:
        return []
    wave = WaveSection.from_json(wave)
    return [
        "## Wave optics: closed forms against Kirchhoff (theory vs theory)",
        "",
        _wave_reference_text(wave),
        "",
        _wave_domain_table(wave),
        "",
        "F(θi)·e^(−g): the coherent (specular) power of the ensemble for Gaussian heights "
        "(Davies/Debye–Waller); one tile keeps a speckle floor of about the incident power "
        "over its number of correlation cells. Kirchhoff's domain: correlation length and "
        "radii of curvature ≫ λ, no shadowing or multiple scattering (the ray tracer's masked "
        "fraction stands for the shadowing). "
        "Rayleigh–Rice is first order in σ/λ (σ ≪ λ); for small g the Kirchhoff diffuse power "
        "is F(1 − e^(−g)) while Rayleigh–Rice's is ≈ F·g, so Rayleigh–Rice lies ≈ g/2 above.",
        "",
        _wave_verdict_table(wave.verdicts),
        "",
        f"The Kirchhoff result (order powers as bin-averaged BRDF, `Result` schema, "
        f'`meta.method = "kirchhoff"`) is in `{wave.file}`.',
        "",
    ]


def _wave_reference_text(wave: WaveSection) -> str:
    """What the wave verdicts are judged against: the Kirchhoff solver's settings, its tiles
    and wavelength, and how the two sides are compared."""
    tile = " × ".join(
        f"{fmt(a, 4)} ({fmt(b, 3)} λ)" for a, b in zip(wave.tile, wave.tile_over_lambda)
    )
    n, n_run = wave.realisations, wave.run_realisations
    tiles = (
        ("the run's tile" if n == 1 else f"the run's {n} tiles")
        if n == n_run
        else f"{n} of the run's {n_run} tiles"
    )
    se_from = (
        "the scatter over the tiles"
        if wave.stderr_method == "realisations"
        else "the speckle of the orders in each bin"
    )
    return (
        f"Reference of every verdict in this section: the scalar Kirchhoff (tangent-plane) "
        f"solver (`microsim.wave`, surface model `{wave.surface_model}`, Fresnel at the "
        f"{'half-vector' if wave.fresnel_angle == 'half' else 'incidence'} angle, "
        f"upsample {wave.upsample}) on {tiles}, tile {tile}, wavelength λ = "
        f"{fmt(wave.wavelength, 4)} in the {wave.length_unit}, σ/λ = "
        f"{fmt(wave.sigma_over_lambda)} (nominal; the tiles' realised rms height: "
        f"{fmt(wave.realised_sigma_over_lambda)} λ, the σ in g below), on the run's bins; "
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
        "against the ray tracer."
    )


def _wave_domain_table(wave: WaveSection) -> str:
    """Per θi: g, the specular order's power against Debye–Waller, the ray tracer's masked
    fraction and whether Kirchhoff is in its domain."""
    return md_table(
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
                "yes" if ok else f"no (masked ≥ {100 * wave.masked_limit:g} %)",
            ]
            for t, g, p, dw, m, ok in zip(
                wave.theta_i,
                wave.g,
                wave.specular_power,
                wave.debye_waller,
                wave.masked_fraction,
                wave.in_domain,
            )
        ],
    )


def _wave_verdict_table(verdicts: Sequence[WaveVerdict]) -> str:
    """One row per wave verdict: status, energy deviation, rel RMS, agreement region."""
    return md_table(
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
                f"{v.theta_i:g}",
                v.model,
                "Kirchhoff, theory vs theory",
                _WAVE_STATUS.get(v.status, v.status),
                signed_pct(v.energy_dev, v.energy_dev_se),
                f"{pct(v.rel_error)} ({pct(v.noise_floor)})",
                _region_text(v.region),
                _outside_text(v.outside),
                str(v.energy_bins),
            ]
            for v in verdicts
        ],
    )


def _wave_index_rows(docs: Sequence[Mapping]) -> tuple[list[str], list[list[str]]]:
    """(the wave models in order of appearance, one row per wave scene and θi of each
    model's status against Kirchhoff)."""
    waves = [
        (d.scene, WaveSection.from_json(d.wave))
        for d in (RunDocument.from_json(d) for d in docs)
        if d.wave
    ]
    models = list(dict.fromkeys(v.model for _, w in waves for v in w.verdicts))
    rows = []
    for scene, w in waves:
        for t in w.theta_i:
            cells = []
            for m in models:
                v = next(
                    (x for x in w.verdicts if x.model == m and abs(x.theta_i - t) < 1e-9),
                    None,
                )
                if v is None:
                    cells.append("–")
                    continue
                text = signed_pct(v.energy_dev, v.energy_dev_se)
                if v.status == "agrees":
                    text = f"**agrees** {text}"
                elif v.status == "agrees-in-region":
                    text += f"; agrees only in θo {_region_text(v.region)}"
                else:
                    text += "; differs"
                cells.append(text)
            rows.append(
                [f"[{scene}]({scene}/report.md)", fmt(w.sigma_over_lambda), f"{t:g}"] + cells
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
    and, when ``regimes`` is given (``RegimeMaps`` with its chart, or its dict), the regime
    chart and crossover table; then
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
        lines += _regime_lines(RegimeMaps.from_json(regimes))
    if fullwave is not None and Path(fullwave).is_file():
        lines += _fullwave_lines(Path(fullwave))
    if methods is not None:
        lines += methods_section(methods)
    return lines


def _regime_lines(regimes: RegimeMaps) -> list[str]:
    """The regime chart and, per family and method, the σ/λ range where it holds."""
    crit = None
    table = []
    for m in regimes.maps:
        crit = m.meta.get("criterion", crit)
        for i, (model, by_theta) in enumerate(m.crossovers().items()):
            below = model in ("rayleigh-rice", "low-smooth")  # small-roughness theories
            table.append(
                [m.family, model]
                + [
                    _crossover_cell(by_theta[t], m.energy_dev[i, :, k], crit or 0.05, below)
                    for k, t in enumerate(m.theta_i)
                ]
            )
    thetas = regimes.maps[0].theta_i
    return [
        "Regime map: the energy-weighted error (energy deviation over the 90 % energy set) "
        "of each method against the Kirchhoff reference as the roughness σ/λ grows, for an "
        "ABC-PSD and a Gaussian family at fixed correlation length "
        "(`microsim.analysis.regimes`). Rayleigh–Rice and Löw smooth hold at small σ/λ, "
        "geometric optics (Torrance–Sparrow with Smith masking, and the tile's own facets "
        "without masking: the ray tracer with masking off) at large σ/λ; Kirchhoff has no "
        "masking, so the geometric verdicts are clean only where masking is below 1 %.",
        "",
        f"Settings: {regimes.settings}.",
        "",
        f"![Where each method holds]({regimes.chart})",
        "",
        f"Where each method holds: the σ/λ range in which its |energy deviation| from "
        f"Kirchhoff stays within {100 * (crit or 0.05):g} % (the crossing interpolated in "
        "log σ); *never*: beyond it at every σ/λ of the grid; *everywhere*: within it at "
        "every σ/λ; –: no single crossing (e.g. a method that holds only in the middle "
        "of the grid).",
        "",
        md_table(["family", "method"] + [f"θi = {t:g}°" for t in thetas], table),
        "",
    ]


def _fullwave_lines(path: Path) -> list[str]:
    """ "The rung above Kirchhoff" from ``fullwave.json`` at ``path`` (its chart when
    ``fullwave-map.png`` lies beside it); an unreadable file says how to remake it."""
    from .fullwave_map import FULLWAVE_CHART, FULLWAVE_COMMAND, fullwave_section, load_fullwave

    chart = FULLWAVE_CHART if (path.parent / FULLWAVE_CHART).is_file() else None
    try:
        return fullwave_section(load_fullwave(path), chart=chart)
    except UsageError as err:
        return [f"`{path.name}` unreadable ({err}); rerun `{FULLWAVE_COMMAND}`.", ""]
