"""The facet-table path's primary rays drawn and walked in one compiled pass: a chunk's
stratified origins (``streams.StratifiedDraw``) are drawn block by block into scratch of one
block (``origin_kernels.draw_block``) and walked on the heightfield grid at once, with their
facet look-ups (``primary.tabled_tiles``). The bits are those of ``streams.chunk_origins``
followed by ``primary.cast_tabled_primary``; what changes is that a chunk's origins (24 bytes
a ray) and their uniform numbers (16) are never written out whole, so they do not push the
walk's cells and the look-ups' table out of the caches."""

from __future__ import annotations

import numpy as np

from microsim.jit import allocating

from .engine import primary
from .origin_kernels import draw_block

__all__ = ["cast_drawn_tabled"]


@allocating
def cast_drawn_tabled(draw, block, down, grid, ahead, table, hz, geometry, out, masking):
    """``primary.cast_tabled_primary`` of the rays of ``draw`` (``streams.StratifiedDraw``,
    blocks of ``block`` rays), their origins drawn one block at a time. Returns the number of
    masking rays set up, or −1 as soon as an origin falls outside the tile (x = Lx/2 or
    y = Ly/2 after rounding; ``Tracer.grid_walk`` leaves such chunks to ``periodic_walk``, so
    the caller traces the chunk from its origin columns instead; what was written is then
    overwritten). The other arguments as ``cast_tabled_primary``'s."""
    u, x, y = np.empty(2 * block), np.empty(block), np.empty(block)
    z = np.full(block, draw.z)
    scratch = primary.tabled_scratch()
    m = int(0)  # a plain int, not a literal: one compiled ``tabled_tiles`` (``microsim.jit``)
    for k in range(0, draw.n, block):
        b = draw_block(draw, k, block, u, x, y)
        for q in range(b):
            if not (-draw.hx <= x[q] < draw.hx and -draw.hy <= y[q] < draw.hy):
                return -1
        origins = (x[:b], y[:b], z[:b])
        m = primary.tabled_tiles(
            origins, down, grid, ahead, table, hz, geometry, out, masking, k, m, scratch
        )
    return m
