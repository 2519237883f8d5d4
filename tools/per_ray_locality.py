"""What walking a tile's masking rays with its primaries saves on the per-ray path of a
heightfield grid: ns per primary ray of ``primary.cast_traced_primary`` (the grid walk, the
per-ray pass and the masking rays' walk, tile by tile) against the same three steps each over
the whole chunk in turn (``Tracer.cast_falling``, ``primary.traced_primary``,
``MaskingRays.trace``), on ``bench``'s Gaussian field (σ = 1.2, ℓ = 8 cells) at n² points,
aluminium at θi = 30°, 1 thread: the chunks (2¹⁶ rays each, as ``simulate`` cuts them) of a
run of ``rays`` stratified rays, the two alternating, four rounds; both write the same bits
(tests/test_heightfield_caster.py). The grid walk alone (``Tracer.cast_falling``) is timed
too: what a ray's first hit costs as the tile grows at a given ray count. docs/performance.md
quotes it.

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
        hs, prim, p = tracer.cast_falling(x, down)
        mask = MaskingRays.work(m)
        k = primary.traced_primary(
            segments.WalkResult(hs, prim, *p), shared, tracer.facets, True, tracer.rise_bound,
            tracer.horizon, tracer.groove_clear, geometry, ledger, mask.kernel_args(),
        )  # fmt: skip
        mask.trace(tracer, k, ledger.status)

    def fused(x):
        primary.cast_traced_primary(
            tuple(x), tuple(down), tracer.grid_walk(x, down), tracer.grid.cell_min,
            tracer.facets, tracer.rise_bound, tracer.horizon, tracer.groove_clear, geometry,
            ledger, MaskingRays.work(TILE).kernel_args(), FROM_ESCAPE,
        )  # fmt: skip

    ways = {
        "grid walk alone": lambda x: tracer.cast_falling(x, down),
        "in turn": in_turn,
        "tile by tile": fused,
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
        print(f"  {label:15s} ns per ray: best {min(ns):.1f}, rounds {[round(t, 1) for t in ns]}")


def _origins(tracer, rays: int, blocks) -> list:
    """Copies of the origin columns of ``blocks`` of a run of ``rays`` stratified rays."""
    return [c.copy() for c in chunk_origins(tracer, rays, blocks, (0, 0, 0), False)[0]]


if __name__ == "__main__":
    main(*(int(a) for a in sys.argv[1:3]))
