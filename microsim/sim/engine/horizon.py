"""Masking rays decided without tracing: the steepness test wo_z > slope·|wo_h| against a
heightfield's Lipschitz bound (``horizon_bounds.rise_bound``) and the coarse-grid horizon test
(``horizon_clear``: the same test against the steepest facet near the start, then a 2-D DDA
over cell maxima and slopes, its first cell walked exactly on a heightfield grid). Tile
coordinates."""

from __future__ import annotations

import math

from microsim.jit import compiled, vector_inlined, vectorised

from ..heightfield_caster import NO_STEPS, cast_one, direction_terms, height_at
from .codes import ESCAPED
from .facets import facet_corners

CLEAR_MARGIN = 1.0 + 1e-6  # a masking ray is skipped when wo_z > this × slope bound × |wo_h|


@compiled
def fill_horizon(facets, vertices, faces, lo, hi, slope, x0, y0, cw, ch, cmax, cslope):
    """The coarse bounds of ``horizon_clear``: for facets ``lo`` … ``hi`` − 1 (corners
    ``facets.facet_corners`` of the mesh ``vertices``, ``faces``, or of the heightfield grid
    of ``facets`` where ``faces`` is empty; slope ``slope[f]`` = |∇h|), every cell of the
    (ny, nx) grid of cells cw × ch from (x0, y0) that its bounding box overlaps gets the
    facet's highest vertex in ``cmax`` and its slope in ``cslope`` (running maxima; start from
    −inf and 0)."""
    ny, nx = cmax.shape
    for f in range(lo, hi):
        xa, ya, za, xb, yb, zb, xc, yc, zc = facet_corners(facets, vertices, faces, f)
        i0 = max(int(math.floor((min(xa, xb, xc) - x0) / cw)), 0)
        i1 = min(int(math.floor((max(xa, xb, xc) - x0) / cw)), nx - 1)
        j0 = max(int(math.floor((min(ya, yb, yc) - y0) / ch)), 0)
        j1 = min(int(math.floor((max(ya, yb, yc) - y0) / ch)), ny - 1)
        top = max(za, zb, zc)
        for j in range(j0, j1 + 1):
            for i in range(i0, i1 + 1):
                cmax[j, i] = max(cmax[j, i], top)
                cslope[j, i] = max(cslope[j, i], slope[f])


