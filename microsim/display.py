"""How results are shown: compact HTML for notebooks, and text for streams that cannot
encode microsim's symbols.

Jupyter shows an object through its ``_repr_html_`` method when it has one; ``html_table``
builds the small tables those methods return (cells escaped, numbers as given).

The command line writes verdict marks, Greek letters and units (✓, ✗, θ, ±, °, sr⁻¹, …). A
stream whose encoding lacks them (``LC_ALL=C`` without UTF-8 mode: ASCII; or
``PYTHONIOENCODING=latin-1``) would raise ``UnicodeEncodeError`` part-way through a command;
``ascii_fallback`` gives such a stream the ``"microsim-ascii"`` error handler instead, which
writes each character it cannot encode as ASCII (``ASCII_SYMBOLS``, Greek letters by name,
accents dropped, superscripts after ``^``) — the one place that decides, for every line the
CLI prints.
"""

from __future__ import annotations

import codecs
import html
import unicodedata
from typing import Iterable, Sequence

__all__ = ["html_table", "ascii_fallback", "ascii_text", "ASCII_SYMBOLS", "ERRORS"]

ASCII_SYMBOLS = {
    "✓": "ok",
    "✗": "x",
    "±": "+/-",
    "°": " deg",
    "…": "...",
    "—": "-",
    "–": "-",
    "−": "-",
    "≤": "<=",
    "≥": ">=",
    "×": "x",
    "·": "*",
    "→": "->",
    "√": "sqrt",
    "≈": "~",
    "∈": "in",
    "⊂": "in",
    "∪": "U",
    "∞": "inf",
    "⌈": "ceil(",
    "⌉": ")",
    "§": "S",
    "ℓ": "l",
    "λ": "lambda",
    "µ": "u",
}
"""ASCII for the symbols microsim prints (``ascii_text``)."""

ERRORS = "microsim-ascii"
"""The codec error handler ``ascii_fallback`` sets (``codecs.register_error``)."""

_SAMPLE = "✓✗θ±°…"


def ascii_text(text: str) -> str:
    """``text`` in ASCII: ``ASCII_SYMBOLS``, Greek letters by name (θ → theta, Δ → Delta),
    accents dropped, superscripts after one ``^`` (sr⁻¹ → sr^-1), anything else ``?``."""
    out, superscript = [], False
    for ch in text:
        name = unicodedata.name(ch, "")
        was, superscript = superscript, name.startswith("SUPERSCRIPT")
        if ch.isascii():
            out.append(ch)
        elif ch in ASCII_SYMBOLS:
            out.append(ASCII_SYMBOLS[ch])
        elif name.startswith("GREEK") and " LETTER " in name:
            word = name.rsplit(" ", 1)[-1].lower()
            out.append(word.capitalize() if " CAPITAL " in name else word)
        else:
            plain = unicodedata.normalize("NFKD", ch)
            plain = "".join(ASCII_SYMBOLS.get(c, c) for c in plain if not unicodedata.combining(c))
            plain = plain if plain.isascii() else "?"
            out.append(("^" if superscript and not was else "") + plain)
    return "".join(out)


def _ascii_errors(exc: UnicodeError):
    if not isinstance(exc, UnicodeEncodeError):
        raise exc
    return ascii_text(exc.object[exc.start : exc.end]), exc.end


codecs.register_error(ERRORS, _ascii_errors)


def ascii_fallback(*streams) -> None:
    """Give each of ``streams`` (text streams such as ``sys.stdout``) whose encoding cannot
    write microsim's symbols the ``ERRORS`` handler: what it cannot encode is written as
    ``ascii_text``. Streams that can, and those that cannot be reconfigured (a test's
    capture), are left as they are."""
    for stream in streams:
        encoding = getattr(stream, "encoding", None) or "ascii"
        try:
            _SAMPLE.encode(encoding)
            continue
        except UnicodeEncodeError:
            pass
        except LookupError:  # an encoding Python does not know: leave the stream alone
            continue
        try:
            stream.reconfigure(errors=ERRORS)
        except (AttributeError, ValueError, OSError):
            pass


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
