"""What every report chart shares: its size (``figure_size``, ``DPI``), the fixed style of
each model name (``model_style``: a colour per model, a line style per family; no chart draws
two models in one colour, ``chart_styles``), the simulation's colour, and the plumbing that
makes a Figure, titles it and writes it as a PNG atomically (``charts`` module docstring)."""

from __future__ import annotations

import math
import os
import zlib
from typing import Iterable

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from microsim.errors import UsageError

from ..atomic import atomic_open

__all__ = [
    "DPI",
    "SIM_COLOUR",
    "FRESNEL_COLOUR",
    "Z_LIMIT",
    "model_style",
    "model_colour",
    "chart_styles",
    "figure_size",
]

DPI = 100
SIM_COLOUR = "#c2185b"  # magenta: simulation points everywhere (no model uses it)
FRESNEL_COLOUR = "#000000"
Z_LIMIT = 10.0  # z-score colour range ±Z_LIMIT (beyond saturates); ±5 marked

# Styles of the model names the runner uses (``catalogue.REPORT_MODELS``): a line style per
# family — solid the closed forms with the ensemble NDF, dashed Beckmann at the nominal m,
# dotted Beckmann at the realised m, dash-dot the fitted models, dotted the wave-optics and
# multiple-scattering models — and a colour per model. A chart never draws two models in one
# colour (``chart_styles``); names not listed get a stable colour from _PALETTE by CRC-32.
_PALETTE = (
    "#e6550d",
    "#843c39",
    "#5254a3",
    "#31a354",
    "#6b6ecf",
    "#e7ba52",
    "#3182bd",
    "#756bb1",
    "#636363",
    "#8ca252",
    "#ad494a",
    "#7b4173",
    "#17becf",
    "#bcbd22",
    "#393b79",
    "#637939",
)
_STYLES = {
    "ts-vgroove": ("#1f77b4", "-"),
    "ts-smith": ("#ff7f0e", "-"),
    "ts-smith-corr": ("#2ca02c", "-"),
    "ts-smith-correlated": ("#2ca02c", "-"),
    "ts-none": ("#7f7f7f", "-"),
    "ts-facets": ("#17becf", "-"),
    "ts-vgroove-oriented": ("#1f77b4", "--"),
    "facets": ("#17becf", "-"),
    "ts-beckmann-nominal-vgroove": ("#1f77b4", "--"),
    "ts-beckmann-nominal-smith": ("#ff7f0e", "--"),
    "ts-beckmann-nominal-smith-corr": ("#2ca02c", "--"),
    "ts-beckmann-realised-vgroove": ("#5254a3", ":"),
    "ts-beckmann-realised-smith": ("#e6550d", ":"),
    "ts-beckmann-realised-smith-corr": ("#8ca252", ":"),
    "ts-beckmann-nominal-smith-corr-geomean": ("#d62728", "--"),
    "ts-ggx-nominal-vgroove": ("#1f77b4", "--"),
    "ts-ggx-nominal-smith": ("#ff7f0e", "--"),
    "ts-ggx-nominal-smith-corr": ("#2ca02c", "--"),
    "ts-student-t-nominal-vgroove": ("#1f77b4", "--"),
    "ts-student-t-nominal-smith": ("#ff7f0e", "--"),
    "ts-student-t-nominal-smith-corr": ("#2ca02c", "--"),
    "mirror-fresnel": ("#1f77b4", "-"),
    "cook-torrance": ("#8c564b", "-."),
    "low-microfacet": ("#9467bd", "-."),
    "low-smooth": ("#bcbd22", "-."),
    "edwards": ("#393b79", "-."),
    "edwards-fit": ("#393b79", "-."),
    "rayleigh-rice": ("#7b4173", ":"),
    "kirchhoff-first-order": ("#636363", ":"),
    "walk-2": ("#31a354", ":"),
    "walk-2+": ("#756bb1", ":"),
    "random-walk": ("#3182bd", ":"),
    "kulla-conty": ("#e7ba52", "--"),
    "mikkelsen-eq28": ("#843c39", "-."),
    "mikkelsen-mix": ("#637939", "-."),
    "stratified": ("#1f77b4", "-"),
    "independent": ("#ff7f0e", "-"),
    # Mikkelsen Fig. 6 draws κ=1024 in red: too close to SIM_COLOUR
    "κ=17": ("#2ca02c", "-"),
    "κ=1024": ("#1f77b4", "-"),
}


