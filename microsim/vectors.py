"""Direction vectors in the local frame (macro normal +z, unit vectors pointing away from the
surface; docs/design.md, "Conventions"): dot products, normalisation, half vectors and
directions from spherical angles (radians, or degrees in ``spherical_deg``).
"""

from __future__ import annotations

import numpy as np

__all__ = ["dot", "normalize", "half_vector", "refract", "spherical", "spherical_deg"]


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


def refract(w: np.ndarray, m: np.ndarray, eta, cos_w=None) -> tuple[np.ndarray, np.ndarray]:
    """Snell's law in vector form: the refracted direction t (pointing away from the facet,
    on the other side) of the direction ``w`` (pointing away from the facet, w·m > 0) through
    facets of unit normal ``m`` with relative index ``eta`` = η_t/η_i,
    t = −w/η + (c/η − cos θt) m, c = w·m (``cos_w`` if given), cos θt = √(1 − (1 − c²)/η²);
    and where it exists (False: total internal reflection, t then undefined)."""
    c = dot(w, m) if cos_w is None else cos_w
    eta = np.asarray(eta, dtype=np.float64)
    sin2_t = (1.0 - c * c) / (eta * eta)
    cos_t = np.sqrt(np.maximum(1.0 - sin2_t, 0.0))
    return -w / eta[..., None] + (c / eta - cos_t)[..., None] * m, sin2_t < 1.0


def spherical(theta, phi) -> np.ndarray:
    """Unit vectors from polar angle θ and azimuth φ in radians, shape broadcast(θ, φ) + (3,)."""
    theta, phi = np.broadcast_arrays(np.asarray(theta, float), np.asarray(phi, float))
    s = np.sin(theta)
    return np.stack([s * np.cos(phi), s * np.sin(phi), np.cos(theta)], axis=-1)


def spherical_deg(theta_deg, phi_deg) -> np.ndarray:
    """`spherical` with angles in degrees (the public-interface unit)."""
    return spherical(np.radians(theta_deg), np.radians(phi_deg))
