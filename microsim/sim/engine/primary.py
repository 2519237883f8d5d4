"""Primary hits to ledger classes (``paths.LEDGER``), Fresnel cosines, mirror directions
wo = 2(n·wi)n − wi and the masking rays that must still be traced, set up as the first
segment of their walk (``segments.setup_ray``); the exact V-groove masking margin
(``VGrooveProfile.margin_from_rim``) that clears the rest."""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from microsim.jit import TILE, allocating, compiled, vector_inlined

from ..heightfield_caster import NO_STEPS, cast_columns, cast_falling
from .codes import DOWNWARD, ESCAPED, HIT, MISSED, RAY_MISSED, RAY_UNRESOLVED, SINGLE
from .facets import Facets, facet_plane
from .horizon import CLEAR_MARGIN, horizon_clear
from .segments import WalkResult, setup_ray


class FacetColumns(NamedTuple):
    """A ``facet_tables.FacetTable`` as ``tabled_primary`` reads it, per facet: ledger ``code``,
    Fresnel ``fweight``, the tracer's ``facets`` (``facets.Facets``: unit normal and plane
    offset n·v0; a masking ray starts on the plane n·x = n·v0 + eps, the facet's lift),
    float32 mirror direction ``wo32`` (F, 3), bin ``fbin`` and ``fclear`` (surely
    escapes)."""

    code: np.ndarray
    fweight: np.ndarray
    facets: Facets
    wo32: np.ndarray
    fbin: np.ndarray
    fclear: np.ndarray


class PrimaryLedger(NamedTuple):
    """Per primary ray, written by ``tabled_primary``: ledger ``status``, Fresnel ``weight``
    and flat bin ``where`` (−1 if none)."""

    status: np.ndarray
    weight: np.ndarray
    where: np.ndarray


class TracedLedger(NamedTuple):
    """Per primary ray, written by ``traced_primary``: ledger ``status``, ``cosine`` = n·wl
    (0 without a hit or back-facing) and the float64 mirror direction (wox, woy, woz)."""

    status: np.ndarray
    cosine: np.ndarray
    wox: np.ndarray
    woy: np.ndarray
    woz: np.ndarray


@allocating
def tabled_primary(walk, table, hz, geometry, out, masking):
    """Ledger class, Fresnel weight and bin of primary rays from their first hits, looked up
    per facet (``facet_tables.FacetTable``: ``code``, ``fweight``, ``facets`` (unit normal n,
    lift = n·v0 + eps), mirror direction ``wo32`` (float32, used as
    float64 too), bin ``fbin``, ``fclear``: lit facets whose rays surely escape), and the
    masking rays of the other lit ones (code SINGLE) that the coarse grid ``hz``
    (``horizon_bounds.HorizonGrid``, ``horizon_clear``) cannot clear, set up as the first
    segment of their walk (``Tracer.escape_columns(first=...)``). Masking ray m of primary
    ray ``mi[m]`` starts at its hit point p moved along n onto the facet plane and eps above
    it, p − (p·n − lift)·n, wrapped into the tile (``sx/sy/sz``), along the facet's mirror
    direction (``mdx``… ``md32``), with its Embree input in slot m (``setup_ray``: ``o32``,
    ``tq``, ``top``; ``keep[m]`` = m). A start at or above zmax has nothing above it: the ray
    escapes without a masking ray (as ``segment_setup`` decides). ``hs`` is the walk status:
    HIT, MISSED/ESCAPED (→ RAY_MISSED) or UNRESOLVED. Writes ``status``, ``weight`` (0
    without a hit) and ``where`` (the facet bin for lit rays, else −1) of every ray; returns
    the number of masking rays. In tiles of ``TILE`` rays: the look-ups one by one, the
    starts only for the candidates (few: most lit facets are ``fclear``), the masking rays
    by ``masking_starts``.

    Arguments: ``walk`` (``segments.WalkResult``: hs, prim, px, py, pz), ``table``
    (``FacetColumns``: code, fweight, facets, wo32, fbin, fclear), ``hz``,
    ``geometry``, ``out`` (``PrimaryLedger``: status, weight, where; written) and
    ``masking`` (the masking rays' arrays, ``masking_rays.MaskingRays.kernel_args``)."""
    tile = np.empty((6, TILE))  # per-ray scratch of one tile: masking starts, directions
    cand = np.empty(TILE, np.bool_)
    m = int(0)  # a plain int, not a literal: one compiled ``_tabled_tile`` (``microsim.jit``)
    for t in range(0, len(walk[0]), TILE):
        n = min(TILE, len(walk[0]) - t)
        m = _tabled_tile(walk, t, t, n, table, hz, geometry, out, masking, tile, cand, m)
    return m


