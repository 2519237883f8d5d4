"""The periodic walk: rays followed through the infinite repetition of one tile, one Embree
call per segment (``Tracer``'s scene) between two compiled passes over the live rays
(``segments.segment_setup``/``segment_finish``: float32 inputs and tfar; hits, escapes and
wall re-entries). Embree gets a single direction when all rays share it, and the rays still
live after a segment (those re-entering through a wall; most finish in the first) are
compacted for the next.

On a tracer with a heightfield grid (``Tracer.grid``) the same query walks each ray on the
grid instead (``heightfield_caster.cast_columns``, in float64, from the side of the surface
its start lies on): the same statuses, the facet Embree finds but for rays within float32
rounding of an edge, the hit on the facet's plane."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from microsim.jit import read_only

from .engine import codes, segments
from .heightfield_caster import cast_columns
from .scratch import WorkArray, WorkColumns

__all__ = ["TFAR_REL", "ColumnHits", "walk_columns"]

TFAR_REL = 4e-7  # a segment is traced a hair beyond its exit (float32 rounding)


class ColumnHits(NamedTuple):
    """First hits of rays on per-axis columns: ``status`` (N,) int8 (``codes``: HIT, ESCAPED,
    UNRESOLVED, MISSED), ``prim`` (N,) int32 face index (−1 without a hit) and ``point`` (3
    columns (N,), undefined where status is not HIT); ``prim`` and ``point`` are None for
    occlusion queries."""

    status: np.ndarray
    prim: np.ndarray | None
    point: list | None


# this thread's work arrays (``scratch``): one walk's per-segment rays (the next segment's in
# two generations)
_WALK_O32 = WorkArray("walk-o32", np.float32, columns=3)
_WALK_D32 = WorkArray("walk-d32", np.float32, columns=3)
_WALK_TFAR = WorkArray("walk-tfar", np.float32)
_WALK_KEEP = WorkArray("walk-keep", np.int64)
_WALK_TOP = WorkArray("walk-top", np.bool_)
_NEXT_LIVE = WorkArray("walk-next-live", np.int64, generations=2)
_NEXT_START = WorkColumns("walk-next-start", generations=2)
_NEXT_DIRECTION = WorkColumns("walk-next-direction", generations=2)
_NEXT_D32 = WorkArray("walk-next-d32", np.float32, columns=3, generations=2)
_NO_TFAR = np.empty(0, dtype=np.float32)
_IDENTITY = np.arange(0, dtype=np.int64)


def _identity(n: int) -> np.ndarray:
    """0 … n − 1 (int64), a read-only view of one shared array grown when needed (a fresh
    np.arange of a chunk faults in its pages on every walk)."""
    global _IDENTITY
    if len(_IDENTITY) < n:
        grown = np.arange(max(n, 2 * len(_IDENTITY)), dtype=np.int64)
        grown.flags.writeable = False
        _IDENTITY = grown
    return _IDENTITY[:n]


class _SegmentInput(NamedTuple):
    """One segment's Embree input: ``k`` rays, float32 origins ``o32``, tfar ``tq``, the ray
    slot each came from (``keep``), whether it starts at the top (``top``) and its float32
    directions ``d32`` (unused when shared)."""

    k: int
    o32: np.ndarray
    tq: np.ndarray
    keep: np.ndarray
    top: np.ndarray
    d32: np.ndarray


def _wrapped_starts(tracer, x, first) -> list:
    """The start columns ``x`` as contiguous float64, wrapped into the tile unless ``first``
    is given (its rays all lie in it)."""
    x = [np.ascontiguousarray(c, dtype=np.float64) for c in x]
    if first is None and not tracer.holds(x):
        for a in (0, 1):
            h = tracer.half[a]
            out = (x[a] < -h) | (x[a] >= h)
            x[a] = np.where(out, np.mod(x[a] + h, 2 * h) - h, x[a])
    return x


def walk_columns(tracer, x, d, d32, occlusion: bool, first=None, wraps=None) -> ColumnHits:
    """Rays from origins ``x`` (3 arrays (N,), float64, wrapped into the tile here) along
    ``d`` (3 arrays (N,) or 3 floats shared by all rays) with their float32 (N, 3) (or
    (1, 3)) copy ``d32``, walked through the periodic repetition of ``tracer``'s tile: their
    first hits, or for ``occlusion`` only whether they escape (``ColumnHits``).

    ``first``: the first segment's Embree input (o32, tq, keep, top) already set up by the
    caller exactly as ``segment_setup`` would from these rays, which then all lie in the
    tile and are all traced (``primary.tabled_primary``, ``segments.falling_first_segment``;
    unused on a grid).
    ``wraps``: the wrap cap (segments − 1) instead of ``tracer.max_wraps``."""
    if tracer.grid is not None:
        return _grid_columns(tracer, x, d, occlusion, wraps)
    n = len(x[0])
    shared = np.isscalar(d[0])
    x = _wrapped_starts(tracer, x, first)
    if shared:
        d = [np.array([float(c)]) for c in d]
    else:
        d = [np.ascontiguousarray(c, dtype=np.float64) for c in d]
    d32 = np.ascontiguousarray(d32, dtype=np.float32)
    falling_shared = bool(shared and d[2][0] <= 0)
    hits = 0 if occlusion else n  # prim and point are not kept for occlusion queries
    result = segments.WalkResult(
        np.full(n, codes.UNRESOLVED, dtype=np.int8),
        np.full(hits, -1, dtype=np.int32),
        *(np.empty(hits) for _ in range(3)),
    )
    live = _identity(n)  # read only: the next segment's live rays are a new array
    # per-segment work arrays (this thread's, reused; sized for the first, largest segment)
    work = (_WALK_O32(n), _WALK_TFAR(n), _WALK_KEEP(n), _WALK_TOP(n), _WALK_D32(0 if shared else n))
    hx, hy = (float(c) for c in tracer.half)
    box = segments.WalkBox(hx, hy, float(tracer.zmax), float(tracer.zmin), float(tracer.eps))
    for segment in range((tracer.max_wraps if wraps is None else int(wraps)) + 1):
        if live.size == 0:
            break
        rays = segments.WalkRays(live, *x, *d, shared)
        if segment == 0 and first is not None:
            seg = _SegmentInput(n, *first, d32)
        else:
            o32, tq, keep, top, d32k = work
            k = segments.segment_setup(
                rays, d32, box, TFAR_REL, result.status, o32, d32k, tq, keep, top
            )
            seg = _SegmentInput(k, o32, tq, keep, top, d32k)
        if seg.k == 0:
            break
        k = seg.k
        pid, tfar = tracer.scene.run(
            seg.o32[:k], d32 if shared else seg.d32[:k], seg.tq[:k], occlusion
        )
        tfar = _NO_TFAR if occlusion else tfar
        if segment == 0 and first is not None and not occlusion:
            seg, pid, tfar = _first_segment_misses(seg, pid, tfar, rays, result)
        nr = _next_segment(seg.k, segment % 2, shared)
        m = segments.segment_finish(
            seg.k, pid, tfar, occlusion, seg.keep, seg.top, rays, falling_shared, seg.d32, box,
            result, nr,
        )  # fmt: skip
        live, x = read_only(nr.live[:m]), [nr.x[:m], nr.y[:m], nr.z[:m]]
        if not shared:
            d, d32 = [nr.dx[:m], nr.dy[:m], nr.dz[:m]], nr.d32[:m]
    if occlusion:
        return ColumnHits(result.status, None, None)
    return ColumnHits(result.status, result.prim, [result.x, result.y, result.z])


def _grid_columns(tracer, x, d, occlusion: bool, wraps) -> ColumnHits:
    """``walk_columns`` on ``tracer``'s heightfield grid (``heightfield_caster.cast_columns``)."""
    x = [np.ascontiguousarray(c, dtype=np.float64) for c in x]
    shared = np.isscalar(d[0])
    if shared:
        d = [np.array([float(c)]) for c in d]
    else:
        d = [np.ascontiguousarray(c, dtype=np.float64) for c in d]
    n = len(x[0])
    hits = 0 if occlusion else n
    out = segments.WalkResult(
        np.empty(n, dtype=np.int8),
        np.empty(hits, dtype=np.int32),
        *(np.empty(hits) for _ in range(3)),
    )
    cap = tracer.max_wraps if wraps is None else int(wraps)
    grid = tracer.grid
    cast_columns(
        *x,
        *d,
        shared,
        grid.geometry(tracer.zmin, tracer.zmax, cap),
        grid.cell_min,
        cap,
        occlusion,
        out,
    )
    if occlusion:
        return ColumnHits(out.status, None, None)
    return ColumnHits(out.status, out.prim, [out.x, out.y, out.z])


def _first_segment_misses(seg: _SegmentInput, pid, tfar, rays, result) -> tuple:
    """The hits of a first segment set up by the caller (slot i is ray i and most rays hit:
    primaries), written vectorised; (the segment reduced to its misses, their pid, tfar),
    left to ``segment_finish``."""
    segments.first_segment_hits(pid, tfar, *rays[1:], *result)
    rest = np.flatnonzero(pid < 0)
    d32 = seg.d32 if rays.shared else seg.d32[rest]
    misses = _SegmentInput(len(rest), None, None, seg.keep[rest], seg.top[rest], d32)
    return misses, pid[rest], tfar[rest]


def _next_segment(k: int, generation: int, shared: bool) -> segments.NextSegment:
    """This thread's arrays for the next segment's rays, at most ``k``, in ``generation`` (the
    one written by this segment, read by the next)."""
    return segments.NextSegment(
        _NEXT_LIVE(k, generation),
        *_NEXT_START(k, generation),
        *_NEXT_DIRECTION(0 if shared else k, generation),
        _NEXT_D32(0 if shared else k, generation),
    )
