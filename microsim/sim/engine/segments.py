"""One segment of the periodic walk (``periodic_walk.walk_columns``): the Embree input of the live
rays (float32 origin strictly inside the tile, tfar to the nearer wall or up to zmax) and,
from Embree's answers, hits, escapes, leaks and re-entries through the opposite wall.
Tile coordinates, unit directions, distances along the ray."""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from microsim.jit import compiled, vector_inlined, vectorised

from .codes import ESCAPED, HIT, MISSED


class WalkRays(NamedTuple):
    """The live rays of a segment: global indices ``live``, origins (x, y, z) per ray and
    directions (dx, dy, dz), one shared (index 0) when ``shared``, else one per ray."""

    live: np.ndarray
    x: np.ndarray
    y: np.ndarray
    z: np.ndarray
    dx: np.ndarray
    dy: np.ndarray
    dz: np.ndarray
    shared: bool


class WalkBox(NamedTuple):
    """The walk's box: the tile's half extents, the relief's top ``zmax`` and bottom
    ``zmin``, and the tracer's ``eps`` (tile units)."""

    half_x: float
    half_y: float
    zmax: float
    zmin: float
    eps: float


class WalkResult(NamedTuple):
    """Per ray (global index): walk ``status``, the ``prim`` hit and the hit point (x, y, z)
    (empty arrays for occlusion queries)."""

    status: np.ndarray
    prim: np.ndarray
    x: np.ndarray
    y: np.ndarray
    z: np.ndarray


class NextSegment(NamedTuple):
    """The rays re-entering through a wall, compacted: global index ``live``, origin
    (x, y, z), and unless shared direction (dx, dy, dz) and its float32 copy ``d32``."""

    live: np.ndarray
    x: np.ndarray
    y: np.ndarray
    z: np.ndarray
    dx: np.ndarray
    dy: np.ndarray
    dz: np.ndarray
    d32: np.ndarray


@vector_inlined
def _wall_distance(x, d, half):
    """Distance ≥ 0 along a ray at coordinate x with direction component d to the wall
    ±half it heads for (inf if parallel)."""
    if d == 0.0:
        return math.inf
    return max((math.copysign(half, d) - x) / d, 0.0)


@vector_inlined
def _segment_bounds(x, y, z, dx, dy, dz, hx, hy, zmax):
    """Distances along a ray at (x, y, z) with direction (dx, dy, dz) to the x wall, the y
    wall, the nearer of the two, and up to zmax (inf unless rising)."""
    a = _wall_distance(x, dx, hx)
    b = _wall_distance(y, dy, hy)
    t = max((zmax - z) / dz, 0.0) if dz > 0.0 else math.inf
    return a, b, min(a, b), t


@compiled
def setup_ray(k, x, y, z, dx, dy, dz, hx, hy, zmax, eps, rel, o32, tq, top):
    """Slot k of a segment's Embree input for the ray at (x, y, z) along (dx, dy, dz): float32
    origin ``o32[k]`` (kept strictly inside the tile, ``_strictly_inside``), tfar
    ``tq[k]`` = min(wall distance, distance to zmax when rising)·(1 + rel) + eps (float32; inf
    beyond float32) and ``top[k]``: whether it rises to the top no later than a wall."""
    _, _, w, t = _segment_bounds(x, y, z, dx, dy, dz, hx, hy, zmax)
    tq[k] = np.float32(min(w, t) * (1.0 + rel) + eps)
    top[k] = t <= w and dz > 0.0  # a vertical falling ray has t = w = inf
    o32[k, 0] = _strictly_inside(np.float32(x), np.float32(hx))
    o32[k, 1] = _strictly_inside(np.float32(y), np.float32(hy))
    o32[k, 2] = np.float32(z)


@compiled
def _strictly_inside(v, half):
    """A float32 coordinate moved (by one ulp at most) off the tile's walls ±half into the
    tile. A ray exactly on the wall runs along the mesh's boundary edge, which Embree's
    watertight test can give to the absent neighbouring triangle: measured, 23 of 10⁹ primary
    rays on the bench mesh (starts within half an ulp of +L/2 round onto the wall) leaked
    through the surface before this."""
    if v >= half:
        return np.nextafter(half, np.float32(0.0))
    if v <= -half:
        return np.nextafter(-half, np.float32(0.0))
    return v


@compiled
def segment_setup(rays, d32, box, rel, status, o32, d32k, tq, keep, top):
    """First half of one segment of the periodic walk (``periodic_walk.walk_columns``).

    Live ray i (global index ``live[i]``) at (ox, oy, oz)[i] with direction (dx, dy, dz)[j]
    (j = 0 if ``shared`` else i) and float32 copy ``d32[j]``: a ray rising from at or above
    ``zmax`` has escaped (``status`` ← ESCAPED); every other ray gets slot k of the Embree
    input (``setup_ray``; direction ``d32k[k]`` unless shared) and ``keep[k]`` = i.
    Returns k, the number of rays to trace. ``rays``: ``WalkRays``; ``box``: ``WalkBox``;
    ``rel``: the relative tfar margin."""
    live, ox, oy, oz, dx, dy, dz, shared = rays
    hx, hy, zmax, _, eps = box
    k = 0
    for i in range(len(live)):
        j = 0 if shared else i
        if dz[j] > 0.0 and oz[i] >= zmax:
            status[live[i]] = ESCAPED
            continue
        setup_ray(k, ox[i], oy[i], oz[i], dx[j], dy[j], dz[j], hx, hy, zmax, eps, rel, o32, tq, top)
        if not shared:
            d32k[k, 0] = d32[i, 0]
            d32k[k, 1] = d32[i, 1]
            d32k[k, 2] = d32[i, 2]
        keep[k] = i
        k += 1
    return k


