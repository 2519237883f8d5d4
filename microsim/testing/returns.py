"""What a user's callable (BRDF, sampler, pdf) returned, as a real float64 array.

NumPy would turn complex values into their real part (with a warning only) and text or a
ragged list into a bare ``ValueError``; ``real_values`` refuses each with a one-line
``UsageError`` saying what the callable must return and what it returned instead.
"""

from __future__ import annotations

import numpy as np

from microsim.errors import UsageError

__all__ = ["real_values"]


def real_values(value, requirement: str, shape: str) -> np.ndarray:
    """``value`` as a float64 array; UsageError ``"<requirement> real numbers (float64) of
    shape <shape>, got …"`` unless it holds integers or floats (complex numbers, booleans,
    text and other objects are refused). ``requirement`` names the callable, e.g.
    ``"brdf(wi, wo) must return"``; the caller checks the shape."""
    try:
        a = np.asarray(value)
    except (TypeError, ValueError):
        got = f"a ragged {type(value).__name__} that is not an array"
    else:
        if a.dtype.kind in "iuf":
            return a.astype(np.float64, copy=False)
        got = f"dtype {a.dtype}"
    raise UsageError(f"{requirement} real numbers (float64) of shape {shape}, got {got}")
