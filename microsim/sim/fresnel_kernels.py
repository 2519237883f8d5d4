"""Fresnel weights F(c), c = n·wi > 0, of the compiled passes (``fresnel_real_scalar`` in
real arithmetic onto η² = n² − k², or 1 for a mirror, 0 for η = 1), and the per-facet
table of one incidence (``facet_mirror``: weight, mirror direction, ledger class).

``COSINE``, a material for the geometry pass of spectral runs (``spectral``): its "weight" is
the cosine c itself, so a single-bounce path traced with it hands back every ray's c, from
which ``fresnel_weights`` gives each material's F(c) — the very values a run of that material
computes."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from microsim.analytic.fresnel import fresnel_real_scalar
from microsim.jit import compiled, vector_inlined, vectorised

from .engine.codes import DOWNWARD, RAY_UNRESOLVED, SINGLE
from .engine.facets import facet_plane

# ``fresnel_weight``'s modes
FRESNEL_REAL, FRESNEL_MIRROR, FRESNEL_NONE, FRESNEL_COSINE = 0, 1, 2, 3


class _Cosine:
    """The type of ``COSINE``: the weight of a hit is its cosine c (``FRESNEL_COSINE``)."""

    def __repr__(self) -> str:
        return "COSINE"


COSINE = _Cosine()
"""Not a material: the weight F(c) = c records each hit's cosine (``spectral``)."""


@vectorised
def fresnel_weights(c, n2, k2, fresnel_mode, weight):
    """weight[i] = F(c[i]) (``fresnel_weight``), 0 where c ≤ 0 (no hit, back-facing), in a
    vectorised loop (``fresnel_tile``)."""
    fresnel_tile(c, len(c), n2, k2, fresnel_mode, weight, 0)


@vector_inlined
def fresnel_weight(c, n2, k2, fresnel_mode):
    """F(c) for c > 0 by ``fresnel_mode``: FRESNEL_REAL ``fresnel_real_scalar`` onto η² with
    n2 = n², k2 = k²; FRESNEL_MIRROR 1; FRESNEL_NONE 0 (η = 1: nothing reflects off grazing);
    FRESNEL_COSINE c itself (``COSINE``)."""
    if fresnel_mode == FRESNEL_REAL:
        return fresnel_real_scalar(c, n2, k2)
    if fresnel_mode == FRESNEL_COSINE:
        return c
    return 1.0 if fresnel_mode == FRESNEL_MIRROR else 0.0


@compiled
def facet_mirror(
    facets, lo, wix, wiy, wiz, n2, k2, fresnel_mode, weight, code, wox, woy, woz, wo32
):
    """Per facet f = ``lo`` + k (k < len(``weight``)) of ``facets`` (``engine.facets.Facets``:
    unit normal n) lit from wi: the Fresnel weight F(n·wi) (``weight``, 0 if back-facing;
    ``fresnel_weight``), the mirror direction wo = 2(n·wi)·n − wi (``wox/woy/woz``, float32
    copy ``wo32``) and the class a primary hit gets (``code``): SINGLE if lit and wo rises (a
    masking ray decides), DOWNWARD if lit and wo points down, RAY_UNRESOLVED if back-facing
    (n·wi ≤ 0); all indexed by k."""
    for k in range(len(weight)):
        nx, ny, nz, _ = facet_plane(facets, lo + k)
        c = nx * wix + ny * wiy + nz * wiz
        x = 2.0 * c * nx - wix
        y = 2.0 * c * ny - wiy
        z = 2.0 * c * nz - wiz
        wox[k] = x
        woy[k] = y
        woz[k] = z
        wo32[k, 0] = np.float32(x)
        wo32[k, 1] = np.float32(y)
        wo32[k, 2] = np.float32(z)
        if c <= 0.0:
            code[k] = RAY_UNRESOLVED
            weight[k] = 0.0
        else:
            code[k] = SINGLE if z > 0.0 else DOWNWARD
            weight[k] = fresnel_weight(c, n2, k2, fresnel_mode)


@vector_inlined
def fresnel_tile(c, m, n2, k2, fresnel_mode, weight, t):
    """weight[t + j] = F(c[j]) (``fresnel_weight``), 0 where c ≤ 0 (back-facing), for
    j < m: one loop per mode, so that each vectorises (into ``weight``'s view from t: an index
    from 0 needs no wrap-around)."""
    w = weight[t:]
    if fresnel_mode == FRESNEL_REAL:
        for j in range(m):
            w[j] = 0.0 if c[j] <= 0.0 else fresnel_real_scalar(c[j], n2, k2)
    elif fresnel_mode == FRESNEL_COSINE:
        for j in range(m):
            w[j] = 0.0 if c[j] <= 0.0 else c[j]
    else:
        one = 1.0 if fresnel_mode == FRESNEL_MIRROR else 0.0
        for j in range(m):
            w[j] = 0.0 if c[j] <= 0.0 else one


class FresnelMaterial(NamedTuple):
    """The material as ``fresnel_kernels.fresnel_mode`` encodes it: n², k² (of η = n + ik)
    and the mode (FRESNEL_REAL: Fresnel of η; FRESNEL_MIRROR: F = 1; FRESNEL_NONE: F = 0;
    FRESNEL_COSINE: F = c)."""

    n2: float
    k2: float
    mode: int


def fresnel_material(ior) -> FresnelMaterial:
    """``fresnel_mode(ior)`` as the ``FresnelMaterial`` the kernels take."""
    mode, n2, k2 = fresnel_mode(ior)
    return FresnelMaterial(n2, k2, mode)


def fresnel_mode(ior) -> tuple:
    """(mode, n², k²) of ``fresnel_weight`` for a resolved index ``ior`` (None = mirror;
    ``COSINE``: the cosine itself)."""
    if ior is None:
        return FRESNEL_MIRROR, 0.0, 0.0
    if ior is COSINE:
        return FRESNEL_COSINE, 0.0, 0.0
    eta = complex(ior)
    return (FRESNEL_NONE if eta == 1 else FRESNEL_REAL), eta.real**2, eta.imag**2