@allocating
def cast_tabled_primary(origins, down, grid, ahead, table, hz, geometry, out, masking):
    """``tabled_primary`` of rays from ``origins`` (x, y, z columns) along one falling
    direction ``down`` (dx, dy, dz), their first hits found tile by tile by the heightfield
    grid walk (``heightfield_caster.cast_falling`` on ``grid``, ``Tracer.grid_walk``) into
    scratch of one tile: the same bits as the walk into whole columns followed by
    ``tabled_primary``, without writing and reading back five columns of hits."""
    first, m = int(0), int(0)  # plain ints, not literals: one compiled ``tabled_tiles``
    return tabled_tiles(
        origins, down, grid, ahead, table, hz, geometry, out, masking, first, m, tabled_scratch()
    )


@allocating
def tabled_scratch():
    """``tabled_tiles``' scratch of one tile: the walk's results (``_tile_walk``), the masking
    starts and directions (6, TILE) and the candidates (TILE,)."""
    return _tile_walk(), np.empty((6, TILE)), np.empty(TILE, np.bool_)


@compiled
def tabled_tiles(origins, down, grid, ahead, table, hz, geometry, out, masking, first, m, scratch):
    """``cast_tabled_primary`` of the rays of ``origins``, tile by tile, as the rays
    ``first`` … ``first`` + n − 1 of ``out`` and of the masking rays' ``mi``, their masking
    rays from slot ``m`` on (``scratch``: ``tabled_scratch``). Returns the new m."""
    walk, tile, cand = scratch
    w = int(0)  # a plain int, not a literal: one compiled ``_tabled_tile``
    for t in range(0, len(origins[0]), TILE):
        n = _walk_tile(origins, down, grid, ahead, t, walk)
        m = _tabled_tile(walk, w, first + t, n, table, hz, geometry, out, masking, tile, cand, m)
    return m


@allocating
def _tile_walk():
    """The walk results of one tile (``segments.WalkResult``: hs, prim, px, py, pz)."""
    hits = np.empty((3, TILE))
    return WalkResult(np.empty(TILE, np.int8), np.empty(TILE, np.int32), hits[0], hits[1], hits[2])


@compiled
def _walk_tile(origins, down, grid, ahead, t, walk):
    """The first hits of the rays t … t + n − 1 from ``origins`` along ``down`` by the grid
    walk (``cast_falling`` on ``grid``) into ``walk`` (``_tile_walk``); returns n ≤ ``TILE``."""
    x, y, z = origins
    n = min(TILE, len(x) - t)
    e = t + n
    status, prim, px, py, pz = walk
    cast_falling(
        x[t:e], y[t:e], z[t:e], down[0], down[1], down[2], grid, ahead, status, prim, px, py, pz
    )
    return n


@compiled
def _tabled_tile(walk, w, t, n, table, hz, geometry, out, masking, tile, cand, m):
    """``tabled_primary`` for the n rays t … t + n − 1, their walk results at ``walk``'s
    entries w … w + n − 1 (w = t on whole columns, 0 on one tile's); ``tile`` (6, TILE)
    and ``cand`` (TILE,) scratch; masking rays from slot m on. Returns the new m."""
    hs, prim, px, py, pz = (walk[0][w:], walk[1][w:], walk[2][w:], walk[3][w:], walk[4][w:])
    status, weight, where = out[0][t:], out[1][t:], out[2][t:]  # views indexed from 0
    code, fweight, facets, wo32, fbin, fclear = table
    x_, y_, z_, dx_, dy_, dz_ = tile[0], tile[1], tile[2], tile[3], tile[4], tile[5]
    for j in range(n):  # one by one: the hit facet's entries (indexed loads)
        h = hs[j]
        hit = h == HIT
        f = prim[j] if hit else 0
        c = code[f]
        miss = RAY_MISSED if (h == MISSED) | (h == ESCAPED) else RAY_UNRESOLVED
        status[j] = c if hit else miss
        weight[j] = fweight[f] if hit else 0.0
        where[j] = fbin[f] if hit & (c == SINGLE) else -1
        cand[j] = hit & (c == SINGLE) & (not fclear[f])  # else: escapes, no masking ray
        if cand[j]:  # the masking ray's start on the facet plane (few rays: most are clear)
            a, b, e, plane = facet_plane(facets, f)
            off = px[j] * a + py[j] * b + pz[j] * e - (plane + facets.eps)
            x_[j], y_[j], z_[j] = px[j] - off * a, py[j] - off * b, pz[j] - off * e
            dx_[j], dy_[j], dz_[j] = wo32[f, 0], wo32[f, 1], wo32[f, 2]
    return masking_starts(cand, t, n, x_, y_, z_, dx_, dy_, dz_, hz, geometry, m, masking)