@compiled
def horizon_clear(x, y, z, dx, dy, dz, hz, zmax):
    """Whether a ray from (x, y, z) on a periodic heightfield (at or just above it), rising
    along (dx, dy, dz), surely clears the surface before it rises above ``zmax``, decided on
    the coarse grid ``hz`` (``horizon_bounds.HorizonGrid``: origin x0, y0, cells cw × ch, per
    cell the highest vertex ``cmax``, the steepest facet ``cslope`` and the steepest facet
    ``nearby`` within ``reach``; tolerance ``tol``) without tracing it. The ray's height is
    z + s·cot (s horizontal distance, cot = dz/|d_h|); it must climb to zmax by
    s = (zmax − z)/cot. First the slope bound of the start's surroundings: when that run is
    within ``reach``, every point the ray passes over is within the cells ``nearby`` covers,
    so a ray with cot > nearby clears them (h(p + s·û) − h(p) ≤ nearby·s, as
    ``horizon_bounds.rise_bound`` over the whole tile). Else the height is followed cell by
    cell (2-D DDA, indices wrapped) up to s = (zmax − z)/cot; a cell is cleared when the ray
    enters it above the cell's highest vertex (+ ``tol``), or when it stays above the
    Lipschitz bound h(p) ≤ z + Σ cslope·(run in each cell so far) at the cell's entry and exit
    (in the first cell, where the ray starts on the surface: cot > cslope). Where the masking
    rays are walked on the heightfield's grid (``hz.walked``), a first cell steeper than the
    ray is walked exactly instead (``_walk_clears``: the walk the ray would take, stopped where
    it leaves the cell or rises above its highest vertex), and the chain goes on from the
    surface's height where the ray leaves it. Any doubt — a cell fails, the walk meets the
    surface, or more than 64 cells — returns False (the ray is traced)."""
    if dz <= 0.0:
        return False
    h = math.sqrt(dx * dx + dy * dy)
    if h == 0.0:
        return True
    cot = dz / h
    x0, y0, cw, ch, cmax, cslope, tol = hz.x0, hz.y0, hz.cw, hz.ch, hz.cmax, hz.cslope, hz.tol
    s_end = (zmax + tol - z) / cot
    if s_end <= 0.0:
        return True
    ny, nx = cmax.shape
    ux, uy = dx / h, dy / h
    gx, gy = (x - x0) / cw, (y - y0) / ch
    ix, iy = int(math.floor(gx)), int(math.floor(gy))
    cx, cy = ix % nx, iy % ny  # the cell, wrapped; stepped by ±1 below (no modulo per step)
    if s_end <= hz.reach and cot > hz.nearby[cy, cx] * CLEAR_MARGIN:
        return True  # steeper than every facet it can pass over
    tx, dtx, sx = math.inf, math.inf, 0
    if ux > 0.0:
        tx, dtx, sx = (ix + 1 - gx) * cw / ux, cw / ux, 1
    elif ux < 0.0:
        tx, dtx, sx = (gx - ix) * cw / -ux, cw / -ux, -1
    ty, dty, sy = math.inf, math.inf, 0
    if uy > 0.0:
        ty, dty, sy = (iy + 1 - gy) * ch / uy, ch / uy, 1
    elif uy < 0.0:
        ty, dty, sy = (gy - iy) * ch / -uy, ch / -uy, -1
    s_in, bound = 0.0, z
    for step in range(64):
        s_out = min(tx, ty, s_end)
        slope = cslope[cy, cx] * CLEAR_MARGIN
        z_in = z + cot * s_in
        walked = False
        if z_in <= cmax[cy, cx] + tol:  # the cell may reach the ray: Lipschitz chain
            if step == 0:
                if not cot > slope:
                    # the first cell walked exactly, up to where the ray leaves it or rises
                    # above its highest vertex; the chain goes on from the surface's height
                    # where it leaves (at most that vertex when the ray rose above it first)
                    s_stop = min(s_out, (cmax[cy, cx] + tol - z) / cot)
                    if not hz.walked or not _walk_clears(
                        x, y, z, dx, dy, dz, z + cot * s_stop, hz.walk
                    ):
                        return False
                    walked, g = True, hz.walk
                    bound = cmax[cy, cx]
                    if s_stop >= s_out:
                        x_out, y_out = x + ux * s_out, y + uy * s_out
                        bound = height_at(g[0], g[2], g[3], g[4], g[5], g[6], x_out, y_out)
            elif not (
                z_in - tol > bound and z + cot * s_out - tol > bound + slope * (s_out - s_in)
            ):
                return False
        if not walked:
            bound += slope * (s_out - s_in)
        if s_out >= s_end:
            return True
        if tx < ty:
            cx += sx
            cx = 0 if cx == nx else (nx - 1 if cx < 0 else cx)
            s_in = tx
            tx += dtx
        else:
            cy += sy
            cy = 0 if cy == ny else (ny - 1 if cy < 0 else cy)
            s_in = ty
            ty += dty
    return False


@compiled
def _walk_clears(x, y, z, dx, dy, dz, z_stop, walk):
    """Whether the exact grid walk (``heightfield_caster.cast_one`` on ``walk``, from above)
    of the ray from (x, y, z) rising along (dx, dy, dz) rises to ``z_stop`` without meeting
    the surface."""
    stopped = walk[:8] + (z_stop, walk[9])  # its zmax lowered to z_stop
    terms = direction_terms(dx, dy, dz, walk[4])
    status = cast_one(x, y, z, dx, dy, dz, terms, stopped, (1.0, walk[1]), walk[9], NO_STEPS)[0]
    return status == ESCAPED


@compiled
def horizon_clear_all(px, py, pz, dx, dy, dz, hz, zmax, out):
    """``horizon_clear`` for rays from (px, py, pz)[i] (in the tile) along (dx, dy, dz)[i]
    on the grid ``hz`` (``horizon_bounds.HorizonGrid``); writes ``out``."""
    for i in range(len(px)):
        out[i] = horizon_clear(px[i], py[i], pz[i], dx[i], dy[i], dz[i], hz, zmax)


@vector_inlined
def rises_clear(dx, dy, dz, slope):
    """Whether the direction (dx, dy, dz) rises more steeply than ``slope`` (a bound on the
    surface's slopes): dz > slope·√(dx² + dy²) — a ray leaving the surface along it surely
    escapes (``horizon_bounds.rise_bound``)."""
    return dz > slope * math.sqrt(dx * dx + dy * dy)


@vectorised
def surely_escaping(dx, dy, dz, slope, out):
    """out[i] = ``rises_clear``: rays rising more steeply than the surface can
    (``Tracer.surely_escapes``, ``traced_primary``), vectorised."""
    for i in range(len(dx)):
        out[i] = rises_clear(dx[i], dy[i], dz[i], slope)
