"""Argument validation shared by the analytic models.

Every check raises ``ValueError`` naming the parameter and the allowed range, so that a
researcher who passes a bad value learns what to pass instead.
"""
from __future__ import annotations

from microsim.errors import UsageError
import numpy as np

UNIT_TOL = 1e-6  # allowed | |w| - 1 | for a direction called "unit"


def positive(name: str, value, *, allow_inf: bool = False) -> float:
    """Return ``value`` as float, or raise if it is not a finite number > 0."""
    v = float(value)
    if not (v > 0) or (np.isinf(v) and not allow_inf) or np.isnan(v):
        raise UsageError(f"{name} must be a finite number > 0, got {value!r}")
    return v


def in_range(name: str, value, lo: float, hi: float, *, lo_open=False, hi_open=False) -> float:
    """Return ``value`` as float, or raise if it lies outside [lo, hi] (open ends as flagged)."""
    v = float(value)
    ok = (v > lo if lo_open else v >= lo) and (v < hi if hi_open else v <= hi)
    if not ok or np.isnan(v):
        lb, rb = ("(" if lo_open else "["), (")" if hi_open else "]")
        raise UsageError(f"{name} must lie in {lb}{lo}, {hi}{rb}, got {value!r}")
    return v


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
        raise UsageError(f"{name} must be unit vectors (| |w| - 1 | <= {UNIT_TOL}), "
                         f"got norms in [{norm.min():.6g}, {norm.max():.6g}]")
    if upper and np.any(a[..., 2] < -UNIT_TOL):
        raise UsageError(f"{name} must lie in the upper hemisphere (z >= 0), "
                         f"got z down to {a[..., 2].min():.6g}")
    return a


def dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Broadcast dot product over the last axis."""
    return np.sum(np.asarray(a) * np.asarray(b), axis=-1)


def normalize(v: np.ndarray) -> np.ndarray:
    """Unit vectors along ``v`` (last axis); zero vectors stay zero."""
    v = np.asarray(v, dtype=np.float64)
    n = np.sqrt(np.sum(v * v, axis=-1, keepdims=True))
    return np.divide(v, n, out=np.zeros_like(v), where=n > 0)


def half_vector(wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """Unit half vector h = (wi + wo)/|wi + wo| (Mikkelsen eq. 11)."""
    return normalize(np.asarray(wi, dtype=np.float64) + np.asarray(wo, dtype=np.float64))


def spherical(theta, phi) -> np.ndarray:
    """Unit vectors from polar angle θ and azimuth φ in radians, shape broadcast(θ, φ) + (3,)."""
    theta, phi = np.broadcast_arrays(np.asarray(theta, float), np.asarray(phi, float))
    s = np.sin(theta)
    return np.stack([s * np.cos(phi), s * np.sin(phi), np.cos(theta)], axis=-1)


def spherical_deg(theta_deg, phi_deg) -> np.ndarray:
    """`spherical` with angles in degrees (the public-interface unit)."""
    return spherical(np.radians(theta_deg), np.radians(phi_deg))