@allocating
def traced_primary(
    walk, incident, facets, trace_masking, clear_slope, hz, groove, geometry, out, masking
):
    """``tabled_primary`` for rays that each carry their own incident direction wl (``wx/wy/
    wz``, length N, or 1: one shared), so nothing can be tabled per facet: per hit facet n (unit
    normal n and lift n·v0 + eps, ``facets``), c = n·wl (``cosine``: 0
    without a hit or back-facing, for ``fresnel_weights``); back-facing (c ≤ 0): RAY_UNRESOLVED;
    else the mirror direction wo = 2c·n − wl (``wox/woy/woz``, float64); DOWNWARD if wo_z ≤ 0,
    else SINGLE. With ``trace_masking`` the SINGLE rays whose float32 wo rises more steeply than
    ``clear_slope`` (× ``CLEAR_MARGIN`` as in ``Tracer.surely_escapes``; inf: none), that start
    at or above zmax or that clear the coarse grid ``hz`` (``horizon_clear``) escape without a
    ray, and the others get their masking ray set up as the first segment of their walk, exactly
    as ``tabled_primary`` (float64 direction wo, its float32 copy in ``md32``); returns the
    number of masking rays (0 without ``trace_masking``: the caller decides masking itself).
    ``groove``: V-groove surfaces' per-facet (rim x, tanθ σ, rim-to-rim width W, rim-to-bottom
    extent) and a tolerance (``Tracer.groove_clear``; empty arrays otherwise): a ray whose exact
    masking margin s(1 + tanθ σ wo_x/wo_z) − W (``VGrooveProfile.margin_from_rim``) is below
    −tolerance escapes without a ray (the margins within it are left to Embree).

    Arguments: ``walk`` (``segments.WalkResult``: hs, prim, px, py, pz), ``incident`` (wx,
    wy, wz), ``facets`` (the tracer's ``facets.Facets``), ``out`` (``TracedLedger``: status,
    cosine, wox, woy, woz; written); the others as named above."""
    tile = np.empty((11, TILE))  # per-ray scratch of one tile
    cand = np.empty(TILE, np.bool_)
    rules = (trace_masking, CLEAR_MARGIN * clear_slope, hz, groove, geometry)
    m = int(0)  # a plain int, not a literal: one compiled ``_traced_tile`` (``microsim.jit``)
    for t in range(0, len(walk[0]), TILE):
        n = min(TILE, len(walk[0]) - t)
        m = _traced_tile(walk, t, t, n, incident, facets, rules, out, masking, tile, cand, m)
    return m


