"""Masking decided per facet: whether every masking ray a lit facet of a heightfield grid can
send along its mirror direction surely escapes (``beam_clear``), so that no ray from it
needs a horizon test or an Embree ray (``facet_tables.facet_table``'s ``clear``).

With one incidence wi every ray reflected by facet f leaves along the same direction wo; the
rays from all points of f form a beam: the facet's triangle swept along wo. On the grid of a
heightfield (``heightfield_caster.HeightfieldGrid``: cells of size c, each split into two
triangles) the facet lies in its cell C; the points of the beam at horizontal distance s from
their starts lie in the unit square C + s·û (û the unit horizontal direction of wo), which is
inside the 2 × 2 block of cells whose lower corner is ⌊corner of C + s·û⌋. Following that
corner with a 2-D DDA visits, in order of s, blocks that cover the beam; in the block met over
[s_in, s_out] a ray from p at height z_p ≥ h(p) climbs as z_p + s·cot (cot = wo_z/|wo_h|) and
is above the surface throughout if either

- it enters above the block's highest vertex: z_lo + s_in·cot > block max + tol, with z_lo
  the facet's lowest vertex − tol (a height test, any start p); or
- it stays above a Lipschitz chain along û: h(p + s·û) − h(p) ≤ B(s), B growing in each block
  by D·(run in the block), D the largest directional slope ∇h·û of the block's eight
  triangles (h is continuous and piecewise linear, so h(p + s·û) − h(p) = ∫ ∇h·û ds), checked
  at both ends: s·cot − B(s) > tol (in the first block, which holds the start, at its exit
  only: the ray starts on the surface, and the facet's own ∇h·û < cot because wo·n > 0).
  After the first block cleared by height the chain is no longer followed (the blocks beyond
  are decided by height alone: as cheap, and they almost always are).

Every block up to the height zmax + tol cleared means every ray of the beam escapes. Any doubt
(a block fails both tests, or more than ``MAX_BLOCKS`` blocks) leaves the facet to the per-ray
tests. Grid coordinates u = (x − x0)/c, v = (y − y0)/c; distances s horizontal, tile units.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from microsim.jit import compiled, inlined

from ..schedule import in_parts

MAX_BLOCKS = 256  # blocks followed per facet before the facet is left to the per-ray tests


class BeamGrid(NamedTuple):
    """What ``beam_clear`` reads of a heightfield grid: vertex heights ``hp`` (ny + 1, nx + 1),
    ``block_max`` (``block_maxima``), per-facet gradients ``gx``/``gy`` (∇h = −n_h/n_z; faces
    numbered as ``heightfield_caster``: A faces then B faces), cell size ``cell``, the relief's
    top ``zmax`` and the height tolerance ``tol`` (tile units)."""

    hp: np.ndarray
    block_max: np.ndarray
    gx: np.ndarray
    gy: np.ndarray
    cell: float
    zmax: float
    tol: float


def beam_grid(grid, facets, zmax: float, tol: float) -> BeamGrid:
    """The ``BeamGrid`` of a ``HeightfieldGrid`` with facets ``facets``
    (``engine.facets.Facets``)."""
    gx, gy = facet_gradients(facets, 1.0)
    return BeamGrid(
        grid.hp, block_maxima(grid.cell_max), gx, gy, float(grid.cell), float(zmax), float(tol)
    )


def mirrored_beam_grid(grid, facets, zmin: float, tol: float) -> BeamGrid:
    """The ``BeamGrid`` of the relief turned upside down (heights −h, the lowest point −zmin
    its top): whether rays leaving a facet downward, below the surface (inside a dielectric
    medium), surely leave the relief is whether their mirror images (d_z → −d_z) escape on
    it."""
    gx, gy = facet_gradients(facets, -1.0)
    return BeamGrid(
        np.ascontiguousarray(-grid.hp),
        block_maxima(-grid.cell_min),
        gx,
        gy,
        float(grid.cell),
        -float(zmin),
        float(tol),
    )


GRADIENT_PIECE = 1 << 16  # facets whose normals ``facet_gradients`` reads at a time


def facet_gradients(facets, sign: float) -> tuple:
    """Per facet the gradient ∇h = −n_h/n_z of the surface (``sign`` 1) or of the relief
    turned upside down (−1: n_h/n_z), (F,) each, in facet ranges on several threads
    (``schedule.in_parts``), ``GRADIENT_PIECE`` facets at a time."""
    gx, gy = np.empty(facets.count), np.empty(facets.count)

    def fill(lo: int, hi: int) -> None:
        for a in range(lo, hi, GRADIENT_PIECE):
            b = min(hi, a + GRADIENT_PIECE)
            nx, ny, nz = facets.columns(a, b)
            np.divide(-nx if sign > 0 else nx, nz, out=gx[a:b])
            np.divide(-ny if sign > 0 else ny, nz, out=gy[a:b])

    in_parts(facets.count, fill)
    return gx, gy


def block_maxima(cell_max: np.ndarray) -> np.ndarray:
    """Highest vertex of each 2 × 2 block of cells, indexed by its lower cell (j, i), wrapped:
    max of ``cell_max`` over cells (i, j), (i + 1, j), (i, j + 1), (i + 1, j + 1)."""
    m = np.empty_like(cell_max)  # along rows, then along columns in place
    np.maximum(cell_max[:, :-1], cell_max[:, 1:], out=m[:, :-1])
    np.maximum(cell_max[:, -1], cell_max[:, 0], out=m[:, -1])
    last = m[0].copy()  # row 0 before it is overwritten: the wrapped neighbour of the last
    np.maximum(m[:-1], m[1:], out=m[:-1])
    np.maximum(m[-1], last, out=m[-1])
    return m


@inlined
def _block_slope(gx, gy, ux, uy, bi, bj, nx, ny):
    """Largest directional slope ∇h·(ux, uy) of the eight triangles of the 2 × 2 block with
    lower cell (bi, bj) (``gx``/``gy``: per-facet gradients, A faces then B faces)."""
    d = -math.inf
    for dj in range(2):
        j = bj + dj
        j = j - ny if j >= ny else j
        for di in range(2):
            i = bi + di
            i = i - nx if i >= nx else i
            a = j * nx + i
            b = a + nx * ny
            d = max(d, gx[a] * ux + gy[a] * uy, gx[b] * ux + gy[b] * uy)
    return d


@compiled
def beam_clear(f0, candidates, wo, grid, out):
    """``out[k]`` = whether every masking ray of facet f = f0 + k surely escapes (module
    docstring), for the facets with ``candidates[k]`` (others: False); ``wo[k]`` its float32
    mirror direction (traced as the float64 value of it); ``grid`` a ``BeamGrid``."""
    for q in range(len(candidates)):
        out[q] = False
        if candidates[q]:
            w = (np.float64(wo[q, 0]), np.float64(wo[q, 1]), np.float64(wo[q, 2]))
            out[q] = beam_escapes(f0 + q, w, grid)


@inlined
def beam_escapes(f, wo, grid):
    """Whether every ray leaving facet ``f`` of the ``BeamGrid`` ``grid`` along the float64
    direction ``wo`` surely escapes (module docstring)."""
    hp, bmax, gx, gy, cell, zmax, tol = grid
    ny, nx = bmax.shape
    ox, oy, oz = wo
    h = math.sqrt(ox * ox + oy * oy)
    if oz <= 0.0 or h == 0.0:
        return False
    cot = oz / h
    ux, uy = ox / h, oy / h
    k = f - nx * ny if f >= nx * ny else f
    ci, cj = k % nx, k // nx
    if f < nx * ny:  # triangle A: (v00, v01, v11)
        zlo = min(hp[cj, ci], hp[cj, ci + 1], hp[cj + 1, ci + 1])
    else:  # triangle B: (v00, v11, v10)
        zlo = min(hp[cj, ci], hp[cj + 1, ci + 1], hp[cj + 1, ci])
    zlo -= tol
    s_end = (zmax + tol - zlo) / cot
    # DDA of the block corner from (ci, cj) along û, grid units per unit s: û / cell
    bi, bj = ci, cj
    tx, dtx, sx = math.inf, math.inf, 0
    if ux > 0.0:
        tx, dtx, sx = cell / ux, cell / ux, 1
    elif ux < 0.0:
        tx, dtx, sx = cell / -ux, cell / -ux, -1
        bi -= 1
    ty, dty, sy = math.inf, math.inf, 0
    if uy > 0.0:
        ty, dty, sy = cell / uy, cell / uy, 1
    elif uy < 0.0:
        ty, dty, sy = cell / -uy, cell / -uy, -1
        bj -= 1
    bi = bi + nx if bi < 0 else bi
    bj = bj + ny if bj < 0 else bj
    s_in, chain = 0.0, 0.0
    for step in range(MAX_BLOCKS):
        s_out = min(tx, ty, s_end)
        if not zlo + s_in * cot > bmax[bj, bi] + tol:  # the block may reach a ray
            if step > 0 and not s_in * cot - chain > tol:  # (the start: on the surface)
                return False
            chain += _block_slope(gx, gy, ux, uy, bi, bj, nx, ny) * (s_out - s_in)
            if not s_out * cot - chain > tol:
                return False
        else:  # above the block: the chain is not followed further (height tests only)
            chain = math.inf
        if s_out >= s_end:
            return True
        if tx < ty:
            bi += sx
            bi = 0 if bi == nx else (nx - 1 if bi < 0 else bi)
            s_in = tx
            tx += dtx
        else:
            bj += sy
            bj = 0 if bj == ny else (ny - 1 if bj < 0 else bj)
            s_in = ty
            ty += dty
    return False
