"""The cells of the markdown reports: numbers, percentages, angle ranges, parameters and the
bounds a fit ended on, written the same way in the scene report and the index."""

from __future__ import annotations

import math
from typing import Mapping, Sequence

import numpy as np

from .markdown import percent, plain
from .study_records import Fit, FitBound

__all__ = [
    "fmt",
    "pct",
    "signed_pct",
    "VERDICT_SYMBOLS",
    "verdict_cell",
    "ranges_text",
    "params_text",
    "bounds_text",
    "bounds_brief",
    "converged_text",
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


def pct(x) -> str:
    """A table's percentage column: 3 significant figures, "12.3%"."""
    return percent(x, 3)


def ranges_text(dev) -> str:
    return ", ".join(f"{a:g}–{b:g}°" for a, b in dev) if dev else "–"


def params_text(p: Mapping) -> str:
    return ", ".join(f"{k} = {fmt(v, 4)}" for k, v in p.items()) if p else "–"


def signed_pct(x, se=None) -> str:
    """A signed deviation, 3 significant figures, ± its standard error when given."""
    text = percent(x, 3, signed=True, unit=" %")
    return text if se is None or text == "–" else f"{text} ± {percent(se, unit=' %')}"


VERDICT_SYMBOLS = {"agrees": "✓", "deviates": "✗", "inconclusive": "?"}
"""The symbol of each verdict kind (``Verdict.kind``) in the reports' tables."""


def verdict_cell(kind: str, energy_dev, energy_dev_se, rel_rms) -> str:
    """A model against the simulation in one cell: the verdict kind's symbol, the energy
    deviation ± its standard error and the relative RMS error ("–" without an RMS error)."""
    if rel_rms is None:
        return "–"
    return (
        f"{VERDICT_SYMBOLS[kind]} {signed_pct(energy_dev, energy_dev_se)}, "
        f"rel RMS {percent(rel_rms, unit=' %')}"
    )


def _bound(b: FitBound) -> str:
    return f"{b.param} = {fmt(b.bound, 4)}"


def bounds_text(at_bounds: Sequence[FitBound]) -> str:
    """The bounds a fit ended on (``fits.BoundReached`` records), search limits first:
    "stopped at the search limit C = 10: the best fit may lie beyond; kd = 0, on its physical
    bound kd ≥ 0"; "" for none."""
    limits = [_bound(b) for b in at_bounds if not b.physical]
    parts = []
    if limits:
        plural = "s" if len(limits) > 1 else ""
        parts.append(
            f"stopped at the search limit{plural} {', '.join(limits)}: the best fit may lie beyond"
        )
    parts += [
        f"{_bound(b)}, on its physical bound {b.param} "
        f"{'≥' if b.side == 'lower' else '≤'} {fmt(b.bound, 4)}"
        for b in at_bounds
        if b.physical
    ]
    return "; ".join(parts)


def bounds_brief(at_bounds: Sequence[FitBound]) -> str:
    """``bounds_text`` for an index cell: "search limit: C = 10; physical bound: kd = 0"."""
    parts = []
    for physical, name in ((False, "search limit"), (True, "physical bound")):
        mine = [_bound(b) for b in at_bounds if b.physical == physical]
        parts += [f"{name}{'s' if len(mine) > 1 else ''}: {', '.join(mine)}"] if mine else []
    return "; ".join(parts)


def converged_text(fit: Fit | Mapping) -> str:
    """The fits table's "converged" cell of ``fit`` (a ``Fit`` or its JSON object): yes or
    no (the optimiser's evaluation limit or a search limit reached), with the bounds the fit
    ended on."""
    fit = Fit.from_json(fit)
    why = [] if fit.success else ["the optimiser stopped at its evaluation limit"]
    why += [bounds_text(fit.at_bounds)] if fit.at_bounds else []
    return fmt(fit.converged) + (f": {'; '.join(why)}" if why else "")
