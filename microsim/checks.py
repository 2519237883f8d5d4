"""Argument validation shared by every layer (the analytic models, surfaces, simulation and app).

Every check raises ``UsageError`` (a ``ValueError``) with a one-line message naming the
parameter and the allowed range, so that a researcher who passes a bad value learns what to
pass instead. ``check_memory`` refuses, before allocating, an object that would need more than
``memory_limit()`` (``MEMORY_FRACTION`` of the physical memory).
"""

from __future__ import annotations

import numbers
import os
from pathlib import Path

import numpy as np

from microsim.errors import UsageError

UNIT_TOL = 1e-6  # allowed | |w| - 1 | for a direction called "unit"

MEMORY_FRACTION = 0.5
"""Share of the physical memory one object (a mesh, a bin grid, a heightfield) may need."""


def memory_limit() -> int:
    """Bytes one microsim object may take: ``MEMORY_FRACTION`` of the physical memory
    (``os.sysconf``; 8 GiB assumed where the platform does not say). The rest is left to
    the Python process, its other objects and the system; a request above it would swap or be
    killed, so it is refused up front (``check_memory``)."""
    try:
        phys = os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        phys = 8 << 30
    return int(MEMORY_FRACTION * phys)


def short(value, width: int = 80) -> str:
    """One-line ``repr`` of ``value`` for a message, cut to ``width`` characters."""
    text = " ".join(repr(value).split())
    return text if len(text) <= width else text[: width - 1] + "…"


def gigabytes(n: float) -> str:
    """``n`` bytes as a short text in GB (10⁹ bytes)."""
    return f"{n / 1e9:.3g} GB"


def check_memory(name: str, need: float, what: str) -> None:
    """Raise a UsageError naming ``name`` if ``need`` bytes (``what`` needs them) exceed
    ``memory_limit()``. Called before the allocation."""
    limit = memory_limit()
    if need > limit:
        raise UsageError(
            f"{name}: {what} would need about {gigabytes(need)} of memory, above "
            f"the limit of {gigabytes(limit)} ({MEMORY_FRACTION:.0%} of this "
            f"machine's physical memory)"
        )


PATH_RULE = "a file path (non-empty text without NUL characters)"
"""What ``file_path`` accepts, for messages."""


def is_file_path(value) -> bool:
    """Whether ``value`` can name a file: text or ``os.PathLike``, not empty, and without the
    NUL character no file system path can hold."""
    if not isinstance(value, (str, os.PathLike)):
        return False
    text = os.fspath(value)
    return isinstance(text, str) and text != "" and "\x00" not in text


def file_path(name: str, value) -> Path:
    """``value`` as a ``Path``, or a UsageError naming ``name`` unless ``is_file_path``."""
    if not is_file_path(value):
        shown = os.fspath(value) if isinstance(value, os.PathLike) else value
        raise UsageError(f"{name} must be {PATH_RULE}, got {short(shown)}")
    return Path(value)


def integer(name: str, value, lo: int = 1, hi: int | None = None, why: str = "") -> int:
    """Return ``value`` as int, or raise unless it is an integer (int, NumPy integer, or an
    integral float) in [lo, hi]. Strings, bools, NaN and None are refused."""
    ok = (
        not isinstance(value, (bool, np.bool_))
        and isinstance(value, numbers.Real)
        and np.isfinite(float(value))
        and float(value).is_integer()
    )
    rng = f">= {lo}" if hi is None else f"in [{lo}, {hi:,}]"
    if not ok or not lo <= int(value) or (hi is not None and int(value) > hi):
        raise UsageError(f"{name} must be an integer {rng}{why}, got {short(value)}")
    return int(value)


def _real(name: str, value, what: str) -> float:
    """``value`` as float; text, bools, None and non-numbers are refused naming ``name``."""
    if isinstance(value, (bool, np.bool_, str, bytes)) or value is None:
        raise UsageError(f"{name} must be {what}, got {short(value)}")
    try:
        return float(value)
    except (TypeError, ValueError):
        raise UsageError(f"{name} must be {what}, got {short(value)}") from None


def finite(name: str, value) -> float:
    """Return ``value`` as float, or raise if it is not a finite number."""
    v = _real(name, value, "a finite number")
    if not np.isfinite(v):
        raise UsageError(f"{name} must be a finite number, got {value!r}")
    return v


def positive(name: str, value, *, allow_inf: bool = False) -> float:
    """Return ``value`` as float, or raise if it is not a finite number > 0."""
    v = _real(name, value, "a finite number > 0")
    if not (v > 0) or (np.isinf(v) and not allow_inf) or np.isnan(v):
        raise UsageError(f"{name} must be a finite number > 0, got {value!r}")
    return v


def in_range(name: str, value, lo: float, hi: float, *, lo_open=False, hi_open=False) -> float:
    """Return ``value`` as float, or raise if it lies outside [lo, hi] (open ends as flagged)."""
    v = _real(name, value, f"a number in [{lo}, {hi}]")
    ok = (v > lo if lo_open else v >= lo) and (v < hi if hi_open else v <= hi)
    if not ok or np.isnan(v):
        lb, rb = ("(" if lo_open else "["), (")" if hi_open else "]")
        raise UsageError(f"{name} must lie in {lb}{lo}, {hi}{rb}, got {value!r}")
    return v


def broadcast(directions: dict, values: dict | None = None) -> tuple:
    """The common leading shape of the ``directions`` (name → array (..., 3)) and the
    ``values`` (name → array of one number per direction); a UsageError naming every argument
    and its shape if they do not broadcast together (instead of NumPy's message later)."""
    values = values or {}
    try:
        return np.broadcast_shapes(
            *(np.shape(a)[:-1] for a in directions.values()),
            *(np.shape(v) for v in values.values()),
        )
    except ValueError:
        arrays = {**directions, **values}
        *first, last = arrays
        shapes = ", ".join(f"{k} {np.shape(a)}" for k, a in arrays.items())
        raise UsageError(
            f"{', '.join(first)} and {last} must have shapes that broadcast together, got {shapes}"
        ) from None


def directions(name: str, w, *, upper: bool = False) -> np.ndarray:
    """Return ``w`` as a float64 array of shape (..., 3) of unit vectors.

    Raises if the last axis is not 3, if any vector is not unit length within ``UNIT_TOL``,
    or (``upper=True``) if any vector points below the horizon (z < 0).
    """
    a = np.asarray(w, dtype=np.float64)
    if a.ndim == 0 or a.shape[-1] != 3:
        raise UsageError(f"{name} must be an array of shape (..., 3), got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise UsageError(f"{name} must be finite unit vectors; got NaN or inf")
    norm = np.sqrt(np.einsum("...i,...i->...", a, a))
    if np.any(np.abs(norm - 1.0) > UNIT_TOL):
        raise UsageError(
            f"{name} must be unit vectors (| |w| - 1 | <= {UNIT_TOL}), "
            f"got norms in [{norm.min():.6g}, {norm.max():.6g}]"
        )
    if upper and np.any(a[..., 2] < -UNIT_TOL):
        raise UsageError(
            f"{name} must lie in the upper hemisphere (z >= 0), got z down to {a[..., 2].min():.6g}"
        )
    return a
