"""How far an RGL ".bsdf" file is from the BRDF it was written from (``interpolation_error``).

Interpolation error: the file reproduces f at its nodes; between them the error is that of
linear interpolation (second order in the node spacings of s, θi and the NDF's u_θ) plus a
first-order kink where wo crosses the horizon. ``interpolation_error`` measures the
energy-weighted relative RMS error against the exported function (see there); for
``TorranceSparrow(GGX(0.3), Smith(correlated=True), "aluminium")`` at ``DEFAULT_RESOLUTION``
``pytest tests/test_rgl.py -k falls -s`` prints it (docs/python.md gives the figure).
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from microsim import checks as _checks
from microsim.vectors import spherical

from .rgl_warp import Table2D, elevation, phi2u, theta2u, u2phi, u2theta

__all__ = ["interpolation_error"]


def interpolation_error(rgl, brdf: Callable, n: int = 1 << 16, seed: int = 0) -> dict:
    """Energy-weighted relative RMS error of ``rgl.evaluate`` against ``brdf`` (sr⁻¹), the
    relative L2 error of the energy-transfer kernel f cos θi cos θo (what a renderer
    integrates; the readers return f cos θo):

        ε² = ∫∫ (f̂ − f)² cos²θi cos²θo dωi dωo / ∫∫ f² cos²θi cos²θo dωi dωo

    over the upper hemispheres, estimated with ``n`` pairs whose wi is cosine-distributed and
    whose wo is drawn half and half from the cosine density and from the file's own sampling
    density (luminance, then the VNDF warp, as Mitsuba samples: the estimator follows the
    lobe). Returns {"rel_rms", "stderr" (of rel_rms, delta method over the pairs), "n"}."""
    n = _checks.integer("n", n, 16)
    rng = np.random.default_rng(seed)
    wi = _cosine(rng.random(n), rng.random(n))
    wo_cos = _cosine(rng.random(n), rng.random(n))
    wo_lobe, _ = _sample_file(rgl, wi, rng.random((n, 2)))
    pick = rng.random(n) < 0.5
    wo = np.where(pick[:, None], wo_cos, wo_lobe)
    up = wo[:, 2] > 0
    wo = np.where(up[:, None], wo, (0.0, 0.0, 1.0))
    dens = 0.5 * wo[:, 2] / np.pi + 0.5 * _file_pdf(rgl, wi, wo)
    # cos²θi / (cos θi/π) ∝ cos θi for wi, cos²θo / p(wo) for wo
    w = np.where(up, wi[:, 2] * wo[:, 2] ** 2 / np.maximum(dens, 1e-300), 0.0)
    f = np.asarray(brdf(wi, wo), dtype=np.float64).reshape(n)
    g = np.asarray(rgl.f(wi, wo), dtype=np.float64)
    a, b = w * (g - f) ** 2, w * f**2
    A, B = a.mean(), b.mean()
    rel = np.sqrt(A / B)
    cov = np.cov(np.stack([a, b]))  # delta method for √(A/B)
    var = (cov[0, 0] / B**2 - 2 * A * cov[0, 1] / B**3 + A**2 * cov[1, 1] / B**4) / n
    return {"rel_rms": float(rel), "stderr": float(np.sqrt(max(var, 0.0)) / (2 * rel)), "n": n}


def _cosine(u1, u2) -> np.ndarray:
    r, phi = np.sqrt(u1), 2.0 * np.pi * u2
    return np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(np.maximum(1 - u1, 0.0))], -1)


def _lum_table(rgl) -> Table2D:
    tab = getattr(rgl, "_lum", None)
    if tab is None:
        f = rgl.fields
        tab = Table2D(f["luminance"], (f["phi_i"], f["theta_i"]), warp=True)
        object.__setattr__(rgl, "_lum", tab)
    return tab


def _sample_file(rgl, wi, u) -> tuple[np.ndarray, np.ndarray]:
    """wo drawn as the readers sample (luminance, then the VNDF warp), and the half vector."""
    theta_i, phi_i = elevation(wi), np.arctan2(wi[:, 1], wi[:, 0])
    params = (phi_i, theta_i)
    s, _ = _lum_table(rgl).sample(u, params)
    u_m, _ = rgl._vndf.sample(s, params)
    m = spherical(u2theta(u_m[:, 0]), u2phi(u_m[:, 1]) + phi_i)
    wo = 2.0 * np.einsum("ij,ij->i", wi, m)[:, None] * m - wi
    return wo / np.linalg.norm(wo, axis=-1, keepdims=True), m


def _file_pdf(rgl, wi, wo) -> np.ndarray:
    """The readers' sampling density of wo (sr⁻¹): vndf · luminance / Jacobian."""
    s = wi + wo
    m = s / np.linalg.norm(s, axis=-1, keepdims=True)
    theta_i, phi_i = elevation(wi), np.arctan2(wi[:, 1], wi[:, 0])
    theta_m, phi_m = elevation(m), np.arctan2(m[:, 1], m[:, 0])
    uy = phi2u(phi_m - phi_i)
    u_m = np.stack([theta2u(theta_m), uy - np.floor(uy)], -1)
    params = (phi_i, theta_i)
    sample, vndf_pdf = rgl._vndf.invert(u_m, params)
    lum_pdf = _lum_table(rgl).eval(sample, params)
    jac = (
        np.maximum(2 * np.pi**2 * u_m[:, 0] * np.sin(theta_m), 1e-6)
        * 4
        * np.einsum("ij,ij->i", wi, m)
    )
    return np.where((wi[:, 2] > 0) & (wo[:, 2] > 0), vndf_pdf * lum_pdf / jac, 0.0)
