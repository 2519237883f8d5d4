"""Report charts: pure functions from plain arrays / a ``Result`` to a matplotlib Figure.

Every chart returns its ``matplotlib.figure.Figure``, so it shows inline in a notebook. By
default it builds its own Figure (Agg canvas, no pyplot, no global state) of exactly
``figure_size(...)`` × ``DPI`` pixels (no tight bounding box); ``ax=`` draws into the caller's
Axes instead (one Axes, or a sequence for a multi-panel chart, as each chart says; the caller's
figure then keeps its own title and layout). With ``path`` the figure is also written as a PNG,
atomically (temporary file in the target directory, then ``os.replace``); ``path=None`` writes
nothing.

Conventions: angles in degrees, BRDFs in sr⁻¹, Δφ = φo − φi (mirror direction at Δφ = 180°).
Styles are fixed per name (``model_style``: a colour per model, a line style per family) so a
model looks the same in every chart, and no chart draws two models in one colour
(``chart_styles``); the simulation is always drawn in ``SIM_COLOUR``.
"""

from __future__ import annotations

import math
import textwrap
from dataclasses import dataclass, fields
from typing import Mapping, NamedTuple, Sequence

import matplotlib as mpl
import numpy as np
from matplotlib.axes import Axes
from matplotlib.colors import LogNorm, TwoSlopeNorm
from matplotlib.figure import Figure

from microsim.errors import UsageError

from . import incidence
from .chart_style import (
    DPI,
    FRESNEL_COLOUR,
    SIM_COLOUR,
    Z_LIMIT,
    _figure,
    _given_axes,
    _grid,
    _log_limits,
    _output,
    _positive,
    _title,
    chart_styles,
    figure_size,
    model_colour,
    model_style,
)
from .json_record import JsonRecord
from .markdown import percent
from .verdicts import verdict_kind

__all__ = [
    "DPI",
    "figure_size",
    "SIM_COLOUR",
    "FAIL_THRESHOLD",
    "model_colour",
    "model_style",
    "chart_styles",
    "inplane_curves",
    "hemisphere_maps",
    "energy_chart",
    "mikkelsen_fig6",
    "speed_accuracy",
    "stability_chart",
    "Z_LIMIT",
]

FAIL_THRESHOLD = 0.05  # relative error above which a closed form "fails" (stability chart)


# --- 1. in-plane curves ----------------------------------------------------------------------
def _in_plane_slice(a: np.ndarray, bins) -> np.ndarray:
    """(T, Θ, Φ) → (T, 2Θ): backward side (Δφ = 0° bin) reversed, then forward (Δφ = 180°)."""
    a = np.asarray(a, dtype=np.float64)
    return np.concatenate([a[:, ::-1, bins.backward_index], a[:, :, bins.forward_index]], axis=1)


RATIO_MAX_REL_SE = 0.5
"""The ratio panels leave out bins whose relative standard error exceeds this (noise alone)."""


