"""What walking a tile's masking rays with its primaries saves on the per-ray path of a
heightfield grid, and what the masking rays cost: ns per primary ray of
``primary.cast_traced_primary`` (the grid walk, the per-ray pass and the masking rays' walk,
tile by tile) against the same three steps each over the whole chunk in turn
(``Tracer.cast_falling``, ``primary.traced_primary``, ``MaskingRays.trace``), and tile by tile
with no masking ray (the slope bound set to 0, so that every rising reflection counts as
escaping: a timing of the walk and the per-ray pass alone, not a result), on ``bench``'s
Gaussian field (σ = 1.2, ℓ = 8 cells) at n² points, aluminium at θi = 30°, 1 thread: the chunks
(2¹⁶ rays each, as ``simulate`` cuts them) of a run of ``rays`` stratified rays, the ways
alternating, four rounds; in turn and tile by tile write the same bits
(tests/test_heightfield_caster.py). Tile by tile also with the coarse test's first cell decided
by its bounds alone, not walked exactly (``HorizonGrid.walked`` off: the same results, as
tests/test_tracer.py checks).
The grid walk alone (``Tracer.cast_falling``) is timed too: what a ray's first hit costs as the
tile grows at a given ray count. Then, on the first chunk, what the masking rays are: the
share of primaries whose reflection rises less steeply than the tile's steepest facet
(``Tracer.rise_bound``, printed) and is tested on the coarse grid
(``engine.horizon.horizon_clear``) and of those the share its first test, the steepest facet
near the start (``HorizonGrid.nearby``), clears, and what the test costs per ray; of those
walked on the grid (and how many would be with the first cell's bounds alone), of those
masked, and of the walked ones whose start already fails the coarse grid's first cell (the ray
rises less steeply than that cell's steepest facet, ``cslope``), and their elevations above
the horizon.
docs/performance.md quotes it.

    .venv/bin/python tools/per_ray_locality.py [n] [rays]      (defaults: 4096 1048576)
"""

import dataclasses
import sys
import time

import numpy as np

from microsim.app.bench import BenchConfig, _bins, _surface
from microsim.jit import TILE
from microsim.sim import simulate
from microsim.sim.engine import primary, segments
from microsim.sim.engine.horizon import CLEAR_MARGIN
from microsim.sim.ledger import MASKED, SINGLE
from microsim.sim.masking_rays import FROM_ESCAPE, MaskingRays, segment_geometry
from microsim.sim.streams import BLOCK, chunk_origins
from microsim.sim.tracer_cache import tracer_for
from microsim.vectors import spherical_deg

THETA = 30.0
CHUNK_BLOCKS = 16  # 2¹⁶ rays: simulate's default chunk
ROUNDS = 4