@allocating
def cast_traced_primary(
    origins, down, grid, cell_min, facets, clear_slope, hz, groove, geometry, out, masking, escape
):
    """``traced_primary`` of rays from ``origins`` (x, y, z columns) along one falling
    direction ``down`` (dx, dy, dz; the incident direction is −down), masking traced, on a
    heightfield grid, tile by tile: the first hits by the grid walk (``cast_falling`` on
    ``grid``, ``Tracer.grid_walk``), their classes, cosines and mirror directions, and at once
    the masking rays the tests cannot clear, walked on the grid (``cast_columns``, occlusion,
    the primaries' wrap cap; ``cell_min`` the grid's cell minima), their primaries' status
    set from the walk's (``escape``: walk status → ledger class). A tile's masking rays start
    among the cells its primaries just walked, which are still in cache. Every ray gets the
    bits of the walk into whole columns, ``traced_primary`` and ``Tracer.escape_columns`` in
    turn. ``facets``, ``clear_slope``, ``hz``, ``groove`` and ``geometry`` (the masking rays'
    ``segment_geometry``) as ``traced_primary``'s; ``out`` a ``TracedLedger``, written;
    ``masking`` the masking rays' arrays of one tile (``MaskingRays.work(TILE).kernel_args()``),
    reused tile after tile."""
    incident = (np.array([-down[0]]), np.array([-down[1]]), np.array([-down[2]]))
    tile = np.empty((11, TILE))
    cand = np.empty(TILE, np.bool_)
    walk = _tile_walk()
    esc = np.empty(TILE, np.int8)
    no_hits = (np.empty(0, np.int32), np.empty(0), np.empty(0), np.empty(0))
    # plain ints and bools, not literals, and the walk's own tuple type: the callees are
    # compiled once for these calls and for those from Python (``microsim.jit``)
    yes, no, zero = bool(True), bool(False), int(0)
    rules = (yes, CLEAR_MARGIN * clear_slope, hz, groove, geometry)
    status = out[0]
    for t in range(0, len(origins[0]), TILE):
        n = _walk_tile(origins, down, grid, NO_STEPS, t, walk)
        m = _traced_tile(walk, zero, t, n, incident, facets, rules, out, masking, tile, cand, zero)
        mi, sx, sy, sz, mdx, mdy, mdz = masking[:7]
        cast_columns(
            sx[:m], sy[:m], sz[:m], mdx[:m], mdy[:m], mdz[:m], no, grid, cell_min, grid[9],
            yes, WalkResult(esc[:m], *no_hits),
        )  # fmt: skip
        apply_escape(status, mi[:m], esc[:m], escape)


@compiled
def _traced_tile(walk, w, t, n, incident, facets, rules, out, masking, tile, cand, m):
    """``traced_primary`` for the n rays t … t + n − 1, their walk results at ``walk``'s
    entries w … w + n − 1 (w = t on whole columns, 0 on one tile's); ``rules`` =
    (trace_masking, slope bound × ``CLEAR_MARGIN``, hz, groove, geometry); ``tile``
    (11, TILE) and ``cand`` (TILE,) scratch; masking rays from slot m on. Returns the new m."""
    # the tile's own entries as views indexed from 0: an index the compiler can tell is not
    # negative needs no wrap-around, so the loops below load and store whole vectors
    hs, prim, px, py, pz = (walk[0][w:], walk[1][w:], walk[2][w:], walk[3][w:], walk[4][w:])
    status, cosine, wox, woy, woz = (out[0][t:], out[1][t:], out[2][t:], out[3][t:], out[4][t:])
    shared = len(incident[0]) == 1
    s0 = 0 if shared else t  # one shared incident direction, or the tile's own
    wx, wy, wz = incident[0][s0:], incident[1][s0:], incident[2][s0:]
    trace_masking, slope, hz, groove, geometry = rules
    grim, gtan, gwidth, gextent, gtol = groove
    grooved = len(grim) > 0
    a_, b_, e_, lift_, x_, y_, z_ = tile[0], tile[1], tile[2], tile[3], tile[4], tile[5], tile[6]
    rim_, tan_, width_, extent_ = tile[7], tile[8], tile[9], tile[10]
    for j in range(n):  # one by one: the hit facet's normal and lift (indexed loads)
        f = prim[j] if hs[j] == HIT else 0
        a_[j], b_[j], e_[j], plane = facet_plane(facets, f)
        lift_[j] = plane + facets.eps
    if grooved:
        for j in range(n):
            f = prim[j] if hs[j] == HIT else 0
            rim_[j], tan_[j], width_[j], extent_[j] = grim[f], gtan[f], gwidth[f], gextent[f]
    for j in range(n):  # vectorised: reflection and class
        k = 0 if shared else j
        h = hs[j]
        a, b, e = a_[j], b_[j], e_[j]
        c = wx[k] * a + wy[k] * b + wz[k] * e
        oz = 2.0 * c * e - wz[k]
        st = SINGLE if oz > 0.0 else DOWNWARD
        st = st if c > 0.0 else RAY_UNRESOLVED
        miss = RAY_MISSED if (h == MISSED) | (h == ESCAPED) else RAY_UNRESOLVED
        status[j] = st if h == HIT else miss
        cosine[j] = c if (h == HIT) & (c > 0.0) else 0.0
        wox[j], woy[j], woz[j] = 2.0 * c * a - wx[k], 2.0 * c * b - wy[k], oz
    for j in range(n):  # vectorised: masking candidates and their starts
        gx, gy = np.float64(np.float32(wox[j])), np.float64(np.float32(woy[j]))
        gz = np.float64(np.float32(woz[j]))
        steep = gz > slope * math.sqrt(gx * gx + gy * gy)  # escapes: no masking ray
        cand[j] = trace_masking & (status[j] == SINGLE) & (not steep)
        a, b, e = a_[j], b_[j], e_[j]
        off = px[j] * a + py[j] * b + pz[j] * e - lift_[j]  # on the plane, eps above
        x_[j], y_[j], z_[j] = px[j] - off * a, py[j] - off * b, pz[j] - off * e
    if grooved:  # clears the opposite facet by more than the tolerance: escapes
        for j in range(n):
            s = min(abs(px[j] - rim_[j]), extent_[j])
            cand[j] &= not groove_margin(s, tan_[j], width_[j], wox[j], woz[j]) < -gtol
    return masking_starts(cand, t, n, x_, y_, z_, wox, woy, woz, hz, geometry, m, masking)