def inplane_curves(
    result, models: Mapping[str, np.ndarray], path=None, scene_name: str = "", *, ax=None
) -> Figure:
    """In-plane scattering curves, one panel per incidence (as Löw et al. 2012, Figs. 3 and 12),
    each with a ratio panel below it.

    x: signed θo in degrees (specular side Δφ = 180° positive, backward side Δφ = 0° negative);
    y: bin-averaged BRDF in sr⁻¹, log scale. Simulation: points with ±1 standard-error bars;
    models (name → (T, Θ, Φ) bin averages on ``result.bins``): constant over each bin (steps),
    one colour and line style each (``chart_styles``). Ratio panel: model / simulation per bin
    with the simulation's ±1σ band around 1 (bins with relative standard error above
    ``RATIO_MAX_REL_SE`` left out; ratios beyond the axis drawn at its edge as triangles), so a
    20 % error reads as 0.8 or 1.2 whatever the dynamic range above. The mirror direction
    θo = +θi is marked. ``ax``: one Axes per incidence (the curves only, no ratio panels; the
    legend then goes in the first).
    """
    bins = result.bins
    ip = result.in_plane()
    te = np.asarray(bins.theta_edges, dtype=np.float64)
    edges = np.concatenate([-te[::-1], te[1:]])
    centres = 0.5 * (edges[:-1] + edges[1:])
    curves = {name: _in_plane_slice(m, bins) for name, m in models.items()}
    styles = chart_styles(curves)
    n_t = len(result.theta_i)
    with_phi = incidence.several_azimuths(result.phi_i)
    given = _given_axes(ax, n_t, "inplane_curves", "one per incidence")
    ratio_axes = [None] * n_t
    if given is None:
        rows, cols = _grid(n_t)
        fig = _figure(figure_size("inplane", n_t))
        grid = fig.subplots(
            2 * rows, cols, squeeze=False, height_ratios=[3.0, 1.3] * rows, sharex=True
        )
        axes = [grid[2 * (k // cols), k % cols] for k in range(rows * cols)]
        ratio_axes = [grid[2 * (k // cols) + 1, k % cols] for k in range(rows * cols)]
        for k in range(1, len(axes)):
            axes[k].sharey(axes[0])
            ratio_axes[k].sharey(ratio_axes[0])
    else:
        rows, cols, axes, fig = 1, n_t, given, given[0].figure
    lo, hi = _log_limits([ip.brdf] + [c for c in curves.values()], 1e-6)
    panel = _InPlanePanel(ip, curves, styles, edges, centres)
    ratios = []
    for t in range(rows * cols):
        ax, rx = axes[t], ratio_axes[t]
        if t >= n_t:
            ax.set_visible(False)
            if rx is not None:
                rx.set_visible(False)
            continue
        th_i = float(result.theta_i[t])
        panel.curves_panel(ax, t, th_i, (lo, hi))
        ax.set_title(incidence.label(th_i, float(result.phi_i[t]), with_phi))
        if t % cols == 0:
            ax.set_ylabel("BRDF (sr⁻¹)")
        ax.grid(True, which="major", alpha=0.3)
        if rx is None:
            ax.set_xlabel("θo (°)   − backward (Δφ=0°) | + specular (Δφ=180°)")
            continue
        ax.tick_params(labelbottom=False)
        ratios.append(panel.ratios(rx, t, th_i))
        if t % cols == 0:
            rx.set_ylabel("model / sim.")
        rx.grid(True, which="major", alpha=0.3)
    if given is not None:
        axes[0].legend(fontsize=8)
        return _output(fig, path)
    _ratio_limits(ratios)
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, fontsize=8, loc="outside right center")  # never over the data
    fig.supxlabel("θo (°): − backward side (Δφ = 0°), + specular side (Δφ = 180°)", fontsize=9)
    fig.suptitle(
        _title(scene_name, "in-plane scattering (bin averages); below: model / simulation")
    )
    return _output(fig, path)


class _InPlanePanel(NamedTuple):
    """What ``inplane_curves`` draws in each incidence's panels: the in-plane slice ``ip``,
    the models' slices ``curves`` with their ``styles``, the signed θo bin ``edges`` and
    ``centres``."""

    ip: object
    curves: Mapping[str, np.ndarray]
    styles: Mapping[str, tuple]
    edges: np.ndarray
    centres: np.ndarray

    def curves_panel(self, ax, t: int, th_i: float, ylim) -> None:
        """The models as steps, the simulation ±1σ as points, the mirror direction marked."""
        ip = self.ip
        for name, c in self.curves.items():
            colour, style = self.styles[name]
            ax.stairs(
                _positive(c[t]), self.edges, baseline=None, color=colour, ls=style, lw=1.6,
                label=name,
            )  # fmt: skip
        y = _positive(ip.brdf[t])
        ax.errorbar(
            ip.theta,
            y,
            yerr=np.where(np.isfinite(y), ip.stderr[t], np.nan),
            fmt="o",
            ms=3.0,
            color=SIM_COLOUR,
            ecolor=SIM_COLOUR,
            elinewidth=1.0,
            capsize=1.5,
            label="simulation ±1σ",
            zorder=5,
        )
        ax.axvline(th_i, color="0.35", ls="--", lw=0.9, label="mirror θo = +θi")
        ax.axvline(0.0, color="0.75", lw=0.6)
        ax.set_yscale("log")
        ax.set_ylim(*ylim)
        ax.set_xlim(-90, 90)
        ax.set_xticks(np.arange(-90, 91, 30))

    def ratios(self, rx, t: int, th_i: float):
        """Model / simulation per bin with the simulation's ±1σ band (noisy bins left out);
        (rx, x, [(ratio, colour)]) for ``_ratio_limits``."""
        ip = self.ip
        sim = np.array(ip.brdf[t], dtype=np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            rel_se = np.asarray(ip.stderr[t], dtype=np.float64) / sim
            keep = np.isfinite(rel_se) & (sim > 0) & (rel_se <= RATIO_MAX_REL_SE)
            rx.fill_between(
                self.centres,
                np.where(keep, 1 - rel_se, np.nan),
                np.where(keep, 1 + rel_se, np.nan),
                step="mid",
                color=SIM_COLOUR,
                alpha=0.18,
                lw=0,
                label="simulation ±1σ",
            )
            marks = []
            for name, c in self.curves.items():
                r = np.where(keep, c[t] / sim, np.nan)
                colour, style = self.styles[name]
                marks.append((r, colour))
                rx.stairs(r, self.edges, baseline=None, color=colour, ls=style, lw=1.4)
        rx.axhline(1.0, color=SIM_COLOUR, lw=0.9)
        rx.axvline(th_i, color="0.35", ls="--", lw=0.9)
        rx.set_xlabel("θo (°)")
        return rx, self.centres, marks


def _ratio_limits(panels) -> None:
    """A common y range for the ratio panels (``panels``: [(Axes, x, [(ratio, colour)])]): the
    central 98 % of the ratios, at least 0.8–1.2, at most 0–3; ratios beyond it marked at the
    edge (triangles pointing out)."""
    vals = [np.ravel(r) for _, _, rs in panels for r, _ in rs]
    vals = np.concatenate(vals) if vals else np.array([1.0])
    vals = vals[np.isfinite(vals)]
    lo, hi = np.percentile(vals, [1, 99]) if vals.size else (1.0, 1.0)
    lo, hi = max(0.0, min(0.8, lo - 0.05)), min(3.0, max(1.2, hi + 0.05))
    for rx, x, rs in panels:
        rx.set_ylim(lo, hi)
        for r, colour in rs:
            with np.errstate(invalid="ignore"):
                up, down = r > hi, r < lo
            rx.plot(x[up], np.full(up.sum(), hi), "^", ms=4, color=colour)
            rx.plot(x[down], np.full(down.sum(), lo), "v", ms=4, color=colour)


# --- 2. hemisphere maps ----------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class ChartVerdict(JsonRecord):
    """The fields of a verdict the charts show, read from a verdict or its dict (which may
    hold NaN for an undefined number, or lack the verdict itself: ``agrees`` None)."""

    model: str = ""
    theta_i: float = 0.0
    phi_i: float = 0.0
    rel_rms: float | None = None
    chi2_dof: float | None = None
    max_abs_z: float | None = None
    agrees: bool | None = None
    tile_departure: float | None = None


def _flatten_verdicts(verdicts) -> list[ChartVerdict]:
    """All verdicts (dicts with a "model" key) in any nesting of lists / dicts."""
    if isinstance(verdicts, Mapping):
        if "model" in verdicts:
            return [ChartVerdict.from_json(dict(verdicts))]
        verdicts = verdicts.values()
    out = []
    for v in verdicts:
        out += _flatten_verdicts(v)
    return out


def _num(v) -> float:
    """A verdict number as float; None (undefined) → NaN."""
    return np.nan if v is None else float(v)


def _select_verdicts(verdicts, theta_i: float, phi_i: float, names) -> list[ChartVerdict]:
    """Verdicts of incidence (``theta_i``, ``phi_i``) (deg) for the models in ``names`` with a
    finite rel_rms."""
    sel = [
        v
        for v in _flatten_verdicts(verdicts)
        if v.model in names
        and math.isclose(float(v.theta_i), theta_i, abs_tol=1e-6)
        and math.isclose(float(v.phi_i), phi_i, abs_tol=1e-6)
        and np.isfinite(_num(v.rel_rms))
    ]
    if not sel:
        raise UsageError(
            f"verdicts must hold a dict with finite rel_rms for θi = {theta_i:g}°, "
            f"φi = {phi_i:g}° and one of the models {sorted(names)}"
        )
    return sorted(sel, key=lambda v: _num(v.rel_rms))


def _unfold(values: np.ndarray, bins) -> tuple[np.ndarray, np.ndarray]:
    """(Θ, Φ) map → (azimuth edges in rad, (Θ, Φ') values) covering the full circle.
    Folded grids are mirrored about Δφ = 0 (the BRDF is symmetric in ±Δφ)."""
    pe = np.asarray(bins.phi_edges, dtype=np.float64)
    if not bins.folded:
        return np.radians(pe), values
    edges = np.concatenate([-pe[::-1], pe[1:]])
    return np.radians(edges), np.concatenate([values[:, ::-1], values], axis=1)


def _polar_panel(ax, values, bins, theta_i, norm, cmap, title, colour):
    """Draw the (Θ, Φ) map ``values`` on the polar Axes ``ax``: (ax, its QuadMesh)."""
    ang, v = _unfold(values, bins)
    r = np.sin(np.radians(bins.theta_edges))
    cm = cmap.with_extremes(bad="0.85")
    mesh = ax.pcolormesh(
        ang, r, np.ma.masked_invalid(v), norm=norm, cmap=cm, shading="flat", rasterized=True
    )
    ax.plot(
        [math.pi],
        [math.sin(math.radians(theta_i))],
        marker="o",
        ms=9,
        mfc="none",
        mec="k",
        mew=1.5,
        ls="none",
        clip_on=False,
        zorder=6,
        label="mirror",
    )
    ax.set_theta_zero_location("W")  # Δφ = 0° (back towards the light) on the left
    ax.set_theta_direction(-1)
    ax.set_ylim(0, 1)
    ax.set_yticks(np.sin(np.radians([30, 60, 90])))
    ax.set_yticklabels(["30°", "60°", "90°"], fontsize=7)
    ax.set_rlabel_position(315.0)  # lower left: clear of the azimuth labels
    ax.set_xticks(np.radians([0, 90, 180, 270]))
    ax.set_xticklabels(["Δφ=0°", "90°", "180°", "270°"], fontsize=7)
    ax.spines["polar"].set_color(colour)
    ax.spines["polar"].set_linewidth(3.0)
    ax.set_title(title, fontsize=9, color=colour if colour != "k" else "k")
    return ax, mesh


def hemisphere_maps(
    result,
    models: Mapping[str, np.ndarray],
    verdicts,
    path=None,
    t_index: int = 0,
    scene_name: str = "",
    *,
    ax=None,
) -> Figure:
    """Polar maps at incidence ``t_index``: r = sin θo, angle = Δφ (folded grids mirrored),
    of the simulation, the best and the worst model by ``rel_rms`` (shared log colour scale,
    sr⁻¹), and the z-scores (sim − model)/stderr of both (diverging, symmetric, ±5 marked;
    bins without events grey); a single model is shown as "model" (2 × 2 panels). Models
    outside their domain are not passed in ``models`` by the runner. ``verdicts``: verdict
    dicts (keys theta_i, model, rel_rms, chi2_dof, max_abs_z, agrees, …) in any list/dict
    nesting. The mirror direction is circled.
    ``ax``: six Axes in the 2 × 3 layout of the PNG, row by row — simulation, best, worst
    (polar), verdict table, z of best, z of worst (polar); those of the worst model stay empty
    when one model is shown.
    """
    n_t = len(result.theta_i)
    if not (0 <= int(t_index) < n_t):
        raise UsageError(f"t_index must be in [0, {n_t - 1}], got {t_index}")
    t = int(t_index)
    theta_i, phi_i = float(result.theta_i[t]), float(result.phi_i[t])
    sel = _select_verdicts(verdicts, theta_i, phi_i, set(models))
    best, worst = sel[0], sel[-1]
    shown = [best] if best.model == worst.model else [best, worst]
    sim = _positive(result.brdf[t])
    maps = {v.model: np.asarray(models[v.model][t], dtype=np.float64) for v in shown}
    norm, zs, zmax = _hemisphere_scales(result, t, sim, maps)
    zlim = Z_LIMIT
    znorm = TwoSlopeNorm(vcenter=0.0, vmin=-zlim, vmax=zlim)

    given = _given_axes(ax, 6, "hemisphere_maps", "simulation, best, worst, table, z best, z worst")
    fig, panel = _hemisphere_layout(given, len(shown))

    def polar(row, col, values, norm, cmap, title, colour):
        args = (result.bins, theta_i, norm, mpl.colormaps[cmap], title, colour)
        return _polar_panel(panel(row, col), values, *args)

    ax, mesh = polar(0, 0, sim, norm, "viridis", "simulation", SIM_COLOUR)
    brdf_axes, z_axes = [ax], []
    for j, v in enumerate(shown):
        role = "model" if len(shown) == 1 else ("best" if v is best else "worst")
        col, name = model_colour(v.model), v.model
        brdf_axes.append(
            polar(0, j + 1, _positive(maps[name]), norm, "viridis", f"{role}: {name}", col)[0]
        )
        z_title = f"z = (sim − {name}) / σ"
        zax, zmesh = polar(1, j + 1, zs[name], znorm, "RdBu_r", z_title, col)
        _mark_z5(zax, zs[name], result.bins)
        z_axes.append(zax)
    cb = fig.colorbar(mesh, ax=brdf_axes, shrink=0.8, pad=0.02)
    cb.set_label("BRDF (sr⁻¹), log scale")
    _z_colourbar(fig, zmesh, z_axes, zmax > zlim, zlim)
    _hemisphere_notes(panel(1, 0, polar=False), sel, result.bins.folded)
    if given is None:
        at = incidence.label(theta_i, phi_i, incidence.several_azimuths(result.phi_i))
        fig.suptitle(_title(scene_name, f"hemisphere at {at}"))
    elif len(shown) == 1:
        given[2].axis("off")
        given[5].axis("off")
    return _output(fig, path)


def _hemisphere_scales(result, t: int, sim, maps: Mapping[str, np.ndarray]):
    """(the BRDF maps' shared log scale, each model's z-scores (sim − model)/stderr, the
    largest |z|) at incidence ``t``."""
    err = np.asarray(result.stderr[t], dtype=np.float64)
    lo, hi = _log_limits([sim], 1e-4)
    hi = max(hi, _log_limits(list(maps.values()), 1e-4)[1])
    with np.errstate(divide="ignore", invalid="ignore"):
        zs = {k: np.where(err > 0, (result.brdf[t] - m) / err, np.nan) for k, m in maps.items()}
    zmax = max([np.nanmax(np.abs(z)) if np.isfinite(z).any() else 0.0 for z in zs.values()])
    return LogNorm(vmin=lo, vmax=hi), zs, zmax


def _hemisphere_layout(given, n_models: int):
    """(figure, panel(row, col, polar=True) → Axes) of ``hemisphere_maps``: the given six Axes
    (checked polar where a map goes), or a new figure of 2 × (1 + ``n_models``) panels."""
    if given is None:
        w, h = figure_size("hemisphere_maps")
        fig = _figure((w * (1 + n_models) / 3, h))  # no empty column for a single model
        gs = fig.add_gridspec(2, 1 + n_models)
    else:
        fig = given[0].figure
        for k in (0, 1, 2, 4, 5):
            if given[k].name != "polar":
                raise UsageError(f"hemisphere_maps: ax[{k}] must be a polar Axes")

    def panel(row: int, col: int, polar: bool = True) -> Axes:
        if given is not None:
            return given[3 * row + col]
        return fig.add_subplot(gs[row, col], **({"projection": "polar"} if polar else {}))

    return fig, panel


def _z_colourbar(fig, zmesh, z_axes, beyond: bool, zlim: float) -> None:
    """The z-scores' colour bar, ±5 marked; arrows when some |z| lies ``beyond`` ``zlim``."""
    extend = "both" if beyond else "neither"
    zcb = fig.colorbar(zmesh, ax=z_axes, shrink=0.8, pad=0.02, extend=extend)
    zcb.set_label("z-score (σ)")
    for s in (-5.0, 5.0):
        zcb.ax.axhline(s, color="k", lw=1.5)
    zcb.set_ticks(sorted({-zlim, -5.0, 0.0, 5.0, zlim}))


def _hemisphere_notes(tax, verdicts, folded: bool) -> None:
    """The verdict table of the shown incidence and the key of the maps, in panel ``tax``."""
    tax.axis("off")
    tax.text(
        0.0,
        1.0,
        _verdict_table(verdicts),
        family="monospace",
        fontsize=8,
        va="top",
        transform=tax.transAxes,
    )
    tax.text(
        0.0,
        0.0,
        f"r = sin θo, angle = Δφ"
        f"{' (mirrored from the folded half)' if folded else ' (full circle)'}\n"
        "○ mirror direction; black contour |z| = 5; grey: no events",
        fontsize=8,
        va="bottom",
        transform=tax.transAxes,
    )


def _mark_z5(ax, z, bins):
    """Contour |z| = 5 over the bin centres (skipped when no bin reaches it, and on a grid
    of one θo bin, where no contour can be drawn)."""
    a = np.abs(z)
    if not (np.isfinite(a) & (a >= 5.0)).any():
        return
    ang, v = _unfold(a, bins)
    if min(v.shape) < 2:
        return
    ac = 0.5 * (ang[1:] + ang[:-1])
    rc = np.sin(np.radians(bins.theta_centers))
    ax.contour(ac, rc, np.ma.masked_invalid(v), levels=[5.0], colors="k", linewidths=0.8)


MODEL_COLUMN = 38
"""Longest model name the hemisphere chart's table prints whole (the catalogue's longest,
``ts-beckmann-nominal-smith-corr-geomean``)."""


def _verdict_table(sel: list[ChartVerdict]) -> str:
    """The chart's text table: one row per verdict, its verdict in ``verdict_kind``'s words
    (the rule of every output) and, for an inconclusive tile, the tile's departure."""
    width = min(max([len("model")] + [len(str(v.model)) for v in sel]), MODEL_COLUMN) + 1
    head = f"{'model':<{width}}{'χ²/dof':>8}{'max|z|':>8}{'rel rms':>9}  verdict"
    rows = [head, "-" * len(head)]
    for v in sel:
        kind = verdict_kind(v) if v.agrees is not None else "–"
        if kind == "inconclusive" and v.tile_departure is not None:
            kind += f" (tile departs {percent(v.tile_departure)})"
        rows.append(
            f"{str(v.model)[: width - 1]:<{width}}{_num(v.chi2_dof):>8.2f}"
            f"{_num(v.max_abs_z):>8.1f}{_num(v.rel_rms):>9.3f}  {kind}"
        )
    return "\n".join(rows)


# --- 3. energy ------------------------------------------------------------------------------
def energy_chart(
    theta_i,
    rho_sim,
    rho_sim_err,
    rho_models: Mapping[str, tuple],
    lost_sim,
    path=None,
    scene_name: str = "",
    *,
    ax=None,
) -> Figure:
    """Single-bounce albedo ρ(θi) (Mikkelsen eq. 27) of the simulation (points, ±1σ) against
    each model's ρ (name → (θ grid in deg, ρ)), and, on a second panel, the fraction of the
    incident energy single scattering loses: ``lost_sim`` either an array over θi or a dict
    name → array (e.g. masked, downward; their sum is drawn as "total"). Fractions of incident
    power, dimensionless. ``ax``: two Axes (albedo, energy lost).
    """
    th = np.asarray(theta_i, dtype=np.float64)
    given = _given_axes(ax, 2, "energy_chart", "albedo, energy lost")
    if given is None:
        fig = _figure(figure_size("energy"))
        ax, bx = fig.subplots(1, 2)
    else:
        (ax, bx), fig = given, given[0].figure
    styles = chart_styles(rho_models)
    for name, (grid, rho) in rho_models.items():
        ax.plot(
            np.asarray(grid, float),
            np.asarray(rho, float),
            color=styles[name][0],
            ls=styles[name][1],
            lw=1.6,
            label=name,
        )
    ax.errorbar(
        th,
        np.asarray(rho_sim, float),
        yerr=np.asarray(rho_sim_err, float),
        fmt="o",
        ms=4,
        color=SIM_COLOUR,
        capsize=2,
        label="simulation ±1σ",
        zorder=5,
    )
    ax.set_xlabel("θi (°)")
    ax.set_ylabel("ρ(θi), single-bounce albedo")
    ax.set_title("albedo ρ(θi) (Mikkelsen eq. 27)")
    ax.legend(fontsize=8)
    if isinstance(lost_sim, Mapping):
        parts = {k: np.asarray(v, float) for k, v in lost_sim.items()}
        total = np.sum(list(parts.values()), axis=0) if len(parts) > 1 else None
    else:
        parts, total = {"lost": np.asarray(lost_sim, float)}, None
    markers = iter(["s", "^", "v", "D", "P", "X"])
    for name, v in parts.items():
        bx.plot(
            th, v, marker=next(markers, "o"), ms=4, ls="--", lw=1.0, color=SIM_COLOUR, label=name
        )
    if total is not None:
        bx.plot(th, total, marker="o", ms=4, lw=1.8, color=SIM_COLOUR, label="total")
    bx.set_xlabel("θi (°)")
    bx.set_ylabel("fraction of incident power")
    bx.set_title("energy lost by single scattering (simulation)")
    bx.legend(fontsize=8)
    bx.set_ylim(bottom=0)
    for a in (ax, bx):
        a.set_xlim(0, 90)
        a.set_xticks(np.arange(0, 91, 15))
        a.grid(True, alpha=0.3)
    if given is None:
        fig.suptitle(_title(scene_name, "energy"))
    return _output(fig, path)


# --- 4. Mikkelsen Fig. 6(c)(d) -----------------------------------------------------------------
@dataclass(frozen=True)
class Fig6Curve:
    """One curve of ``mikkelsen_fig6``, read from its dict by ``of``: the ``material`` (given,
    else the label's first word), the ``series`` (the label without it, e.g. "κ=17": keys the
    colour, the same in both panels); θ (deg) with the model's 1 − ρ and the Fresnel
    transmittance; the simulation's θ, 1 − ρ and its standard error."""

    material: str
    series: str
    theta: np.ndarray
    one_minus_rho_model: np.ndarray
    fresnel_T: np.ndarray
    sim_theta: np.ndarray
    sim_one_minus_rho: np.ndarray
    sim_err: np.ndarray

    @classmethod
    def of(cls, curve: Mapping) -> "Fig6Curve":
        words, given = str(curve.get("label")).split(), curve.get("material")
        series = words if given or len(words) < 2 else words[1:]
        arrays = (np.asarray(curve.get(f.name), float) for f in fields(cls)[2:])
        return cls(str(given or words[0]), " ".join(series), *arrays)


def mikkelsen_fig6(curves: list[Mapping], path=None, title: str = "", *, ax=None) -> Figure:
    """Mikkelsen 2009, Fig. 6(c)(d): 1 − ρ(θ) (ρ of eq. 27, vMF NDF) and the Fresnel transmittance
    Ft(θ) = 1 − F(θ) against θ (deg), one panel per material side by side.

    ``curves``: dicts read by ``Fig6Curve.of`` (a "label" such as "methanol κ=17", an optional
    "material", the arrays). Model: line in ``model_colour(series)``; simulation: points ±1σ.
    As in the paper, 1 − ρ approaches Ft as κ grows. ``ax``: one Axes per material."""
    groups: dict[str, list[Fig6Curve]] = {}
    for c in map(Fig6Curve.of, curves):
        groups.setdefault(c.material, []).append(c)
    if not groups:
        raise UsageError("curves must hold at least one curve dict")
    given = _given_axes(ax, len(groups), "mikkelsen_fig6", "one per material")
    if given is None:
        fig = _figure(figure_size("mikkelsen_fig6", len(groups)))
        axes = fig.subplots(1, len(groups), squeeze=False)[0]
    else:
        axes, fig = given, given[0].figure
    markers = ("o", "s", "^", "D", "v", "P")
    for ax, (material, group) in zip(axes, groups.items()):
        c0 = group[0]
        ax.plot(c0.theta, c0.fresnel_T, color=FRESNEL_COLOUR, ls="--", lw=1.4,
                label="Fresnel transmittance Ft(θ)")  # fmt: skip
        top = [np.nanmax(c0.fresnel_T)]
        for k, c in enumerate(group):
            col = model_colour(c.series)
            ax.plot(c.theta, c.one_minus_rho_model, color=col, lw=1.8,
                    label=f"1 − ρ model, {c.series}")  # fmt: skip
            ax.errorbar(
                c.sim_theta,
                c.sim_one_minus_rho,
                yerr=c.sim_err,
                fmt=markers[k % len(markers)],
                ms=5,
                mfc=SIM_COLOUR,
                mec=col,
                mew=1.2,
                ecolor=SIM_COLOUR,
                capsize=2,
                ls="none",
                label=f"1 − ρ simulation ±1σ, {c.series}",
                zorder=5,
            )
            top += [np.nanmax(c.one_minus_rho_model), np.nanmax(c.sim_one_minus_rho)]
        ax.set_title(material)
        ax.set_xlim(0, 90)
        ax.set_xticks(np.arange(0, 91, 15))
        ax.set_ylim(0, min(1.02, 1.1 * max(top)))
        ax.set_xlabel("θ between n and ω (°)")
        ax.set_ylabel("fraction of incident power")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7, loc="lower left")
    if given is None:
        fig.suptitle(_title(title, "Mikkelsen Fig. 6(c)(d): 1 − ρ(θ) vs Fresnel transmittance"))
    return _output(fig, path)


# --- 5. speed vs accuracy ------------------------------------------------------------------------
def speed_accuracy(
    runs: Mapping[str, tuple],
    path=None,
    title: str = "",
    error_label: str = "error (relative RMS)",
    *,
    ax=None,
) -> Figure:
    """Error against wall time (s), log–log, per estimator variant (name → (wall_times, errors)),
    each with a dotted 1/√t reference anchored at the variant's first point (Monte Carlo rate).
    ``ax``: one Axes.
    """
    given = _given_axes(ax, 1, "speed_accuracy", "one")
    if given is None:
        fig = _figure(figure_size("speed_accuracy"))
        ax = fig.subplots()
    else:
        ax, fig = given[0], given[0].figure
    for k, (name, (times, errors)) in enumerate(runs.items()):
        t = np.asarray(times, float)
        e = np.asarray(errors, float)
        order = np.argsort(t)
        t, e = t[order], e[order]
        col = model_colour(name)
        ax.plot(t, e, marker="o", color=col, lw=1.6, label=name)
        ref = np.geomspace(t[0], t[-1] if t[-1] > t[0] else t[0] * 10, 50)
        ax.plot(
            ref,
            e[0] * np.sqrt(t[0] / ref),
            color=col,
            ls=":",
            lw=1.2,
            label="∝ 1/√t" if k == 0 else None,
        )
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("wall time (s)")
    ax.set_ylabel(error_label)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title(_title(title, "speed vs accuracy"))
    return _output(fig, path)


# --- 6. stability ----------------------------------------------------------------------------
def _fail_ranges(th: np.ndarray, err: np.ndarray, threshold: float) -> list[tuple[float, float]]:
    """Contiguous θi ranges (deg) where ``err`` exceeds ``threshold`` (NaN: undefined, not
    failing)."""
    with np.errstate(invalid="ignore"):
        edge = np.diff(np.concatenate([[0], (err > threshold).astype(np.int8), [0]]))
    starts, ends = np.flatnonzero(edge == 1), np.flatnonzero(edge == -1) - 1
    return [(float(th[a]), float(th[b])) for a, b in zip(starts, ends)]


def stability_chart(
    theta_i,
    rel_err: Mapping[str, np.ndarray],
    path=None,
    warnings: Sequence[str] = (),
    title: str = "",
    *,
    ax=None,
) -> Figure:
    """Relative error of each closed form against θi ∈ [0°, 89°] (log y); the region above
    ``FAIL_THRESHOLD`` (5 %) is shaded and each model's failing θi ranges are drawn as a
    coloured bar under the plot. Estimator ``warnings`` are printed as text notes below.
    ``ax``: three Axes (errors, failing ranges, notes).
    """
    th = np.asarray(theta_i, dtype=np.float64)
    notes = [textwrap.fill("• " + str(w), 120) for w in warnings] or ["• no estimator warnings"]
    n_lines = sum(n.count("\n") + 1 for n in notes)
    given = _given_axes(ax, 3, "stability_chart", "errors, failing ranges, notes")
    if given is None:
        fig = _figure(figure_size("stability", n_lines))
        gs = fig.add_gridspec(
            3, 1, height_ratios=[5.0, 0.25 * max(1, len(rel_err)), 0.22 * n_lines + 0.2]
        )
        ax = fig.add_subplot(gs[0])
        bar = fig.add_subplot(gs[1], sharex=ax)
        txt = fig.add_subplot(gs[2])
    else:
        (ax, bar, txt), fig = given, given[0].figure
    half = 0.5 * (np.median(np.diff(th)) if th.size > 1 else 1.0)  # half a θi step (bars)
    all_err, styles = [], chart_styles(rel_err)
    for k, (name, e) in enumerate(rel_err.items()):
        e = np.abs(np.asarray(e, dtype=np.float64))
        all_err.append(e)
        col, style = styles[name]
        ax.plot(th, _positive(e), marker="o", ms=3, color=col, ls=style, lw=1.6, label=name)
        for a, b in _fail_ranges(th, e, FAIL_THRESHOLD):
            bar.barh(k, b - a + 2 * half, left=a - half, height=0.7, color=col)
    lo, hi = _log_limits(all_err + [np.array([FAIL_THRESHOLD])], 1e-5)
    ax.set_yscale("log")
    ax.set_ylim(lo, max(hi, 2 * FAIL_THRESHOLD))
    ax.axhspan(
        FAIL_THRESHOLD,
        ax.get_ylim()[1],
        color="#f4cccc",
        alpha=0.6,
        zorder=0,
        label=f"fails (> {FAIL_THRESHOLD:.0%})",
    )
    ax.axhline(FAIL_THRESHOLD, color="#b71c1c", lw=1.0)
    ax.set_xlim(0, 89)
    ax.set_ylabel("relative error of the model")
    ax.grid(True, which="major", alpha=0.3)
    ax.legend(fontsize=8, loc="upper left")
    ax.set_title(_title(title, "where each closed form fails"))
    ax.tick_params(labelbottom=False)
    bar.set_yticks(range(len(rel_err)))
    bar.set_yticklabels(list(rel_err), fontsize=7)
    bar.set_ylim(-0.6, len(rel_err) - 0.4)
    bar.invert_yaxis()
    bar.set_title(f"θi where the relative error exceeds {FAIL_THRESHOLD:.0%}", fontsize=8)
    bar.set_xlabel("θi (°)")
    bar.set_xticks([0, 15, 30, 45, 60, 75, 89])
    bar.set_xlim(0, 89)
    bar.grid(True, axis="x", alpha=0.3)
    txt.axis("off")
    txt.text(
        0.0,
        1.0,
        "Estimator notes:\n" + "\n".join(notes),
        fontsize=8,
        va="top",
        transform=txt.transAxes,
    )
    return _output(fig, path)
