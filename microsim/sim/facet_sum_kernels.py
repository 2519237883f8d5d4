"""Compiled loops of the facet sum behind ``predict.bin_average_facets``
(Torrance–Sparrow with a surface's own facets as D): the reflection terms of the (facet,
azimuth) pairs for a G that depends on the pair's cosines alone (V-groove or none), and the
per-(facet, bin) accumulation of the sum and its variance for any G.

The pairs are those of ``predict._facet_sum``: facet k's copy j is its normal rotated about z
by ψ_kj = 2π(j + u_k)/J (``cos_sin``: the same bits on every machine), or the normal itself
when J = 1. A V-groove surface's sum runs over ~2·10⁶ such pairs per incidence
(``compare.VGROOVE_PAIRS``): NumPy passes over them cost ~0.6 µs a pair, these loops a
tenth of that."""

from __future__ import annotations

import math

from microsim.analytic.masking import vgroove_g1_cosines
from microsim.bin_kernels import _bin_of
from microsim.jit import compiled
from microsim.trig import cos_sin

from .fresnel_kernels import fresnel_weight

G_VGROOVE, G_NONE = 0, 1
"""``local_terms``'s G: V-groove (Mikkelsen 2009, eq. 25) or none (χ⁺ conditions only)."""


@compiled
def local_terms(normals, u, copies, wi, material, g_mode, bins, x, idx):
    """For pair p = k·``copies`` + j of the facets ``normals`` (K, 3) with azimuth offsets
    ``u`` (K,) (unused when ``copies`` = 1): its half vector h (the normal rotated by ψ_kj),
    wo = 2(wi·h)h − wi normalised, and
        x[p] = F(wi·h) G(wi, wo, h) (wi·h)/(cos θi h_z)  (0 unless wi·h, h_z, wo_z > 0),
        idx[p] = wo's flat bin (−1 below the horizon; ``bin_kernels._bin_of``).
    ``wi``: unit incidence (3,); ``material``: (n², k², ``fresnel_kernels`` mode) of F;
    ``g_mode``: ``G_VGROOVE`` or ``G_NONE``; ``bins``: (φi degrees, n_θ, n_φ, folded,
    φ edges) as ``bin_kernels.bin_index`` takes them."""
    wix, wiy, wiz = wi[0], wi[1], wi[2]
    n2, k2, fresnel_mode = material
    phi_i, n_theta, n_phi, folded, edges = bins
    for k in range(normals.shape[0]):
        nx, ny, nz = normals[k, 0], normals[k, 1], normals[k, 2]
        for j in range(copies):
            p = k * copies + j
            hx, hy = nx, ny
            if copies > 1:
                c, s = cos_sin(2.0 * math.pi * (j + u[k]) / copies)
                hx = c * nx - s * ny
                hy = s * nx + c * ny
            wih = hx * wix + hy * wiy + nz * wiz
            ox = 2.0 * wih * hx - wix
            oy = 2.0 * wih * hy - wiy
            oz = 2.0 * wih * nz - wiz
            r = math.sqrt(ox * ox + oy * oy + oz * oz)
            ox, oy, oz = ox / r, oy / r, oz / r
            idx[p] = _bin_of(ox, oy, oz, phi_i, n_theta, n_phi, folded, edges)
            x[p] = 0.0
            if wih > 0.0 and nz > 0.0 and oz > 0.0:
                woh = ox * hx + oy * hy + oz * nz
                if g_mode == G_VGROOVE:
                    g = min(vgroove_g1_cosines(wiz, wih, nz), vgroove_g1_cosines(oz, woh, nz))
                else:
                    g = 1.0 if woh > 0.0 else 0.0
                f = fresnel_weight(min(wih, 1.0), n2, k2, fresnel_mode)
                x[p] = f * g * wih / (wiz * nz)


@compiled
def add_facet_terms(x, idx, copies, a, acc, touched, total, s1, s2):
    """Add the pairs' terms (``local_terms``, or the same from NumPy) of the facets with
    weights ``a`` (K,) to Σ_k a_k X_kB (``total``), Σ_k a_k² X_kB (``s1``) and
    Σ_k (a_k X_kB)² (``s2``), X_kB = Σ_j x_kj/J over facet k's pairs in bin B (idx ≥ 0,
    x > 0), J = ``copies``. ``acc`` (bins,) is zero on entry and on return; ``touched``
    (bins,) is scratch."""
    for k in range(len(a)):
        m = 0
        for j in range(copies):
            p = k * copies + j
            b = idx[p]
            if b >= 0 and x[p] > 0.0:
                if acc[b] == 0.0:
                    touched[m] = b
                    m += 1
                acc[b] += x[p] / copies
        ak = a[k]
        for t in range(m):
            b = touched[t]
            xk = acc[b]
            acc[b] = 0.0
            total[b] += ak * xk
            s1[b] += ak * ak * xk
            s2[b] += (ak * xk) ** 2