def main(n: int = 4096, rays: int = 2**20) -> None:
    surface = _surface(dataclasses.replace(BenchConfig(), n=n))
    simulate(surface, "aluminium", THETA, rays=BLOCK, bins=_bins(), threads=1)  # the tracer
    tracer = tracer_for(surface, "traced")[0]
    wi = spherical_deg(THETA, 0.0)
    down = [-float(c) for c in wi]
    blocks = -(-rays // BLOCK)
    chunks = [
        _origins(tracer, rays, range(b, min(b + CHUNK_BLOCKS, blocks)))
        for b in range(0, blocks, CHUNK_BLOCKS)
    ]
    m = len(chunks[0][0])
    ledger = primary.TracedLedger(np.empty(m, np.int8), np.empty(m), *(np.empty(m) for _ in "xyz"))
    shared = tuple(np.array([float(c)]) for c in wi)
    geometry = segment_geometry(tracer)

    def in_turn(x):
        mask, k = _walk_and_pass(tracer, x, down, shared, geometry, ledger)
        mask.trace(tracer, k, ledger.status)

    def fused(x, slope=tracer.rise_bound, hz=tracer.horizon):
        primary.cast_traced_primary(
            tuple(x), tuple(down), tracer.grid_walk(x, down), tracer.grid.cell_min,
            tracer.facets, slope, hz, tracer.groove_clear, geometry,
            ledger, MaskingRays.work(TILE).kernel_args(), FROM_ESCAPE,
        )  # fmt: skip

    bounds_alone = tracer.horizon._replace(walked=False)
    ways = {
        "grid walk alone": lambda x: tracer.cast_falling(x, down),
        "in turn": in_turn,
        "tile by tile": fused,
        "first cell bound": lambda x: fused(x, hz=bounds_alone),
        "no masking ray": lambda x: fused(x, 0.0),
    }
    for way in ways.values():  # compiled and warm
        way(chunks[0])
    times = {label: [] for label in ways}
    for _ in range(ROUNDS):
        for label, way in ways.items():
            t0 = time.perf_counter()
            for x in chunks:
                way(x)
            times[label].append((time.perf_counter() - t0) / (len(chunks) * m) * 1e9)
    print(f"{n}² Gaussian field, {rays:,} rays in chunks of {m:,}, θi = {THETA}°, 1 thread")
    for label, ns in times.items():
        print(f"  {label:16s} ns per ray: best {min(ns):.1f}, rounds {[round(t, 1) for t in ns]}")
    _masking_rays(tracer, chunks[0], down, shared, geometry)


def _walk_and_pass(tracer, x, down, shared, geometry, ledger) -> tuple:
    """The grid walk of the primaries from ``x`` and the per-ray pass over the whole chunk
    (``primary.traced_primary``, into ``ledger``): (their ``MaskingRays``, how many)."""
    hs, prim, p = tracer.cast_falling(x, down)
    mask = MaskingRays.work(len(x[0]))
    k = primary.traced_primary(
        segments.WalkResult(hs, prim, *p), shared, tracer.facets, True, tracer.rise_bound,
        tracer.horizon, tracer.groove_clear, geometry, ledger, mask.kernel_args(),
    )  # fmt: skip
    return mask, k


def _masking_rays(tracer, x, down, shared, geometry) -> None:
    """Print what the masking rays of the primaries from ``x`` are (module docstring)."""
    m = len(x[0])
    ledger = primary.TracedLedger(np.empty(m, np.int8), np.empty(m), *(np.empty(m) for _ in "xyz"))
    hz = tracer.horizon
    try:  # how many would be walked with the coarse test's first cell decided by its bounds
        tracer.horizon = hz._replace(walked=False)
        bounded = _walk_and_pass(tracer, x, down, shared, geometry, ledger)[1]
    finally:
        tracer.horizon = hz
    mask, k = _walk_and_pass(tracer, x, down, shared, geometry, ledger)
    wo = np.stack([ledger.wox, ledger.woy, ledger.woz]).astype(np.float32).astype(np.float64)
    tested = (ledger.status == SINGLE) & ~(
        wo[2] > CLEAR_MARGIN * tracer.rise_bound * np.hypot(wo[0], wo[1])
    )
    hz = tracer.horizon
    hits = [c[tested] for c in tracer.cast_falling(x, down)[2]]  # the same walk again
    nearby = _nearby_clears(tracer, hits, ledger, tested)
    test_ns = _horizon_ns(tracer, hits, ledger, tested)
    (sx, sy, sz), (dx, dy, dz) = ([c[:k] for c in cols] for cols in (mask.start, mask.d))
    cx = np.floor((sx - hz.x0) / hz.cw).astype(np.int64) % hz.cmax.shape[1]
    cy = np.floor((sy - hz.y0) / hz.ch).astype(np.int64) % hz.cmax.shape[0]
    first = (sz <= hz.cmax[cy, cx] + hz.tol) & ~(
        dz / np.hypot(dx, dy) > hz.cslope[cy, cx] * CLEAR_MARGIN
    )
    rise = np.degrees(np.arctan2(dz, np.hypot(dx, dy)))
    deciles = [f"{q:.1f}" for q in np.percentile(rise, [10, 50, 90])]
    mask.trace(tracer, k, ledger.status)
    masked = ledger.status[mask.ray[:k]] == MASKED
    print(
        f"  masking rays of {m:,} primaries (slope bound {tracer.rise_bound:.3f}): "
        f"{tested.mean():.1%} tested on the coarse grid ({test_ns:.0f} ns each; {nearby:.1%} "
        f"of them cleared by the steepest facet nearby), "
        f"{k / m:.2%} walked ({bounded / m:.2%} with the first cell's bounds alone), "
        f"{masked.sum() / m:.2%} masked; of the walked, {first.mean():.1%} "
        f"fail the coarse grid's first cell and {1 - masked.mean():.1%} escape; their "
        f"elevations' 10th, 50th and 90th percentiles {', '.join(deciles)}°"
    )


def _nearby_clears(tracer, hits, ledger, tested) -> float:
    """The share of the ``tested`` primaries' masking rays (from their ``hits``, without the
    facet lift) that the coarse grid's ``nearby`` bound clears alone: its cell maxima and
    slopes set to inf, so that ``horizon_clear``'s walk over the grid clears nothing."""
    hz = tracer.horizon
    inf = np.full_like(hz.cmax, np.inf)
    start = np.column_stack(hits)
    d = np.column_stack([ledger.wox[tested], ledger.woy[tested], ledger.woz[tested]])
    try:
        tracer.horizon = hz._replace(cmax=inf, cslope=inf)
        return float(tracer.clears_horizon(start, d).mean())
    finally:
        tracer.horizon = hz


def _horizon_ns(tracer, hits, ledger, tested) -> float:
    """ns per ray of the coarse grid's whole test (``Tracer.clears_horizon``) on the
    ``tested`` primaries' masking rays from their ``hits``, best of ``ROUNDS`` calls."""
    start = np.column_stack(hits)
    d = np.column_stack([ledger.wox[tested], ledger.woy[tested], ledger.woz[tested]])
    best = np.inf
    for _ in range(ROUNDS + 1):  # the first compiles or loads the kernel
        t0 = time.perf_counter()
        tracer.clears_horizon(start, d)
        best = min(best, time.perf_counter() - t0)
    return best / max(len(d), 1) * 1e9


def _origins(tracer, rays: int, blocks) -> list:
    """Copies of the origin columns of ``blocks`` of a run of ``rays`` stratified rays."""
    return [c.copy() for c in chunk_origins(tracer, rays, blocks, (0, 0, 0), False)[0]]


if __name__ == "__main__":
    main(*(int(a) for a in sys.argv[1:3]))
