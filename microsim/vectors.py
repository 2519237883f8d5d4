"""Direction vectors in the local frame (macro normal +z, unit vectors pointing away from the
surface; docs/design.md, "Conventions"): dot products, normalisation, half vectors and
directions from spherical angles (radians, or degrees in ``spherical_deg``).
"""

from __future__ import annotations

import numpy as np

__all__ = ["dot", "normalize", "half_vector", "spherical", "spherical_deg"]


def dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Broadcast dot product over the last axis."""
    return np.sum(np.asarray(a) * np.asarray(b), axis=-1)


def normalize(v: np.ndarray) -> np.ndarray:
    """Unit vectors along ``v`` (last axis); zero vectors stay zero."""
    v = np.asarray(v, dtype=np.float64)
    n = np.sqrt(np.sum(v * v, axis=-1, keepdims=True))
    return np.divide(v, n, out=np.zeros_like(v), where=n > 0)


def half_vector(wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """Unit half vector h = (wi + wo)/|wi + wo| (Mikkelsen 2009, eq. 11)."""
    return normalize(np.asarray(wi, dtype=np.float64) + np.asarray(wo, dtype=np.float64))


def spherical(theta, phi) -> np.ndarray:
    """Unit vectors from polar angle θ and azimuth φ in radians, shape broadcast(θ, φ) + (3,)."""
    theta, phi = np.broadcast_arrays(np.asarray(theta, float), np.asarray(phi, float))
    s = np.sin(theta)
    return np.stack([s * np.cos(phi), s * np.sin(phi), np.cos(theta)], axis=-1)


def spherical_deg(theta_deg, phi_deg) -> np.ndarray:
    """`spherical` with angles in degrees (the public-interface unit)."""
    return spherical(np.radians(theta_deg), np.radians(phi_deg))