@compiled
def masking_starts(cand, t, n, x_, y_, z_, ox_, oy_, oz_, hz, geometry, m, masking):
    """The masking rays of the candidates j < n of a tile starting at ray t (``cand``: lit,
    rising, not surely escaping), from (``x_``, ``y_``, ``z_``) along (``ox_``, ``oy_``,
    ``oz_``) traced as its float32 copy: a start at or above zmax has nothing above it and one
    that clears the coarse grid ``hz`` (``horizon_clear``) escapes; the others, wrapped into
    the tile, get slot m onwards of the first segment of their walk (``setup_ray``;
    ``keep[m]`` = m, ``mi[m]`` = their ray). ``geometry``: (hx, hy, zmax, eps, rel);
    ``masking``: the ``masking_rays.MaskingRays`` arrays (mi, sx, sy, sz, mdx, mdy, mdz, md32, o32,
    tq, keep, top). Returns the new m."""
    hx, hy, zmax, eps, rel = geometry
    mi, sx, sy, sz, mdx, mdy, mdz, md32, o32, tq, keep, top = masking
    for j in range(n):
        if not cand[j]:
            continue
        x, y, z = x_[j], y_[j], z_[j]
        if z >= zmax:  # nothing above: escaped
            continue
        if x < -hx or x >= hx:  # into the tile
            x = (x + hx) % (2.0 * hx) - hx
        if y < -hy or y >= hy:
            y = (y + hy) % (2.0 * hy) - hy
        ox, oy, oz = ox_[j], oy_[j], oz_[j]
        if horizon_clear(x, y, z, ox, oy, oz, hz, zmax):
            continue  # clears the coarse grid: escaped
        sx[m], sy[m], sz[m] = x, y, z
        mdx[m], mdy[m], mdz[m] = ox, oy, oz
        md32[m, 0], md32[m, 1], md32[m, 2] = np.float32(ox), np.float32(oy), np.float32(oz)
        setup_ray(m, x, y, z, ox, oy, oz, hx, hy, zmax, eps, rel, o32, tq, top)
        keep[m] = m
        mi[m] = t + j
        m += 1
    return m


@compiled
def apply_escape(status, rays, esc, from_escape):
    """``status[rays[m]] = from_escape[esc[m]]`` for the masking rays' walk statuses ``esc``."""
    for m in range(len(esc)):
        status[rays[m]] = from_escape[esc[m]]


@vector_inlined
def groove_margin(s, signed_tan, width, ox, oz):
    """The exact V-groove masking margin s(1 + tanθ σ wo_x/wo_z) − W of a hit at horizontal
    distance s from its facet's rim, leaving along wo (``VGrooveProfile.margin_from_rim``):
    > 0 ⇔ masked by the opposite facet."""
    return s * (1.0 + signed_tan * ox / oz) - width