def _key(name: str) -> str:
    return "-".join(str(name).strip().lower().replace("_", "-").split())


def model_style(name: str) -> tuple[str, str]:
    """(hex colour, matplotlib line style) of a model (or estimator variant) ``name``: fixed
    for the report's names (case, spaces and underscores ignored), otherwise a stable colour
    from a CRC-32 of the name, solid."""
    key = _key(name)
    if key in _STYLES:
        return _STYLES[key]
    return _PALETTE[zlib.crc32(key.encode("utf-8")) % len(_PALETTE)], "-"


def model_colour(name: str) -> str:
    """The colour of ``model_style(name)``."""
    return model_style(name)[0]


def chart_styles(names: Iterable[str]) -> dict[str, tuple[str, str]]:
    """``model_style`` of each of ``names``, except that no colour is used twice in the
    chart: a model whose colour is taken gets the first free one of _PALETTE (then grey)."""
    out, used = {}, {SIM_COLOUR}
    for name in names:
        colour, style = model_style(name)
        if colour in used:
            colour = next((c for c in _PALETTE if c not in used), "#7f7f7f")
        used.add(colour)
        out[name] = (colour, style)
    return out


# --- writing ---------------------------------------------------------------------------------
def figure_size(chart: str, n: int = 1) -> tuple[float, float]:
    """(width, height) in inches of ``chart``; the PNG is that × ``DPI`` pixels. ``n``: panels
    for "inplane" (incidences), materials for "mikkelsen_fig6", text lines of estimator notes
    for "stability"; ignored otherwise."""
    if chart == "inplane":
        rows, cols = _grid(n)
        return 4.6 * cols + 3.0, 5.0 * rows + 0.6  # + a legend column; ratio panels below
    if chart == "mikkelsen_fig6":
        return 5.2 * n + 0.4, 4.6
    if chart == "stability":
        return 9.0, 5.6 + 0.18 * n
    fixed = {"hemisphere_maps": (13.0, 8.6), "energy": (11.0, 4.6), "speed_accuracy": (7.0, 5.0)}
    if chart not in fixed:
        raise UsageError(
            f"chart must be one of inplane, mikkelsen_fig6, stability, "
            f"{', '.join(fixed)}; got {chart!r}"
        )
    return fixed[chart]


def _figure(size: tuple[float, float]) -> Figure:
    fig = Figure(figsize=size, dpi=DPI, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _output(fig: Figure, path) -> Figure:
    """Write ``fig`` as PNG to ``path`` atomically (unless ``path`` is None); return ``fig``."""
    if path is not None:
        with atomic_open(os.fspath(path), "wb") as fh:
            fig.savefig(fh, format="png", dpi=DPI)
    return fig


def _given_axes(ax, n: int, chart: str, what: str) -> list | None:
    """The caller's ``ax`` as a list of ``n`` Axes (None: the chart makes its own figure)."""
    if ax is None:
        return None
    axes = [ax] if isinstance(ax, Axes) else list(np.ravel(np.asarray(ax, dtype=object)))
    if len(axes) != n or not all(isinstance(a, Axes) for a in axes):
        raise UsageError(f"{chart}: ax must be {n} matplotlib Axes ({what}), got {ax!r}")
    return axes


def _title(prefix: str, text: str) -> str:
    return f"{prefix} — {text}" if prefix else text


def _grid(n: int) -> tuple[int, int]:
    """(rows, cols) for ``n`` panels: one row up to 3, 2×2 for 4, then rows of 3."""
    cols = n if n <= 3 else (2 if n == 4 else 3)
    return math.ceil(n / cols), cols


def _positive(a) -> np.ndarray:
    """Float copy with non-positive / non-finite values set to NaN (for log axes)."""
    a = np.array(a, dtype=np.float64)
    a[~(np.isfinite(a) & (a > 0))] = np.nan
    return a


def _log_limits(values: Iterable[np.ndarray], floor_ratio: float) -> tuple[float, float]:
    """(lo, hi) of a log axis covering the positive values, reaching down to at most
    ``floor_ratio`` × the maximum (far-tail model values would otherwise squash the plot)."""
    pos = np.concatenate([np.ravel(_positive(v)) for v in values])
    pos = pos[np.isfinite(pos)]
    if pos.size == 0:
        return 1e-3, 1.0
    hi = pos.max()
    lo = max(pos.min(), hi * floor_ratio)
    return lo / 2.0, hi * 2.0
