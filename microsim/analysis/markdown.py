"""Markdown tables and the numbers in them, for the reports and the index."""

from __future__ import annotations

import math
from typing import Iterable, Sequence

import numpy as np

__all__ = ["md_table", "plain", "percent", "PERCENT_FLOOR"]

PERCENT_FLOOR = 1e-4
"""Percentages smaller than this in magnitude (but not 0) are printed "< 0.0001%"."""


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


def _positional(x: float, digits: int) -> str:
    return np.format_float_positional(x, precision=digits, unique=False, fractional=False, trim="-")


def plain(x: float, digits: int = 3) -> str:
    """``digits`` significant figures in positional notation: "-1080", "0.011", "24"; below
    1e-4 or from 1e7 on in magnitude, "1.2e-05" style (too many zeros). Not for percentages:
    ``percent`` never writes an exponent."""
    x = float(x)
    if x != 0 and not 1e-4 <= abs(x) < 1e7:
        return f"{x:.{digits}g}"
    return _positional(x, digits)


def percent(fraction, digits: int = 2, *, signed: bool = False, unit: str = "%") -> str:
    """The one way every report, index, chart and command writes a percentage: ``fraction``
    × 100 to ``digits`` significant figures in plain decimals, never an exponent ("100%",
    "140%", "0.012%", "-5400%"), then ``unit`` as given ("%", " %" or " pp" for percentage
    points). ``signed``: "+" before a positive value. None or not finite: "–"; a magnitude
    below ``PERCENT_FLOOR`` percent (not 0): "< 0.0001" and the unit."""
    if fraction is None or not math.isfinite(float(fraction)):
        return "–"
    v = 100.0 * float(fraction) + 0.0  # + 0.0: no "-0"
    if v != 0 and abs(v) < PERCENT_FLOOR:
        return f"< {_positional(PERCENT_FLOOR, 1)}{unit}"
    return f"{'+' if signed and v > 0 else ''}{_positional(v, digits)}{unit}"
