"""Bounds that decide a heightfield's masking rays without tracing them: the steepest facet
slope (``rise_bound``: a ray rising more steeply always escapes) and a coarse grid of cell
maxima (``HorizonGrid``, ``horizon_grid``: a ray that clears every cell's top escapes). The
compiled tests are ``engine.horizon``'s; ``Tracer.surely_escapes`` and
``Tracer.clears_horizon`` apply them."""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from scipy import ndimage

from microsim.jit import read_only

from .engine import horizon
from .heightfield_caster import HeightfieldGrid
from .schedule import in_parts

__all__ = [
    "CLEAR_MARGIN",
    "HORIZON_FACETS",
    "NEARBY_CELLS",
    "HorizonGrid",
    "slope_magnitudes",
    "rise_bound",
    "horizon_grid",
]

HORIZON_FACETS = 32  # facets per cell of the coarse grid of ``Tracer.horizon``
SLOPE_PIECE = 1 << 16  # facets whose normals ``slope_magnitudes`` reads at a time
CLEAR_MARGIN = horizon.CLEAR_MARGIN  # ``surely_escapes`` asks wo_z > this × rise_bound × |wo_h|


def slope_magnitudes(facets) -> np.ndarray:
    """|∇h_f| = √(n_x² + n_y²)/n_z of every facet (F,) of ``facets`` (``engine.facets.Facets``),
    in facet ranges on several threads (``schedule.in_parts``), each ``SLOPE_PIECE`` facets at
    a time (where the normals are derived, only those are computed at once)."""
    slopes = np.empty(facets.count)

    def fill(lo: int, hi: int) -> None:
        for a in range(lo, hi, SLOPE_PIECE):
            b = min(hi, a + SLOPE_PIECE)
            nx, ny, nz = facets.columns(a, b)
            np.hypot(nx, ny, out=slopes[a:b])
            slopes[a:b] /= nz  # in place: one array of F

    in_parts(facets.count, fill)
    return slopes


def rise_bound(surface, slopes) -> float:
    """The steepest facet slope L = max_f |∇h_f| (``slopes``: ``slope_magnitudes``) of a periodic
    heightfield surface (one with ``heights``: Gaussian, ABC, file and grating tiles; or
    kind "vgrooves" or "flat", whose profiles are single-valued too), else inf.

    Such a surface is a continuous graph z = h(x, y) with |h(q) − h(p)| ≤ L |q − p|_h, so a
    ray leaving a point of it (at or above its facet) upwards along wo with
    wo_z > L |wo_h| stays strictly above it: after a horizontal run s it has climbed
    s wo_z/|wo_h| > L s ≥ h(p + s ŵo) − h(p). Its masking test is decided without tracing
    (``Tracer.surely_escapes``): on the bench heightfield (σ = 1.2, ℓ = 8, L = 0.96) that is
    70 % of the masking rays at θi = 30°. A mesh not known to be a heightfield gets inf
    (every masking ray is traced)."""
    known = surface.heights is not None or surface.kind in ("vgrooves", "flat")
    if not (known and surface.periodic):
        return math.inf
    return float(np.max(slopes))


NEARBY_CELLS = 3
"""The coarse cells on each side of a cell over which ``HorizonGrid.nearby`` takes the steepest
facet (a window of 7 × 7 cells, ~1,600 facets). On Gaussian fields its bound is about half the
tile's and clears about two thirds of the masking rays below the tile's (``horizon_grid``)."""


class HorizonGrid(NamedTuple):
    """``horizon.horizon_clear``'s coarse grid: origin (``x0``, ``y0``), cell size (``cw``,
    ``ch``), per cell (ny, nx) the highest vertex ``cmax`` and the steepest facet ``cslope`` of
    the facets overlapping it and the steepest of the cells within ``NEARBY_CELLS`` of it
    (``nearby``, wrapped), which bounds the slope of every point within ``reach`` =
    ``NEARBY_CELLS``·min(cw, ch) of any point in the cell; the tolerance ``tol`` (length
    units); and, where the masking rays are walked on a heightfield grid (``walked``), that
    walk's geometry (``HeightfieldGrid.geometry``; else ``NO_WALK``'s), on which a ray's first
    cell is walked exactly."""

    x0: float
    y0: float
    cw: float
    ch: float
    cmax: np.ndarray
    cslope: np.ndarray
    nearby: np.ndarray
    reach: float
    tol: float
    walk: tuple
    walked: bool


NO_WALK = HeightfieldGrid.of_heights(np.zeros((1, 1)), 1.0).geometry(0.0, 0.0, 0)
"""``HorizonGrid.walk`` where the masking rays are not walked on a grid (typed as a grid's)."""


def horizon_grid(facets, vertices, faces, slopes, rise: float, tile, walk=None) -> HorizonGrid:
    """The ``HorizonGrid`` of a heightfield's ``facets`` (``engine.facets.Facets``; corners
    those of the mesh ``vertices``, ``faces``, or of the heightfield grid where ``faces`` is
    empty; finite ``rise`` bound; ``slopes``: its ``slope_magnitudes``), cells of
    ~``HORIZON_FACETS`` facets, tol = 4 eps (float32 rays); for other meshes a 1 × 1 grid
    that clears nothing. Facet ranges on several threads (``schedule.in_parts``) each fill a
    grid of their own, whose maxima are merged (the same maxima). ``walk``: the geometry of
    the grid walk the masking rays take (``HeightfieldGrid.geometry``), if they are walked."""
    walked = walk is not None
    walk = walk if walked else NO_WALK
    if not math.isfinite(rise):
        none = np.full((1, 1), np.inf)
        return HorizonGrid(0.0, 0.0, 1.0, 1.0, none, none, none, 0.0, 0.0, walk, False)
    lx, ly = tile
    cells = facets.count / HORIZON_FACETS
    nx = int(np.clip(round(math.sqrt(cells * lx / ly)), 1, 1024))
    ny = int(np.clip(round(math.sqrt(cells * ly / lx)), 1, 1024))
    x0, y0, cw, ch = -lx / 2, -ly / 2, lx / nx, ly / ny
    vertices, faces = read_only(vertices), read_only(faces)  # frozen or not: one type

    def fill(lo: int, hi: int) -> tuple:
        cmax, cslope = np.full((ny, nx), -np.inf), np.zeros((ny, nx))
        cells = (x0, y0, cw, ch, cmax, cslope)
        horizon.fill_horizon(facets, vertices, faces, lo, hi, slopes, *cells)
        return cmax, cslope

    grids = in_parts(facets.count, fill)
    cmax, cslope = grids[0]
    for more_max, more_slope in grids[1:]:
        np.maximum(cmax, more_max, out=cmax)
        np.maximum(cslope, more_slope, out=cslope)
    nearby = ndimage.maximum_filter(cslope, size=2 * NEARBY_CELLS + 1, mode="wrap")
    reach = NEARBY_CELLS * min(cw, ch)
    tol = 4.0 * facets.eps
    return HorizonGrid(x0, y0, cw, ch, cmax, cslope, nearby, reach, tol, walk, walked)
