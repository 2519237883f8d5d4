"""Compact HTML for notebooks: the ``_repr_html_`` of results, verdict lists and fits.

Jupyter shows an object through its ``_repr_html_`` method when it has one; these helpers
build the small tables those methods return (cells escaped, numbers as given).
"""

from __future__ import annotations

import html
from typing import Iterable, Sequence

__all__ = ["html_table"]


def html_table(header: Sequence[str], rows: Iterable[Sequence], caption: str | None = None) -> str:
    """An HTML table of ``rows`` under ``header`` (every cell ``str``-ed and escaped), with an
    optional ``caption``."""
    cell = lambda tag, x: f"<{tag}>{html.escape(str(x))}</{tag}>"  # noqa: E731
    out = ["<table>"]
    if caption:
        out.append(f"<caption style='text-align:left'>{html.escape(caption)}</caption>")
    out.append("<tr>" + "".join(cell("th", h) for h in header) + "</tr>")
    out += ["<tr>" + "".join(cell("td", c) for c in row) + "</tr>" for row in rows]
    out.append("</table>")
    return "".join(out)
