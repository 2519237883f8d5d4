"""Markdown tables for the reports and the index."""

from __future__ import annotations

from typing import Iterable, Sequence

__all__ = ["md_table"]


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