@vectorised
def falling_first_segment(x, y, z, dx, dy, dz, shared, hx, hy, zmax, eps, rel, o32, tq, keep, top):
    """``segment_setup`` for the first segment of falling rays (d_z < 0) that all start
    inside the tile, along (dx, dy, dz)[j] (j = 0 if ``shared`` else i): none escapes, so
    ray i takes slot i (``keep[i]`` = i). In loops the compiler vectorises: the same
    ``_segment_bounds`` and float32 arithmetic as ``setup_ray``, the walls' inner float32
    neighbours computed once (``_strictly_inside``). Returns the number of rays."""
    hx32, hy32 = np.float32(hx), np.float32(hy)
    ix = np.nextafter(hx32, np.float32(0.0))
    iy = np.nextafter(hy32, np.float32(0.0))
    for i in range(len(x)):
        j = 0 if shared else i
        _, _, w, t = _segment_bounds(x[i], y[i], z[i], dx[j], dy[j], dz[j], hx, hy, zmax)
        tq[i] = np.float32(min(w, t) * (1.0 + rel) + eps)
        top[i] = t <= w and dz[j] > 0.0
        keep[i] = i
    for i in range(len(x)):
        u, v = np.float32(x[i]), np.float32(y[i])
        u = ix if u >= hx32 else (-ix if u <= -hx32 else u)
        v = iy if v >= hy32 else (-iy if v <= -hy32 else v)
        o32[i, 0], o32[i, 1], o32[i, 2] = u, v, np.float32(z[i])
    return len(x)


@vectorised
def first_segment_hits(pid, tfar, ox, oy, oz, dx, dy, dz, shared, status, prim, px, py, pz):
    """``segment_finish``'s hits for the first segment of an intersect query whose slot i is
    ray i (``first=``): where ``pid[i]`` ≥ 0, status HIT, ``prim`` and the float64 point
    o + t·d (direction j = 0 if ``shared`` else i), in a loop the compiler vectorises; the
    rays without a hit are left to ``segment_finish``."""
    for i in range(len(pid)):
        j = 0 if shared else i
        t = np.float64(tfar[i])
        hit = pid[i] >= 0
        status[i] = HIT if hit else status[i]
        prim[i] = pid[i] if hit else prim[i]
        px[i] = ox[i] + t * dx[j]
        py[i] = oy[i] + t * dy[j]
        pz[i] = oz[i] + t * dz[j]


@compiled
def segment_finish(
    k, pid, tfar, occlusion, keep, top, rays, falling_shared, d32k, box, result, nxt
):
    """Second half of a segment: Embree's answers ``pid`` (primID or geomID, −1 = none) and
    ``tfar`` (float32, intersect queries) for the k traced rays of ``segment_setup``.

    A hit sets ``status`` ← HIT and, for intersect queries, ``prim`` and the float64 point
    o + t·d (``px``, ``py``, ``pz``, by global index). A ray without a hit whose top is no
    farther than its nearer wall (``top``) has escaped (not for ``falling_shared``: one shared
    falling direction never reaches the top); for the others the segment's distances are
    recomputed (``_segment_bounds``, as in the setup): a ray not rising that would leave below
    zmin − eps (or one that never meets a wall) has left the relief through its bottom
    (MISSED: a leak, or for light refracted into a dielectric its escape into the medium); a
    rising ray (one lit from below the relief) and the others re-enter through the
    opposite wall at the same height: the wall point, clipped into the tile, moved to
    −copysign(half, d) on the axis (or axes) whose wall it reached. The re-entering rays are
    written compacted to
    ``nlive``/``nox``/``noy``/``noz`` (and ``ndx``/``ndy``/``ndz``/``nd32`` unless shared).
    Returns their number. ``rays``: ``WalkRays``; ``box``: ``WalkBox``; ``result``:
    ``WalkResult`` (status, prim, px, py, pz); ``nxt``: ``NextSegment`` (nlive, nox, noy,
    noz, ndx, ndy, ndz, nd32)."""
    live, ox, oy, oz, dx, dy, dz, shared = rays
    hx, hy, zmax, zmin, eps = box
    status, prim, px, py, pz = result
    nlive, nox, noy, noz, ndx, ndy, ndz, nd32 = nxt
    m = 0
    for q in range(k):
        i = keep[q]
        g = live[i]
        j = 0 if shared else i
        if pid[q] >= 0:
            status[g] = HIT
            if not occlusion:
                prim[g] = pid[q]
                t = np.float64(tfar[q])
                px[g] = ox[i] + t * dx[j]
                py[g] = oy[i] + t * dy[j]
                pz[g] = oz[i] + t * dz[j]
            continue
        if not falling_shared and top[q]:
            status[g] = ESCAPED
            continue
        a, b, w, _ = _segment_bounds(ox[i], oy[i], oz[i], dx[j], dy[j], dz[j], hx, hy, zmax)
        x = ox[i] + w * dx[j]
        y = oy[i] + w * dy[j]
        z = oz[i] + w * dz[j]
        if (dz[j] <= 0.0 and z < zmin - eps) or not math.isfinite(w):
            status[g] = MISSED
            continue
        x = min(max(x, -hx), hx)  # rounding along the wall
        y = min(max(y, -hy), hy)
        if a <= w:
            x = -math.copysign(hx, dx[j])
        if b <= w:
            y = -math.copysign(hy, dy[j])
        nlive[m] = g
        nox[m] = x
        noy[m] = y
        noz[m] = z
        if not shared:
            ndx[m] = dx[j]
            ndy[m] = dy[j]
            ndz[m] = dz[j]
            nd32[m, 0] = d32k[q, 0]
            nd32[m, 1] = d32k[q, 1]
            nd32[m, 2] = d32k[q, 2]
        m += 1
    return m
